"""One ROS_DOMAIN_ID per running test, held by an flock on /tmp so concurrent test runs never share a domain
(hexa_ros.env.held_ros_domain, which `hexa bench graph` uses too)."""
from hexa_ros.env import NoFreeDomain, held_ros_domain

__all__ = ["NoFreeDomain", "held_ros_domain"]
