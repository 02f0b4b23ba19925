"""Residual observer of the Hexa (seed 000 §3.1, eqs 23–26): momentum form, the paper's direct form, detection.

Momentum (integral) form, on the reduced model of `hexa.dynamics.lagrange` (generalized momentum π = M̃(q)·V of the
plate twist V, eq 23 in twist coordinates):

    r(t) = K (π(t) − π(0) − ∫₀ᵗ (J_ζᵀτ + G + β + r) ds)            ⇒   ṙ = −K r + K W           (eq 25)

so r is W (the external wrench on the plate in `base`, moment about the plate centre P) seen through first-order
lags 1/K_j, and no acceleration is ever formed. Discrete update between samples k−1 and k (any spacing Δt):
the external wrench averaged over the interval is w̄ = (π_k − π_{k−1})/Δt − ½(u_k + u_{k−1}) (u = J_ζᵀτ + G + β,
trapezoid), and r_k = a r_{k−1} + (1 − a) w̄ with a = exp(−K Δt) — the exact solution of eq 25 for a constant W over
the interval, stable for any Δt. The paper's r_7..r_12 (Z-Y-Z) are Q = diag(1, Eᵀ)·r (reported, never inverted).

Direct form (the paper's eq 25 with eq 22): Q from inverse dynamics with measured accelerations, filtered by the same
first-order lag. It needs ζ̈ (or the plate acceleration) — differentiated twice on real data, hence noisy.

Inputs arrive separately: arm samples (t, ζ, τ[, ζ̇]) at up to 1 kHz from the driver, plate poses (t, pose) at
~30 Hz from the cameras. Between plate poses the pose is tracked from ζ by Newton steps on the loop constraints
(f_i = 0, eq 15) started at the last estimate, so the camera chooses the assembly branch and ζ gives the precision;
the plate twist is V = J_ζ⁻¹ ζ̇. ζ̇ is the measured rate when the sample carries one, else the backward difference of
ζ over the (irregular) sample spacing.

Bad input never touches the state: non-finite values, time not increasing, gaps longer than `max_gap`, pose
tracking failure or a singular J_ζ are rejected and counted by reason in `rejected`; after a gap the integration
restarts at the next sample (r is kept) and the detector's runs toward a START or an END start over there.

Detection (`CollisionDetector`): |r_j| > r_low on any plate axis (the paper's criterion, §3.1), or — beside it — the
residual as servo torques τ_r = J_ζ⁻ᵀ r (N·m; u = J_ζᵀ τ maps servo torques onto the plate twist, so τ_r is the torque
each servo delivers beyond the model) over a per-servo threshold. A contact on arm k gives τ_r = e_k·(moment of the
force about the servo axis) exactly; a rod contact spreads over several servos, peaking on one. The sensor noise
is per servo, so a per-servo threshold separates these contacts from free motion sooner than the plate-axis
thresholds, which see them diluted (docs/detectors.md, "Detection in servo coordinates").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterable

import numpy as np

from hexa.dynamics._kernel import (KernelError, SampleKernel, chain_jacobian_array, chain_jacobian_rows, exp_rotate,
                                    solve6)
from hexa.dynamics.lagrange import (DynamicsError, HexaDynamicParameters, MotionState, _Geometry, _momentum_terms,
                                    _Velocity, inverse_dynamics, motion_from_joint_rates, pose_to_position_rotation,
                                    wrench_to_generalized_zyz)
from hexa.stream_gate import ACCEPTED, TimeGate

if TYPE_CHECKING:
    from numpy.typing import NDArray

AXIS_NAMES = ("fx", "fy", "fz", "mx", "my", "mz")
SERVO_AXIS_NAMES = ("servo1", "servo2", "servo3", "servo4", "servo5", "servo6")
EVENT_AXIS_NAMES = AXIS_NAMES + SERVO_AXIS_NAMES  # CollisionEvent.axis 0..11
REJECT_REASONS = ("non_finite", "time_not_increasing", "time_jump", "gap", "bad_shape", "pose_tracking", "singular",
                  "no_pose", "pose_stale")
KINEMATICS = ("arm", "pose")


class ObserverError(ValueError):
    """Bad observer configuration (the message names the value)."""


@dataclass(frozen=True)
class ObserverConfig:
    """Observer and detector settings.

    gains: K_j (1/s) per axis [fx fy fz mx my mz]; thresholds: r_low per axis (N, N·m); servo_thresholds: per
    servo 1..6 (N·m), on the residual as servo torques τ_r = J_ζ⁻ᵀ r, 0 switches that servo's check off;
    release_ratio: an axis releases below release_ratio·threshold (hysteresis); min_duration (s): over a threshold
    this long before START, all axes released this long before END; max_gap (s): longer arm-sample spacing is a gap;
    pose_tolerance (m²): largest |f_i| accepted after pose tracking; max_jump (s): an arm sample more than this after
    the last one is rejected (time_jump), as one before it (time_not_increasing), and `adopt_after` of them in a row
    that follow one another are a clock that jumped for good: integration restarts there, as after a gap
    (hexa.stream_gate).

    kinematics: "arm" — ζ (and ζ̇) come with the arm samples, the plate pose is tracked from them (servos with
    angle feedback, the simulator); "pose" — the arm samples bring only τ (and at most the commanded ζ, used as a
    seed), ζ and the twist come from the camera poses: a polynomial of order `pose_fit_order` fitted to the last
    `pose_window` poses is evaluated (extrapolated) at each arm sample, ζ by Newton on eq 15 per chain; arm samples
    more than `max_pose_age` s after the newest pose are rejected as pose_stale. This is the paper's set-up
    (currents + plate pose from image processing) and the one for hobby servos, whose angle is not measured.
    """

    # the live graph's values (the observer node declares these): K = 100 1/s, a 10 ms first-order lag — with the
    # commands delivered on time, free-motion residual peaks reach r_low only in runs of a few samples, and the plate
    # is detected 35 ms sooner than at 25 1/s; min_duration 0.02 s, 5 consecutive samples at 200 Hz — free motion
    # shows runs of up to 3 samples over a threshold, and 0.015 s raises false STARTs
    # (docs/history/observer_node.md, "Command timing", "Free motion that moves for 60 s"; docs/detectors.md)
    gains: tuple[float, ...] = (100.0, 100.0, 100.0, 100.0, 100.0, 100.0)
    thresholds: tuple[float, ...] = (2.0, 2.0, 2.0, 0.2, 0.2, 0.2)
    # free motion in the live graph peaks at 0.3–0.52 N·m in single samples; an arm push of 5 N gives 0.4–0.54 N·m,
    # a rod push 0.8 N·m (docs/detectors.md, "Detection in servo coordinates")
    servo_thresholds: tuple[float, ...] = (0.35, 0.35, 0.35, 0.35, 0.35, 0.35)
    release_ratio: float = 0.5
    min_duration: float = 0.02
    max_gap: float = 0.1
    pose_tolerance: float = 1e-10
    newton_iterations: int = 4
    kinematics: str = "arm"
    pose_window: int = 8
    pose_fit_order: int = 1
    max_pose_age: float = 0.1
    max_jump: float = 1.0
    adopt_after: int = 5

    def __post_init__(self) -> None:
        g = np.asarray(self.gains, dtype=float)
        if g.shape != (6,) or not np.all(np.isfinite(g)) or np.any(g <= 0):
            raise ObserverError(f"gains must be six positive values (1/s), got {self.gains!r}")
        th = np.asarray(self.thresholds, dtype=float)
        if th.shape != (6,) or not np.all(np.isfinite(th)) or np.any(th <= 0):
            raise ObserverError(f"thresholds must be six positive values, got {self.thresholds!r}")
        _check_servo_thresholds(self.servo_thresholds)
        if not 0.0 < self.release_ratio <= 1.0:
            raise ObserverError(f"release_ratio must be in (0, 1], got {self.release_ratio!r}")
        if not self.min_duration >= 0.0:
            raise ObserverError(f"min_duration must be >= 0 s, got {self.min_duration!r}")
        if not self.max_gap > 0.0:
            raise ObserverError(f"max_gap must be > 0 s, got {self.max_gap!r}")
        if not (self.max_jump > self.max_gap and self.adopt_after >= 1):
            raise ObserverError(f"max_jump must be > max_gap ({self.max_gap!r} s), got {self.max_jump!r}, and "
                                f"adopt_after >= 1, got {self.adopt_after!r}")
        if self.kinematics not in KINEMATICS:
            raise ObserverError(f"kinematics must be one of {KINEMATICS}, got {self.kinematics!r}")
        if not (0 <= self.pose_fit_order <= 3 and self.pose_window >= self.pose_fit_order + 1):
            raise ObserverError(f"pose_fit_order {self.pose_fit_order!r} needs 0..3 and pose_window "
                                f"{self.pose_window!r} >= order + 1")
        if not self.max_pose_age > 0.0:
            raise ObserverError(f"max_pose_age must be > 0 s, got {self.max_pose_age!r}")


def _check_servo_thresholds(values) -> NDArray:
    th = np.asarray(values, dtype=float)
    if th.shape != (6,) or not np.all(np.isfinite(th)) or np.any(th < 0):
        raise ObserverError(f"servo_thresholds must be six values >= 0 (N·m, 0 = off), got {values!r}")
    return th


@dataclass(frozen=True)
class CollisionEvent:
    """START or END of a collision. onset: first sample over threshold; axis: 0..11 (EVENT_AXIS_NAMES: the plate
    axes fx..mz, then servo1..servo6 for τ_r), the axis that triggered (START) or whose |value|/threshold peaked (END);
    value: r (or τ_r) on that axis at the event; peak: largest |value| on it; duration: seconds since onset (0 at
    START); time: time of the event; id: collision number."""

    kind: str
    id: int
    time: float
    onset: float
    axis: int
    value: float
    peak: float
    duration: float

    @property
    def axis_name(self) -> str:
        return EVENT_AXIS_NAMES[self.axis]


@dataclass
class ResidualSample:
    """Observer output at one arm sample: r as a wrench [F, N_P] in `base`, the paper's r_7..r_12 (Z-Y-Z), r as
    servo torques τ_r = J_ζ⁻ᵀ r (N·m; NaN when J_ζ is singular), over-threshold flags of both."""

    time: float
    wrench: NDArray
    r_zyz: NDArray
    over: NDArray
    in_collision: bool
    pose: NDArray
    events: tuple[CollisionEvent, ...] = ()
    servo_torque: NDArray = field(default_factory=lambda: np.full(6, np.nan))
    servo_over: NDArray = field(default_factory=lambda: np.zeros(6, dtype=bool))


class CollisionDetector:
    """|r_j| > r_low, or |τ_r,i| over its servo threshold, with hysteresis (release at release_ratio·threshold) and a
    minimum duration; START/END events. The twelve channels are one detector: a START needs one channel over its
    threshold for min_duration without a break, an END every channel below release for min_duration.

    The run is counted per channel: a contact's residual stays over on the channels its force loads, while the
    model's errors spike for a sample or two on one servo, then on another (a servo answering a new set-point of its
    pulse frame: docs/realism.md). Runs chained across channels would add those spikes up into a START."""

    def __init__(self, config: ObserverConfig) -> None:
        self.config = config
        self._th = np.asarray(config.thresholds, dtype=float)
        self._scale = np.empty(12)  # 1/threshold per channel: plate axes, then servos (0 = not checked)
        self._scale[:6] = 1.0 / self._th
        self.set_servo_thresholds(config.servo_thresholds)
        self.reset()
        self.count = 0

    def reset(self) -> None:
        self.active = False
        self._cand = [math.inf] * 12    # per channel: since when it is over its threshold (inf: it is not)
        self._release_since: float | None = None
        self._onset = 0.0
        self._peak = [0.0] * 12

    def break_runs(self) -> None:
        """The input stream had a gap: a run over a threshold (toward a START) or under release (toward an END)
        counts min_duration from the next sample on, never across the gap; a collision in progress stays active."""
        self._cand = [math.inf] * 12
        self._release_since = None

    def set_thresholds(self, thresholds: Iterable[float]) -> None:
        th = np.asarray(list(thresholds), dtype=float)
        if th.shape != (6,) or not np.all(np.isfinite(th)) or np.any(th <= 0):
            raise ObserverError(f"thresholds must be six positive values, got {thresholds!r}")
        self._th = th
        self._scale[:6] = 1.0 / th
        self._scale_list = self._scale.tolist()

    def set_servo_thresholds(self, thresholds: Iterable[float]) -> None:
        th = _check_servo_thresholds(list(thresholds))
        self._th_servo = th
        self._scale[6:] = np.divide(1.0, th, out=np.zeros(6), where=th > 0)  # 0: that servo's check is off
        self._scale_list = self._scale.tolist()

    @property
    def thresholds(self) -> NDArray:
        return self._th.copy()

    @property
    def servo_thresholds(self) -> NDArray:
        return self._th_servo.copy()

    def update(self, t: float, r: NDArray, servo: NDArray | None = None) -> tuple[NDArray, tuple[CollisionEvent, ...]]:
        """Feed one residual sample r (plate axes) and optionally τ_r (servo torques; None or NaN: not checked);
        returns the twelve over-threshold flags (plate axes, then servos) and the events it caused."""
        # twelve plain floats: at the sample rate numpy's per-call overhead costs more than the arithmetic
        value = (r.tolist() if isinstance(r, np.ndarray) else [float(v) for v in r]) + (
            [0.0] * 6 if servo is None else servo.tolist() if isinstance(servo, np.ndarray)
            else [float(v) for v in servo])
        mag = [abs(v) for v in value]
        ratio = [m * k for m, k in zip(mag, self._scale_list)]
        if sum(ratio) != sum(ratio):  # NaN servo torques (a singular J_ζ): not checked (ratios are ≥ 0 or NaN)
            for i, v in enumerate(ratio):
                if v != v:
                    value[i] = mag[i] = ratio[i] = 0.0
        top = max(ratio)
        over = np.array([v > 1.0 for v in ratio])
        md = self.config.min_duration
        if not self.active:
            if top <= 1.0:
                if min(self._cand) < math.inf:
                    self._cand = [math.inf] * 12
                return over, ()
            cand = self._cand
            fired = -1
            for j, v in enumerate(ratio):
                if v > 1.0:
                    if cand[j] == math.inf:
                        cand[j] = t
                    if t - cand[j] >= md - 1e-12 and (fired < 0 or v > ratio[fired]):
                        fired = j   # of the channels over for min_duration, the first of the largest
                else:
                    cand[j] = math.inf
            if fired >= 0:
                self.active = True
                self.count += 1
                self._onset = cand[fired]
                self._cand = [math.inf] * 12
                self._peak = mag
                self._release_since = None
                return over, (CollisionEvent("START", self.count, t, self._onset, fired, float(value[fired]),
                                             float(self._peak[fired]), 0.0),)
            return over, ()
        self._peak = [max(p, m) for p, m in zip(self._peak, mag)]
        if top < self.config.release_ratio:
            if self._release_since is None:
                self._release_since = t
            if t - self._release_since >= md - 1e-12:
                self.active = False
                peak_ratio = [p * k for p, k in zip(self._peak, self._scale_list)]
                ax = peak_ratio.index(max(peak_ratio))
                return over, (CollisionEvent("END", self.count, t, self._onset, ax, float(value[ax]),
                                             float(self._peak[ax]), t - self._onset),)
        else:
            self._release_since = None
        return over, ()


def _finite(*arrays: NDArray | None) -> bool:
    return all(a is None or bool(np.all(np.isfinite(a))) for a in arrays)


class PoseFit:
    """Least-squares polynomial in time through the last camera poses (Z-Y-X angles unwrapped): pose, twist at t."""

    def __init__(self, window: int, order: int) -> None:
        self.window, self.order = window, order
        self._t: list[float] = []
        self._q: list[list[float]] = []
        self.t_last = -math.inf
        self._coef: list[list[float]] | None = None

    def add(self, t: float, q: list[float]) -> None:
        if self._q:
            last = self._q[-1]
            q = q[:3] + [a + math.remainder(a_new - a, 2 * math.pi) for a, a_new in zip(last[3:], q[3:])]
        self._t.append(t)
        self._q.append(q)
        if len(self._t) > self.window:
            del self._t[0], self._q[0]
        self.t_last = t
        n = len(self._t)
        m = min(self.order, n - 1)
        h = np.asarray(self._t) - t
        A = np.vander(h, m + 1, increasing=True)
        coef, *_ = np.linalg.lstsq(A, np.asarray(self._q), rcond=None)
        self._coef = coef.tolist()

    @property
    def ready(self) -> bool:
        return self._coef is not None

    def clear(self) -> None:
        self._t.clear()
        self._q.clear()
        self._coef = None
        self.t_last = -math.inf

    def evaluate(self, t: float) -> tuple[tuple, tuple, list[float]]:
        """(p, R flat, V = [ṗ, ω]) at time t."""
        h = t - self.t_last
        c = self._coef
        assert c is not None, "evaluate() needs a fit (ready)"
        q = list(c[0])
        qd = [0.0] * 6
        hp = 1.0
        for k in range(1, len(c)):
            ck = c[k]
            for m in range(6):
                qd[m] += k * ck[m] * hp
            hp *= h
            for m in range(6):
                q[m] += ck[m] * hp
        a, b, g = q[3], q[4], q[5]
        da, db, dg = qd[3], qd[4], qd[5]
        ca, sa, cb, sb = math.cos(a), math.sin(a), math.cos(b), math.sin(b)
        w = (-sa * db + ca * cb * dg, ca * db + sa * cb * dg, da - sb * dg)  # ω = E(α, β)·(α̇, β̇, γ̇), eq 38
        return (q[0], q[1], q[2]), _rotation_zyx_flat(a, b, g), [qd[0], qd[1], qd[2], w[0], w[1], w[2]]


class _ArmSample:
    __slots__ = ("t", "zeta", "tau", "zeta_dot", "pi", "u", "p", "R", "V", "Q", "J")

    t: float
    zeta: list
    tau: list
    zeta_dot: list
    pi: list | None
    u: list | None
    p: tuple
    R: tuple
    V: list
    Q: NDArray | None
    J: NDArray  # J_ζ (6×6, chain_jacobian_rows): the twist and the servo-torque residual both use it


class ResidualObserver:
    """Momentum-form residual observer with detection (see module docstring).

    Usage:
        obs = ResidualObserver(HexaDynamicParameters.from_description())
        obs.update_pose(t_cam, pose)                       # whenever a plate pose arrives (~30 Hz)
        out = obs.update_arm(t, zeta, tau, zeta_dot)       # each arm sample (≤ 1 kHz); None when rejected
        out.wrench, out.r_zyz, out.events
    """

    def __init__(self, params: HexaDynamicParameters, config: ObserverConfig | None = None,
                 form: str = "momentum") -> None:
        if form not in ("momentum", "direct"):
            raise ObserverError(f"form must be 'momentum' or 'direct', got {form!r}")
        self.params = params
        self.config = config or ObserverConfig()
        if form == "direct" and self.config.kinematics == "pose":
            raise ObserverError("the direct form needs ζ̈ from the arm samples: use kinematics='arm' with it")
        self._fit = PoseFit(self.config.pose_window, self.config.pose_fit_order)
        self._zeta_est: list[float] | None = None
        self.form = form
        self._K = np.asarray(self.config.gains, dtype=float)
        # (Δt, exp(−K Δt), 1 − exp(−K Δt)) as floats: the sample spacing repeats, the exponentials too
        self._lag: tuple[float, list[float], list[float]] = (math.nan, [1.0] * 6, [0.0] * 6)
        self._kernel = SampleKernel(params)
        self.detector = CollisionDetector(self.config)
        self.rejected: dict[str, int] = {k: 0 for k in REJECT_REASONS}
        self.accepted = 0
        self.clock_jumps = 0
        self._est: tuple | None = None  # (t, p, R, V) of the last accepted sample (pose tracked from it)
        self._cam: tuple | None = None  # (t, p, R) newest camera pose not yet used
        self._cam_t = -math.inf
        self._offset = np.zeros(6)
        self._offset_list = [0.0] * 6
        self._calib: list[NDArray] | None = None
        self.reset()

    # ------------------------------------------------------------------ control
    def reset(self) -> None:
        """Re-zero: r = 0, integration restarts at the next sample; pose estimate, counters and calibration kept."""
        self._prev: _ArmSample | None = None
        self._angles: tuple[float, list] | None = None
        self._last_t = -math.inf
        self._time_gate = TimeGate(self.config.max_jump, self.config.adopt_after)
        self.r = np.zeros(6)
        self.detector.reset()

    def set_config(self, config: ObserverConfig) -> None:
        """Take new gains, thresholds and detector timing at run time; the residual and the pose tracking go on."""
        self.config = config
        self._K = np.asarray(config.gains, dtype=float)
        self._lag = (math.nan, [1.0] * 6, [0.0] * 6)
        self.detector.config = config
        self.detector.set_thresholds(config.thresholds)
        self.detector.set_servo_thresholds(config.servo_thresholds)

    def start_calibration(self) -> None:
        """Start averaging the instantaneous wrench estimate (robot at rest, nothing touching it)."""
        self._calib = []

    def finish_calibration(self) -> NDArray:
        """Stop averaging; the mean becomes the offset subtracted from every later estimate. Returns the offset."""
        if not self._calib:
            self._calib = None
            raise ObserverError("calibration collected no accepted samples")
        offset = np.mean(self._calib, axis=0)
        self._offset = self._offset + offset
        self._offset_list = self._offset.tolist()
        self.r = self.r - offset
        self._calib = None
        return self._offset.copy()

    @property
    def offset(self) -> NDArray:
        return self._offset.copy()

    def _reject(self, reason: str) -> None:
        self.rejected[reason] += 1

    # ------------------------------------------------------------------ inputs
    def update_pose(self, t: float, pose: NDArray) -> bool:
        """A plate pose [x y z α β γ] (m, rad; Z-Y-X) at time t (camera). Returns False when rejected."""
        try:
            t = float(t)
        except (TypeError, ValueError):
            self._reject("bad_shape")
            return False
        q = _floats(pose)
        if q is None or len(q) != 6:
            self._reject("bad_shape")
            return False
        if not (math.isfinite(t) and _all_finite(q)):
            self._reject("non_finite")
            return False
        if t <= self._cam_t:
            self._reject("time_not_increasing")
            return False
        self._cam = (float(t), tuple(q[:3]), _rotation_zyx_flat(q[3], q[4], q[5]))
        self._cam_t = float(t)
        if self.config.kinematics == "pose":
            self._fit.add(float(t), q)
        return True

    def update_arm(self, t: float, zeta: NDArray, tau: NDArray, zeta_dot: NDArray | None = None,
                   pose: NDArray | None = None, zeta_ddot: NDArray | None = None) -> ResidualSample | None:
        """One arm sample: angles ζ (rad), torques τ = K_t·I (N·m), optional ζ̇ (rad/s), optional plate pose at the
        same instant (else tracked), ζ̈ (direct form only; else differentiated). Returns None when rejected (or, without
        ζ̇, for the first sample, kept to difference the next). With kinematics="pose", ζ is only a seed (may be None
        after the first sample) and `pose` is not used: poses come through update_pose."""
        try:
            t = float(t)  # a numpy scalar here would turn every kernel operation into a numpy call
        except (TypeError, ValueError):
            self._reject("bad_shape")
            return None
        pose_mode = self.config.kinematics == "pose"
        z = None if (zeta is None and pose_mode) else _floats(zeta)
        tq = _floats(tau)
        zd = None if zeta_dot is None else _floats(zeta_dot)
        q = None if pose is None else _floats(pose)
        if ((z is None and not pose_mode) or tq is None or (z is not None and len(z) != 6) or len(tq) != 6
                or (zeta_dot is not None and (zd is None or len(zd) != 6))
                or (pose is not None and (q is None or len(q) != 6))):
            self._reject("bad_shape")
            return None
        if not (math.isfinite(t) and (z is None or _all_finite(z)) and _all_finite(tq)
                and (zd is None or _all_finite(zd))
                and (q is None or _all_finite(q))):
            self._reject("non_finite")
            return None
        verdict = self._time_gate.check(t)
        if verdict not in ACCEPTED:
            self._reject("time_jump" if verdict == "time_future" else "time_not_increasing")
            return None
        if verdict == "adopted" or (self._last_t > -math.inf and t - self._last_t > self.config.max_gap):
            # a gap, or a clock that jumped for good: do not integrate across it; r is kept, integration restarts here
            if verdict == "adopted":   # a new stream (a restarted board or simulator): detection starts over, and
                self.clock_jumps += 1  # camera poses are taken on the new time axis
                self.r = np.zeros(6)
                self.detector.reset()
                self._cam, self._cam_t = None, -math.inf
            else:
                self._reject("gap")
                self.detector.break_runs()
            self._prev = None
            self._angles = None
            if self._est is not None:  # predict across the gap at rest, Newton does the rest
                self._est = (self._est[0], self._est[1], self._est[2], (0.0,) * 6)
        ker = self._kernel
        cfg = self.config
        V = None
        if pose_mode:
            if not self._fit.ready:
                self._reject("no_pose")
                return None
            if t - self._fit.t_last > cfg.max_pose_age:
                self._reject("pose_stale")
                return None
            p, R, V = self._fit.evaluate(t)
            seed = self._zeta_est if self._zeta_est is not None else z
            if seed is None:  # the first sample must bring a guess of ζ (the commanded angles will do)
                self._reject("no_pose")
                return None
            try:
                z = ker.arm_angles(seed, p, R)
                geo, _ = ker.geometry(z, p, R)
            except KernelError:
                self._reject("pose_tracking")
                return None
            zd = [0.0] * 6  # not used: the twist comes from the pose fit
        assert z is not None   # given with the sample, or from the pose fit above
        try:
            if pose_mode:
                pass
            elif q is not None:
                p, R = tuple(q[:3]), _rotation_zyx_flat(q[3], q[4], q[5])
                geo, _ = ker.geometry(z, p, R)
            else:
                if self._cam is not None and (self._est is None or self._cam[0] >= self._est[0]):
                    _, p0, R0 = self._cam
                elif self._est is not None:
                    te, pe, Re, Ve = self._est
                    h = t - te
                    p0 = (pe[0] + Ve[0] * h, pe[1] + Ve[1] * h, pe[2] + Ve[2] * h)
                    R0 = exp_rotate(Ve[3] * h, Ve[4] * h, Ve[5] * h, Re)
                else:
                    self._reject("no_pose")
                    return None
                geo, p, R = ker.track_pose(z, p0, R0, cfg.pose_tolerance, cfg.newton_iterations)
        except KernelError:
            self._reject("pose_tracking")
            return None
        if zd is None:
            if self._angles is None:
                self._angles = (t, z)  # first sample without a measured rate: keep it to difference the next
                self._last_t = t
                self._cam = None
                self._est = (t, p, R, (0.0,) * 6)
                return None
            t0, z0 = self._angles
            h = t - t0
            zd = [(z[i] - z0[i]) / h for i in range(6)]
        try:
            s = self._evaluate(t, z, tq, zd, p, R, geo, zeta_ddot, V)
        except (KernelError, DynamicsError, np.linalg.LinAlgError):
            self._reject("singular")
            return None
        # accepted: commit the pose estimate and advance
        prev = self._prev
        self._cam = None
        self._est = (t, p, R, s.V)
        self._zeta_est = z
        self._angles = (t, z)
        self._last_t = t
        self._prev = s
        self.accepted += 1
        if prev is None:
            return self._output(t, s, geo)
        dt = t - prev.t
        if self.form == "momentum":
            pi, u, pi0, u0 = s.pi, s.u, prev.pi, prev.u
            assert pi is not None and u is not None and pi0 is not None and u0 is not None   # the momentum form's
            w = [(pi[m] - pi0[m]) / dt - 0.5 * (u[m] + u0[m]) for m in range(6)]
        else:
            assert s.Q is not None   # the direct form's
            w = s.Q.tolist()
        w = [wm - om for wm, om in zip(w, self._offset_list)]
        if self._calib is not None:
            self._calib.append(np.array(w))
        if dt != self._lag[0]:
            lag = np.exp(-self._K * dt)
            self._lag = (dt, lag.tolist(), (1.0 - lag).tolist())
        _, a, b = self._lag
        # r ← a r + (1 − a) w̄ on plain floats (the same operations as on arrays, rounded the same)
        self.r = np.array([am * rm + bm * wm for am, rm, bm, wm in zip(a, self.r.tolist(), b, w)])
        return self._output(t, s, geo)

    def _output(self, t: float, s: _ArmSample, geo: list) -> ResidualSample:
        servo = servo_torque_residual(geo, self.r, jacobian=s.J)
        over, events = self.detector.update(t, self.r, servo)
        R = s.R
        r = self.r.tolist()
        st = math.hypot(R[2], R[5])
        th = math.atan2(st, R[8])
        ph = math.atan2(R[5], R[2]) if st > 1e-12 else 0.0
        cf, sf, ct, sth = math.cos(ph), math.sin(ph), math.cos(th), math.sin(th)
        r_zyz = np.array([r[0], r[1], r[2], r[5], -sf * r[3] + cf * r[4],
                          cf * sth * r[3] + sf * sth * r[4] + ct * r[5]])  # diag(1, Eᵀ)·r (see lagrange)
        pose = np.array([s.p[0], s.p[1], s.p[2], math.atan2(R[3], R[0]), math.asin(max(-1.0, min(1.0, -R[6]))),
                         math.atan2(R[7], R[8])])
        return ResidualSample(time=t, wrench=np.array(r), r_zyz=r_zyz, over=over[:6], in_collision=self.detector.active,
                              pose=pose, events=events, servo_torque=servo, servo_over=over[6:])

    # ------------------------------------------------------------------ model evaluation
    def _evaluate(self, t, z, tq, zd, p, R, geo, zeta_ddot, V=None) -> _ArmSample:
        s = _ArmSample()
        s.t, s.zeta, s.tau, s.zeta_dot, s.p, s.R = t, z, tq, zd, p, R
        s.J = chain_jacobian_array(geo)
        if self.form == "momentum":
            s.V, s.pi, s.u = self._kernel.terms(geo, zd, tq, p, R, twist=V, jacobian=s.J)
            s.Q = None
            return s
        prm = self.params
        pn = np.array(p)[None]
        Rn = np.array(R).reshape(1, 3, 3)
        zn, zdn = np.array(z)[None], np.array(zd)[None]
        g = _Geometry(prm, zn, pn, Rn)
        V = np.linalg.solve(g.j[0], zdn[0])[None]
        vel = _Velocity(prm, g, V, Rn)
        prev = self._prev
        if zeta_ddot is None:
            if prev is None:
                zdd = np.zeros(6)
            else:
                zdd = (zdn[0] - np.array(prev.zeta_dot)) / (t - prev.t)
        else:
            zdd = np.asarray(zeta_ddot, dtype=float).reshape(6)
        Vd = np.linalg.solve(g.j[0], zdd - vel.jdot[0] @ V[0])[None]
        st = MotionState(zeta=zn, zeta_dot=zdn, p=pn, R=Rn, V=V, zeta_ddot=zdd[None], V_dot=Vd)
        s.Q = inverse_dynamics(prm, st, np.array(tq)[None]).wrench[0]
        s.V = V[0].tolist()
        s.pi = s.u = None
        return s


def servo_torque_residual(geo: list, r: NDArray, jacobian: list[list[float]] | NDArray | None = None) -> NDArray:
    """The residual as servo torques, τ_r = J_ζ⁻ᵀ r (N·m): the torques the servos deliver beyond the model.

    The reduced model's generalized force of the servo torques is u = J_ζᵀ τ (seed 000 eqs 17, 23), so a plate-
    coordinate residual r corresponds to τ_r with J_ζᵀ τ_r = r. A force F at point D of arm k enters r as
    J_ζᵀ e_k ((D − A_k) × F)·e_axis, hence τ_r = e_k × its moment about the servo axis. NaN where J_ζ is singular
    (a type II singularity: there a finite wrench needs unbounded servo torques). `jacobian`: J_ζ's rows
    (chain_jacobian_rows(geo)) if the caller has them already."""
    try:
        rows = chain_jacobian_rows(geo) if jacobian is None else jacobian
        return np.array(solve6(np.asarray(rows).T, r))
    except KernelError:
        return np.full(6, np.nan)


def _floats(x) -> list | None:
    """`x` flattened to a new list of plain floats (None: not numbers); a list of floats or a float64 array, as the
    per-sample path passes them, without a round trip through numpy."""
    if type(x) is list and all(type(v) is float for v in x):
        return list(x)
    if type(x) is np.ndarray and x.dtype == np.float64:
        return x.reshape(-1).tolist()
    try:
        return np.asarray(x, dtype=float).reshape(-1).tolist()
    except (TypeError, ValueError):
        return None


def _all_finite(v: list) -> bool:
    return all(map(math.isfinite, v))


def _rotation_zyx_flat(a: float, b: float, c: float) -> tuple:
    """R = Rz(α)·Ry(β)·Rx(γ) (eq 38), row-major flat."""
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    return (ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc,
            sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc,
            -sb, cb * sc, cb * cc)


# ---------------------------------------------------------------------- batch API
@dataclass
class BatchResidual:
    """Residuals over a recorded run: wrench r (N, 6) in `base`, the paper's r_7..r_12 (N, 6), instantaneous w̄."""

    time: NDArray
    wrench: NDArray
    r_zyz: NDArray
    instantaneous: NDArray = field(repr=False)


