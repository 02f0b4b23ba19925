"""Identification of the Hexa's model from its own motion: current sensors, friction, inertias, servo horns.

Per servo i, at every analysis instant (Khalil & Dombre's inverse dynamic identification model, Gautier's base
parameters; regressor of hexa.calibration.regressor):

    K_i I_i − c_i = Y_base,i θ_base + J_i ζ̈_i − (ms)_i u'_i·g + f_c,i tanh(ζ̇_i/ε) + f_v,i ζ̇_i + (ms_y)_i u_i·g
                    + Y_fixed,i θ_fixed + Y_i θ_payload

with I_i the driver's current, K_i the torque constant at the horn (N·m/A, sensor gain included), c_i = K_i b_i the
torque of its zero offset b_i, θ_base the plate's 10 barycentric parameters and the rods' K_r, θ_fixed the rods'
m_r, m_r κ (regrouped, kept at the description's values), θ_payload a known point mass on the plate. The equation is
linear in x = [K, c, θ_base, J, ms, f_c, f_v, ms_y] (53 unknowns; solved in 1/K_i, below) but homogeneous without a
known mass: scaling every torque constant and every inertial parameter together fits as well. A run carrying a
known payload fixes the scale; without one the mean K_i is held at the description's K_t (said in the result: K_t
is then only as good as that value).

Motion comes from the camera's plate poses: a zero-phase low-pass per pose coordinate gives pose, rate and
acceleration, IK gives the true horn angles ζ (not the servo set-points), J_ζ the arm rates and accelerations; a
periodic excitation's Fourier series over its moving window replaces the low-pass (Swevers: the camera noise
averages out over the periods). Currents go through a zero-phase low-pass at their own rate (before the analysis
grid, which is locked to the servos' pulse frame), and so does every regressor column (parallel filtering).
Output-error least squares (the current is the measured output, so its noise biases nothing), weighted by each
servo's noise from a first pass, with a prior on the zero offsets (`OFFSET_PRIOR`); 95 % confidence intervals from
the covariance σ²(JᵀJ)⁻¹ at the solution.

Physical consistency by construction: the plate's 10 parameters are solved as the Cholesky factor L of its 4×4
pseudo-inertia J = L Lᵀ (Wensing, Kim & Slotine, "Linear matrix inequalities for physically consistent inertial
parameter identification", IEEE RA-L 2017: J ≻ 0 ⇔ positive mass and a COM inertia that obeys the triangle
inequality), so every iterate and the solution is a rigid body; the per-servo J_i, friction, K_i and the rods' K_r
are bounded. The constraint matters because the Hexa's plate is a flat disc: its second moment across the plate,
m t²/12, is 0.3 % of the in-plane ones, so the truth sits on the triangle inequality's edge, and the plate's
rotational inertia is weakly excited (95 % half-widths of the same size as the inertia itself): an unconstrained
fit lands outside the valid set. `consistency` says whether the constraint was active.

Horn offsets: the horn angle from IK of the camera pose minus the set-point the servo acts on (joint_states), per
servo by least squares on [1, I_i, ζ̇_i] after the servo's dead band (`horn_offsets`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Iterable, Sequence

import numpy as np

from hexa.calibration.recording import CALIBRATION_RATE_HZ, Recording
from hexa.calibration.regressor import BASE_SYM, SYM_NAMES, params_with_sym, regressor, sym_from_params

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from hexa.calibration.regressor import Regressor
    from hexa.dynamics.lagrange import HexaDynamicParameters, MotionState
    from hexa.robots.hexa_description import HexaDescription

ANALYSIS_RATE_HZ = 100.0    # currents resampled at this rate and filtered …
CUTOFF_HZ = 4.0             # … by a zero-phase 4th-order Butterworth low-pass at this cut-off; the regressor …
DECIMATE = 4                # … at every DECIMATE-th of those instants (25 Hz)
#: A: 1 σ of a current sensor's zero offset left after the driver's zero-current calibration (ACS712 at rest),
#: the prior of c_i / K_i — an arm's gravity torque changes little over its travel, so the data alone hardly
#: separate the two
OFFSET_PRIOR = 0.02
POSE_CUTOFF_HZ = 2.0        # Hz: the camera poses' low-pass (motion that is not a periodic excitation)
MOVING_SPEED = 0.005        # m/s or rad/s: the plate moves (the periodic window's edges)
PERIODIC_MISS = 0.002       # m RMS: a run whose poses miss the periodic fit by more was not periodic (low-pass motion)
EDGE = 1.0                  # s dropped at both ends of a run (filter edges)
FIXED_SYM = tuple(k for k in range(len(SYM_NAMES)) if k not in BASE_SYM)
Z95 = 1.959963984540054
#: the plate's pseudo-inertia J counts as on the edge of physical validity (the constraint J ≻ 0 active) when its
#: smallest eigenvalue is below this fraction of the largest second moment (the nominal 10 mm disc: 2.7e-3)
EDGE_RATIO = 1e-3


class CalibrationError(ValueError):
    """Identification impossible (no usable motion, too few samples, degenerate data); the message says why."""


@dataclass
class Motion:
    """One run at the analysis instants `t` (decimated): filtered currents (N, 6), the regressor's columns, the
    horn angles, rates and accelerations, the set-points; `payload_sym` its known payload as θ_sym."""

    t: NDArray
    currents: NDArray
    reg: Regressor
    zeta: NDArray
    zeta_dot: NDArray
    zeta_ddot: NDArray
    poses: NDArray
    payload_sym: NDArray
    source: str
    periodic: bool
    horn: tuple[NDArray, NDArray, NDArray, NDArray]   # IK angle − set-point, currents, ζ̇ at the camera instants
    notes: list[str] = field(default_factory=list)


def frame_locked(t_current: NDArray, frame_period: float = 0.0) -> bool:
    """Whether currents sampled at instants `t_current` sit at a few fixed phases of the servos' pulse frame (the
    rate a multiple of a quarter of the frame rate: 50, 100, 200 Hz … for the 20 ms frame), where the frame's torque
    ripple aliases to a steady, speed-proportional error (hexa.calibration.recording.CALIBRATION_RATE_HZ)."""
    from hexa.calibration.recording import SERVO_FRAME_PERIOD

    dt = float(np.median(np.diff(t_current)))
    per_frame = (frame_period or SERVO_FRAME_PERIOD) / dt
    return bool(abs(4.0 * per_frame - round(4.0 * per_frame)) < 0.02 * 4.0)


def _unwrap_pose(poses: NDArray) -> NDArray:
    out = np.array(poses, dtype=float)
    out[:, 3:] = np.unwrap(out[:, 3:], axis=0)
    return out


def _lowpass(x: NDArray, rate: float, cutoff: float = 0.0) -> NDArray:
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, (cutoff or CUTOFF_HZ) / (0.5 * rate), output="sos")
    return sosfiltfilt(sos, x, axis=0)


class _LowPassMotion:
    """Pose, rate and acceleration of camera poses: resampled at ANALYSIS_RATE_HZ, zero-phase low-passed at
    POSE_CUTOFF_HZ, differentiated twice; evaluated at any instants by interpolation."""

    def __init__(self, t: NDArray, P: NDArray) -> None:
        self.tu = np.arange(t[0], t[-1], 1.0 / ANALYSIS_RATE_HZ)
        Pu = np.stack([np.interp(self.tu, t, P[:, k]) for k in range(P.shape[1])], 1)
        self.p = _lowpass(Pu, ANALYSIS_RATE_HZ, POSE_CUTOFF_HZ)
        self.v = np.gradient(self.p, self.tu, axis=0)
        self.a = np.gradient(self.v, self.tu, axis=0)

    def __call__(self, at: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        p, v, a = (np.stack([np.interp(at, self.tu, x[:, k]) for k in range(x.shape[1])], 1)
                   for x in (self.p, self.v, self.a))
        return p, v, a


def fourier_fit(t: NDArray, y: NDArray, period: float, harmonics: int, at: NDArray
                ) -> tuple[NDArray, NDArray, NDArray]:
    """Least-squares Fourier series of period `period` with `harmonics` harmonics through samples y (N, k) at t,
    and its value, first and second derivative at the instants `at`."""
    w = 2.0 * math.pi / period * np.arange(1, harmonics + 1)

    def basis(tt: NDArray, order: int) -> NDArray:
        ph = tt[:, None] * w
        s, c = np.sin(ph), np.cos(ph)
        if order == 0:
            return np.hstack([np.ones((tt.size, 1)), s, c])
        if order == 1:
            return np.hstack([np.zeros((tt.size, 1)), c * w, -s * w])
        return np.hstack([np.zeros((tt.size, 1)), -s * w * w, -c * w * w])

    coef, *_ = np.linalg.lstsq(basis(t, 0), y, rcond=None)
    return basis(at, 0) @ coef, basis(at, 1) @ coef, basis(at, 2) @ coef


def prepare(rec: Recording, desc: HexaDescription, prm: HexaDynamicParameters | None = None,
            period: float | None = None, harmonics: int = 15) -> Motion:
    """A recording → its analysis samples (module docstring). With the `period` (s) of a periodic excitation the
    motion is its Fourier series with `harmonics` harmonics fitted over the moving window (the camera noise averages
    out over the periods); without, the camera poses low-passed at POSE_CUTOFF_HZ.

    Raises:
        RecordingError: a stream is missing, short or bad.
        CalibrationError: the run is too short or leaves the workspace.
    """
    from hexa.dynamics.lagrange import DynamicsError, HexaDynamicParameters, MotionState
    from hexa.kinematics import hexa6rus as kin
    from hexa.servo_motion import servo_motion

    rec.check()
    prm = prm or HexaDynamicParameters.from_description(desc)
    t0 = max(rec.t_pose[0], rec.t_current[0], rec.t_state[0]) + EDGE
    t1 = min(rec.t_pose[-1], rec.t_current[-1], rec.t_state[-1]) - EDGE
    if t1 - t0 < 5.0:
        raise CalibrationError(f"{rec.source or 'recording'}: {t1 - t0:.1f} s where all three streams overlap "
                               "(need ≥ 5 s beside 1 s at each end)")
    P = _unwrap_pose(rec.poses)
    smooth = _LowPassMotion(rec.t_pose, P)
    if period is not None:     # a periodic excitation: its Fourier series over the moving window (Swevers)
        speed = np.abs(smooth(rec.t_pose)[1]).max(axis=1)
        moving = np.flatnonzero(speed > MOVING_SPEED)
        if moving.size == 0:
            raise CalibrationError(f"{rec.source or 'recording'}: the plate does not move")
        t0 = max(t0, rec.t_pose[moving[0]] + 0.05 * period)
        t1 = min(t1, rec.t_pose[moving[-1]] - 0.05 * period)
        if t1 - t0 < period:
            raise CalibrationError(f"{rec.source or 'recording'}: {t1 - t0:.1f} s of motion, less than one "
                                   f"period ({period:g} s)")
    fine = np.arange(t0, t1, 1.0 / ANALYSIS_RATE_HZ)
    t = fine[::DECIMATE]
    periodic = period is not None
    if period is not None:
        inside = (rec.t_pose >= t0 - 0.2) & (rec.t_pose <= t1 + 0.2)
        pose, vel, acc = fourier_fit(rec.t_pose[inside], P[inside], period, harmonics, fine)
        # a run that paused or stretched in time (a late trajectory node holds instead of jumping) is not the
        # periodic motion: its Fourier series misses the poses by far more than the camera's noise
        miss = np.sqrt(np.mean((fourier_fit(rec.t_pose[inside], P[inside], period, harmonics, rec.t_pose[inside])[0]
                                - P[inside])[:, :3] ** 2))
        periodic = bool(miss <= PERIODIC_MISS)
    if not periodic:
        pose, vel, acc = smooth(fine)
    try:
        full = servo_motion(desc, pose, vel, acc, prm)
        zeta = full.zeta
        assert full.zeta_ddot is not None and full.V_dot is not None   # given V̇, motion_from_plate sets both
        state = MotionState(zeta=zeta[::DECIMATE], zeta_dot=full.zeta_dot[::DECIMATE], p=full.p[::DECIMATE],
                            R=full.R[::DECIMATE], V=full.V[::DECIMATE], zeta_ddot=full.zeta_ddot[::DECIMATE],
                            V_dot=full.V_dot[::DECIMATE])
        reg = _filtered_regressor(prm, full)
    except (ValueError, DynamicsError) as exc:
        raise CalibrationError(f"{rec.source or 'recording'}: the plate poses leave the model's workspace ({exc})")
    zeta, pose = zeta[::DECIMATE], pose[::DECIMATE]
    # currents: zero-phase low-pass at their own rate, then on the analysis grid. The analysis grid (100 Hz) is a
    # multiple of the servos' 50 Hz pulse frame: resampled there before the low-pass, the frame's torque ripple would
    # alias to a steady error (frame_locked) whatever the rate the currents were recorded at
    rate_c = 1.0 / float(np.median(np.diff(rec.t_current)))
    cur_native = _lowpass(rec.currents, rate_c)
    tc = np.arange(rec.t_current[0], rec.t_current[-1], 1.0 / ANALYSIS_RATE_HZ)
    cur_f = np.stack([np.interp(tc, rec.t_current, cur_native[:, k]) for k in range(6)], 1)
    cur = np.stack([np.interp(t, tc, cur_f[:, k]) for k in range(6)], 1)
    # horn offsets at the camera instants (raw poses: no filter), inside the window
    inside = (rec.t_pose >= t0) & (rec.t_pose <= t1)
    tp = rec.t_pose[inside]
    zc = kin.inverse_kinematics_batch(desc, rec.poses[inside], check=False)
    sp = np.stack([np.interp(tp, rec.t_state, rec.setpoints[:, k]) for k in range(6)], 1)
    ic = np.stack([np.interp(tp, tc, cur_f[:, k]) for k in range(6)], 1)
    zd = np.stack([np.interp(tp, t, state.zeta_dot[:, k]) for k in range(6)], 1)
    m = rec.payload
    c = np.asarray(rec.payload_point, dtype=float)
    I_pl = m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    payload_sym = np.array([m, *(m * c), I_pl[0, 0], I_pl[1, 1], I_pl[2, 2], I_pl[0, 1], I_pl[0, 2], I_pl[1, 2],
                            0.0, 0.0, 0.0])
    assert state.zeta_ddot is not None   # set from full.zeta_ddot above
    notes = []
    if frame_locked(rec.t_current):
        rate = 1.0 / float(np.median(np.diff(rec.t_current)))
        notes.append(f"{rec.source or 'recording'}: currents at {rate:.0f} Hz, locked to the servos' 20 ms pulse "
                     "frame: their torque ripple aliases to a speed-proportional error that biases friction (and "
                     f"the rest); record with the driver's stream_rate_hz {CALIBRATION_RATE_HZ:.0f}")
    return Motion(t=t, currents=cur, reg=reg, zeta=zeta, zeta_dot=state.zeta_dot, zeta_ddot=state.zeta_ddot,
                  poses=pose, payload_sym=payload_sym, source=rec.source, periodic=periodic,
                  horn=(_wrap(zc - sp), ic, zd, sp), notes=notes)


def _filtered_regressor(prm: HexaDynamicParameters, full: MotionState) -> Regressor:
    """The regressor on the whole analysis grid, every column through the currents' low-pass, at the analysis
    instants (Gautier's parallel filtering: the same filter on both sides of the linear model). The low-pass passes
    a periodic excitation's upper harmonics only in part (4th order at 4 Hz, zero-phase: 63 % at 3.75 Hz); with the
    filter on the currents alone the regressor's inertial columns kept them whole, which pulled the plate mass low
    (−4 % on a realistic robot, −15 % with 25 harmonics) and its COM by 10 mm."""
    from hexa.calibration.regressor import COULOMB_SPEED

    reg = regressor(prm, full)
    reg.sign = np.tanh(full.zeta_dot / COULOMB_SPEED)
    for name in ("Y_sym", "zeta_ddot", "gravity", "sign", "zeta_dot", "gravity_y"):
        x = np.asarray(getattr(reg, name))
        y = _lowpass(x.reshape(x.shape[0], -1), ANALYSIS_RATE_HZ).reshape(x.shape)
        setattr(reg, name, y[::DECIMATE])
    return reg


def _wrap(a: NDArray) -> NDArray:
    return (a + math.pi) % (2 * math.pi) - math.pi


@dataclass
class Estimate:
    """A parameter's value and its 95 % confidence half-width (same unit)."""

    value: float
    ci95: float

    def as_dict(self) -> dict[str, float]:
        return {"value": self.value, "ci95": self.ci95}


@dataclass
class Calibration:
    """What `identify` found (SI): per servo `k_t` (N·m/A), `current_offset` (A), `coulomb` (N·m), `viscous`
    (N·m·s/rad), `inertia` J_i about the motor axis (kg·m², arm + rotor + the rod's share at B_i), `rotor_inertia`
    (J_i minus the description's arm and rod share), `first_moment` (ms)_i and `first_moment_y` (ms_y)_i (kg·m,
    along and across the arm), `horn_offset` (rad); the plate's `plate_mass`, `plate_com` ({P}, m), `plate_inertia`
    (about the COM, {P}); the rods' `rod_K`; `ci95` of each
    (same keys, arrays); `scale`: "payload" or "nominal K_t" (what fixed the torque scale); `consistency`: "free",
    or what shaped the solution: "pseudo-inertia" (the plate's J ≻ 0 active), "bounded" (another bound active);
    `rms` per servo of the fit (N·m) and the number of `samples`; `notes`: what limits the result (a run's
    currents locked to the servos' pulse frame)."""

    k_t: NDArray
    current_offset: NDArray
    coulomb: NDArray
    viscous: NDArray
    inertia: NDArray
    rotor_inertia: NDArray
    first_moment: NDArray
    first_moment_y: NDArray
    horn_offset: NDArray
    plate_mass: float
    plate_com: NDArray
    plate_inertia: NDArray
    rod_K: float
    ci95: dict[str, Any]
    scale: str
    consistency: str
    rms: NDArray
    samples: int
    sources: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            if k == "ci95":
                out[k] = {kk: np.asarray(vv).tolist() for kk, vv in v.items()}
            else:
                out[k] = np.asarray(v).tolist() if isinstance(v, np.ndarray) else v
        return out

    def dynamic_parameters(self, desc: HexaDescription) -> HexaDynamicParameters:
        """The nodes' (symmetric) model with these values: plate, mean arm J and first moment, mean viscous friction
        (the per-servo parts are `servo_torque_correction`'s)."""
        import dataclasses

        from hexa.dynamics.lagrange import HexaDynamicParameters

        prm = HexaDynamicParameters.from_description(desc)
        return dataclasses.replace(prm, m_p=self.plate_mass, c_p=self.plate_com, I_p=self.plate_inertia,
                                   J_a=float(self.inertia.mean()), s_a=float(self.first_moment.mean()) / prm.m_a,
                                   arm_damping=float(self.viscous.mean()), K_t=float(self.k_t.mean()))


def _system(motions: Sequence[Motion], theta_fixed: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """All runs stacked per row (servo i, instant n): the measured current I, the model's torque columns M (the
    base plate/rod parameters, then the per-servo J, ms, f_c, f_v) and its known part τ_0 (fixed rod parameters,
    payload), τ = M x + τ_0; and each row's servo index."""
    nb = len(BASE_SYM)
    cur, cols, known, servo = [], [], [], []
    for mo in motions:
        r = mo.reg
        n = r.Y_sym.shape[0]
        M = np.concatenate([r.Y_sym[..., list(BASE_SYM)], r.servo_columns()], axis=2)
        cols.append(M.reshape(n * 6, nb + 30))
        known.append((r.Y_sym[..., list(FIXED_SYM)] @ theta_fixed + r.Y_sym @ mo.payload_sym).reshape(-1))
        cur.append(mo.currents.reshape(-1))
        servo.append(np.tile(np.arange(6), n))
    return np.concatenate(cur), np.concatenate(cols), np.concatenate(known), np.concatenate(servo)


def _bounds(nb: int) -> tuple[NDArray, NDArray]:
    """Bounds of v = [1/K (6), b (6), L (10), K_r, J, ms, f_c, f_v, ms_y (6 each)]: physical consistency (the
    plate's by J = L Lᵀ, unbounded)."""
    lo = np.full(12 + nb + 30, -np.inf)
    hi = np.full_like(lo, np.inf)
    lo[:6] = 0.1                        # K_i < 10 N·m/A
    hi[:6] = 100.0                      # K_i > 0.01 N·m/A
    lo[12 + nb - 1] = 0.0               # K_r ≥ 0
    lo[12 + nb:12 + nb + 6] = 0.0       # J_i ≥ 0
    lo[12 + nb + 12:12 + nb + 24] = 0.0  # Coulomb and viscous friction ≥ 0
    return lo, hi


#: the 10 entries of a lower-triangular 4×4 L (row-major), the plate's unknowns in the solver (J = L Lᵀ)
_TRIL = np.tril_indices(4)


def pseudo_inertia(theta_plate: NDArray) -> NDArray:
    """The plate's 4×4 pseudo-inertia J = [[Σ, h], [hᵀ, m]] (Wensing, Kim & Slotine 2017) of its 10
    barycentric parameters [m, h = m c, I_xx, I_yy, I_zz, I_xy, I_xz, I_yz] about P: Σ = ½ tr(I_P) 1 − I_P, the
    second moment ∫ r rᵀ dm. J ≻ 0 ⇔ m > 0 and a COM inertia that is positive and obeys the triangle inequality."""
    m, h, I_P = float(theta_plate[0]), np.asarray(theta_plate[1:4], dtype=float), _inertia_matrix(theta_plate[4:10])
    J = np.empty((4, 4))
    J[:3, :3] = 0.5 * np.trace(I_P) * np.eye(3) - I_P
    J[:3, 3] = J[3, :3] = h
    J[3, 3] = m
    return J


def _inertia_matrix(i6: Iterable[float]) -> NDArray:
    xx, yy, zz, xy, xz, yz = (float(v) for v in i6)
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def plate_of_pseudo_inertia(J: NDArray) -> NDArray:
    """The 10 barycentric parameters of a pseudo-inertia (the inverse of `pseudo_inertia`; linear in J)."""
    S = 0.5 * (J[:3, :3] + J[:3, :3].T)
    I_P = np.trace(S) * np.eye(3) - S
    return np.array([J[3, 3], *J[:3, 3], I_P[0, 0], I_P[1, 1], I_P[2, 2], I_P[0, 1], I_P[0, 2], I_P[1, 2]])


def _plate_of_cholesky(ell: NDArray) -> tuple[NDArray, NDArray]:
    """θ_plate(J = L Lᵀ) of the entries `ell` of L and its Jacobian ∂θ/∂ell (10 × 10): dJ = E Lᵀ + L Eᵀ."""
    L = np.zeros((4, 4))
    L[_TRIL] = ell
    D = np.empty((10, 10))
    for k, (i, j) in enumerate(zip(*_TRIL)):
        E = np.zeros((4, 4))
        E[i, j] = 1.0
        D[:, k] = plate_of_pseudo_inertia(E @ L.T + L @ E.T)
    return plate_of_pseudo_inertia(L @ L.T), D


def _cholesky_of_plate(theta_plate: NDArray, floor: float) -> NDArray:
    """The entries of L with L Lᵀ the pseudo-inertia of `theta_plate`, its eigenvalues raised to ≥ `floor` first
    (the solver's start: strictly inside the valid set)."""
    w, V = np.linalg.eigh(pseudo_inertia(theta_plate))
    return np.linalg.cholesky(V @ np.diag(np.maximum(w, floor)) @ V.T)[_TRIL]


class _CholeskyPlate:
    """An `_OutputError` in v = u with the plate's θ (u[12:22]) replaced by the entries of L, J = L Lᵀ (chain rule
    through `_plate_of_cholesky`)."""

    def __init__(self, prob: _OutputError) -> None:
        self.prob = prob

    def u(self, v: NDArray) -> NDArray:
        u = v.copy()
        u[12:22] = _plate_of_cholesky(v[12:22])[0]
        return u

    def residual(self, v: NDArray) -> NDArray:
        return self.prob.residual(self.u(v))

    def jacobian(self, v: NDArray) -> NDArray:
        u = v.copy()
        u[12:22], D = _plate_of_cholesky(v[12:22])
        Jm = self.prob.jacobian(u)
        Jm[:, 12:22] = Jm[:, 12:22] @ D
        return Jm


class _OutputError:
    """Weighted residuals r = w_i (I − g_i (M x + τ_0) − b_i) with the priors, and their Jacobian, in the unknowns
    u = [g = 1/K (6), b (6), x (nb + 30)]; the current is the measured output (its noise is not in the regressor,
    so the estimate has no errors-in-variables bias)."""

    def __init__(self, I, M, tau0, servo, w, K_t: float, scale_row: bool) -> None:
        self.I, self.M, self.tau0, self.servo, self.w = I, M, tau0, servo, w
        self.K_t, self.scale_row = K_t, scale_row
        self.rows = np.arange(I.size)
        self.big = 1e3 * math.sqrt(I.size)

    def residual(self, u: NDArray) -> NDArray:
        g, b, x = u[:6], u[6:12], u[12:]
        tau = self.M @ x + self.tau0
        r = self.w * (self.I - g[self.servo] * tau - b[self.servo])
        extra: list[NDArray | list[float]] = [b / OFFSET_PRIOR]
        if self.scale_row:
            extra.append([self.big * (float(np.mean(1.0 / g)) / self.K_t - 1.0)])
        return np.concatenate([r, *map(np.atleast_1d, extra)])

    def jacobian(self, u: NDArray) -> NDArray:
        g, x = u[:6], u[12:]
        tau = self.M @ x + self.tau0
        n = self.I.size
        J = np.zeros((n + 6 + int(self.scale_row), u.size))
        J[self.rows, self.servo] = -self.w * tau
        J[self.rows, 6 + self.servo] = -self.w
        J[:n, 12:] = -(self.w * g[self.servo])[:, None] * self.M
        J[n + np.arange(6), 6 + np.arange(6)] = 1.0 / OFFSET_PRIOR
        if self.scale_row:
            J[n + 6, :6] = -self.big / (6.0 * self.K_t * g * g)
        return J


def identify(motions: Sequence[Motion], desc: HexaDescription) -> Calibration:
    """Identify the model from prepared runs (module docstring).

    Raises:
        CalibrationError: no runs, or the runs do not excite every parameter.
    """
    from scipy.optimize import least_squares

    from hexa.dynamics.lagrange import HexaDynamicParameters

    if not motions:
        raise CalibrationError("no runs to identify from")
    prm = HexaDynamicParameters.from_description(desc)
    theta_nom = sym_from_params(prm)
    theta_fixed = theta_nom[list(FIXED_SYM)]
    nb = len(BASE_SYM)
    I, M, tau0, servo = _system(motions, theta_fixed)
    with_payload = any(mo.payload_sym[0] > 0 for mo in motions)
    scale = "payload" if with_payload else "nominal K_t"
    # start: the linear model at the nominal K_t (K_t I − c = M x + τ_0), then output-error least squares
    A0 = np.zeros((I.size, 6 + M.shape[1]))
    A0[np.arange(I.size), servo] = -1.0
    A0[:, 6:] = -M
    b0 = tau0 - float(desc.K_t) * I
    col = np.linalg.norm(A0, axis=0) + 1e-300
    sv = np.linalg.svd(A0 / col, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    if cond > 1e6:
        raise CalibrationError(f"the runs do not excite every parameter (condition number {cond:.3g}); record "
                               "the trajectory of `hexa calibrate excite`")
    y0 = np.linalg.lstsq(A0 / col, b0, rcond=None)[0] / col
    lo, hi = _bounds(nb)
    u = np.concatenate([np.full(6, 1.0 / float(desc.K_t)), y0[:6] / float(desc.K_t), y0[6:]])
    u = np.clip(u, lo + 1e-12, np.where(np.isfinite(hi), hi - 1e-12, np.inf))
    # the plate's 10 parameters enter the solver as the Cholesky factor L of its pseudo-inertia J = L Lᵀ (Wensing et
    # al. 2017): every iterate, hence the solution, is a physically valid rigid body, with no correction afterwards.
    # The linear fit's plate starts it, its J's eigenvalues raised to at least the nominal plate's smallest (a
    # strictly inner start: from the edge, where L is singular, the solve can stall there)
    v = u.copy()
    v[12:22] = _cholesky_of_plate(u[12:22], float(np.linalg.eigvalsh(pseudo_inertia(theta_nom[:10]))[0]))
    w = np.ones(I.size)
    for _ in range(2):                   # unweighted, then each servo's rows weighted by 1/σ of its residual
        prob = _OutputError(I, M, tau0, servo, w, float(desc.K_t), not with_payload)
        fit = _CholeskyPlate(prob)
        sol = least_squares(fit.residual, v, jac=fit.jacobian, bounds=(lo, hi), method="trf", x_scale="jac",
                            max_nfev=200)
        v = sol.x
        u = fit.u(v)
        r = prob.residual(u)[:I.size] / w
        sig = np.array([np.sqrt(np.mean(r[servo == i] ** 2)) for i in range(6)])
        w = 1.0 / np.maximum(sig[servo], 1e-6)
    prob = _OutputError(I, M, tau0, servo, w, float(desc.K_t), not with_payload)
    Jm = prob.jacobian(u)
    res = prob.residual(u)
    # the low-pass makes neighbouring rows' errors correlated: (rate / DECIMATE) / (2·CUTOFF_HZ) rows per
    # independent one, which scale the variance
    correlated = max(1.0, ANALYSIS_RATE_HZ / DECIMATE / (2.0 * CUTOFF_HZ))
    s2 = correlated * float(res[:I.size] @ res[:I.size]) / max(1, I.size - u.size)
    cj = np.linalg.norm(Jm, axis=0) + 1e-300
    cov = np.linalg.pinv((Jm / cj).T @ (Jm / cj)) * s2 / np.outer(cj, cj)
    ci = Z95 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    active = bool(np.any(sol.active_mask != 0))
    g, boff, x = u[:6], u[6:12], u[12:]
    theta = theta_nom.copy()
    theta[list(BASE_SYM)] = x[:nb]
    cal_prm = params_with_sym(prm, theta)
    I_p = cal_prm.I_p
    # what shaped the solution: "pseudo-inertia" (J ≻ 0 active: the solution's J on the edge, its smallest
    # eigenvalue < EDGE_RATIO of its largest second moment), "bounded" (a bound on K, friction, J_i or K_r active),
    # or "free" (neither)
    J_plate = pseudo_inertia(x[:10])
    on_edge = bool(np.linalg.eigvalsh(J_plate)[0] < EDGE_RATIO * float(np.linalg.eigvalsh(J_plate[:3, :3])[-1]))
    consistency = ", ".join([k for k, on in (("pseudo-inertia", on_edge), ("bounded", active)) if on]) or "free"
    K = 1.0 / g
    J, ms, fc, fv, ms_y = (x[nb + 6 * k:nb + 6 * (k + 1)] for k in range(5))
    rod_share = _rod_share_at_B(prm)
    J_arm = prm.J_a - float(_armature(desc))
    horn, horn_ci = horn_offsets(motions, servo_dead_band(desc))
    ci_x = lambda k: ci[12 + nb + 6 * k:12 + nb + 6 * (k + 1)]  # noqa: E731
    ci_plate = ci[12:12 + nb]
    torque_res = r * K[servo]            # the fit's residual in N·m
    return Calibration(
        k_t=K, current_offset=boff, coulomb=fc, viscous=fv, inertia=J, rotor_inertia=J - J_arm - rod_share,
        first_moment=ms, first_moment_y=ms_y, horn_offset=horn, plate_mass=float(cal_prm.m_p),
        plate_com=np.asarray(cal_prm.c_p),
        plate_inertia=I_p, rod_K=float(theta[12]),
        ci95={"k_t": ci[:6] * K * K, "current_offset": ci[6:12], "coulomb": ci_x(2), "viscous": ci_x(3),
              "inertia": ci_x(0), "first_moment": ci_x(1), "horn_offset": horn_ci, "plate_mass": float(ci_plate[0]),
              "plate_first_moment": ci_plate[1:4], "plate_inertia_P": ci_plate[4:10], "rod_K": float(ci_plate[10])},
        scale=scale, consistency=consistency,
        rms=np.array([np.sqrt(np.mean(torque_res[servo == i] ** 2)) for i in range(6)]),
        samples=int(I.size // 6), sources=[mo.source for mo in motions],
        notes=[n for mo in motions for n in mo.notes])


#: s: an MG996R-class servo's dead band in pulse width (datasheet: 5 µs)
DEAD_BAND_US = 5e-6


def servo_dead_band(desc: HexaDescription) -> float:
    """The servo's dead band (rad, total width) from its pulse dead band and the description's µs per rad."""
    return DEAD_BAND_US * 1e6 / float(desc.us_per_rad)


def _armature(desc: HexaDescription) -> float:
    from hexa.dynamics._desc_adapter import servo_armature_damping

    return servo_armature_damping(desc)[0]


def _rod_share_at_B(prm: HexaDynamicParameters) -> float:
    """The inertia about the motor axis a rod's regrouped share at B_i adds to J_i (m_r (1−κ)… as a point at B_i):
    (m_r − 2 m_r κ + K_r) l_a² — the rod's kinetic energy at B_i's speed when C_i stands still."""
    K_r = prm.m_r * prm.kappa ** 2 + prm.I_r / prm.l_d ** 2
    return float((prm.m_r - 2 * prm.m_r * prm.kappa + K_r) * prm.l_a ** 2)


def horn_offsets(motions: Sequence[Motion], dead_band: float) -> tuple[NDArray, NDArray]:
    """Per-servo horn offset δ_i (rad) and its 95 % half-width from e = ζ_IK − set-point over all runs.

    The servo's position loop τ = k_p·db(s + δ − ζ) − k_v ζ̇ (db: the dead band of total width `dead_band`) gives
    e = δ − (τ + k_v ζ̇)/k_p − (dead_band/2)·sign(τ + k_v ζ̇): least squares on [1, I_i, ζ̇_i] after removing the
    dead-band term, whose sign comes from the previous fit (an arm that always pushes against gravity has the same
    sign throughout, so the term cannot be a column of its own beside the intercept)."""
    e = np.concatenate([mo.horn[0] for mo in motions])
    cur = np.concatenate([mo.horn[1] for mo in motions])
    zd = np.concatenate([mo.horn[2] for mo in motions])
    off, ci = np.zeros(6), np.zeros(6)
    for i in range(6):
        X = np.column_stack([np.ones(e.shape[0]), cur[:, i], zd[:, i]])
        y = e[:, i].copy()
        sol = np.zeros(3)
        push = cur[:, i].copy()          # a < 0 (τ = K I pulls ζ below the set-point)
        for _ in range(3):
            y = e[:, i] + 0.5 * dead_band * np.tanh(push / 1e-3)
            sol, *_ = np.linalg.lstsq(X, y, rcond=None)
            push = -(sol[1] * cur[:, i] + sol[2] * zd[:, i])     # (τ + k_v ζ̇)/k_p, up to sign
        r = y - X @ sol
        s2 = float(r @ r) / max(1, X.shape[0] - X.shape[1])
        off[i] = sol[0]
        ci[i] = Z95 * math.sqrt(s2 * np.linalg.pinv(X.T @ X)[0, 0])
    return off, ci
