"""An independent TF listener (as RViz or Foxglove): subscribes to /tf_static (transient local, late join), /tf and
/hexa/external_wrench with tf2's QoS, and prints one JSON line once it holds every frame asked for and a wrench.

Usage: tf_listener_peer.py TIMEOUT_S FRAME [FRAME ...]   (also waits for external_joint_torques)
       tf_listener_peer.py TIMEOUT_S --latched              (a late joiner: /tf_static, collision_state and
                                                              trajectory_state, all transient local)
"""
from __future__ import annotations

import json
import sys
import time

from hexa_bringup.rosenv import apply_defaults


def main() -> int:
    apply_defaults()
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from hexa_msgs.msg import CollisionEvent
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from tf2_msgs.msg import TFMessage

    timeout, latched = float(sys.argv[1]), sys.argv[2:] == ["--latched"]
    wanted = {"cam_top_link", "cam_side_link"} if latched else set(sys.argv[2:])
    rclpy.init()
    node = rclpy.create_node("tf_listener_peer")
    static = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    dynamic = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    frames: dict[str, dict] = {}
    wrenches: list[dict] = []

    def on_tf(msg: TFMessage, source: str) -> None:
        for t in msg.transforms:
            tr, q = t.transform.translation, t.transform.rotation
            frames[t.child_frame_id] = {"parent": t.header.frame_id, "source": source,
                                        "t": [tr.x, tr.y, tr.z], "q": [q.x, q.y, q.z, q.w],
                                        "stamp": t.header.stamp.sec + 1e-9 * t.header.stamp.nanosec}

    def on_wrench(m: WrenchStamped) -> None:
        f = m.wrench.force
        wrenches.append({"frame_id": m.header.frame_id, "force": [f.x, f.y, f.z]})

    node.create_subscription(TFMessage, "/tf_static", lambda m: on_tf(m, "tf_static"), static)
    node.create_subscription(TFMessage, "/tf", lambda m: on_tf(m, "tf"), dynamic)
    node.create_subscription(WrenchStamped, "/hexa/external_wrench", on_wrench, dynamic)
    torques: list[dict] = []
    node.create_subscription(JointState, "/hexa/external_joint_torques",
                             lambda m: torques.append({"name": list(m.name), "effort": list(m.effort)}), dynamic)
    states: dict[str, object] = {}
    node.create_subscription(CollisionEvent, "/hexa/collision_state",
                             lambda m: states.update(collision=[m.event, m.id]), static)
    node.create_subscription(String, "/hexa/trajectory_state", lambda m: states.update(trajectory=m.data), static)

    def done() -> bool:
        if latched:
            return wanted <= frames.keys() and len(states) == 2
        return wanted <= frames.keys() and bool(wrenches) and bool(torques)

    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end and not done():
        rclpy.spin_once(node, timeout_sec=0.1)
    print(json.dumps({"frames": frames, "wrenches": wrenches[-5:], "torques": torques[-2:], "states": states,
                      "type": TFMessage.__module__}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0 if done() else 1


if __name__ == "__main__":
    sys.exit(main())
