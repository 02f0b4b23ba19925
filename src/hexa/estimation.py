"""Arm-angle estimator for hobby servos: ζ, ζ̇ at the current-sample rate from the commanded angles and the measured
torques (servo model), corrected by the camera plate poses through inverse kinematics (seed 000 eqs 15-18).

Hobby servos (MG996R class) report no angle. What the host knows at each current sample k (≈1 kHz) is the commanded
angle u_k (joint_states.position) and the horn torque τ_k = K_t·(I_k − I_0) (joint_states.effort); the cameras add a
plate pose every ~33 ms. The servo is modelled as the simulator models it (hexa.sim.mjcf / Simulator._step_once):

    c_k = c_{k−1} + clip(u(t_k − d) − c_{k−1}, ±ω_max·Δt)       speed limit on the set-point (d: command latency)
    τ   = k_p (c − ζ) − k_v ζ̇                                  the servo's position loop (MuJoCo position actuator)

so y_k = c_k − τ_k/k_p = ζ_k + (k_v/k_p)·ζ̇_k is a direct measurement of the arm state, accurate to σ_τ/k_p (0.3 mrad
for 10-bit current sensing). Per arm a constant-velocity Kalman filter on x = [ζ, ζ̇, b] (white acceleration of
spectral density q = accel_sigma²) fuses y_k with H = [1, k_v/k_p, 1], R = (torque_sigma/k_p)²; the six arms are
filtered together; per sample the state [ζ, ζ̇, b] and the covariance of each arm are plain floats (flat lists: at
1 kHz numpy's per-call overhead on six values costs more than the filter), as numpy arrays for the camera update.

Stalled servos: when |τ_i| > saturation·τ_max the position loop no longer says exactly where the arm is (its true
torque is beyond the clipped one), so that arm's sample is only a weak measurement (stall_sigma) and its acceleration
density is raised to stall_accel_sigma; the camera corrects it.

Camera correction: each plate pose p(t_c) gives ζ_IK = IK(p) (eq 18), a measurement of ζ at t_c (noise camera_sigma)
applied now as ζ_IK + (ζ̂(now) − ζ̂(t_c)) (ζ̂(t_c) interpolated from a short history, so camera latency is respected;
a pose stamped after the newest current sample waits until the samples reach its time — current samples can arrive
late in bursts).
The servo measurement sees ζ + b, the camera sees ζ: a third state b per arm (random walk bias_walk) absorbs what the
servo model cannot know — horn mounting offsets, pot non-linearity, a wrong I₀. Per arm, innovations larger than
camera_gate are skipped; an arm that fails the gate gate_reset_frames frames in a row is restarted from the camera.

Bad input never touches the state and is counted by reason in `rejected`.
"""
from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexa.stream_gate import ACCEPTED, TimeGate

if TYPE_CHECKING:
    from collections.abc import Sequence

    from numpy.typing import ArrayLike, NDArray

    from hexa.robots.hexa_description import HexaDescription

REJECT_REASONS = ("bad_shape", "non_finite", "time_not_increasing", "time_jump", "gap", "camera_unreachable",
                  "camera_gate", "camera_too_old", "camera_before_start")


class EstimationError(ValueError):
    """Bad estimator configuration (the message names the value)."""