def momentum_residual_batch(params: HexaDynamicParameters, t: NDArray, zeta: NDArray, zeta_dot: NDArray,
                            tau: NDArray, poses: NDArray, gains: Iterable[float] | float = 25.0,
                            offset: NDArray | None = None) -> BatchResidual:
    """Momentum-form residual over a recorded run (all arrays (N, ·), poses consistent with ζ). Vectorized model,
    then the exact first-order recursion r_k = a_k r_{k−1} + (1 − a_k) w̄_k (see module docstring)."""
    t = np.asarray(t, dtype=float).reshape(-1)
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise ObserverError("batch times must be strictly increasing with at least 2 samples")
    zeta = np.atleast_2d(np.asarray(zeta, dtype=float))
    zd = np.atleast_2d(np.asarray(zeta_dot, dtype=float))
    p, R = pose_to_position_rotation(poses)
    g = _Geometry(params, zeta, p, R)  # one geometry for the twist and the momentum terms
    try:
        V = np.linalg.solve(g.j, zd[..., None])[..., 0]
    except np.linalg.LinAlgError as exc:
        raise DynamicsError(f"J_ζ is singular (type II singularity) in the batch: {exc}") from exc
    mt = _momentum_terms(params, g, _Velocity(params, g, V, R), R, np.atleast_2d(np.asarray(tau, dtype=float)))
    state = MotionState(zeta=zeta, zeta_dot=zd, p=p, R=R, V=V)
    dt = np.diff(t)
    w_bar = np.zeros((t.size, 6))
    w_bar[1:] = np.diff(mt.momentum, axis=0) / dt[:, None] - 0.5 * (mt.known_rate[1:] + mt.known_rate[:-1])
    if offset is not None:
        w_bar[1:] -= np.asarray(offset, dtype=float)
    r = _first_order_lag(w_bar, dt, gains)
    return BatchResidual(time=t, wrench=r, r_zyz=wrench_to_generalized_zyz(r, state.R), instantaneous=w_bar)


