"""Reports: metrics and plots of demo runs (ROS-free, from arrays)."""
