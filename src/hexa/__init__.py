"""hexa: ROS-free core library (robot models, dynamics, singularity, vision, serial protocol, simulator)."""
