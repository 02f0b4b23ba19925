"""Peer for the trajectory-node test: waits for joint_commands, sends a collision START, checks the hold, calls
~/resume; prints a JSON summary."""
from __future__ import annotations

import json
import sys
import time

from hexa_bringup.rosenv import apply_defaults


def main() -> int:
    apply_defaults()
    import rclpy
    from hexa_msgs.msg import CollisionEvent
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    rclpy.init()
    node = rclpy.create_node("trajectory_peer", namespace="/hexa")
    cmds: list[tuple[float, list[float]]] = []
    states: list[str] = []
    node.create_subscription(JointState, "joint_commands",
                             lambda m: cmds.append((time.monotonic(), list(m.position))), 10)
    node.create_subscription(String, "trajectory_state", lambda m: states.append(m.data), 10)
    pub = node.create_publisher(CollisionEvent, "collision",
                                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    cli = node.create_client(Trigger, "/hexa/trajectory/resume")
    out = {}

    def spin(sec: float) -> None:
        end = time.monotonic() + sec
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.02)

    deadline = time.monotonic() + 30
    while "running" not in states and time.monotonic() < deadline:
        spin(0.1)
    spin(0.5)
    out["running_moves"] = max(abs(a - b) for a, b in zip(cmds[-1][1], cmds[-10][1]))
    pub.publish(CollisionEvent(event=CollisionEvent.START, id=1, axis=0, axis_name="x", value=3.0, peak=3.0))
    spin(1.0)
    n0 = len(cmds)
    spin(1.0)
    held = cmds[n0:]
    out["held_state"] = states[-1]
    out["held_moves"] = max(max(abs(a - b) for a, b in zip(c[1], held[0][1])) for c in held)
    cli.wait_for_service(timeout_sec=10)
    fut = cli.call_async(Trigger.Request())
    while not fut.done():
        spin(0.05)
    out["resume"] = fut.result().success
    spin(1.5)
    out["after_resume_state"] = states[-1]
    out["after_resume_moves"] = max(abs(a - b) for a, b in zip(cmds[-1][1], cmds[-10][1]))
    print(json.dumps(out), flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
