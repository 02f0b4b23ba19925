"""hexa_dynamics: ROS 2 nodes wrapping hexa's dynamics-side core (singularity indices, SRM, observer, RNEA)."""
