"""hexa's shared ROS glue: what every node repeats, written once (the algorithms live in the ROS-free `hexa`)."""