def direct_residual_batch(params: HexaDynamicParameters, t: NDArray, zeta: NDArray, zeta_dot: NDArray,
                          zeta_ddot: NDArray, tau: NDArray, poses: NDArray,
                          gains: Iterable[float] | float = 25.0) -> BatchResidual:
    """The paper's direct form: Q from inverse dynamics (eqs 21–22) filtered by ṙ = −K r + K Q (eq 25)."""
    t = np.asarray(t, dtype=float).reshape(-1)
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise ObserverError("batch times must be strictly increasing with at least 2 samples")
    state = motion_from_joint_rates(params, zeta, zeta_dot, poses, zeta_ddot)
    Q = inverse_dynamics(params, state, tau).wrench
    w = Q.copy()
    w[0] = 0.0
    r = _first_order_lag(w, np.diff(t), gains)
    return BatchResidual(time=t, wrench=r, r_zyz=wrench_to_generalized_zyz(r, state.R), instantaneous=Q)


def _first_order_lag(w: NDArray, dt: NDArray, gains: Iterable[float] | float, span: float = 200.0) -> NDArray:
    """r_0 = 0, r_k = a_k r_{k−1} + (1 − a_k) w_k with a_k = exp(−K Δt_k), vectorized.

    Unrolled, r_k = e^{−K t_k} (e^{K t_s} r_s + Σ_{s<i≤k} e^{K t_i}(1 − a_i) w_i) from a block start s; blocks are cut
    so that K·(t_k − t_s) ≤ `span` (no overflow, no loss of the recent terms)."""
    K = np.broadcast_to(np.asarray(gains, dtype=float), (6,)).astype(float)
    n = w.shape[0]
    t = np.concatenate([[0.0], np.cumsum(dt)])
    b = 1.0 - np.exp(-dt[:, None] * K[None, :])
    bw = np.zeros_like(w)
    bw[1:] = b * w[1:]
    r = np.zeros_like(w)
    block = span / float(K.max())
    start = 0
    r_s = np.zeros(6)
    while start < n - 1:
        stop = int(np.searchsorted(t, t[start] + block, side="right"))
        stop = min(max(stop, start + 2), n)
        tau = t[start:stop] - t[start]
        e = np.exp(K[None, :] * tau[:, None])
        acc = np.cumsum(e[1:] * bw[start + 1:stop], axis=0)
        r[start + 1:stop] = (r_s + acc) / e[1:]
        r_s = r[stop - 1]
        start = stop - 1
    return r
