"""Simulated 3UPS+RPU node for the SRM (seed 003 sec 3.1): actuators under their inner loop, pose by
branch-continuous FK, optional push by hand; publishes what the 3D tracking system and encoders would.

Thin adapter over hexa.srm.plant / hexa.srm.tracking. Run in /upsrpu. Parameters: `description`,
`initial_pose` [x_m, z_m, theta, psi] (default the description's home), `rate_hz` (100 = 1/t_s; the plant
advances t_s per tick), `push_at` (s after start, < 0 = never), `push_force` (N), `publish_markers` (bool),
`marker_noise` (m, default from the description), `seed`.
Topics: sub `joint_commands` (sensor_msgs/JointState, limb_1..limb_4, metres); pub `pose`
(geometry_msgs/PoseStamped in frame `upsrpu_base`, X_c with the push deflection), `pose_fk` (FK of the encoder
lengths), `joint_states` (position q_c m, velocity m/s, effort tau N), `markers/fixed`, `markers/mobile`
(geometry_msgs/PoseArray in frame `tracking_world`), `/diagnostics`.
"""
from __future__ import annotations

import sys

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

import hexa_ros.node
from hexa_ros import diagnostics, qos
from hexa_ros.conversions import UPSRPU_JOINTS, upsrpu_pose_to_msg_fields
from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param, declare_parameters


def _pose_msg(X: np.ndarray) -> Pose:
    (px, py, pz), (qx, qy, qz, qw) = upsrpu_pose_to_msg_fields(X)
    m = Pose()
    m.position.x, m.position.y, m.position.z = px, py, pz
    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = qx, qy, qz, qw
    return m


def _points_msg(points: np.ndarray, header: Header) -> PoseArray:
    arr = PoseArray(header=header)
    for p in points:
        m = Pose()
        m.position.x, m.position.y, m.position.z = (float(v) for v in p)
        m.orientation.w = 1.0
        arr.poses.append(m)
    return arr


class UpsrpuSimNode(Node):
    """The simulated robot: one plant step of t_s per timer tick."""

    def __init__(self, **kwargs) -> None:
        super().__init__("upsrpu_sim", **kwargs)
        from hexa.robots.upsrpu_description import load_upsrpu
        from hexa.srm.plant import SimulatedUpsrpu, half_sine_push
        from hexa.srm.tracking import tracking_model

        self.desc = load_upsrpu(str(declare_parameters(self, {DESCRIPTION: DESCRIPTION_PARAM})[DESCRIPTION]) or None)
        self.tracking = tracking_model(self.desc)
        v = declare_parameters(self, {
            "initial_pose": Param([float(x) for x in self.desc.home], "x_m (m), z_m (m), theta, psi (rad)"),
            "rate_hz": Param(1.0 / self.desc.t_s, "simulation and publishing rate (Hz)", range=(1.0, 10000.0)),
            "push_at": Param(-1.0, "s at which a 2 s half-sine push starts; < 0 = none", range=(-1.0, 1e6)),
            "push_force": Param(10.0, "N, the push's peak force", range=(0.0, 1000.0)),
            "publish_markers": Param(True, "publish the motion-capture marker positions"),
            "marker_noise": Param(float(self.tracking.marker_noise), "m, marker position noise (1 sigma)",
                                  range=(0.0, 0.1)),
            "seed": Param(0, "noise seed", range=(0, 2**31 - 1))})
        X0 = list(v["initial_pose"])
        if len(X0) != 4:
            raise ValueError(f"parameter initial_pose must have 4 values (x_m, z_m, theta, psi), got {X0}")
        rate, push_at, push_force = float(v["rate_hz"]), float(v["push_at"]), float(v["push_force"])
        self.publish_markers, self.noise = bool(v["publish_markers"]), float(v["marker_noise"])
        self.rng = np.random.default_rng(int(v["seed"]))
        push = half_sine_push(push_at, 2.0, np.array([push_force, 0, 0, 0.1 * push_force])) if push_at >= 0 else None
        self.plant = SimulatedUpsrpu(self.desc, np.array(X0, dtype=float), push=push)
        self.q_d = self.plant.q.copy()
        self.pub_pose = self.create_publisher(PoseStamped, "pose", qos.RELIABLE)
        self.pub_fk = self.create_publisher(PoseStamped, "pose_fk", qos.RELIABLE)
        self.pub_js = self.create_publisher(JointState, "joint_states", qos.RELIABLE)
        self.pub_fixed = self.create_publisher(PoseArray, "markers/fixed", qos.RELIABLE)
        self.pub_mobile = self.create_publisher(PoseArray, "markers/mobile", qos.RELIABLE)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.create_subscription(JointState, "joint_commands", self._on_command, qos.RELIABLE)
        self.rejected = 0
        self.fk_failures = 0
        self.ticks = 0
        self.create_timer(1.0 / rate, self._tick)
        self.create_timer(1.0, self._diagnostics)

    def _on_command(self, msg: JointState) -> None:
        try:
            idx = [list(msg.name).index(n) for n in UPSRPU_JOINTS] if msg.name else list(range(4))
            q = np.array([msg.position[i] for i in idx], dtype=float)
        except (ValueError, IndexError):
            self.rejected += 1
            self.get_logger().warn(f"joint_commands need {UPSRPU_JOINTS}, got {list(msg.name)}",
                                   throttle_duration_sec=2.0)
            return
        if not np.all(np.isfinite(q)):
            self.rejected += 1
            return
        self.q_d = np.clip(q, self.desc.q_min, self.desc.q_max)   # the actuators' own end stops

    def _tick(self) -> None:
        from hexa.kinematics.upsrpu import ForwardKinematicsError
        from hexa.srm.tracking import markers_from_pose

        try:
            s = self.plant.advance(self.q_d, self.desc.t_s)
        except ForwardKinematicsError as exc:
            self.fk_failures += 1
            self.get_logger().error(f"plant FK failed: {exc}", throttle_duration_sec=2.0)
            return
        self.ticks += 1
        stamp = self.get_clock().now().to_msg()
        ps = PoseStamped(pose=_pose_msg(s.X))
        ps.header.stamp, ps.header.frame_id = stamp, "upsrpu_base"
        self.pub_pose.publish(ps)
        self.pub_fk.publish(PoseStamped(header=ps.header, pose=_pose_msg(s.X_kin)))
        js = JointState(name=list(UPSRPU_JOINTS), position=[float(v) for v in s.q],
                        velocity=[float(v) for v in s.q_dot], effort=[float(v) for v in s.tau])
        js.header.stamp = stamp
        self.pub_js.publish(js)
        if self.publish_markers:
            fixed, mobile = markers_from_pose(self.tracking, s.X, self.rng, self.noise)
            world = Header(stamp=stamp, frame_id="tracking_world")
            self.pub_fixed.publish(_points_msg(fixed, world))
            self.pub_mobile.publish(_points_msg(mobile, world))

    def _diagnostics(self) -> None:
        bad = self.fk_failures > 0
        st = diagnostics.status(self.get_fully_qualified_name(), diagnostics.WARN if bad else diagnostics.OK,
                                "FK failures" if bad else "ok",
                                {"sim_time": f"{self.plant.t:.2f}", "ticks": self.ticks,
                                 "rejected_commands": self.rejected, "fk_failures": self.fk_failures})
        self.pub_diag.publish(diagnostics.array(self, [st]))


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(UpsrpuSimNode, "upsrpu-sim", argv)


if __name__ == "__main__":
    sys.exit(main())
