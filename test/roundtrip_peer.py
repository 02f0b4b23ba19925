"""Peer process for the cross-process tests: `pub` publishes samples of every hexa_msgs message (latched);
`sub` receives them and prints one JSON line {type: fields-as-dict}; `collision` publishes one CollisionEvent;
`stream` publishes CollisionEvents numbered 0, 1, ... at 100 Hz."""
from __future__ import annotations

import json
import sys
import time

from hexa_bringup.rosenv import apply_defaults

MESSAGES = ["MotorCurrents", "PlateDetection", "PlateDetections", "Residual", "CollisionEvent", "Contact",
            "ContactWrench", "SingularityIndices"]


def latched_qos():
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def main() -> int:
    apply_defaults()
    import rclpy
    import hexa_msgs.msg as hm
    from msg_samples import sample_message
    from hexa_bringup.msgutil import message_to_dict

    mode = sys.argv[1]
    rclpy.init()
    node = rclpy.create_node(f"roundtrip_{mode}")
    try:
        if mode == "pub":
            pubs = []
            for k, name in enumerate(MESSAGES):
                cls = getattr(hm, name)
                pub = node.create_publisher(cls, f"/roundtrip/{name}", latched_qos())
                pub.publish(sample_message(cls, k + 1))
                pubs.append(pub)
            print("published", flush=True)
            rclpy.spin(node)
        elif mode == "collision":
            from rclpy.qos import QoSProfile, ReliabilityPolicy

            pub = node.create_publisher(hm.CollisionEvent, "/hexa/collision",
                                        QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
            msg = hm.CollisionEvent(event=hm.CollisionEvent.START, id=7, axis=2, axis_name="z", value=3.5, peak=3.5)
            msg.header.frame_id = "base"
            msg.onset.sec = 12
            msg.onset.nanosec = 340_000_000
            while rclpy.ok():  # keep publishing so a late subscriber gets one
                pub.publish(msg)
                rclpy.spin_once(node, timeout_sec=0.1)
        elif mode == "stream":
            from rclpy.qos import QoSProfile, ReliabilityPolicy

            pub = node.create_publisher(hm.CollisionEvent, "/hexa/collision",
                                        QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
            count = [0]

            def tick() -> None:
                pub.publish(hm.CollisionEvent(event=hm.CollisionEvent.START, id=count[0], axis_name="z"))
                count[0] += 1

            node.create_timer(0.01, tick)
            rclpy.spin(node)
        elif mode == "sub":
            got: dict[str, dict] = {}
            for name in MESSAGES:
                cls = getattr(hm, name)
                node.create_subscription(cls, f"/roundtrip/{name}",
                                         lambda m, n=name: got.setdefault(n, message_to_dict(m)), latched_qos())
            deadline = time.monotonic() + float(sys.argv[2] if len(sys.argv) > 2 else 30)
            while len(got) < len(MESSAGES) and time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.1)
            print(json.dumps(got), flush=True)
        else:
            raise SystemExit(f"unknown mode {mode!r}")
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
