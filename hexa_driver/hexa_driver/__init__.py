"""hexa_driver: ROS 2 node for the Hexa's serial boards (see docs/driver.md); protocol code is in hexa.protocol."""
