"""Observer node: the collision monitor (hexa.dynamics.monitor: ζ estimator + residual observer, seed 000 §3.1,
eqs 23-26) on the driver's sample streams.

Sub `joint_states`, `motor_currents` (hexa_ros.qos.STREAM), `plate_pose`; pub `residual` (one per accepted sample),
`collision` (START/END, reliable), `zeta_estimate` (JointState: ζ̂, ζ̂̇ and the τ used), `plate_pose_estimate`
(the plate pose tracked from ζ̂, at pose_estimate_rate_hz), `markers` (only while subscribed), `/diagnostics`;
standard types beside them: `external_wrench` (geometry_msgs/WrenchStamped, the residual in `plate`) and
`external_joint_torques` (JointState effort: the residual in servo space), one per sample while subscribed;
`collision_state` (the last CollisionEvent, transient local; END with id 0 before the first collision); `monitoring`
(OK / DEGRADED / LOST: docs/monitoring.md); /tf (base → plate, arm_i, rod_i) and /tf_static (the YAML's cameras).
Service `~/reset`. Parameters: hexa_dynamics.observer_params (descriptors; start-up ones read-only), defaults in
hexa_bringup/config/hexa_params.yaml (`/**/observer`), docs/observer_node.md.
"""
from __future__ import annotations

import dataclasses
import math
import sys
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped, WrenchStamped
from hexa_msgs.msg import CollisionEvent, MotorCurrents, Residual
from hexa_msgs.srv import ResetObserver
from hexa_ros import cdr, diagnostics, markers, node, qos
from hexa_ros.cdr import CdrError, joint_state_from_cdr, motor_currents_from_cdr
from hexa_ros.conversions import JOINT_NAMES, fill_pose_msg, ordered_values, pose_fields, wrench_stamped
from hexa_ros.stamps import to_sec, to_stamp
from hexa_ros.node import DESCRIPTION, declare_parameters
from hexa_ros.tf import TfPublisher
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from hexa import frames
from hexa.dynamics.monitor import ESTIMATOR_KEYS, CollisionMonitor, MonitorConfig
from hexa.dynamics.monitoring import WatchConfig
from hexa.dynamics.observer import ObserverConfig
from hexa.estimation import EstimatorConfig
from hexa.kinematics.hexa6rus import rotation_zyx
from hexa.robots.hexa_description import calibration_summary, load_hexa
from hexa_dynamics.monitoring_publisher import MonitoringPublisher
from hexa_dynamics.observer_params import observer_parameters

OBSERVER_KEYS = ("gains", "thresholds", "servo_thresholds", "release_ratio", "min_duration")


