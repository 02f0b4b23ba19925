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
restarts at the next sample (r is kept).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterable

import numpy as np

from hexa.dynamics.lagrange import (DynamicsError, HexaDynamicParameters, MotionState, _Geometry, _momentum_terms,
                                    _Velocity, _accelerations, _cross, inverse_dynamics, momentum_terms,
                                    motion_from_joint_rates, pose_to_position_rotation, rotation_to_zyx, wrench_to_generalized_zyz)

if TYPE_CHECKING:
    from numpy.typing import NDArray

AXIS_NAMES = ("fx", "fy", "fz", "mx", "my", "mz")
REJECT_REASONS = ("non_finite", "time_not_increasing", "gap", "bad_shape", "pose_tracking", "singular", "no_pose")


class ObserverError(ValueError):
    """Bad observer configuration (the message names the value)."""


@dataclass(frozen=True)
class ObserverConfig:
    """Observer and detector settings.

    gains: K_j (1/s) per axis [fx fy fz mx my mz]; thresholds: r_low per axis (N, N·m); release_ratio: an axis
    releases below release_ratio·r_low (hysteresis); min_duration (s): over threshold this long before START, all axes
    released this long before END; max_gap (s): longer arm-sample spacing is a gap; pose_tolerance (m²): largest
    |f_i| accepted after pose tracking.
    """

    gains: tuple[float, ...] = (25.0, 25.0, 25.0, 25.0, 25.0, 25.0)
    thresholds: tuple[float, ...] = (2.0, 2.0, 2.0, 0.2, 0.2, 0.2)
    release_ratio: float = 0.5
    min_duration: float = 0.01
    max_gap: float = 0.1
    pose_tolerance: float = 1e-10
    newton_iterations: int = 4

    def __post_init__(self) -> None:
        g = np.asarray(self.gains, dtype=float)
        if g.shape != (6,) or not np.all(np.isfinite(g)) or np.any(g <= 0):
            raise ObserverError(f"gains must be six positive values (1/s), got {self.gains!r}")
        th = np.asarray(self.thresholds, dtype=float)
        if th.shape != (6,) or not np.all(np.isfinite(th)) or np.any(th <= 0):
            raise ObserverError(f"thresholds must be six positive values, got {self.thresholds!r}")
        if not 0.0 < self.release_ratio <= 1.0:
            raise ObserverError(f"release_ratio must be in (0, 1], got {self.release_ratio!r}")
        if not self.min_duration >= 0.0:
            raise ObserverError(f"min_duration must be >= 0 s, got {self.min_duration!r}")
        if not self.max_gap > 0.0:
            raise ObserverError(f"max_gap must be > 0 s, got {self.max_gap!r}")


@dataclass(frozen=True)
class CollisionEvent:
    """START or END of a collision. onset: first sample over threshold; axis: 0..5 (AXIS_NAMES), the axis that
    triggered (START) or whose |r|/r_low peaked (END); value: r on that axis at the event; peak: largest |r| on it;
    duration: seconds since onset (0 at START); time: time of the event; id: collision number."""

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
        return AXIS_NAMES[self.axis]


@dataclass
class ResidualSample:
    """Observer output at one arm sample: r as a wrench [F, N_P] in `base`, the paper's r_7..r_12 (Z-Y-Z), flags."""

    time: float
    wrench: NDArray
    r_zyz: NDArray
    over: NDArray
    in_collision: bool
    pose: NDArray
    events: tuple[CollisionEvent, ...] = ()


class CollisionDetector:
    """|r_j| > r_low with hysteresis (release at release_ratio·r_low) and a minimum duration; START/END events."""

    def __init__(self, config: ObserverConfig) -> None:
        self.config = config
        self._th = np.asarray(config.thresholds, dtype=float)
        self.reset()
        self.count = 0

    def reset(self) -> None:
        self.active = False
        self._cand_onset: float | None = None
        self._cand_axis = 0
        self._release_since: float | None = None
        self._onset = 0.0
        self._peak = np.zeros(6)

    def set_thresholds(self, thresholds: Iterable[float]) -> None:
        th = np.asarray(list(thresholds), dtype=float)
        if th.shape != (6,) or not np.all(np.isfinite(th)) or np.any(th <= 0):
            raise ObserverError(f"thresholds must be six positive values, got {thresholds!r}")
        self._th = th

    @property
    def thresholds(self) -> NDArray:
        return self._th.copy()

    def update(self, t: float, r: NDArray) -> tuple[NDArray, tuple[CollisionEvent, ...]]:
        """Feed one residual sample; returns the per-axis over-threshold flags and the events it caused."""
        ratio = np.abs(r) / self._th
        over = ratio > 1.0
        md = self.config.min_duration
        if not self.active:
            if over.any():
                if self._cand_onset is None:
                    self._cand_onset = t
                    self._cand_axis = int(np.argmax(ratio))
                if t - self._cand_onset >= md - 1e-12:
                    self.active = True
                    self.count += 1
                    self._onset = self._cand_onset
                    self._peak = np.abs(r).copy()
                    self._release_since = None
                    ax = int(np.argmax(ratio))
                    return over, (CollisionEvent("START", self.count, t, self._onset, ax, float(r[ax]),
                                                 float(self._peak[ax]), 0.0),)
            else:
                self._cand_onset = None
            return over, ()
        np.maximum(self._peak, np.abs(r), out=self._peak)
        if np.all(ratio < self.config.release_ratio):
            if self._release_since is None:
                self._release_since = t
            if t - self._release_since >= md - 1e-12:
                self.active = False
                self._cand_onset = None
                ax = int(np.argmax(self._peak / self._th))
                return over, (CollisionEvent("END", self.count, t, self._onset, ax, float(r[ax]),
                                             float(self._peak[ax]), t - self._onset),)
        else:
            self._release_since = None
        return over, ()


