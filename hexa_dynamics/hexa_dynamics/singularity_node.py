"""Type II singularity monitor node (seed 003 sec 2.2-2.3) for the Hexa or the 3UPS+RPU.

Thin wrapper over hexa.singularity. Parameters: `robot` ("hexa" | "upsrpu"; default from the namespace: "upsrpu"
when it contains "upsrpu", else "hexa"), `input` ("pose" | "markers"),
`description` (YAML path, default packaged), `det_jd_limit`, `omega_limit` (rad; default Table 2 for the
3UPS+RPU, 1.8 deg and no det limit for the Hexa).
Topics (relative; run in /upsrpu or /hexa): sub `pose` (3UPS+RPU, geometry_msgs/PoseStamped, X_c from the
tracking system) or `plate_pose` (Hexa), or `markers/fixed` + `markers/mobile` (geometry_msgs/PoseArray,
marker positions in the tracking world) with input=markers; pub `singularity` (hexa_msgs/SingularityIndices),
`/diagnostics`.
"""
from __future__ import annotations

import math
import sys

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseArray, PoseStamped
from hexa_msgs.msg import SingularityIndices
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from hexa_dynamics.conversions import hexa_pose_from_msg, points_from_pose_array, upsrpu_pose_from_msg


class SingularityNode(Node):
    """Publishes det J_D, every Omega_ij, the minimum pair and the near-flag for each measured pose."""

    def __init__(self) -> None:
        super().__init__("singularity")
        self.robot = str(self.declare_parameter("robot", "").value) or (
            "upsrpu" if "upsrpu" in self.get_namespace() else "hexa")
        mode = str(self.declare_parameter("input", "pose").value)
        path = str(self.declare_parameter("description", "").value) or None
        if self.robot == "upsrpu":
            from hexa.robots.upsrpu_description import load_upsrpu

            self.desc = load_upsrpu(path)
            det_default, om_default = self.desc.det_jd_limit, self.desc.omega_limit
        elif self.robot == "hexa":
            from hexa.robots.hexa_description import load_hexa

            self.desc = load_hexa(path)
            det_default, om_default = 0.0, math.radians(1.8)
        else:
            raise ValueError(f"parameter robot must be 'hexa' or 'upsrpu', got {self.robot!r}")
        self.det_limit = float(self.declare_parameter("det_jd_limit", float(det_default)).value)
        self.omega_limit = float(self.declare_parameter("omega_limit", float(om_default)).value)
        self.pub = self.create_publisher(SingularityIndices, "singularity",
                                         QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                                    history=HistoryPolicy.KEEP_LAST))
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.rejected = 0
        self.published = 0
        self._fixed: PoseArray | None = None
        if mode == "markers":
            if self.robot != "upsrpu":
                raise ValueError("input=markers is only for the 3UPS+RPU")
            from hexa.srm.tracking import tracking_model

            self.tracking = tracking_model(self.desc)
            self.create_subscription(PoseArray, "markers/fixed", self._on_fixed, 10)
            self.create_subscription(PoseArray, "markers/mobile", self._on_mobile, 10)
        else:
            topic = "pose" if self.robot == "upsrpu" else "plate_pose"
            self.create_subscription(PoseStamped, topic, self._on_pose, 10)
        self.create_timer(1.0, self._diagnostics)

    def _on_fixed(self, msg: PoseArray) -> None:
        self._fixed = msg

    def _on_mobile(self, msg: PoseArray) -> None:
        from hexa.srm.tracking import pose_from_markers

        if self._fixed is None:
            return
        try:
            X, _ = pose_from_markers(self.tracking, points_from_pose_array(self._fixed), points_from_pose_array(msg))
        except ValueError as exc:
            self.rejected += 1
            self.get_logger().warn(f"marker fit rejected: {exc}", throttle_duration_sec=2.0)
            return
        self._publish(X, msg.header)

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            X = upsrpu_pose_from_msg(msg.pose) if self.robot == "upsrpu" else hexa_pose_from_msg(msg.pose)
        except ValueError as exc:
            self.rejected += 1
            self.get_logger().warn(f"pose rejected: {exc}", throttle_duration_sec=2.0)
            return
        self._publish(X, msg.header)

    def _publish(self, X: np.ndarray, header) -> None:
        from hexa import singularity

        try:
            rep = (singularity.upsrpu_indices(self.desc, X) if self.robot == "upsrpu"
                   else singularity.hexa_indices(self.desc, X))
        except ValueError as exc:                      # e.g. an unreachable Hexa pose
            self.rejected += 1
            self.get_logger().warn(f"indices not computed: {exc}", throttle_duration_sec=2.0)
            return
        out = SingularityIndices()
        out.header = header
        out.robot = self.robot
        out.det_jd = float(rep.det_jd)
        out.omega = [float(w) for w in rep.omega]
        out.pairs = list(rep.pairs)
        out.min_omega = float(rep.min_omega)
        out.min_pair = rep.min_pair
        out.det_jd_limit = self.det_limit
        out.omega_limit = self.omega_limit
        out.near = bool(abs(rep.det_jd) < self.det_limit or rep.min_omega < self.omega_limit)
        self.pub.publish(out)
        self.published += 1

    def _diagnostics(self) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        st = DiagnosticStatus(level=DiagnosticStatus.OK, name=f"{self.get_fully_qualified_name()}",
                              message="ok" if self.rejected == 0 else "some inputs rejected")
        st.values = [KeyValue(key="published", value=str(self.published)),
                     KeyValue(key="rejected", value=str(self.rejected))]
        arr.status = [st]
        self.pub_diag.publish(arr)


def main(argv: list[str] | None = None) -> int:
    from hexa_bringup.rosenv import apply_defaults

    apply_defaults()
    rclpy.init(args=argv if argv is not None else sys.argv)
    node = SingularityNode()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
