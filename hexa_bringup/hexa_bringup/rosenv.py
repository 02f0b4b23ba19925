"""The ROS environment of hexa processes; it lives in the shared glue package (hexa_ros.env)."""
from hexa_ros.env import PROFILE, RMW, apply_defaults, defaults, ros_env

__all__ = ["PROFILE", "RMW", "apply_defaults", "defaults", "ros_env"]
