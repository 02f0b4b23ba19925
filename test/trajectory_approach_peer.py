"""Peer for the trajectory-node approach test: checks that nothing is commanded before a plate pose is measured,
sends a bad pose then a pose away from the trajectory's start, and records the approach; prints a JSON summary."""
from __future__ import annotations

import json
import math
import sys
import time

import numpy as np

from hexa_bringup.rosenv import apply_defaults

OFFSET = np.array([0.015, -0.02, 0.01, 0.04, 0.0, -0.03])   # the measured pose: start pose + this (m, rad)


def main() -> int:
    apply_defaults()
    import rclpy
    import rclpy.duration
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    from hexa.kinematics import hexa6rus
    from hexa.robots.hexa_description import load_hexa
    from hexa.trajectories import TRAJECTORIES
    from hexa.rotations import quaternion_from_matrix

    desc = load_hexa()
    start = np.asarray(TRAJECTORIES["circle"](0.0)[0])
    here = start + OFFSET
    rclpy.init()
    node = rclpy.create_node("trajectory_approach_peer", namespace="/hexa")
    cmds: list[tuple[float, list[float]]] = []
    states: list[str] = []
    node.create_subscription(JointState, "joint_commands",
                             lambda m: cmds.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                                                    list(m.position))), 10)
    node.create_subscription(String, "trajectory_state", lambda m: states.append(m.data), 10)
    pub = node.create_publisher(PoseStamped, "plate_pose", 10)

    def spin(sec: float) -> None:
        end = time.monotonic() + sec
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.02)

    def pose_msg(pose: np.ndarray, quat=None, age: float = 0.0) -> PoseStamped:
        m = PoseStamped()
        m.header.frame_id = "base"
        m.header.stamp = (node.get_clock().now() - rclpy.duration.Duration(seconds=age)).to_msg()
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in pose[:3])
        q = quat or quaternion_from_matrix(hexa6rus.rotation_zyx(*pose[3:]))
        m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = q
        return m

    out: dict = {}
    deadline = time.monotonic() + 30
    while "waiting_for_pose" not in states and time.monotonic() < deadline:
        spin(0.1)
    spin(2.0)                                                  # no pose yet: the arms must not be commanded
    out["commands_before_pose"] = len(cmds)
    out["state_before_pose"] = states[-1] if states else None
    for _ in range(3):                                         # a bad pose (zero quaternion, NaN): rejected
        pub.publish(pose_msg(here, (0.0, 0.0, 0.0, 0.0)))
        pub.publish(pose_msg(np.full(6, math.nan)))
        spin(0.2)
    out["commands_after_bad_pose"] = len(cmds)
    for _ in range(5):                                         # a good pose, but 2 s old: not used
        pub.publish(pose_msg(here, age=2.0))
        spin(0.2)
    out["commands_after_stale_pose"] = len(cmds)
    out["state_after_stale_pose"] = states[-1] if states else None
    deadline = time.monotonic() + 20
    while not cmds and time.monotonic() < deadline:
        pub.publish(pose_msg(here))
        spin(0.1)
    deadline = time.monotonic() + 30
    while "running" not in states[-5:] and time.monotonic() < deadline:
        spin(0.1)
    spin(0.3)
    z = np.array([c[1] for c in cmds])
    t = np.array([c[0] for c in cmds])
    out["first_command_error"] = float(np.abs(z[0] - hexa6rus.inverse_kinematics(desc, here)).max())
    rates = np.abs(np.diff(z, axis=0)) / np.maximum(np.diff(t), 1e-6)[:, None]
    k_run = next(i for i, s in enumerate(states) if s == "running")
    out["saw_approaching"] = "approaching" in states[:k_run]
    n_app = sum(1 for s in states if s == "approaching")
    out["approach_commands"] = n_app
    out["approach_peak_rate"] = float(rates[: max(1, n_app - 1)].max())
    gap = np.abs(z[:n_app] - hexa6rus.inverse_kinematics(desc, start)).max(axis=1)
    out["gap_first"], out["gap_last"] = float(gap[0]), float(gap[-1])
    print(json.dumps(out), flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
