"""Observer node: ζ estimator + residual observer (seed 000 §3.1, eqs 23-26) at the current-sample rate → `residual`,
`collision` START/END, residual markers.

Each `joint_states` sample (driver: position = COMMANDED angle, effort = K_t·(I − I₀)) feeds hexa.estimation.
ZetaEstimator (servo model + Kalman filter, corrected by every `plate_pose` through IK), whose ζ̂, ζ̂̇ and the measured
τ feed H5's hexa.dynamics.observer.ResidualObserver (momentum form, kinematics "arm"); the plate pose is tracked from
ζ̂ and re-seeded from the camera when they disagree by more than `reseed_distance` (or tracking failed).

Parameters (all declared; the detector and estimator ones are settable at runtime with `ros2 param set`-like calls,
e.g. `hexa param set /hexa/observer thresholds "[3.0,3.0,3.0,0.3,0.3,0.3]"`):
  description (str, ""): robot YAML (default packaged hexa.yaml).
  zeta_source ("estimator"): "estimator" (hobby servos: position = commanded angle) or "measured" (position = measured
    angle, velocity used when present: sim/joint_states_truth or servos with feedback).
  time_source ("auto"): sample times from the current board's clock (motor_currents.board_time_us, τ = K_t·I) once
    motor_currents arrive, else joint_states header stamps (τ = effort); "board" / "stamp" force one.
  board_clock ("auto"): "sim" = board time is sim time (hexa.sim.boards: the virtual boards run on sim time),
    "track" = follow the mean (stamp − board time); auto = sim when use_sim_time is true. Set "track" to replay a
    bag recorded on the real robot with --clock.
  gains (double[6], 100 1/s): observer gains K_j per axis [fx fy fz mx my mz].
  thresholds (double[6], [2,2,2,0.2,0.2,0.2] N, N·m): r_low per axis.
  servo_thresholds (double[6], 0.35 N·m each): threshold on the residual as servo torques τ_r = J_ζ⁻ᵀ r, servo 1..6
    (0 switches one off); a START comes from either criterion (docs/observer_node.md, "Detection in servo coordinates").
  release_ratio (0.5): an axis releases below release_ratio·r_low.  min_duration (0.02 s): confirmation time.
  max_gap (0.1 s): longer joint_states spacing restarts the integration.
  pose_delay (0.5 s): camera poses are applied at sample time image stamp + pose_delay, so the output depends on
    stamps only (deterministic replay); poses later than that are applied on arrival (diagnostics `late_poses`).
  accel_sigma (2), torque_sigma (0.2 N·m), camera_sigma (0.004 rad), bias_walk (0.005 rad/√s),
    saturation (0.97), stall_sigma (0.02 rad), command_delay (0.0 s): ZetaEstimator settings (see hexa.estimation).
  reseed_distance (0.005 m): camera pose re-seeds the observer's pose tracking when this far from it.
  calibration_duration (1.0 s): averaging time of `~/reset` with recalibrate=true (robot at rest, untouched).
  marker_rate_hz (10), marker_scale (0.02 m/N): residual force arrow at the plate on `markers`.
  frame_id ("base").
Topics (relative): sub `joint_states` (reliable), `motor_currents` (reliable), `plate_pose` (PoseStamped);
pub `residual` (hexa_msgs/Residual, each accepted sample), `collision` (hexa_msgs/CollisionEvent, reliable keep-last
20), `zeta_estimate` (JointState ζ̂, ζ̂̇),
`markers` (visualization_msgs/MarkerArray), `/diagnostics` (1 Hz, rejects by reason). Service `~/reset`
(hexa_msgs/srv/ResetObserver). Time: the board clock of motor_currents, else message stamps (sim time in sim mode).
"""
from __future__ import annotations

import dataclasses
import math
import sys
from collections import deque
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PoseStamped
from hexa_msgs.msg import CollisionEvent, Residual
from hexa_msgs.srv import ResetObserver
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker, MarkerArray

JOINT_NAMES = [f"arm_{i}" for i in range(1, 7)]
ESTIMATOR_KEYS = ("accel_sigma", "torque_sigma", "camera_sigma", "bias_walk", "saturation", "stall_sigma")
INPUT_QOS = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
EVENT_QOS = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)


def stamp_seconds(stamp: Any) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def stamp_from_seconds(t: float) -> Any:
    from builtin_interfaces.msg import Time

    sec = math.floor(t)
    return Time(sec=int(sec), nanosec=min(int(round((t - sec) * 1e9)), 999_999_999))


