"""Observer node: the collision monitor (hexa.dynamics.monitor: ζ estimator + residual observer, seed 000 §3.1,
eqs 23-26) on the driver's sample streams.

Sub `motor_currents` (hexa_ros.qos.STREAM; each message carries the servo set-points of its sample), `joint_states`
(only while the motor_currents carry no set-points: bags recorded before the field, time_source stamp), `plate_pose`;
pub `residual` (one per accepted sample), `collision` (START/END, reliable), `zeta_estimates` (hexa_msgs/
ZetaEstimates: ζ̂, ζ̂̇ and the τ used, zeta_batch_period s of samples per message: the rnea node's input),
`zeta_estimate` (the same, a JointState per sample while subscribed), `plate_pose_estimate` (the plate pose tracked
from ζ̂, at pose_estimate_rate_hz), `markers` (only while subscribed), `/diagnostics`; standard types beside them:
`external_wrench` (geometry_msgs/WrenchStamped, the residual in `plate`) and `external_joint_torques` (JointState
effort: the residual in servo space), one per sample while subscribed; `collision_state` (the last CollisionEvent,
transient local; END with id 0 before the first collision); `monitoring` (OK / DEGRADED / LOST: docs/monitoring.md);
/tf (base → plate, arm_i, rod_i, while subscribed) and /tf_static (the YAML's cameras). The outputs:
hexa_dynamics.observer_outputs.
Service `~/reset`. Parameters: hexa_dynamics.observer_params (descriptors; start-up ones read-only), defaults in
hexa_bringup/config/hexa_params.yaml (`/**/observer`), docs/observer_node.md.
"""
from __future__ import annotations

import dataclasses
import sys
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from hexa_msgs.msg import MotorCurrents
from hexa_msgs.srv import ResetObserver
from hexa_ros import diagnostics, node, qos
from hexa_ros.cdr import CdrError, joint_state_from_cdr, motor_currents_from_cdr
from hexa_ros.conversions import ordered_values, pose_fields
from hexa_ros.node import DESCRIPTION, declare_parameters
from hexa_ros.realtime import REALTIME_PRIORITY, realtime_priority_of, request_realtime_priority
from hexa_ros.stamps import to_sec
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState

from hexa.dynamics.cusum import CusumConfig
from hexa.dynamics.monitor import ESTIMATOR_KEYS, CollisionMonitor, MonitorConfig
from hexa.dynamics.monitoring import WatchConfig
from hexa.dynamics.observer import ObserverConfig
from hexa.estimation import EstimatorConfig
from hexa.robots.hexa_description import calibration_summary, load_hexa
from hexa_dynamics.monitoring_publisher import MonitoringPublisher
from hexa_dynamics.observer_outputs import ObserverOutputs
from hexa_dynamics.observer_params import observer_parameters

OBSERVER_KEYS = ("gains", "thresholds", "servo_thresholds", "release_ratio", "min_duration")
OUTPUT_KEYS = ("marker_rate_hz", "marker_scale", "pose_estimate_rate_hz", "tf_rate_hz", "zeta_batch_period")
CUSUM_KEYS = ("drift", "alarm", "velocity_gain", "accel_gain", "accel_tau", "baseline_tau")   # cusum_<key>