@dataclass(frozen=True)
class ServoModel:
    """Servo position loop τ = k_p (c − ζ) − k_v ζ̇ (N·m/rad, N·m·s/rad), set-point speed limit ω_max (rad/s),
    command latency (s) between the commanded angle and the servo's set-point."""

    kp: float
    kv: float
    speed_max: float
    command_delay: float = 0.0

    def __post_init__(self) -> None:
        for name in ("kp", "speed_max"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise EstimationError(f"servo {name} must be > 0, got {v!r}")
        if not (math.isfinite(self.kv) and self.kv >= 0):
            raise EstimationError(f"servo kv must be >= 0, got {self.kv!r}")
        if not (math.isfinite(self.command_delay) and self.command_delay >= 0):
            raise EstimationError(f"servo command_delay must be >= 0 s, got {self.command_delay!r}")

    @classmethod
    def from_description(cls, desc: HexaDescription, command_delay: float = 0.0) -> "ServoModel":
        """k_p, k_v from the description's `sim.servo` section (the simulator's servo), ω_max from `actuators`."""
        servo = {}
        try:
            servo = dict(desc.section("sim").get("servo", {}))
        except (KeyError, AttributeError):
            servo = {}
        return cls(kp=float(servo.get("kp", 40.0)), kv=float(servo.get("kv", 0.6)),
                   speed_max=float(desc.speed_max), command_delay=float(command_delay))


@dataclass(frozen=True)
class EstimatorConfig:
    """Filter settings.

    accel_sigma: white-acceleration density √q_a of the constant-velocity model (rad/s^1.5); torque_sigma: noise of
    the servo measurement expressed as torque (N·m, 1σ) → variance (torque_sigma/k_p)². The ADC alone is ≈ 0.012 N·m,
    but commands reach the servo with a varying latency (a staircase of 3-6 mrad steps at 100 Hz), so the set-point
    is uncertain by about a step: 0.2 N·m (5 mrad) with accel_sigma 2 halves the residual noise of a 0-40 ms jittered
    command delivery (1.2 instead of 2.3 N peak) and costs nothing without jitter; saturation: a servo whose |τ| exceeds
    saturation·τ_max is stalled: its acceleration density is stall_accel_sigma, and its sample is only a weak
    measurement with noise stall_sigma (rad; 0 = not used): the servo pushes at its limit, so the arm is at least
    that far from the set-point — skipping it let ζ̂ coast at the pre-stall velocity for the 0.5 s until the camera
    poses arrived (77 mrad off in the rod case), and the return of the servo measurement then made ζ̂̇ jump by 3 rad/s
    in one sample (an outlier in the identified force); camera_sigma: noise of ζ from a camera
    pose through IK (rad, 1σ; 0 disables the camera); bias_sigma: initial uncertainty of the servo-model offset
    b (rad); bias_walk: its random walk (rad/√s); camera_gate: largest |ζ_IK − ζ̂| accepted (rad); max_gap: longer
    sample spacing restarts the filter (s); history: how far back camera stamps are matched (s); settle_time: after a
    (re)start the estimate is flagged not `settled` this long (s) while ζ̇ converges from 0; gate_reset_frames: an arm
    whose camera innovation exceeds camera_gate in this many consecutive frames is restarted from the camera;
    command_smoothing: time constant (s) of a first-order low-pass on the commanded angles before the servo model —
    a staircase of commands that reaches the servo with a varying latency is better modelled as a ramp (0 = off);
    max_jump: a sample more than this after the last accepted one (s) is rejected (`time_jump`), as one before it is
    (`time_not_increasing`), leaving the state alone; adopt_after: this many such samples in a row that follow one
    another are a clock that really jumped: the filter restarts at them (`clock_jumps`)."""

    accel_sigma: float = 2.0
    stall_accel_sigma: float = 30.0
    torque_sigma: float = 0.2
    saturation: float = 0.97
    stall_sigma: float = 0.02
    camera_sigma: float = 0.004
    bias_sigma: float = 0.02
    bias_walk: float = 0.005
    camera_gate: float = 0.15
    max_gap: float = 0.1
    history: float = 1.0
    settle_time: float = 0.03
    command_smoothing: float = 0.0
    gate_reset_frames: int = 5
    max_jump: float = 1.0
    adopt_after: int = 5

    def __post_init__(self) -> None:
        checks = {"accel_sigma": self.accel_sigma > 0, "stall_accel_sigma": self.stall_accel_sigma > 0,
                  "torque_sigma": self.torque_sigma > 0,
                  "saturation": 0 < self.saturation <= 1.0, "stall_sigma": self.stall_sigma >= 0,
                  "camera_sigma": self.camera_sigma >= 0,
                  "bias_sigma": self.bias_sigma > 0, "bias_walk": self.bias_walk >= 0,
                  "camera_gate": self.camera_gate > 0, "max_gap": self.max_gap > 0, "history": self.history > 0,
                  "settle_time": self.settle_time >= 0,
                  "command_smoothing": self.command_smoothing >= 0, "gate_reset_frames": self.gate_reset_frames >= 1,
                  "max_jump": self.max_jump > self.max_gap, "adopt_after": self.adopt_after >= 1}
        for name, ok in checks.items():
            if not (ok and math.isfinite(getattr(self, name))):
                raise EstimationError(f"estimator {name} out of range, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class ArmEstimate:
    """ζ̂ (rad), ζ̂̇ (rad/s) at `time`; bias: servo-model offset b (rad); setpoint: servo set-point c (rad);
    sigma: 1σ uncertainty of ζ̂ (rad); settled: False during `settle_time` after a (re)start."""

    time: float
    zeta: NDArray
    zeta_dot: NDArray
    bias: NDArray
    setpoint: NDArray
    sigma: NDArray
    settled: bool = True


def _six(x: ArrayLike | None) -> NDArray | None:
    try:
        a = np.asarray(x, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    return a if a.shape == (6,) else None


def six_floats(x: ArrayLike) -> list[float] | None:
    """Six values as a new list of plain floats, or None when `x` is not six numbers (the per-sample paths compute
    on floats: numpy's per-call overhead dominates on six values)."""
    if type(x) is np.ndarray and x.shape == (6,) and x.dtype == np.float64:
        return x.tolist()
    a = _six(x)
    return None if a is None else a.tolist()


class ZetaEstimator:
    """ζ, ζ̇ of the six arms from commanded angles + torques, corrected by camera poses (see module docstring).

    Usage:
        est = ZetaEstimator(desc)
        e = est.update(t, zeta_commanded, tau)   # every current sample; None when rejected
        est.update_camera(t_cam, pose)           # every plate pose [x y z α β γ] (m, rad; Z-Y-X)
        e.zeta, e.zeta_dot
    """

    def __init__(self, desc: HexaDescription, servo: ServoModel | None = None,
                 config: EstimatorConfig | None = None) -> None:
        self.desc = desc
        self.servo = servo or ServoModel.from_description(desc)
        self.config = config or EstimatorConfig()
        self.rejected: dict[str, int] = {k: 0 for k in REJECT_REASONS}
        self.accepted = 0
        self.camera_accepted = 0
        self.saturated = 0
        self.camera_resets = 0
        self.clock_jumps = 0
        self._time_gate = TimeGate(self.config.max_jump, self.config.adopt_after)
        self._gated = np.zeros(6, dtype=int)
        self.torque_max = float(getattr(desc, "torque_max", math.inf))
        self._commands: deque[tuple[float, list[float]]] = deque()
        self._hist: deque[tuple[float, list[float]]] = deque()   # (t, ζ̂ without the camera corrections so far)
        self.reset()

    def reset(self) -> None:
        """Forget the filter state; the next sample re-initialises it."""
        self._t: float | None = None
        self._t_start = -math.inf
        self._c: list[float] | None = None
        self._us = [0.0] * 6               # the smoothed command (command_smoothing)
        self._y = [0.0] * 6                # the servo measurement c − τ/k_p of the newest sample
        self._xs = [0.0] * 18              # [ζ, ζ̇, b] per arm, flat (the `_x` property: as a (6, 3) array)
        self._Ps = [0.0] * 54              # P per arm, row-major, flat (`_P`: as a (6, 3, 3) array)
        self._corr = [0.0] * 6             # the camera corrections of ζ̂ so far
        self._commands.clear()
        self._hist.clear()
        self._pending_cam: deque[tuple[float, NDArray]] = deque(maxlen=64)
        self._last: ArmEstimate | None = None   # built when asked for (`last`)

    @property
    def _x(self) -> NDArray:
        """The filter states [ζ, ζ̇, b] of the six arms, (6, 3) (a copy; assign to change them)."""
        return np.array(self._xs).reshape(6, 3)

    @_x.setter
    def _x(self, x: NDArray) -> None:
        self._xs = np.asarray(x, dtype=float).reshape(-1).tolist()

    @property
    def _P(self) -> NDArray:
        """The covariances of the six arms' states, (6, 3, 3) (a copy; assign to change them)."""
        return np.array(self._Ps).reshape(6, 3, 3)

    @_P.setter
    def _P(self, P: NDArray) -> None:
        self._Ps = np.asarray(P, dtype=float).reshape(-1).tolist()

    @property
    def last(self) -> ArmEstimate | None:
        """The estimate after the newest accepted sample or camera correction (None before the first sample)."""
        if self._last is None and self._t is not None:
            self._last = self._estimate()
        return self._last

    def _initial_covariance(self) -> NDArray:
        """P of [ζ, ζ̇, b] at a (re)start: ζ = y − b with b ~ N(0, bias_sigma²), ζ̇ ~ N(0, 1 rad²/s²)."""
        cfg = self.config
        r_s = (cfg.torque_sigma / self.servo.kp) ** 2
        sb2 = cfg.bias_sigma ** 2
        return np.array([[r_s + sb2, 0.0, -sb2], [0.0, 1.0, 0.0], [-sb2, 0.0, sb2]])

    def _reject(self, reason: str) -> None:
        self.rejected[reason] += 1

    # ------------------------------------------------------------------ servo model
    def _delayed_command(self, t: float, u: list[float]) -> list[float]:
        d = self.servo.command_delay
        self._commands.append((t, u))
        if d <= 0.0:
            self._commands.clear()
            return u
        while len(self._commands) > 1 and self._commands[1][0] <= t - d:
            self._commands.popleft()
        return self._commands[0][1]

    def update(self, t: float, zeta_commanded: ArrayLike, tau: ArrayLike) -> ArmEstimate | None:
        """One current sample: commanded angles u (rad) and horn torques τ (N·m) at time t (s)."""
        return None if self.step(t, zeta_commanded, tau) is None else self.last

    def step(self, t: float, zeta_commanded: ArrayLike, tau: ArrayLike
             ) -> tuple[list[float], list[float], bool] | None:
        """`update` without building the ArmEstimate (the per-sample path): (ζ̂, ζ̂̇ as lists of floats, settled), or
        None when the sample is rejected."""
        u = six_floats(zeta_commanded)
        tq = six_floats(tau)
        try:
            t = float(t)
        except (TypeError, ValueError):
            self._reject("bad_shape")
            return None
        if u is None or tq is None:
            self._reject("bad_shape")
            return None
        if not (math.isfinite(t) and all(map(math.isfinite, u)) and all(map(math.isfinite, tq))):
            self._reject("non_finite")
            return None
        sv = self.servo
        cfg = self.config
        verdict = self._time_gate.check(t)   # the filter's own time, not `_t`: it lives on across a gap restart
        if verdict not in ACCEPTED:
            self._reject("time_jump" if verdict == "time_future" else "time_not_increasing")
            return None
        if verdict == "adopted":             # the clock jumped for good: restart at it
            self.clock_jumps += 1
            self.reset()
        if self._t is not None and t - self._t > cfg.max_gap:
            self._reject("gap")
            self.reset()
        uc = self._delayed_command(t, u)
        if cfg.command_smoothing > 0.0 and self._t is not None:
            k = 1.0 - math.exp(-(t - self._t) / cfg.command_smoothing)
            uc = [s + (v - s) * k for s, v in zip(self._us, uc)]
        self._us = uc
        kp = sv.kp
        r_s = (cfg.torque_sigma / kp) ** 2
        lim = cfg.saturation * self.torque_max
        free = [abs(v) < lim for v in tq]  # saturated servos: τ no longer tells the angle
        self.saturated += 6 - sum(free)
        if self._t is None:
            c = list(uc)
            self._xs = [v for ci, ti in zip(c, tq) for v in (ci - ti / kp, 0.0, 0.0)]
            self._Ps = self._initial_covariance().reshape(-1).tolist() * 6
            self._t_start = t
        else:
            h = t - self._t
            step = sv.speed_max * h
            assert self._c is not None   # set with _t
            c = []
            for ci, ui in zip(self._c, uc):   # the set-point moves by at most ±step
                d = ui - ci
                c.append(ci + (d if -step <= d <= step else step if d > step else -step))
            self._predict_update(h, c, tq, free, r_s)
        self._y = [ci - ti / kp for ci, ti in zip(c, tq)]
        self._c = c
        self._t = t
        self.accepted += 1
        xs, corr = self._xs, self._corr
        self._hist.append((t, [xs[3 * i] - corr[i] for i in range(6)]))  # without the camera corrections so far
        while self._hist and self._hist[0][0] < t - cfg.history:
            self._hist.popleft()
        self._last = None
        while self._pending_cam and self._pending_cam[0][0] <= t:  # camera poses that were ahead of the samples
            tc, q = self._pending_cam.popleft()
            self.update_camera(tc, q)
        xs = self._xs
        return xs[0::3], xs[1::3], t - self._t_start >= cfg.settle_time

    def _predict_update(self, h: float, c: Sequence[float] | NDArray, tq: Sequence[float] | NDArray,
                        free: Sequence[bool] | NDArray, r_s: float) -> None:
        """Kalman predict over h seconds and the servo-model update, for the six arms at once, in closed form.

        State [ζ, ζ̇, b] per arm. Predict: constant velocity (white acceleration √q_a, stall_accel_sigma for a
        saturated servo), bias random walk: P ← F P Fᵀ + Q with F = [[1, h, 0], [0, 1, 0], [0, 0, 1]]. Update with
        y = c − τ/k_p = ζ + (k_v/k_p) ζ̇ + b (H = [1, a, 1]); a saturated servo's y is only a weak measurement (noise
        stall_sigma): its true torque is larger than the clipped one it reports. Written out per arm on the six
        distinct covariance entries in plain floats: at 1 kHz the 3×3 numpy products of the matrix form cost ten
        times more (numpy's per-call overhead on 3×3 arrays), for the same numbers."""
        cfg, sv = self.config, self.servo
        a = sv.kv / sv.kp
        kp = sv.kp
        h2, h3 = h * h, h * h * h
        qb = cfg.bias_walk ** 2 * h
        q_free, q_stall = cfg.accel_sigma ** 2, cfg.stall_accel_sigma ** 2
        r_stall = cfg.stall_sigma ** 2
        stall_measured = cfg.stall_sigma > 0.0
        xs, Ps = self._xs, self._Ps   # flat lists, updated in place
        if isinstance(c, np.ndarray):   # arrays from a caller other than `step`
            c, tq, free = c.tolist(), np.asarray(tq).tolist(), np.asarray(free).tolist()
        for i, (ci, ti, fi) in enumerate(zip(c, tq, free)):
            z, zd, b = xs[3 * i:3 * i + 3]
            p00, p01, p02, _, p11, p12, _, _, p22 = Ps[9 * i:9 * i + 9]
            qa = q_free if fi else q_stall
            z += h * zd
            n00 = p00 + 2.0 * h * p01 + h2 * p11 + qa * (h3 / 3.0)
            n01 = p01 + h * p11 + qa * (h2 / 2.0)
            n02 = p02 + h * p12
            n11 = p11 + qa * h
            n12 = p12
            n22 = p22 + qb
            if fi or stall_measured:
                ph0 = n00 + a * n01 + n02
                ph1 = n01 + a * n11 + n12
                ph2 = n02 + a * n12 + n22
                S = ph0 + a * ph1 + ph2 + (r_s if fi else r_stall)
                g = (ci - ti / kp - (z + a * zd + b)) / S
                z, zd, b = z + ph0 * g, zd + ph1 * g, b + ph2 * g
                n00, n01, n02 = n00 - ph0 * ph0 / S, n01 - ph0 * ph1 / S, n02 - ph0 * ph2 / S
                n11, n12, n22 = n11 - ph1 * ph1 / S, n12 - ph1 * ph2 / S, n22 - ph2 * ph2 / S
            xs[3 * i:3 * i + 3] = z, zd, b
            Ps[9 * i:9 * i + 9] = n00, n01, n02, n01, n11, n12, n02, n12, n22

    def _estimate(self) -> ArmEstimate:
        assert self._t is not None and self._c is not None   # called after a sample was taken
        x = self._x
        return ArmEstimate(time=self._t, zeta=x[:, 0].copy(), zeta_dot=x[:, 1].copy(),
                           bias=x[:, 2].copy(), setpoint=np.array(self._c),
                           sigma=np.sqrt(np.maximum(self._P[:, 0, 0], 0.0)),
                           settled=self._t - self._t_start >= self.config.settle_time)

    # ------------------------------------------------------------------ camera correction
    def _filter_at(self, t: float) -> NDArray | None:
        h = self._hist
        if not h or t < h[0][0]:
            return None
        corr = np.array(self._corr)
        if t >= h[-1][0]:  # never extrapolate with the velocity the camera is about to correct
            return np.array(h[-1][1]) + corr
        lo, hi = 0, len(h) - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if h[mid][0] <= t:
                lo = mid
            else:
                hi = mid
        (t0, l0), (t1, l1) = h[lo], h[hi]
        z0, z1 = np.array(l0), np.array(l1)
        w = (t - t0) / (t1 - t0) if t1 > t0 else 0.0
        return z0 + w * (z1 - z0) + corr  # every camera correction so far shifts the past estimate too

    def zeta_at(self, t: float) -> NDArray | None:
        """ζ̂ at a past time t within `history` (interpolated, with every camera correction so far); None outside."""
        z = self._filter_at(float(t))
        return None if z is None else z.copy()

    def update_camera(self, t: float, pose: ArrayLike) -> bool:
        """A plate pose [x y z α β γ] (m, rad) stamped t (the image time): ζ_IK = IK(pose) (eq 18) is a measurement
        of ζ at t, applied now as ζ_IK + (ζ̂(now) − ζ̂(t)). Returns False when rejected."""
        from hexa.kinematics.hexa6rus import UnreachablePoseError, inverse_kinematics

        q = _six(pose)
        try:
            t = float(t)
        except (TypeError, ValueError):
            self._reject("bad_shape")
            return False
        if q is None:
            self._reject("bad_shape")
            return False
        if not (math.isfinite(t) and np.all(np.isfinite(q))):
            self._reject("non_finite")
            return False
        if self._t is None:
            self._reject("camera_before_start")
            return False
        if self.config.camera_sigma <= 0.0:
            return False
        if t > self._t:  # the pose is newer than the newest current sample (samples can arrive late): wait for them
            self._pending_cam.append((t, q))
            return True
        z_then = self._filter_at(t)
        if z_then is None:
            self._reject("camera_too_old")
            return False
        try:
            z_ik = np.asarray(inverse_kinematics(self.desc, q), dtype=float)
        except (UnreachablePoseError, ValueError):
            self._reject("camera_unreachable")
            return False
        e = np.remainder(z_ik - z_then + math.pi, 2 * math.pi) - math.pi
        cfg = self.config
        ok = np.abs(e) <= cfg.camera_gate  # per arm: an outlier (or a lost arm) does not move the others
        self._gated = np.where(ok, 0, self._gated + 1)
        lost = self._gated >= cfg.gate_reset_frames  # the camera disagrees frame after frame: restart from it
        x, P = self._x, self._P
        z_before = x[:, 0].copy()
        if lost.any():
            x[lost, 0] += e[lost]
            x[lost, 1] = 0.0
            # the offset that makes the servo model agree with the camera
            x[lost, 2] = np.array(self._y)[lost] - x[lost, 0]
            P[lost] = self._initial_covariance()
            self._gated[lost] = 0
            self.camera_resets += int(lost.sum())
        if not ok.all():
            self._reject("camera_gate")
        use = ok & ~lost
        if use.any():
            S = P[:, 0, 0] + cfg.camera_sigma ** 2
            K = P[:, :, 0] / S[:, None] * use[:, None]      # (6, 3); zero gain on gated arms
            x += K * e[:, None]
            P = P - K[:, :, None] * P[:, 0, None, :]
            P = 0.5 * (P + np.swapaxes(P, 1, 2))
        self._x, self._P = x, P
        self._corr = [c + d for c, d in zip(self._corr, (x[:, 0] - z_before).tolist())]
        if not use.any() and not lost.any():
            return False
        self.camera_accepted += 1
        self._last = None
        return True


class InputCheck:
    """Values of the driver's sample streams that no working robot sends, rejected before they are paired: so a bad
    message costs only itself (paired first, it would take its good partner down with it). Counted by reason in
    `rejected`.

    currents (A): six finite values within ±current_factor·current_max (beyond the sensors' range);
    states: six finite commanded (or measured) angles within the joint range ± angle_margin (rad; the driver rejects
    commands outside it), finite velocities and efforts when present, efforts within ±current_factor·K_t·current_max.
    """

    def __init__(self, desc: HexaDescription, current_factor: float = 4.0, angle_margin: float = 0.1) -> None:
        self.current_max = current_factor * float(desc.current_max)
        self.torque_max = self.current_max * float(desc.K_t)
        self.zeta_range = (float(desc.zeta_min) - angle_margin, float(desc.zeta_max) + angle_margin)
        self.rejected: Counter[str] = Counter()

    def currents(self, currents: ArrayLike) -> NDArray | None:
        """The six currents as an array, or None (counted: currents_bad_shape, currents_non_finite, currents_range)."""
        cur = _six(currents)
        if cur is None:
            self.rejected["currents_bad_shape"] += 1
            return None
        values = cur.tolist()   # plain floats: numpy's per-call overhead dominates on six values at 1 kHz
        if not all(map(math.isfinite, values)):
            self.rejected["currents_non_finite"] += 1
        elif max(map(abs, values)) > self.current_max:
            self.rejected["currents_range"] += 1
        else:
            return cur
        return None

    def states(self, position: ArrayLike | None, velocity: ArrayLike | None, effort: ArrayLike | None,
               kind: str = "states") -> bool:
        """Whether a joint_states sample is usable (counted when not: states_bad_shape, states_non_finite,
        states_range; with kind "setpoint" the set-points a motor_currents carries: setpoint_bad_shape, ...)."""
        arrays = [_six(position)] + [_six(v) for v in (velocity, effort) if v is not None]
        if any(a is None for a in arrays):
            self.rejected[f"{kind}_bad_shape"] += 1
            return False
        values = [a.tolist() for a in arrays if a is not None]
        if not all(all(map(math.isfinite, v)) for v in values):
            self.rejected[f"{kind}_non_finite"] += 1
            return False
        lo, hi = self.zeta_range
        if min(values[0]) < lo or max(values[0]) > hi or (
                effort is not None and max(map(abs, values[-1])) > self.torque_max):
            self.rejected[f"{kind}_range"] += 1
            return False
        return True


#: the other topic of a sample's pair
OTHER = {"currents": "states", "states": "currents"}


class SampleSequencer:
    """Deterministic ordering of the three input streams of the live nodes: the result depends only on message
    stamps and contents, never on the order in which DDS delivers the topics, so a replayed bag gives the same
    events every time.

    Streams: current samples (motor_currents: header stamp, board time t, τ), joint_states (header stamp, commanded
    angles, velocity, effort) and camera plate poses (image stamp). The driver publishes one motor_currents and one
    joint_states per sample with the same header stamp, each topic in order, so the k-th of one pairs with the k-th
    of the other (matched by stamp; a partner lost in transport is dropped and counted). A sample is released only
    once its pair is complete, with the command of its own joint_states (the one the driver had sent when it handled
    the sample) — not the command current at its board time by host stamps: in sim mode those stamps are quantized
    and lagged by /clock, which misplaced command changes by a few ms (docs/history/observer_node.md, "Command timing").

    Camera poses are released into the same stream at sample time stamp + pose_delay (the vision chain's latency is
    0.1-0.47 s on this loaded machine); a pose that arrives later than that is released on arrival and counted in
    `late_poses` (only those can make a run non-deterministic). In `stamp` mode (no motor_currents: a bag or peer
    without them) each joint_states is a sample at its stamp with τ = effort. In `auto` mode the board mode is
    chosen when a motor_currents arrives before `auto_wait` joint_states are queued; a motor_currents that arrives
    after auto mode settled on stamps switches it to board mode for good (`to_board`): a node that starts while the
    driver runs can match its joint_states subscription before its motor_currents one.

    Output items: ("sample", t, commanded ζ, τ, velocity or None) and ("pose", t_image, pose).

    One message with a stamp far from its stream's costs only itself: the stamps of each stream pass a
    hexa.stream_gate.TimeGate (each at or after the last accepted one, at most `max_step` s later; a stream that
    really jumped — a restarted simulator, a bag played again — is adopted after `adopt_after` consistent messages, or
    at once when the other topic's newest stamp is already within `max_step` of it (both resume after a silence),
    and the queued messages the jump left behind, or ahead of it in the adopted stream, are dropped as unpaired), and
    a pose stamped more than `max_step` after the newest sample time waits for nothing: it is rejected. A message
    stamped less than `max_step` ahead is accepted and holds the good ones back until `adopt_after` of them re-adopt
    the stream: it costs that many samples, not one. Rejects are counted by reason in `rejected`
    (currents_time_past, states_time_future, pose_time_future, ...)."""

    def __init__(self, mode: str = "auto", pose_delay: float = 0.5, auto_wait: int = 20,
                 max_queue: int = 2000, max_step: float = 0.25, adopt_after: int = 5) -> None:
        if mode not in ("auto", "board", "stamp"):
            raise EstimationError(f"sequencer mode must be 'auto', 'board' or 'stamp', got {mode!r}")
        if not (math.isfinite(pose_delay) and pose_delay >= 0):
            raise EstimationError(f"sequencer pose_delay out of range, got {pose_delay!r}")
        self.mode, self.pose_delay, self.auto_wait, self.max_queue = (
            mode, float(pose_delay), int(auto_wait), int(max_queue))
        self.board = mode == "board"
        self._stamp_mode = mode == "stamp"
        self._cur: deque[tuple[float, float, NDArray]] = deque()  # (stamp, board t, τ)
        # (stamp, commanded, velocity, effort)
        self._js: deque[tuple[float, NDArray, NDArray | None, NDArray | None]] = deque()
        self._poses: list[tuple[float, int, NDArray]] = []
        self._seq = 0
        self.last_t = -math.inf
        self.late_poses = 0
        self.unpaired = 0
        self.to_board = 0
        self.max_step = float(max_step)
        self._gates = {k: TimeGate(self.max_step, adopt_after, repeats=True) for k in ("currents", "states")}
        self._seen = {"currents": -math.inf, "states": -math.inf}   # each topic's newest stamp, accepted or not
        self.rejected: Counter[str] = Counter()

    @property
    def takes_currents(self) -> bool:
        """False in stamp mode: current samples are ignored."""
        return self.mode != "stamp"

    @property
    def adopted(self) -> int:
        """How many times a stream's stamps jumped for good and were adopted."""
        return sum(g.adopted for g in self._gates.values())

    def admit(self, stream: str, stamp: float) -> bool:
        """Whether a message of `stream` ("currents" | "states") stamped `stamp` follows its stream (counted by
        reason when not); on a re-adopted jump, the queued messages more than max_step away from the new stamp are
        dropped as unpaired. push_currents and push_states call it unless told the caller did (`admitted`): the
        monitor checks a current sample's stamp before its board time, so that a bad stamp never moves the board
        clock."""
        gate = self._gates[stream]
        verdict = gate.check(stamp)
        if verdict == "time_future" and abs(stamp - self._seen[OTHER[stream]]) <= self.max_step:
            gate.adopt(stamp)     # the other topic is there already: both resume after a silence, not one bad stamp
            verdict = "adopted"
        self._seen[stream] = stamp
        if verdict == "adopted":   # drop what the jump left behind, and this stream's messages ahead of it (the one
            own = self._cur if stream == "currents" else self._js     # that moved the reference, if that was bad)
            for q in (self._cur, self._js):
                keep = [m for m in q if stamp - self.max_step <= m[0] and (q is not own or m[0] <= stamp)]
                self.unpaired += len(q) - len(keep)
                q.clear()
                q.extend(keep)   # type: ignore[arg-type]  # each queue gets back its own kind of entries
        elif verdict != "ok":
            self.rejected[f"{stream}_{verdict}"] += 1
            return False
        return True

    # ------------------------------------------------------------------ inputs
    def push_currents(self, stamp: float, t: float, tau: NDArray, admitted: bool = False) -> list[tuple]:
        if not self.takes_currents:
            return []
        if not (admitted or self.admit("currents", stamp)):
            return []
        if self._stamp_mode:     # auto mode had settled on stamps before the first motor_currents: board mode now
            self._stamp_mode = False
            self.to_board += 1
        self.board = True
        self._cur.append((float(stamp), float(t), tau))
        if len(self._cur) > self.max_queue:  # no joint_states at all: nothing to pair with
            self._cur.popleft()
            self.unpaired += 1
        return self._drain()

    def push_sample(self, stamp: float, t: float, tau: NDArray, commanded: NDArray, admitted: bool = False
                    ) -> list[tuple]:
        """A current sample that carries the command in effect when it was measured (motor_currents.setpoint, the
        same values as its joint_states): released at once, no pairing. Messages of a stream that carried its
        commands apart before (a driver without the field, then one with it) are dropped as unpaired."""
        if not self.takes_currents or not (admitted or self.admit("currents", stamp)):
            return []
        if self._stamp_mode:
            self._stamp_mode = False
            self.to_board += 1
        self.board = True
        if self._cur or self._js:
            self.unpaired += len(self._cur) + len(self._js)
            self._cur.clear()
            self._js.clear()
        out: list[tuple] = []
        self._sample(t, commanded, tau, None, out)
        return out

    def push_states(self, stamp: float, commanded: NDArray, velocity: NDArray | None, effort: NDArray | None
                    ) -> list[tuple]:
        if not self.admit("states", stamp):
            return []
        self._js.append((float(stamp), commanded, velocity, effort))
        if len(self._js) > self.max_queue:
            self._js.popleft()
            self.unpaired += 1
        return self._drain()

    def push_pose(self, stamp: float, pose: NDArray) -> list[tuple]:
        import heapq

        stamp = float(stamp)
        if not math.isfinite(stamp):
            self.rejected["pose_non_finite"] += 1
            return []
        if stamp > self.last_t + self.max_step and math.isfinite(self.last_t):   # a pose from the future
            self.rejected["pose_time_future"] += 1
            return []
        if stamp + self.pose_delay < self.last_t:  # later than its slot: released now (counted)
            self.late_poses += 1
            return [("pose", stamp, pose)]
        heapq.heappush(self._poses, (stamp, self._seq, pose))
        self._seq += 1
        return []

    # ------------------------------------------------------------------ ordering
    def _release_poses(self, t: float, out: list) -> None:
        import heapq

        while self._poses and self._poses[0][0] + self.pose_delay <= t:
            tp, _, pose = heapq.heappop(self._poses)
            out.append(("pose", tp, pose))

    def _sample(self, t: float, cmd: NDArray, tau: NDArray, vel: NDArray | None, out: list) -> None:
        self._release_poses(t, out)
        out.append(("sample", t, cmd, tau, vel))
        self.last_t = t   # sample times only go back when a clock jump was adopted upstream: follow it

    def _drain(self) -> list[tuple]:
        out: list[tuple] = []
        if not self.board:
            if self.mode == "auto" and not self._stamp_mode:
                if len(self._js) < self.auto_wait:
                    return out  # a motor_currents may still come: decide on board mode from the data, not the timing
                self._stamp_mode = True
            while self._js:
                s, pos, vel, eff = self._js.popleft()
                if eff is not None:
                    self._sample(s, pos, eff, vel, out)
            return out
        while self._cur and self._js:
            sc, t, tau = self._cur[0]
            sj, pos, vel, _ = self._js[0]
            if sc < sj:  # its joint_states was lost
                self._cur.popleft()
                self.unpaired += 1
                continue
            self._js.popleft()
            if sj < sc:  # a joint_states without its motor_currents
                self.unpaired += 1
                continue
            self._cur.popleft()
            # the command the driver had sent when it handled this sample (its own joint_states): placing command
            # changes by the host stamps (in sim mode quantized and lagged by /clock) misplaced them by a few ms, and
            # at K = 100 1/s each misplaced 5 mrad step shows in the residual
            self._sample(t, pos, tau, vel, out)
        return out