def ordered_joints(msg: JointState, field: str) -> np.ndarray | None:
    """The six values of `field` ordered arm_1..arm_6 by msg.name (in message order when names are absent);
    None when the names or lengths do not fit."""
    vals = list(getattr(msg, field))
    if len(vals) != 6:
        return None
    names = list(msg.name)
    if not names:
        return np.asarray(vals, dtype=float)
    if len(names) != 6 or set(names) != set(JOINT_NAMES):
        return None
    idx = {n: k for k, n in enumerate(names)}
    return np.asarray([vals[idx[n]] for n in JOINT_NAMES], dtype=float)


def declare_estimator(node: Node):
    """Declare the ZetaEstimator parameters on `node`; returns (EstimatorConfig, ServoModel kwargs)."""
    from hexa.estimation import EstimatorConfig

    d = EstimatorConfig()
    vals = {k: float(node.declare_parameter(k, float(getattr(d, k))).value) for k in ESTIMATOR_KEYS}
    delay = float(node.declare_parameter("command_delay", 0.0).value)
    return EstimatorConfig(**vals), delay


def make_estimator(desc: Any, config: Any, delay: float):
    from hexa.estimation import ServoModel, ZetaEstimator

    return ZetaEstimator(desc, servo=ServoModel.from_description(desc, command_delay=delay), config=config)


def diagnostic(node: Node, level: int, message: str, values: dict[str, Any]) -> DiagnosticArray:
    arr = DiagnosticArray()
    arr.header.stamp = node.get_clock().now().to_msg()
    st = DiagnosticStatus(level=level, name=node.get_fully_qualified_name(), message=message)
    st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    arr.status = [st]
    return arr


class BoardClock:
    """Sample times from the current board's microsecond clock (MotorCurrents.board_time_us, wraps at 2³²) on the ROS
    time axis: t = offset + unwrapped board time, the offset following the mean of (stamp − board time) with time
    constant `tau` (receive latency, host/board clock drift), re-anchored when they disagree by more than `jump` s
    (board reset). The lower envelope would be the better latency estimate on hardware, but in sim mode the host
    stamps come from /clock and may lag the board (= sim) time.

    Host receive stamps jitter by milliseconds (USB, scheduling; in sim mode they are quantized by /clock), which at
    200-1000 Hz would corrupt the observer's Δt; the board's clock does not."""

    def __init__(self, tau: float = 10.0, jump: float = 0.5, fixed_offset: float | None = None) -> None:
        self.tau, self.jump, self.fixed_offset = tau, jump, fixed_offset
        self._raw: int | None = None
        self._board = 0.0
        self._offset = 0.0
        self.backwards = 0

    def time(self, stamp: float, board_us: int) -> float | None:
        raw = int(board_us) & 0xFFFFFFFF
        if self.fixed_offset is not None:  # board time is ROS time + offset (the simulator's boards run on sim time)
            d = 0 if self._raw is None else (raw - self._raw) & 0xFFFFFFFF
            if self._raw is not None and (d == 0 or d >= 1 << 31):
                self.backwards += 1
                return None
            self._board = raw * 1e-6 if self._raw is None else self._board + d * 1e-6
            self._raw = raw
            return self._board + self.fixed_offset
        if self._raw is None:
            self._raw, self._board, self._offset = raw, 0.0, stamp
            return stamp
        d = (raw - self._raw) & 0xFFFFFFFF
        if d == 0 or d >= 1 << 31:  # repeated or older sample
            self.backwards += 1
            return None
        dt = d * 1e-6
        self._raw = raw
        self._board += dt
        err = stamp - (self._offset + self._board)
        if abs(err) > self.jump:
            self._offset = stamp - self._board
        else:  # mean receive latency and clock drift (in sim mode the stamps lag sim time by the /clock delivery)
            self._offset += err * min(1.0, dt / self.tau)
        return self._offset + self._board