class ObserverNode(Node):
    """joint_states + motor_currents + plate_pose → CollisionMonitor → residual, collision, estimates, markers."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("observer", **kwargs)
        v = declare_parameters(self, observer_parameters())
        desc = load_hexa(str(v[DESCRIPTION]) or None)
        self.get_logger().info(calibration_summary(desc))   # per-servo K_t, offsets, friction of an overlay
        sim = MonitorConfig.sim_clock_of(str(v["board_clock"]), bool(self.get_parameter("use_sim_time").value))
        mcfg = MonitorConfig(zeta_source=str(v["zeta_source"]), time_source=str(v["time_source"]), sim_clock=sim,
                             **{k: float(v[k]) for k in ("pose_delay", "reseed_distance", "command_delay")})
        ocfg = ObserverConfig(**{k: _value(v[k]) for k in OBSERVER_KEYS}, max_gap=float(v["max_gap"]))
        ecfg = EstimatorConfig(**{k: float(v[k]) for k in ESTIMATOR_KEYS})
        self.monitor = CollisionMonitor(desc, mcfg, ocfg, ecfg)   # raises ValueError naming a bad value
        self.set = {k: v[k] for k in ("calibration_duration", "marker_rate_hz", "marker_scale",
                                      "pose_estimate_rate_hz", "tf_rate_hz")}
        self.frame_id = str(v["frame_id"])
        self.last = {"marker": -math.inf, "pose": -math.inf, "tf": -math.inf}
        self.events_sent = 0
        self.pub_residual = self.create_publisher(Residual, "residual", qos.STREAM)
        self.pub_collision = self.create_publisher(CollisionEvent, "collision", qos.EVENT)
        self.pub_state = self.create_publisher(CollisionEvent, "collision_state", qos.LATCHED)
        self.pub_state.publish(CollisionEvent(event=CollisionEvent.END, id=0))
        self.pub_wrench = self.create_publisher(WrenchStamped, "external_wrench", qos.STREAM)
        self.pub_torques = self.create_publisher(JointState, "external_joint_torques", qos.STREAM)
        self.desc, self.tf = desc, TfPublisher(self)
        self.tf.send_static(frames.static_transforms(desc))
        self.pub_zeta = self.create_publisher(JointState, "zeta_estimate", qos.STREAM)
        self.pub_pose = self.create_publisher(PoseStamped, "plate_pose_estimate", qos.RELIABLE)
        self.pub_markers = self.create_publisher(MarkerArray, "markers", qos.RELIABLE)
        self.pub_diag = self.create_publisher(diagnostics.DiagnosticArray, "/diagnostics", qos.RELIABLE)
        # the driver's 1 kHz streams are read from their serialized bytes (hexa_ros.cdr): cheaper than message objects
        self.create_subscription(JointState, "joint_states", self._on_states, qos.STREAM, raw=True)
        if mcfg.time_source != "stamp":
            self.create_subscription(MotorCurrents, "motor_currents", self._on_currents, qos.STREAM, raw=True)
        self.create_subscription(PoseStamped, "plate_pose", self._on_pose, qos.STREAM)
        self.create_service(ResetObserver, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.create_timer(1.0, self._diagnostics)
        self.monitoring = MonitoringPublisher(self, self.monitor, WatchConfig.from_values(v), self.frame_id,
                                              self._diagnostics)   # the inputs pass through its watch
        self.watch = self.monitoring.watch
        self.get_logger().info(f"observer: ζ from {mcfg.zeta_source}, r_low {list(ocfg.thresholds)}, servo "
                               f"thresholds {list(ocfg.servo_thresholds)} N·m, K {list(ocfg.gains)}")

    def _on_set_parameters(self, params: list) -> SetParametersResult:
        m = self.monitor
        ocfg, ecfg, reseed = m.observer.config, m.estimator.config, None
        try:
            for prm in params:
                if prm.name in OBSERVER_KEYS:
                    ocfg = dataclasses.replace(ocfg, **{prm.name: _value(prm.value)})
                elif prm.name in ESTIMATOR_KEYS:
                    ecfg = dataclasses.replace(ecfg, **{prm.name: float(prm.value)})
                elif prm.name == "reseed_distance":
                    reseed = float(prm.value)
            m.configure(ocfg, ecfg, reseed)   # applied only when every value is valid
        except (TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.set.update({prm.name: prm.value for prm in params if prm.name in self.set})
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ inputs → monitor → outputs
    def _on_states(self, data: bytes) -> None:
        try:
            t, names, pos, vel, eff = joint_state_from_cdr(data)
        except CdrError:
            self.monitor.rejects["bad_joint_names"] += 1
            return
        self._publish(self.watch.push_states(t, ordered_values(names, pos), ordered_values(names, vel),
                                             ordered_values(names, eff)))

    def _on_currents(self, data: bytes) -> None:
        try:
            t, current, board_us = motor_currents_from_cdr(data)
        except CdrError:
            self.monitor.rejects["bad_currents"] += 1
            return
        self._publish(self.watch.push_currents(t, board_us, current))

    def _on_pose(self, msg: PoseStamped) -> None:
        self._publish(self.watch.push_pose(to_sec(msg.header.stamp), np.concatenate(pose_fields(msg.pose))))

    def _publish(self, samples: list) -> None:
        det = self.monitor.observer.detector
        for s in samples:
            out, stamp = s.residual, to_stamp(s.time)
            w = out.wrench.tolist()
            # both per-sample outputs published as their serialized bytes (hexa_ros.cdr): the message objects cost
            # more to build and convert than the observer's update
            self.pub_residual.publish(cdr.residual_to_cdr(
                stamp.sec, stamp.nanosec, self.frame_id, out.r_zyz.tolist(), w[:3], w[3:], det.thresholds.tolist(),
                out.over.tolist(), out.servo_torque.tolist(), det.servo_thresholds.tolist(), out.servo_over.tolist(),
                bool(out.in_collision)))
            self._standard(out, stamp)
            for ev in out.events:
                self._event(ev)
            self.pub_zeta.publish(cdr.joint_state_to_cdr(
                stamp.sec, stamp.nanosec, "", JOINT_NAMES, s.zeta.tolist(),
                [] if s.zeta_dot is None else s.zeta_dot.tolist(), s.tau.tolist()))
            if s.time - self.last["pose"] >= 1.0 / max(float(self.set["pose_estimate_rate_hz"]), 1e-3):
                self.last["pose"] = s.time
                ps = PoseStamped()
                ps.header.stamp, ps.header.frame_id = stamp, self.frame_id
                fill_pose_msg(ps.pose, rotation_zyx(*out.pose[3:6]), out.pose[:3])
                self.pub_pose.publish(ps)
            if s.time - self.last["tf"] >= 1.0 / max(float(self.set["tf_rate_hz"]), 1e-3):
                self.last["tf"] = s.time
                self.tf.send(frames.robot_transforms(self.desc, out.pose, s.zeta), stamp)
            due = s.time - self.last["marker"] >= 1.0 / max(float(self.set["marker_rate_hz"]), 1e-3)
            if (due or out.events) and self.pub_markers.get_subscription_count() > 0:
                self.last["marker"] = s.time
                self.pub_markers.publish(self._markers(out, stamp))
        for line in self.monitor.log:
            self.get_logger().info(line)
        self.monitor.log.clear()

    def _event(self, ev: Any) -> None:
        c = CollisionEvent(event=CollisionEvent.START if ev.kind == "START" else CollisionEvent.END, id=int(ev.id),
                           onset=to_stamp(ev.onset), axis=int(ev.axis), axis_name=ev.axis_name, value=float(ev.value),
                           peak=float(ev.peak), duration=float(ev.duration))
        c.header.stamp, c.header.frame_id = to_stamp(ev.time), self.frame_id
        self.pub_collision.publish(c)
        self.pub_state.publish(c)
        self.events_sent += 1
        self.get_logger().warn(f"collision {ev.id} {ev.kind} on {ev.axis_name}: {ev.value:.3f} (peak {ev.peak:.3f}, "
                               f"onset {ev.onset:.3f} s)")

    def _standard(self, out: Any, stamp: Any) -> None:
        """The residual as a WrenchStamped in `plate` (moment about the plate centre) and as servo-space efforts."""
        if self.pub_wrench.get_subscription_count() > 0:
            R = rotation_zyx(*out.pose[3:6])
            self.pub_wrench.publish(wrench_stamped(frames.PLATE, stamp, R.T @ out.wrench[:3], R.T @ out.wrench[3:]))
        if self.pub_torques.get_subscription_count() > 0:
            js = JointState(name=list(JOINT_NAMES), effort=out.servo_torque.tolist())
            js.header.stamp = stamp
            self.pub_torques.publish(js)

    def _markers(self, out: Any, stamp: Any) -> MarkerArray:
        """The residual force as an arrow at the plate (green; red in collision)."""
        P, F = out.pose[:3], out.wrench[:3]
        rgba = (1.0, 0.1, 0.1, 1.0) if out.in_collision else (0.1, 0.8, 0.2, 0.8)
        return MarkerArray(markers=[markers.arrow("residual_force", self.frame_id, stamp, P,
                                                  P + float(self.set["marker_scale"]) * F, rgba)])

    def _on_reset(self, req: Any, resp: Any) -> Any:
        resp.message = self.monitor.reset(bool(req.recalibrate), float(self.set["calibration_duration"]))
        self.watch.restart(self.monitoring.now())
        resp.success = True
        self.get_logger().info(resp.message)
        return resp

    def _diagnostics(self) -> None:
        level, msg = self.watch.health()
        values = {**self.watch.values(), "events_sent": self.events_sent}
        st = diagnostics.status(self.get_fully_qualified_name(), getattr(diagnostics, level), msg, values)
        self.pub_diag.publish(diagnostics.array(self, [st]))


def _value(v: Any) -> Any:
    """A parameter value as the config takes it: a tuple of floats for arrays, a float for numbers."""
    return tuple(float(x) for x in v) if isinstance(v, (list, tuple)) or hasattr(v, "tolist") else float(v)


def main(argv: list[str] | None = None) -> int:
    return node.main(ObserverNode, "observer", argv)


if __name__ == "__main__":
    sys.exit(main())
