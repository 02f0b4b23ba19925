"""A stand-in for "other ROS nodes": subscribes to /hexa/collision and /hexa/contact_wrench with the documented
QoS and types, prints one JSON line per message until killed (SIGINT)."""
from __future__ import annotations

import json
import sys

from hexa_bringup.rosenv import apply_defaults


def main() -> int:
    apply_defaults()
    import rclpy
    from hexa_msgs.msg import CollisionEvent, ContactWrench
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy.init()
    node = rclpy.create_node("other_ros_node")
    reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)

    def on_collision(m: CollisionEvent) -> None:
        print(json.dumps({"topic": "collision", "type": type(m).__module__ + "." + type(m).__name__,
                          "event": m.event, "id": m.id, "axis_name": m.axis_name, "frame_id": m.header.frame_id,
                          "t": m.header.stamp.sec + m.header.stamp.nanosec * 1e-9}), flush=True)

    def on_wrench(m: ContactWrench) -> None:
        print(json.dumps({"topic": "contact_wrench", "type": type(m).__module__ + "." + type(m).__name__,
                          "link": m.link, "chain": m.chain, "frame_id": m.header.frame_id,
                          "force": [m.force.x, m.force.y, m.force.z], "force_model": m.force_model}), flush=True)

    node.create_subscription(CollisionEvent, "/hexa/collision", on_collision, reliable)
    node.create_subscription(ContactWrench, "/hexa/contact_wrench", on_wrench, reliable)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