def _finite(*arrays: NDArray | None) -> bool:
    return all(a is None or bool(np.all(np.isfinite(a))) for a in arrays)


class _ArmSample:
    __slots__ = ("t", "zeta", "tau", "zeta_dot", "pi", "u", "p", "R", "V", "Q")


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
        self.form = form
        self._K = np.asarray(self.config.gains, dtype=float)
        self.detector = CollisionDetector(self.config)
        self.rejected: dict[str, int] = {k: 0 for k in REJECT_REASONS}
        self.accepted = 0
        self._pose_p: NDArray | None = None
        self._pose_R: NDArray | None = None
        self._pose_t = -math.inf
        self._offset = np.zeros(6)
        self._calib: list[NDArray] | None = None
        self.reset()

    # ------------------------------------------------------------------ control
    def reset(self) -> None:
        """Re-zero: r = 0, integration restarts at the next sample; pose estimate, counters and calibration kept."""
        self._prev: _ArmSample | None = None
        self._angles: tuple[float, NDArray] | None = None
        self._last_t = -math.inf
        self.r = np.zeros(6)
        self.detector.reset()

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
        pose = np.asarray(pose, dtype=float).reshape(-1)
        if pose.shape != (6,):
            self._reject("bad_shape")
            return False
        if not (math.isfinite(t) and _finite(pose)):
            self._reject("non_finite")
            return False
        if t <= self._pose_t:
            self._reject("time_not_increasing")
            return False
        p, R = pose_to_position_rotation(pose[None])
        self._pose_p, self._pose_R, self._pose_t = p, R, float(t)
        return True

    def update_arm(self, t: float, zeta: NDArray, tau: NDArray, zeta_dot: NDArray | None = None,
                   pose: NDArray | None = None, zeta_ddot: NDArray | None = None) -> ResidualSample | None:
        """One arm sample: angles ζ (rad), torques τ = K_t·I (N·m), optional ζ̇ (rad/s), optional plate pose at the
        same instant (else tracked), ζ̈ (direct form only; else differentiated). Returns None when rejected."""
        zeta = np.asarray(zeta, dtype=float).reshape(-1)
        tau = np.asarray(tau, dtype=float).reshape(-1)
        zd = None if zeta_dot is None else np.asarray(zeta_dot, dtype=float).reshape(-1)
        if zeta.shape != (6,) or tau.shape != (6,) or (zd is not None and zd.shape != (6,)):
            self._reject("bad_shape")
            return None
        if not (math.isfinite(t) and _finite(zeta, tau, zd)):
            self._reject("non_finite")
            return None
        if pose is not None:
            pose = np.asarray(pose, dtype=float).reshape(-1)
            if pose.shape != (6,) or not _finite(pose):
                self._reject("non_finite" if pose.shape == (6,) else "bad_shape")
                return None
        if t <= self._last_t:
            self._reject("time_not_increasing")
            return None
        if self._prev is not None and t - self._last_t > self.config.max_gap:
            self._reject("gap")  # do not integrate across the gap; r is kept, integration restarts here
            self._prev = None
            self._angles = None
        if pose is not None:
            p, R = pose_to_position_rotation(pose[None])
        elif self._pose_p is None:
            self._reject("no_pose")
            return None
        else:
            try:
                p, R = self._track_pose(zeta, self._pose_p, self._pose_R)
            except (DynamicsError, np.linalg.LinAlgError):
                self._reject("pose_tracking")
                return None
        if zd is None:
            if self._angles is None or t - self._angles[0] > self.config.max_gap:
                self._angles = (t, zeta)  # first sample without a measured rate: keep it to difference the next
                self._last_t = t
                self._pose_p, self._pose_R = p, R
                return None
            zd = (zeta - self._angles[1]) / (t - self._angles[0])
        try:
            s = self._evaluate(t, zeta, tau, zd, p, R, zeta_ddot)
        except (DynamicsError, np.linalg.LinAlgError):
            self._reject("singular")
            return None
        # accepted: commit the pose estimate and advance
        prev = self._prev
        self._pose_p, self._pose_R = p, R
        self._angles = (t, zeta)
        self._last_t = t
        self._prev = s
        self.accepted += 1
        if prev is None:
            return self._output(t, s)
        dt = t - prev.t
        if self.form == "momentum":
            w_bar = (s.pi - prev.pi) / dt - 0.5 * (s.u + prev.u)
        else:
            w_bar = s.Q
        if self._calib is not None:
            self._calib.append(w_bar - self._offset)
        a = np.exp(-self._K * dt)
        self.r = a * self.r + (1.0 - a) * (w_bar - self._offset)
        return self._output(t, s)

    def _output(self, t: float, s: _ArmSample) -> ResidualSample:
        over, events = self.detector.update(t, self.r)
        r_zyz = wrench_to_generalized_zyz(self.r[None], s.R)[0]
        pose = np.concatenate([s.p[0], rotation_to_zyx(s.R)[0]])
        return ResidualSample(time=t, wrench=self.r.copy(), r_zyz=r_zyz, over=over, in_collision=self.detector.active,
                              pose=pose, events=events)

    # ------------------------------------------------------------------ model evaluation
    def _track_pose(self, zeta: NDArray, p: NDArray, R: NDArray) -> tuple[NDArray, NDArray]:
        """Newton steps on f_i(ζ, pose) = 0 (eq 15) from the last pose estimate (forward kinematics by tracking)."""
        prm = self.params
        z = zeta[None]
        for _ in range(self.config.newton_iterations):
            g = _Geometry(prm, z, p, R)
            f = g.dd - prm.l_d**2
            if np.max(np.abs(f)) < self.config.pose_tolerance:
                return p, R
            Phi = np.empty((6, 6))
            Phi[:, :3] = 2.0 * g.d[0]
            Phi[:, 3:] = 2.0 * _cross(g.r[0], g.d[0])
            dx = np.linalg.solve(Phi, -f[0])
            p = p + dx[None, :3]
            R = _exp_so3(dx[3:]) @ R
        g = _Geometry(prm, z, p, R)
        if np.max(np.abs(g.dd - prm.l_d**2)) > 1e3 * self.config.pose_tolerance:
            raise DynamicsError(f"pose tracking did not converge for zeta {zeta.tolist()}")
        return p, R

    def _evaluate(self, t, zeta, tau, zd, p, R, zeta_ddot) -> _ArmSample:
        prm = self.params
        g = _Geometry(prm, zeta[None], p, R)
        V = np.linalg.solve(g.j[0], zd)[None]
        vel = _Velocity(prm, g, V, R)
        s = _ArmSample()
        s.t, s.zeta, s.tau, s.zeta_dot, s.p, s.R, s.V = t, zeta, tau, zd, p, R, V
        if self.form == "momentum":
            mt = _momentum_terms(prm, g, vel, R, tau[None])
            s.pi = mt.momentum[0]
            s.u = mt.known_rate[0]
            s.Q = None
        else:
            prev = self._prev
            if zeta_ddot is None:
                if prev is None or prev.zeta_dot is None:
                    zdd = np.zeros(6)
                else:
                    zdd = (zd - prev.zeta_dot) / (t - prev.t)
            else:
                zdd = np.asarray(zeta_ddot, dtype=float).reshape(6)
            Vd = np.linalg.solve(g.j[0], zdd - vel.jdot[0] @ V[0])[None]
            st = MotionState(zeta=zeta[None], zeta_dot=zd[None], p=p, R=R, V=V, zeta_ddot=zdd[None], V_dot=Vd)
            s.Q = inverse_dynamics(prm, st, tau[None]).wrench[0]
            s.pi = None
            s.u = None
        return s


def _exp_so3(w: NDArray) -> NDArray:
    th = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + math.sin(th) / th * K + (1.0 - math.cos(th)) / th**2 * (K @ K)


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
    state = motion_from_joint_rates(params, zeta, zeta_dot, poses)
    mt = momentum_terms(params, state, tau)
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


def _first_order_lag(w: NDArray, dt: NDArray, gains: Iterable[float] | float) -> NDArray:
    K = np.broadcast_to(np.asarray(gains, dtype=float), (6,))
    a = np.exp(-dt[:, None] * K[None, :])
    b = 1.0 - a
    r = np.zeros_like(w)
    rk = np.zeros(6)
    bw = b * w[1:]
    for k in range(a.shape[0]):
        rk = a[k] * rk + bw[k]
        r[k + 1] = rk
    return r
