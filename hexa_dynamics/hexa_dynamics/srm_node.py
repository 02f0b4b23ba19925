"""Singularity release module node (seed 003 sec 2.5, Algorithm 1): the outer loop of the hybrid controller.

Thin adapter over hexa.srm.loop.ReleaseLoop, run at 1/t_s = 100 Hz in /upsrpu. Each tick: the
reference q_ind^r (IK of the Cartesian reference), the measured pose X_c (last `pose` or marker fit),
V_Omega and det J_D at X_c, Algorithm 1, publish q_ind^d.
Parameters: `description`, `variant` (1 | 2), `trajectory` ("" = hold the first measured pose, "1".."5" =
Table 3, "TR15"/"TRR0" = authors' references; played from the first measured pose on), `input`
("pose" | "markers"), `enabled` (initial enable pin), `auto_enable_after` (s after the reference ends; < 0 =
only through the service), `pose_timeout` (s; older X_c freezes Delta), `rate_hz` (default 1/t_s).
Topics: sub `pose` (geometry_msgs/PoseStamped) or `markers/fixed` + `markers/mobile` (PoseArray); pub
`joint_commands` (sensor_msgs/JointState, limb_1..limb_4, q_ind^d in m), `joint_references` (q_ind^r, m),
`/diagnostics`. Service `enable_srm` (hexa_msgs/EnableSrm): the enable pin e_pin and the variant.
"""
from __future__ import annotations

import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped
from hexa_msgs.srv import EnableSrm
from rclpy.node import Node
from sensor_msgs.msg import JointState

import hexa_ros.node
from hexa_ros import diagnostics, qos
from hexa_ros.conversions import UPSRPU_JOINTS, points_from_pose_array, upsrpu_pose_from_msg
from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param, declare_parameters


# trajectory "1".."5" arrives as an integer from `-p trajectory:=2`: any type is accepted, its text used
PARAMETERS = {DESCRIPTION: DESCRIPTION_PARAM,
              "variant": Param(1, "Algorithm 1 variant (seed 003): 1 or 2", range=(1, 2)),
              "trajectory": Param("", "reference trajectory 1..5 (seed 003); empty = none", dynamic_typing=True),
              "input": Param("pose", "pose | markers", choices=("pose", "markers")),
              "enabled": Param(False, "initial enable pin (then the enable_srm service)"),
              "auto_enable_after": Param(-1.0, "s after the reference ends to set the enable pin; < 0 = never",
                                         range=(-1.0, 1e6)),
              "pose_timeout": Param(0.1, "largest age (s) of the measured pose that still counts as fresh",
                                    range=(0.001, 10.0))}


class SrmNode(Node):
    """Algorithm 1 at 100 Hz with the enable pin as a service."""

    def __init__(self, **kwargs) -> None:
        super().__init__("srm", **kwargs)
        from hexa.robots.upsrpu_description import load_upsrpu
        from hexa.srm.loop import ReleaseLoop

        v = declare_parameters(self, PARAMETERS)
        desc = load_upsrpu(str(v[DESCRIPTION]) or None)
        variant, trajectory, mode = int(v["variant"]), str(v["trajectory"] or ""), str(v["input"])
        enabled, auto_enable_after, pose_timeout = bool(v["enabled"]), float(v["auto_enable_after"]), float(
            v["pose_timeout"])
        rate = float(declare_parameters(self, {"rate_hz": Param(1.0 / desc.t_s, "control rate (Hz); default 1/T_s",
                                                                range=(1.0, 1000.0))})["rate_hz"])
        reference = None
        if trajectory:
            from hexa.srm.experiment import reference_path

            reference = reference_path(desc, trajectory)
        self.loop = ReleaseLoop(desc, variant, reference, enabled, auto_enable_after, pose_timeout)
        self.pub_cmd = self.create_publisher(JointState, "joint_commands", qos.RELIABLE)
        self.pub_ref = self.create_publisher(JointState, "joint_references", qos.RELIABLE)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        if mode == "markers":
            from hexa.srm.tracking import MarkerTracker, tracking_model

            self.tracker = MarkerTracker(tracking_model(desc))
            self.create_subscription(PoseArray, "markers/fixed", self._on_fixed, qos.RELIABLE)
            self.create_subscription(PoseArray, "markers/mobile", self._on_mobile, qos.RELIABLE)
        else:
            self.create_subscription(PoseStamped, "pose", self._on_pose, qos.RELIABLE)
        self.create_service(EnableSrm, "enable_srm", self._on_enable)
        self.create_timer(1.0 / rate, self._tick)
        self.create_timer(1.0, self._diagnostics)

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            self.loop.set_pose(upsrpu_pose_from_msg(msg.pose), time.monotonic())
        except ValueError:
            self.loop.rejected += 1

    def _on_fixed(self, msg: PoseArray) -> None:
        self.tracker.add_fixed(points_from_pose_array(msg))

    def _on_mobile(self, msg: PoseArray) -> None:
        try:
            X = self.tracker.add_mobile(points_from_pose_array(msg))
        except ValueError:
            self.loop.rejected += 1
            return
        if X is not None:
            self.loop.set_pose(X, time.monotonic())

    def _on_enable(self, request: EnableSrm.Request, response: EnableSrm.Response) -> EnableSrm.Response:
        response.success, response.message = self.loop.enable(request.enable, request.variant)
        if response.success:
            self.get_logger().info(response.message)
        return response

    def _tick(self) -> None:
        step = self.loop.step(time.monotonic())
        if step is None:
            return
        if step.auto_enabled:
            self.get_logger().info(f"enable pin set automatically (SRM-V{self.loop.srm.variant})")
        stamp = self.get_clock().now().to_msg()
        for pub, q in ((self.pub_cmd, step.q_d), (self.pub_ref, step.q_r)):
            js = JointState(name=list(UPSRPU_JOINTS), position=[float(v) for v in q])
            js.header.stamp = stamp
            pub.publish(js)

    def _diagnostics(self) -> None:
        loop = self.loop
        fresh = loop.fresh(time.monotonic())
        st = diagnostics.status(self.get_fully_qualified_name(), diagnostics.OK if fresh else diagnostics.WARN,
                                "ok" if fresh else "no fresh pose X_c",
                                {"enabled": loop.enabled, "variant": loop.srm.variant,
                                 "delta": loop.srm.delta.tolist(), "active_steps": loop.steps_active,
                                 "rejected": loop.rejected})
        self.pub_diag.publish(diagnostics.array(self, [st]))


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(SrmNode, "srm", argv)


if __name__ == "__main__":
    sys.exit(main())