class ArmSampleInput:
    """joint_states / motor_currents / plate_pose → (t, commanded ζ, τ, velocity) samples for `on_sample` and camera
    poses for `on_pose`, in an order that depends only on the message stamps and contents
    (hexa.estimation.SampleSequencer): a replayed bag gives the same output whatever DDS's delivery order.

    time_source "auto": when `motor_currents` arrive, each of them (paired with the joint_states of the same driver
    sample) is a sample: t from the board clock, τ = K_t·I, the commanded angles current at that time; else (bags or
    peers without motor_currents) each joint_states is a sample at its header stamp with τ = effort. "board" /
    "stamp" force one of the two. Poses reach `on_pose` at sample time stamp + pose_delay (parameter, 0.5 s: the
    vision chain's latency is 0.1-0.47 s on this loaded machine), so every run applies each pose between the same
    two samples."""

    def __init__(self, node: Node, k_t: float, on_sample: Any, rejects: dict[str, int], on_pose: Any = None) -> None:
        from hexa.estimation import SampleSequencer
        from hexa_msgs.msg import MotorCurrents

        self.node, self.k_t, self.on_sample, self.on_pose, self.rejects = node, float(k_t), on_sample, on_pose, rejects
        self.source = str(node.declare_parameter("time_source", "auto").value)
        if self.source not in ("auto", "board", "stamp"):
            raise ValueError(f"parameter time_source must be 'auto', 'board' or 'stamp', got {self.source!r}")
        mode = str(node.declare_parameter("board_clock", "auto").value)
        if mode not in ("auto", "sim", "track"):
            raise ValueError(f"parameter board_clock must be 'auto', 'sim' or 'track', got {mode!r}")
        pose_delay = float(node.declare_parameter("pose_delay", 0.5).value)
        if not (math.isfinite(pose_delay) and 0.0 <= pose_delay <= 0.9):
            raise ValueError(f"parameter pose_delay must be in [0, 0.9] s (estimator history 1 s), got "
                             f"{pose_delay!r}")
        use_sim = bool(node.get_parameter("use_sim_time").value)
        self.clock = BoardClock(fixed_offset=0.0 if mode == "sim" or (mode == "auto" and use_sim) else None)
        self.seq = SampleSequencer(self.source, pose_delay=pose_delay)
        rejects.setdefault("bad_joint_names", 0)
        rejects.setdefault("bad_currents", 0)
        rejects.setdefault("board_time", 0)
        node.create_subscription(JointState, "joint_states", self._on_joint_states, INPUT_QOS)
        if self.source != "stamp":
            node.create_subscription(MotorCurrents, "motor_currents", self._on_currents, INPUT_QOS)
        if on_pose is not None:
            node.create_subscription(PoseStamped, "plate_pose", self._on_pose_msg, INPUT_QOS)

    @property
    def board_seen(self) -> bool:
        return self.seq.board

    def _dispatch(self, items: list) -> None:
        for item in items:
            if item[0] == "sample":
                self.on_sample(*item[1:])
            elif self.on_pose is not None:
                self.on_pose(item[1], item[2])

    def _on_joint_states(self, msg: JointState) -> None:
        pos = ordered_joints(msg, "position")
        if pos is None:
            self.rejects["bad_joint_names"] += 1
            return
        vel = ordered_joints(msg, "velocity")
        tau = ordered_joints(msg, "effort")
        if tau is None and not self.seq.board:
            self.rejects["bad_joint_names"] += 1
        self._dispatch(self.seq.push_states(stamp_seconds(msg.header.stamp), pos, vel, tau))

    def _on_currents(self, msg: Any) -> None:
        cur = np.asarray(msg.current, dtype=float)
        if cur.shape != (6,):
            self.rejects["bad_currents"] += 1
            return
        stamp = stamp_seconds(msg.header.stamp)
        t = self.clock.time(stamp, msg.board_time_us)
        if t is None:
            self.rejects["board_time"] += 1
            return
        self._dispatch(self.seq.push_currents(stamp, t, self.k_t * cur))

    def _on_pose_msg(self, msg: PoseStamped) -> None:
        from hexa_dynamics.conversions import hexa_pose_from_msg

        try:
            pose = hexa_pose_from_msg(msg.pose)
        except ValueError:
            self.rejects["bad_pose"] = self.rejects.get("bad_pose", 0) + 1
            return
        if not np.all(np.isfinite(pose)):
            self.rejects["bad_pose"] = self.rejects.get("bad_pose", 0) + 1
            return
        self._dispatch(self.seq.push_pose(stamp_seconds(msg.header.stamp), pose))


