"""Singularity release module node (seed 003 sec 2.5, Algorithm 1): the outer loop of the hybrid controller.

Thin wrapper over hexa.srm.SingularityReleaseModule, run at 1/t_s = 100 Hz in /upsrpu. Each tick: the
reference q_ind^r (IK of the Cartesian reference), the measured pose X_c (last `pose` or marker fit),
V_Omega and det J_D at X_c, Algorithm 1, publish q_ind^d.
Parameters: `description`, `variant` (1 | 2), `trajectory` ("" = hold the first measured pose, "1".."5" =
Table 3, "TR15"/"TRR0" = authors' references; played from the first measured pose on), `input`
("pose" | "markers"), `enabled` (initial enable pin), `auto_enable_after` (s after the reference ends; < 0 =
only through the service), `pose_timeout` (s; older X_c freezes Delta).
Topics: sub `pose` (geometry_msgs/PoseStamped) or `markers/fixed` + `markers/mobile` (PoseArray); pub
`joint_commands` (sensor_msgs/JointState, limb_1..limb_4, q_ind^d in m), `joint_references` (q_ind^r, m),
`/diagnostics`. Service `enable_srm` (hexa_msgs/EnableSrm): the enable pin e_pin and the variant.
"""
from __future__ import annotations

import sys
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseArray, PoseStamped
from hexa_msgs.srv import EnableSrm
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import JointState

from hexa_dynamics.conversions import UPSRPU_JOINTS, points_from_pose_array, upsrpu_pose_from_msg


class SrmNode(Node):
    """Algorithm 1 at 100 Hz with the enable pin as a service."""

    def __init__(self) -> None:
        super().__init__("srm")
        from hexa.robots.upsrpu_description import load_upsrpu
        from hexa.srm import SingularityReleaseModule

        self.desc = load_upsrpu(str(self.declare_parameter("description", "").value) or None)
        variant = int(self.declare_parameter("variant", 1).value)
        self.srm = SingularityReleaseModule(self.desc, variant)
        # "1".."5" arrive as integers from `-p trajectory:=2`: accept any type and use its text
        self.trajectory = str(self.declare_parameter("trajectory", "",
                                                     ParameterDescriptor(dynamic_typing=True)).value or "")
        mode = str(self.declare_parameter("input", "pose").value)
        self.enabled = bool(self.declare_parameter("enabled", False).value)
        self.auto_enable_after = float(self.declare_parameter("auto_enable_after", -1.0).value)
        self.pose_timeout = float(self.declare_parameter("pose_timeout", 0.1).value)
        rate = float(self.declare_parameter("rate_hz", 1.0 / self.desc.t_s).value)
        self.X_c: np.ndarray | None = None
        self.X_c_time = 0.0
        self.X_path: np.ndarray | None = None
        self.index = 0
        self.ticks_at_end = 0
        self.rejected = 0
        self.steps_active = 0
        if self.trajectory:
            from hexa.srm.experiment import reference_path

            self.X_path = reference_path(self.desc, self.trajectory)
        self.pub_cmd = self.create_publisher(JointState, "joint_commands", 10)
        self.pub_ref = self.create_publisher(JointState, "joint_references", 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._fixed: PoseArray | None = None
        if mode == "markers":
            from hexa.srm.tracking import tracking_model

            self.tracking = tracking_model(self.desc)
            self.create_subscription(PoseArray, "markers/fixed", self._on_fixed, 10)
            self.create_subscription(PoseArray, "markers/mobile", self._on_mobile, 10)
        else:
            self.create_subscription(PoseStamped, "pose", self._on_pose, 10)
        self.create_service(EnableSrm, "enable_srm", self._on_enable)
        self.create_timer(1.0 / rate, self._tick)
        self.create_timer(1.0, self._diagnostics)

    # --- inputs -------------------------------------------------------------------------------------------
    def _set_pose(self, X: np.ndarray) -> None:
        if not np.all(np.isfinite(X)):
            self.rejected += 1
            return
        self.X_c = X
        self.X_c_time = time.monotonic()
        if self.X_path is None and not self.trajectory:
            self.X_path = X[None].copy()                 # hold the first measured pose as the reference

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            self._set_pose(upsrpu_pose_from_msg(msg.pose))
        except ValueError:
            self.rejected += 1

    def _on_fixed(self, msg: PoseArray) -> None:
        self._fixed = msg

    def _on_mobile(self, msg: PoseArray) -> None:
        from hexa.srm.tracking import pose_from_markers

        if self._fixed is None:
            return
        try:
            X, _ = pose_from_markers(self.tracking, points_from_pose_array(self._fixed), points_from_pose_array(msg))
        except ValueError:
            self.rejected += 1
            return
        self._set_pose(X)

    def _on_enable(self, request: EnableSrm.Request, response: EnableSrm.Response) -> EnableSrm.Response:
        if request.variant not in (0, 1, 2):
            response.success = False
            response.message = f"variant must be 0 (keep), 1 or 2, got {request.variant}"
            return response
        if request.variant:
            self.srm.variant = int(request.variant)
        self.enabled = bool(request.enable)
        response.success = True
        response.message = f"SRM-V{self.srm.variant} {'enabled' if self.enabled else 'disabled'}"
        self.get_logger().info(response.message)
        return response

    # --- the controller -----------------------------------------------------------------------------------
    def _tick(self) -> None:
        from hexa.kinematics.upsrpu import inverse_kinematics
        from hexa.singularity import upsrpu_indices

        if self.X_c is None or self.X_path is None:
            return
        X_r = self.X_path[min(self.index, len(self.X_path) - 1)]
        if self.index < len(self.X_path) - 1:
            self.index += 1
        else:
            self.ticks_at_end += 1
            if 0 <= self.auto_enable_after <= self.ticks_at_end * self.desc.t_s and not self.enabled:
                self.enabled = True
                self.get_logger().info(f"enable pin set automatically (SRM-V{self.srm.variant})")
        q_r = inverse_kinematics(self.desc, X_r)
        fresh = time.monotonic() - self.X_c_time <= self.pose_timeout
        rep = upsrpu_indices(self.desc, self.X_c)
        q_d = self.srm.step(q_r, self.X_c, self.enabled and fresh, rep)
        if self.srm.last.active:
            self.steps_active += 1
        stamp = self.get_clock().now().to_msg()
        for pub, q in ((self.pub_cmd, q_d), (self.pub_ref, q_r)):
            js = JointState()
            js.header.stamp = stamp
            js.name = list(UPSRPU_JOINTS)
            js.position = [float(v) for v in q]
            pub.publish(js)

    def _diagnostics(self) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        fresh = self.X_c is not None and time.monotonic() - self.X_c_time <= self.pose_timeout
        level = DiagnosticStatus.OK if fresh else DiagnosticStatus.WARN
        st = DiagnosticStatus(level=level, name=self.get_fully_qualified_name(),
                              message="ok" if fresh else "no fresh pose X_c")
        st.values = [KeyValue(key="enabled", value=str(self.enabled)),
                     KeyValue(key="variant", value=str(self.srm.variant)),
                     KeyValue(key="delta", value=str(self.srm.delta.tolist())),
                     KeyValue(key="active_steps", value=str(self.steps_active)),
                     KeyValue(key="rejected", value=str(self.rejected))]
        arr.status = [st]
        self.pub_diag.publish(arr)


def main(argv: list[str] | None = None) -> int:
    from hexa_bringup.rosenv import apply_defaults

    apply_defaults()
    rclpy.init(args=argv if argv is not None else sys.argv)
    node = SrmNode()
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