class ObserverNode(Node):
    """motor_currents (+ joint_states) + plate_pose → CollisionMonitor → residual, collision, estimates, markers."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("observer", **kwargs)
        v = declare_parameters(self, observer_parameters())
        request_realtime_priority(self, int(v[REALTIME_PRIORITY]))   # the 1 kHz path first (hexa_ros.realtime)
        desc = load_hexa(str(v[DESCRIPTION]) or None)
        self.get_logger().info(calibration_summary(desc))   # per-servo K_t, offsets, friction of an overlay
        sim = MonitorConfig.sim_clock_of(str(v["board_clock"]), bool(self.get_parameter("use_sim_time").value))
        mcfg = MonitorConfig(zeta_source=str(v["zeta_source"]), time_source=str(v["time_source"]), sim_clock=sim,
                             **{k: float(v[k]) for k in ("pose_delay", "reseed_distance", "command_delay")})
        ocfg = ObserverConfig(**{k: _value(v[k]) for k in OBSERVER_KEYS}, max_gap=float(v["max_gap"]))
        ecfg = EstimatorConfig(**{k: float(v[k]) for k in ESTIMATOR_KEYS})
        ccfg = CusumConfig(**{k: float(v[f"cusum_{k}"]) for k in CUSUM_KEYS})
        self.monitor = CollisionMonitor(desc, mcfg, ocfg, ecfg, detector=str(v["detector"]),
                                        cusum=ccfg)   # raises ValueError naming a bad value
        self.set = {k: v[k] for k in ("calibration_duration", *OUTPUT_KEYS)}
        self.frame_id = str(v["frame_id"])
        self.out = ObserverOutputs(self, desc, self.frame_id, self.set)
        self.pub_diag = self.create_publisher(diagnostics.DiagnosticArray, "/diagnostics", qos.RELIABLE)
        # the driver's 1 kHz streams are read from their serialized bytes (hexa_ros.cdr): cheaper than message objects
        self.sub_states = self._subscribe_states()
        if mcfg.time_source != "stamp":
            self.create_subscription(MotorCurrents, "motor_currents", self._on_currents, qos.STREAM, raw=True)
        self.create_subscription(PoseStamped, "plate_pose", self._on_pose, qos.STREAM)
        self.create_service(ResetObserver, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.create_timer(1.0, self._diagnostics)
        self.monitoring = MonitoringPublisher(self, self.monitor, WatchConfig.from_values(v), self.frame_id,
                                              self._diagnostics)   # the inputs pass through its watch
        self.watch = self.monitoring.watch
        self.get_logger().info(f"observer: ζ from {mcfg.zeta_source}, {v['detector']} detector, r_low "
                               f"{list(ocfg.thresholds)}, servo thresholds {list(ocfg.servo_thresholds)} N·m, "
                               f"K {list(ocfg.gains)}")

    def _subscribe_states(self) -> Any:
        return self.create_subscription(JointState, "joint_states", self._on_states, qos.STREAM, raw=True)

    def _on_set_parameters(self, params: list) -> SetParametersResult:
        m = self.monitor
        ocfg, ecfg, reseed, ccfg = m.observer.config, m.estimator.config, None, None
        try:
            for prm in params:
                if prm.name.startswith("cusum_") and prm.name[6:] in CUSUM_KEYS:
                    ccfg = dataclasses.replace(ccfg or getattr(m.observer.detector, "cusum", CusumConfig()),
                                               **{prm.name[6:]: float(prm.value)})
                elif prm.name in OBSERVER_KEYS:
                    ocfg = dataclasses.replace(ocfg, **{prm.name: _value(prm.value)})
                elif prm.name in ESTIMATOR_KEYS:
                    ecfg = dataclasses.replace(ecfg, **{prm.name: float(prm.value)})
                elif prm.name == "reseed_distance":
                    reseed = float(prm.value)
            m.configure(ocfg, ecfg, reseed, ccfg)   # applied only when every value is valid
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
            t, current, board_us, setpoint = motor_currents_from_cdr(data)
        except CdrError:
            self.monitor.rejects["bad_currents"] += 1
            return
        self._publish(self.watch.push_currents(t, board_us, current, setpoint))
        # joint_states only while the samples do not carry their set-points: one 1 kHz subscription, not two
        if self.monitor.carries_setpoint == (self.sub_states is not None):
            if self.sub_states is None:
                self.sub_states = self._subscribe_states()
            else:
                self.destroy_subscription(self.sub_states)
                self.sub_states = None

    def _on_pose(self, msg: PoseStamped) -> None:
        self._publish(self.watch.push_pose(to_sec(msg.header.stamp), np.concatenate(pose_fields(msg.pose))))

    def _publish(self, samples: list) -> None:
        self.out.publish(samples, self.monitor.observer.detector)
        for line in self.monitor.log:
            self.get_logger().info(line)
        self.monitor.log.clear()

    def _on_reset(self, req: Any, resp: Any) -> Any:
        resp.message = self.monitor.reset(bool(req.recalibrate), float(self.set["calibration_duration"]))
        self.watch.restart(self.monitoring.now())
        resp.success = True
        self.get_logger().info(resp.message)
        return resp

    def _diagnostics(self) -> None:
        level, msg = self.watch.health()
        values = {**self.watch.values(), "events_sent": self.out.events_sent,
                  "joint_states_subscribed": self.sub_states is not None, REALTIME_PRIORITY: realtime_priority_of()}
        st = diagnostics.status(self.get_fully_qualified_name(), getattr(diagnostics, level), msg, values)
        self.pub_diag.publish(diagnostics.array(self, [st]))


def _value(v: Any) -> Any:
    """A parameter value as the config takes it: a tuple of floats for arrays, a float for numbers."""
    return tuple(float(x) for x in v) if isinstance(v, (list, tuple)) or hasattr(v, "tolist") else float(v)


def main(argv: list[str] | None = None) -> int:
    return node.main(ObserverNode, "observer", argv)


if __name__ == "__main__":
    sys.exit(main())