class ObserverNode(Node):
    """joint_states + plate_pose → ζ̂ → residual observer → residual, collision, markers."""

    def __init__(self) -> None:
        super().__init__("observer")
        from hexa.dynamics.lagrange import HexaDynamicParameters
        from hexa.dynamics.observer import ObserverConfig, ResidualObserver
        from hexa.robots.hexa_description import load_hexa

        dflt = ObserverConfig()
        p = self.declare_parameter
        desc_path = str(p("description", "").value) or None
        self.zeta_source = str(p("zeta_source", "estimator").value)
        if self.zeta_source not in ("estimator", "measured"):
            raise ValueError(f"parameter zeta_source must be 'estimator' or 'measured', got {self.zeta_source!r}")
        gains = [float(v) for v in p("gains", [float(v) for v in dflt.gains]).value]
        thresholds = [float(v) for v in p("thresholds", [float(v) for v in dflt.thresholds]).value]
        servo_th = [float(v) for v in p("servo_thresholds", [float(v) for v in dflt.servo_thresholds]).value]
        release = float(p("release_ratio", dflt.release_ratio).value)
        min_dur = float(p("min_duration", dflt.min_duration).value)
        max_gap = float(p("max_gap", dflt.max_gap).value)
        est_cfg, delay = declare_estimator(self)
        self.reseed_distance = float(p("reseed_distance", 0.005).value)
        self.calibration_duration = float(p("calibration_duration", 1.0).value)
        self.marker_period = 1.0 / max(float(p("marker_rate_hz", 10.0).value), 1e-3)
        self.marker_scale = float(p("marker_scale", 0.02).value)
        self.frame_id = str(p("frame_id", "base").value)

        self.desc = load_hexa(desc_path)
        self.params = HexaDynamicParameters.from_description(self.desc)
        cfg = ObserverConfig(gains=tuple(gains), thresholds=tuple(thresholds), servo_thresholds=tuple(servo_th),
                             release_ratio=release,
                             min_duration=min_dur, max_gap=max_gap)  # raises ObserverError naming a bad value
        self.observer = ResidualObserver(self.params, cfg)
        self.estimator = make_estimator(self.desc, est_cfg, delay)
        self.settling = 0
        self.rejects = {"bad_pose": 0, "estimator": 0, "observer": 0}
        self._last_out = None
        self._last_marker_t = -math.inf
        self._calib_until: float | None = None
        self._t = -math.inf
        self.events_sent = 0

        self.pub_residual = self.create_publisher(Residual, "residual", 10)
        self.pub_collision = self.create_publisher(CollisionEvent, "collision", EVENT_QOS)
        self.pub_zeta = self.create_publisher(JointState, "zeta_estimate", 10)
        self.pub_markers = self.create_publisher(MarkerArray, "markers", 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._pose_hist: deque[tuple[float, np.ndarray]] = deque()  # (t, tracked plate pose) for the re-seed test
        self.input = ArmSampleInput(self, self.desc.K_t, self._on_sample, self.rejects, on_pose=self._on_pose)
        self.create_service(ResetObserver, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.create_timer(1.0, self._diagnostics)
        self.get_logger().info(f"observer: ζ from {self.zeta_source}, r_low {thresholds}, servo thresholds "
                               f"{servo_th} N·m, K {gains}")

    # ------------------------------------------------------------------ parameters at runtime
    def _on_set_parameters(self, params: list) -> SetParametersResult:
        from hexa.dynamics.observer import ObserverError
        from hexa.estimation import EstimationError

        obs = self.observer
        cfg = obs.config
        est_cfg = self.estimator.config
        fixed = {"description", "zeta_source", "time_source", "board_clock", "max_gap", "command_delay", "frame_id",
                 "pose_delay"}
        try:
            for prm in params:
                name, val = prm.name, prm.value
                if name in fixed:
                    return SetParametersResult(successful=False, reason=f"{name} is read at start-up only")
                if name == "thresholds":  # validated by ObserverConfig; applied only when every parameter is valid
                    cfg = dataclasses.replace(cfg, thresholds=tuple(float(v) for v in val))
                elif name == "servo_thresholds":
                    cfg = dataclasses.replace(cfg, servo_thresholds=tuple(float(v) for v in val))
                elif name == "gains":
                    cfg = dataclasses.replace(cfg, gains=tuple(float(v) for v in val))
                elif name in ("release_ratio", "min_duration"):
                    cfg = dataclasses.replace(cfg, **{name: float(val)})
                elif name in ESTIMATOR_KEYS:
                    est_cfg = dataclasses.replace(est_cfg, **{name: float(val)})
                elif name == "reseed_distance":
                    self.reseed_distance = float(val)
                elif name == "calibration_duration":
                    self.calibration_duration = float(val)
                elif name == "marker_rate_hz":
                    self.marker_period = 1.0 / max(float(val), 1e-3)
                elif name == "marker_scale":
                    self.marker_scale = float(val)
        except (ObserverError, EstimationError, TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        # adapter over H5's observer: the detector reads its config on every sample, the gains live in _K
        obs.config = cfg
        obs.detector.config = cfg
        obs.detector.set_thresholds(cfg.thresholds)
        obs.detector.set_servo_thresholds(cfg.servo_thresholds)
        obs._K = np.asarray(cfg.gains, dtype=float)
        self.estimator.config = est_cfg
        self.get_logger().info(f"parameters set: {[p.name for p in params]}")
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ inputs
    def _on_pose(self, t: float, pose: np.ndarray) -> None:
        """A camera pose (image time t), released by the sequencer at sample time t + pose_delay."""
        if self.zeta_source == "estimator":
            self.estimator.update_camera(t, pose)
        tracked = self._tracked_pose_at(t)
        if tracked is None or float(np.max(np.abs(tracked[:3] - pose[:3]))) > self.reseed_distance:
            # the observer takes a camera seed only when it is not older than its tracked pose
            self.observer.update_pose(max(t, self._t), pose)

    def _tracked_pose_at(self, t: float) -> np.ndarray | None:
        """The observer's tracked plate pose at the sample nearest before t (None when tracking failed since)."""
        if self._last_out is None:
            return None
        for ts, p in reversed(self._pose_hist):
            if ts <= t:
                return p
        return None

    def _on_sample(self, t: float, pos: np.ndarray, tau: np.ndarray, vel: np.ndarray | None) -> None:
        if self.zeta_source == "estimator":
            e = self.estimator.update(t, pos, tau)
            if e is None:
                self.rejects["estimator"] += 1
                return
            if not e.settled:  # ζ̇ still converging after a (re)start: the observer restarts after it
                self.settling += 1
                return
            zeta, zeta_dot = e.zeta, e.zeta_dot
        else:
            zeta, zeta_dot = pos, vel
        out = self.observer.update_arm(t, zeta, tau, zeta_dot)
        self._last_out = out
        if out is None:
            self.rejects["observer"] += 1
            return
        self._t = t
        self._pose_hist.append((t, np.asarray(out.pose, dtype=float)))
        while self._pose_hist and self._pose_hist[0][0] < t - 1.0:
            self._pose_hist.popleft()
        self._publish(out, stamp_from_seconds(t), zeta, zeta_dot)
        if self._calib_until is not None and t >= self._calib_until:
            self._calib_until = None
            try:
                off = self.observer.finish_calibration()
                self.get_logger().info(f"observer offset recalibrated: {np.round(off, 4).tolist()}")
            except ValueError as exc:
                self.get_logger().error(f"recalibration failed: {exc}")

    # ------------------------------------------------------------------ outputs
    def _publish(self, out: Any, stamp: Any, zeta: np.ndarray, zeta_dot: np.ndarray | None) -> None:
        r = Residual()
        r.header.stamp = stamp
        r.header.frame_id = self.frame_id
        r.r = [float(v) for v in out.r_zyz]
        w = out.wrench
        r.wrench.force.x, r.wrench.force.y, r.wrench.force.z = float(w[0]), float(w[1]), float(w[2])
        r.wrench.torque.x, r.wrench.torque.y, r.wrench.torque.z = float(w[3]), float(w[4]), float(w[5])
        r.threshold = [float(v) for v in self.observer.detector.thresholds]
        r.over = [bool(v) for v in out.over]
        r.servo_torque = [float(v) for v in out.servo_torque]
        r.servo_threshold = [float(v) for v in self.observer.detector.servo_thresholds]
        r.servo_over = [bool(v) for v in out.servo_over]
        r.in_collision = bool(out.in_collision)
        self.pub_residual.publish(r)
        for ev in out.events:
            c = CollisionEvent()
            c.header.stamp = stamp_from_seconds(ev.time)
            c.header.frame_id = self.frame_id
            c.event = CollisionEvent.START if ev.kind == "START" else CollisionEvent.END
            c.id = int(ev.id)
            c.onset = stamp_from_seconds(ev.onset)
            c.axis = int(ev.axis)
            c.axis_name = ev.axis_name
            c.value, c.peak, c.duration = float(ev.value), float(ev.peak), float(ev.duration)
            self.pub_collision.publish(c)
            self.events_sent += 1
            self.get_logger().warn(f"collision {ev.id} {ev.kind} on {ev.axis_name}: {ev.value:.3f} "
                                   f"(peak {ev.peak:.3f}, onset {ev.onset:.3f} s)")
        js = JointState()
        js.header.stamp = stamp
        js.name = JOINT_NAMES
        js.position = [float(v) for v in zeta]
        if zeta_dot is not None:
            js.velocity = [float(v) for v in zeta_dot]
        self.pub_zeta.publish(js)
        if out.time - self._last_marker_t >= self.marker_period or out.events:
            self._last_marker_t = out.time
            self.pub_markers.publish(self._markers(out, stamp))

    def _markers(self, out: Any, stamp: Any) -> MarkerArray:
        m = Marker()
        m.header.stamp = stamp
        m.header.frame_id = self.frame_id
        m.ns, m.id, m.type, m.action = "residual_force", 0, Marker.ARROW, Marker.ADD
        P = out.pose[:3]
        F = out.wrench[:3]
        m.points = [Point(x=float(P[0]), y=float(P[1]), z=float(P[2])),
                    Point(x=float(P[0] + self.marker_scale * F[0]), y=float(P[1] + self.marker_scale * F[1]),
                          z=float(P[2] + self.marker_scale * F[2]))]
        m.scale.x, m.scale.y, m.scale.z = 0.006, 0.012, 0.015     # shaft and head diameters, head length (m)
        m.pose.orientation.w = 1.0
        hot = bool(out.in_collision)
        m.color.r, m.color.g, m.color.b, m.color.a = (1.0, 0.1, 0.1, 1.0) if hot else (0.1, 0.8, 0.2, 0.8)
        return MarkerArray(markers=[m])

    # ------------------------------------------------------------------ services, diagnostics
    def _on_reset(self, req: Any, resp: Any) -> Any:
        self.observer.reset()
        self.estimator.reset()
        self._last_out = None
        self._pose_hist.clear()
        if req.recalibrate:
            self.observer.start_calibration()
            self._calib_until = (self._t if math.isfinite(self._t) else 0.0) + self.calibration_duration
            resp.message = f"reset; recalibrating the rest offset over {self.calibration_duration:g} s"
        else:
            resp.message = "reset"
        resp.success = True
        self.get_logger().info(resp.message)
        return resp

    def _diagnostics(self) -> None:
        obs, est = self.observer, self.estimator
        values: dict[str, Any] = {"accepted": obs.accepted, "collisions": obs.detector.count,
                                  "in_collision": obs.detector.active, "events_sent": self.events_sent,
                                  "servo_saturated_samples": est.saturated, "camera_accepted": est.camera_accepted,
                                  "late_poses": self.input.seq.late_poses, "unpaired_samples": self.input.seq.unpaired,
                                  "time_source": "board" if self.input.board_seen else "stamp",
                                  "estimator_settling_samples": self.settling}
        values.update({f"reject_node_{k}": v for k, v in self.rejects.items()})
        values.update({f"reject_observer_{k}": v for k, v in obs.rejected.items()})
        values.update({f"reject_estimator_{k}": v for k, v in est.rejected.items()})
        level = DiagnosticStatus.WARN if obs.detector.active else DiagnosticStatus.OK
        if obs.accepted == 0:
            level, msg = DiagnosticStatus.WARN, "no accepted joint_states yet"
        else:
            msg = "in collision" if obs.detector.active else "ok"
        self.pub_diag.publish(diagnostic(self, level, msg, values))


def _raise_keyboard_interrupt(_signum: int, _frame: Any) -> None:
    raise KeyboardInterrupt


def run_node(factory: Any, name: str, argv: list[str] | None) -> int:
    """init, build the node (exit 2 on a configuration error naming it), spin, clean shutdown on SIGINT/SIGTERM.

    rclpy's own signal handler would invalidate the context while a callback is still publishing (RCLError on
    Ctrl-C); here SIGINT and SIGTERM raise KeyboardInterrupt in the spinning thread and the node is torn down after."""
    import signal

    from hexa_bringup.rosenv import apply_defaults
    from rclpy.signals import SignalHandlerOptions

    apply_defaults()
    signal.signal(signal.SIGINT, _raise_keyboard_interrupt)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    rclpy.init(args=argv if argv is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = factory()
    except (ValueError, OSError, KeyError) as exc:
        print(f"hexa {name}: {exc}", file=sys.stderr)
        rclpy.shutdown()
        return 2
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        # a bounded wait: with sim time and the simulator gone, nothing wakes an unbounded wait, and a Python signal
        # handler only runs when the wait returns (SIGINT used to take the supervisor's 10 s kill)
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.2)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_node(ObserverNode, "observer", argv)


if __name__ == "__main__":
    sys.exit(main())
