"""Type II singularity monitor node (seed 003 sec 2.2-2.3) for the Hexa or the 3UPS+RPU.

Thin adapter over hexa.singularity.SingularityMonitor. Parameters: `robot` ("hexa" | "upsrpu"; default from the
namespace: "upsrpu" when it contains "upsrpu", else "hexa"), `input` ("pose" | "markers"),
`description` (YAML path, default packaged), `det_jd_limit`, `omega_limit` (rad; default Table 2 for the
3UPS+RPU, 1.8 deg and no det limit for the Hexa).
Topics (relative; run in /upsrpu or /hexa): sub `pose` (3UPS+RPU, geometry_msgs/PoseStamped, X_c from the
tracking system) or `plate_pose` (Hexa), or `markers/fixed` + `markers/mobile` (geometry_msgs/PoseArray,
marker positions in the tracking world) with input=markers; pub `singularity` (hexa_msgs/SingularityIndices),
`/diagnostics`.
"""
from __future__ import annotations

import sys

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped
from hexa_msgs.msg import SingularityIndices
from rclpy.node import Node

import hexa_ros.node
from hexa.pose_check import PoseCheck
from hexa.rotations import pose6_from_transform
from hexa.singularity import SingularityMonitor
from hexa.srm.tracking import pose_from_transform
from hexa_ros import diagnostics, qos
from hexa_ros.conversions import points_from_pose_array, pose_fields
from hexa_ros.stamps import to_sec
from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param, declare_parameters


PARAMETERS = {"robot": Param("", "hexa | upsrpu; empty = from the namespace (/hexa, /upsrpu)",
                             choices=("", "hexa", "upsrpu")),
              "input": Param("pose", "what the indices are computed from: pose | markers (3UPS+RPU)",
                             choices=("pose", "markers")),
              DESCRIPTION: DESCRIPTION_PARAM}


class SingularityNode(Node):
    """Publishes det J_D, every Omega_ij, the minimum pair and the near-flag for each measured pose."""

    def __init__(self, **kwargs) -> None:
        super().__init__("singularity", **kwargs)
        v = declare_parameters(self, PARAMETERS)
        robot = str(v["robot"]) or ("upsrpu" if "upsrpu" in self.get_namespace() else "hexa")
        mode, path = str(v["input"]), str(v[DESCRIPTION]) or None
        self.monitor = m = SingularityMonitor(robot, path)
        limits = declare_parameters(self, {   # defaults: the description's limits (seed 003 Table 2)
            "det_jd_limit": Param(float(m.det_jd_limit), "near-singular below this |det J_D|", range=(0.0, 1e12)),
            "omega_limit": Param(float(m.omega_limit), "near-singular below this Omega_ij (rad)", range=(0.0, 1.6))})
        m.det_jd_limit, m.omega_limit = float(limits["det_jd_limit"]), float(limits["omega_limit"])
        self.pub = self.create_publisher(SingularityIndices, "singularity", qos.RELIABLE)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.rejected = 0
        self.published = 0
        # the Hexa's plate poses pass its speed bounds and workspace; the 3UPS+RPU's the generic bounds (its
        # workspace is checked by the indices themselves)
        self.pose_check = PoseCheck.for_hexa(m.desc) if robot == "hexa" else PoseCheck()
        if mode == "markers":
            if robot != "upsrpu":
                raise ValueError("input=markers is only for the 3UPS+RPU")
            from hexa.srm.tracking import MarkerTracker, tracking_model

            self.tracker = MarkerTracker(tracking_model(m.desc))
            self.create_subscription(PoseArray, "markers/fixed", self._on_fixed, qos.RELIABLE)
            self.create_subscription(PoseArray, "markers/mobile", self._on_mobile, qos.RELIABLE)
        else:
            topic = "pose" if robot == "upsrpu" else "plate_pose"
            self.create_subscription(PoseStamped, topic, self._on_pose, qos.RELIABLE)
        self.create_timer(1.0, self._diagnostics)

    def _on_fixed(self, msg: PoseArray) -> None:
        self.tracker.add_fixed(points_from_pose_array(msg))

    def _on_mobile(self, msg: PoseArray) -> None:
        try:
            X = self.tracker.add_mobile(points_from_pose_array(msg))
        except ValueError as exc:
            self._reject(f"marker fit rejected: {exc}")
            return
        if X is not None:
            self._publish(X, msg.header)

    def _on_pose(self, msg: PoseStamped) -> None:
        T = self.pose_check.check(to_sec(msg.header.stamp), *pose_fields(msg.pose))
        if T is None:
            self._reject(f"pose rejected: {', '.join(sorted(self.pose_check.rejected))} so far")
            return
        X = pose_from_transform(T[:3, :3], T[:3, 3]) if self.monitor.robot == "upsrpu" else pose6_from_transform(T)
        self._publish(X, msg.header)

    def _reject(self, why: str) -> None:
        self.rejected += 1
        self.get_logger().warn(why, throttle_duration_sec=2.0)

    def _publish(self, X: np.ndarray, header) -> None:
        try:
            rep = self.monitor.report(X)
        except ValueError as exc:                      # e.g. an unreachable Hexa pose
            self._reject(f"indices not computed: {exc}")
            return
        m = self.monitor
        self.pub.publish(SingularityIndices(
            header=header, robot=m.robot, det_jd=float(rep.det_jd), omega=[float(w) for w in rep.omega],
            pairs=list(rep.pairs), min_omega=float(rep.min_omega), min_pair=rep.min_pair,
            det_jd_limit=m.det_jd_limit, omega_limit=m.omega_limit, near=bool(m.near(rep))))
        self.published += 1

    def _diagnostics(self) -> None:
        st = diagnostics.status(self.get_fully_qualified_name(), diagnostics.OK,
                                "ok" if self.rejected == 0 else "some inputs rejected",
                                {"published": self.published, "rejected": self.rejected,
                                 **self.pose_check.counters()})
        self.pub_diag.publish(diagnostics.array(self, [st]))


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(SingularityNode, "singularity", argv)


if __name__ == "__main__":
    sys.exit(main())
