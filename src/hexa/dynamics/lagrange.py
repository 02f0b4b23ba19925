"""Hexa inverse dynamics with Lagrange equations of the first kind (seed 000 §2.3, eqs 19–24).

Model. Generalized coordinates q = [ζ1..ζ6, x, y, z, φ, θ, ψ] with the six loop constraints
f_i = b_i cos ζ_i + c_i sin ζ_i − a_i = |B_i − C_i|² − l_d² (eqs 15, 17, 19–20). Bodies: the plate (rigid, 6 DOF),
six arms (rotation about the fixed motor axis through A_i), six rods (slender: inertia I_r about any axis through
the COM perpendicular to the rod, none about the rod axis; COM at fraction κ from B_i to C_i).

The Z-Y-Z angles of the paper are singular at θ = 0 (home pose), so the computation runs on quasi-velocities: the
plate twist V = [ṗ, ω] (ṗ velocity of the plate origin P, ω angular velocity, both in `base`). The generalized force
conjugate to V is the external wrench W = [F, N_P] on the plate in `base` (N_P: moment about P). The paper's
Q_7..Q_12 follow from W by Q = diag(1, 1, 1, Eᵀ) W with ω = E(φ, θ) [φ̇, θ̇, ψ̇] (exact, also at θ = 0 where E is
rank-deficient only in the mapping back). The multipliers λ_i do not depend on the choice of velocity coordinates,
so they are the paper's λ_i.

Two equivalent ways are provided:
- `inverse_dynamics`: the paper's route — λ from the arm equations (eq 21) and W (hence Q) from the plate equations
  (eq 22), with body accelerations (needs ζ̈ or the plate acceleration).
- `momentum_terms`: the reduced system on V with generalized momentum π = M̃(q) V (eq 23 in twist coordinates):
  dπ/dt = J_ζᵀ τ + G(q) + β(q, V) + W, with J_ζ the 6×6 map ζ̇ = J_ζ V, G the gravity wrench and β = Σ_b J̇_bᵀ h_b
  (h_b body momenta). This needs no acceleration and is what the momentum observer integrates.

Every function is batched: leading axis N (a single sample is N = 1).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription
    from numpy.typing import NDArray

GRAVITY = 9.81  # as the simulator (MJCF gravity="0 0 -9.81")


class DynamicsError(ValueError):
    """Raised for bad dynamic parameters or kinematically singular input (the message names the value)."""


def _cross(a: NDArray, b: NDArray) -> NDArray:
    """Cross product on the last axis (faster than np.cross for small arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=float)
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _dot(a: NDArray, b: NDArray) -> NDArray:
    """Dot product on the last axis."""
    return np.einsum("...i,...i->...", a, b)


def _attr(obj: Any, *names: str, default: Any = None) -> Any:
    for name in names:
        if isinstance(obj, dict) and name in obj:
            return obj[name]
        if hasattr(obj, name):
            return getattr(obj, name)
    return default


@dataclass(frozen=True)
class HexaDynamicParameters:
    """Geometry and mass properties the dynamics needs (SI units), built from the robot description.

    A: (6, 3) motor axis points in `base`; C: (6, 3) plate joints in {P}; alpha: (6,) chain angles (eq 5);
    l_a, l_d: arm and rod lengths; m_p, I_p (3×3 about the plate COM, {P} axes), c_p (plate COM in {P});
    m_a, J_a (arm inertia about the motor axis, including the reflected rotor inertia), s_a (arm COM distance from
    A_i along the arm); m_r, I_r (rod inertia about its COM, perpendicular to the rod), kappa (rod COM fraction from
    B_i); arm_damping (viscous, N·m·s/rad at the horn); gravity (3,) in `base`; K_t (N·m/A at the horn).
    """

    A: NDArray
    C: NDArray
    alpha: NDArray
    l_a: float
    l_d: float
    m_p: float
    I_p: NDArray
    c_p: NDArray
    m_a: float
    J_a: float
    s_a: float
    m_r: float
    I_r: float
    kappa: float = 0.5
    arm_damping: float = 0.0
    gravity: NDArray = field(default_factory=lambda: np.array([0.0, 0.0, -GRAVITY]))
    K_t: float = 1.0

    def __post_init__(self) -> None:
        for name in ("A", "C"):
            arr = np.asarray(getattr(self, name), dtype=float)
            if arr.shape != (6, 3) or not np.all(np.isfinite(arr)):
                raise DynamicsError(f"{name} must be a finite (6, 3) array, got shape {arr.shape}")
            object.__setattr__(self, name, arr)
        alpha = np.asarray(self.alpha, dtype=float).reshape(-1)
        if alpha.shape != (6,):
            raise DynamicsError(f"alpha must have 6 values, got {alpha.shape}")
        object.__setattr__(self, "alpha", alpha)
        object.__setattr__(self, "I_p", np.asarray(self.I_p, dtype=float).reshape(3, 3))
        object.__setattr__(self, "c_p", np.asarray(self.c_p, dtype=float).reshape(3))
        object.__setattr__(self, "gravity", np.asarray(self.gravity, dtype=float).reshape(3))
        for name in ("l_a", "l_d", "m_p", "m_a", "m_r"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value <= 0.0:
                raise DynamicsError(f"{name} must be positive, got {value!r}")
            object.__setattr__(self, name, value)
        for name in ("J_a", "s_a", "I_r", "kappa", "arm_damping", "K_t"):
            value = float(getattr(self, name))
            if not np.isfinite(value):
                raise DynamicsError(f"{name} must be finite, got {value!r}")
            object.__setattr__(self, name, value)
        if not 0.0 <= self.kappa <= 1.0:
            raise DynamicsError(f"kappa must be in [0, 1], got {self.kappa}")

    @classmethod
    def from_description(cls, desc: HexaDescription | None = None) -> HexaDynamicParameters:
        """Parameters from the robot description (default: `load_hexa()`); inertias are taken as given there."""
        if desc is None:
            from hexa.robots.hexa_description import load_hexa

            desc = load_hexa()
        return cls(**_parameters_from_description(desc))


def _parameters_from_description(desc: HexaDescription) -> dict:
    """Map the description's fields to HexaDynamicParameters keyword arguments (one place that knows its names)."""
    from hexa.dynamics._desc_adapter import dynamic_fields

    return dynamic_fields(desc)


@dataclass
class MotionState:
    """Batched motion of the Hexa: arm angles and rates, plate pose and twist (all in `base`, SI).

    zeta, zeta_dot: (N, 6); p: (N, 3) plate origin; R: (N, 3, 3) plate orientation; V: (N, 6) twist [ṗ, ω];
    zeta_ddot and V_dot (N, 6) only when accelerations are known (inverse dynamics, identification).
    """

    zeta: NDArray
    zeta_dot: NDArray
    p: NDArray
    R: NDArray
    V: NDArray
    zeta_ddot: NDArray | None = None
    V_dot: NDArray | None = None

    @property
    def n(self) -> int:
        return int(self.zeta.shape[0])


class _Geometry:
    """Per-chain position-level quantities (N, 6, ·) of one batch (seed 000 eqs 10, 14, 17)."""

    __slots__ = ("r", "Cw", "u", "up", "B", "d", "dd", "D", "j", "e")

    def __init__(self, prm: HexaDynamicParameters, zeta: NDArray, p: NDArray, R: NDArray) -> None:
        ca, sa = np.cos(prm.alpha), np.sin(prm.alpha)
        cz, sz = np.cos(zeta), np.sin(zeta)
        self.r = np.einsum("nab,ib->nia", R, prm.C)  # P→C_i in base
        self.Cw = p[:, None, :] + self.r
        u = np.empty(zeta.shape + (3,))
        u[..., 0] = -ca * cz
        u[..., 1] = -sa * cz
        u[..., 2] = sz
        up = np.empty_like(u)  # ∂u/∂ζ
        up[..., 0] = ca * sz
        up[..., 1] = sa * sz
        up[..., 2] = cz
        self.u, self.up = u, up
        self.B = prm.A[None] + prm.l_a * u
        self.d = self.Cw - self.B
        self.dd = _dot(self.d, self.d)
        self.D = prm.l_a * _dot(self.d, up)
        if np.any(np.abs(self.D) < 1e-9 * prm.l_a * prm.l_d):
            bad = np.argwhere(np.abs(self.D) < 1e-9 * prm.l_a * prm.l_d)[0]
            raise DynamicsError(f"chain {bad[1] + 1} is at a serial singularity (rod ⟂ arm motion) in sample {bad[0]}")
        j = np.empty(zeta.shape + (6,))
        j[..., :3] = self.d
        j[..., 3:] = _cross(self.r, self.d)
        self.j = j / self.D[..., None]  # ζ̇_i = j_i · V
        self.e = np.stack([-sa, ca, np.zeros(6)], axis=-1)  # motor axes (6, 3)


def _jc_t(f: NDArray, r: NDArray) -> NDArray:
    """Σ_i J_Cᵢᵀ f_i: generalized force on V of forces f_i (N, 6, 3) applied at the plate joints C_i."""
    out = np.empty(f.shape[:-2] + (6,))
    out[..., :3] = f.sum(axis=-2)
    out[..., 3:] = _cross(r, f).sum(axis=-2)
    return out


def _jb_t(prm: HexaDynamicParameters, g: _Geometry, f: NDArray) -> NDArray:
    """Σ_i J_Bᵢᵀ f_i: generalized force on V of forces f_i applied at the elbows B_i (through ζ̇_i = j_i·V)."""
    s = prm.l_a * _dot(g.up, f)
    return np.einsum("ni,nik->nk", s, g.j)


def _rotation_zyx(angles: NDArray) -> NDArray:
    """R = Rz(α)·Ry(β)·Rx(γ) (seed 000 eq 38) for (N, 3) angles, batched."""
    a, b, c = angles[:, 0], angles[:, 1], angles[:, 2]
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    R = np.empty((angles.shape[0], 3, 3))
    R[:, 0, 0] = ca * cb
    R[:, 0, 1] = ca * sb * sc - sa * cc
    R[:, 0, 2] = ca * sb * cc + sa * sc
    R[:, 1, 0] = sa * cb
    R[:, 1, 1] = sa * sb * sc + ca * cc
    R[:, 1, 2] = sa * sb * cc - ca * sc
    R[:, 2, 0] = -sb
    R[:, 2, 1] = cb * sc
    R[:, 2, 2] = cb * cc
    return R


def pose_to_position_rotation(pose: NDArray) -> tuple[NDArray, NDArray]:
    """Split (N, 6) poses [x, y, z, α, β, γ] (Z-Y-X, eq 38) into positions (N, 3) and rotations (N, 3, 3)."""
    pose = np.atleast_2d(np.asarray(pose, dtype=float))
    return pose[:, :3].copy(), _rotation_zyx(pose[:, 3:6])


def rotation_to_zyx(R: NDArray) -> NDArray:
    """Z-Y-X angles (α, β, γ) of (N, 3, 3) rotations (inverse of eq 38), batched."""
    beta = np.arcsin(np.clip(-R[:, 2, 0], -1.0, 1.0))
    alpha = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    gamma = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    return np.stack([alpha, beta, gamma], axis=-1)


def zyz_rate_matrix(R: NDArray) -> tuple[NDArray, NDArray]:
    """Z-Y-Z angles (φ, θ, ψ) (eq 1) of (N, 3, 3) rotations and E with ω = E·[φ̇, θ̇, ψ̇] (base frame).

    At θ = 0 only φ + ψ is defined; φ = 0 is chosen there (E is then rank 2 — the reason the model runs on ω).
    """
    st = np.hypot(R[:, 0, 2], R[:, 1, 2])
    theta = np.arctan2(st, R[:, 2, 2])
    small = st < 1e-12
    phi = np.where(small, 0.0, np.arctan2(R[:, 1, 2], R[:, 0, 2]))
    psi = np.where(small, np.arctan2(R[:, 1, 0], R[:, 0, 0]), np.arctan2(R[:, 2, 1], -R[:, 2, 0]))
    cf, sf, ct, stt = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
    E = np.zeros((R.shape[0], 3, 3))
    E[:, 2, 0] = 1.0
    E[:, 0, 1] = -sf
    E[:, 1, 1] = cf
    E[:, 0, 2] = cf * stt
    E[:, 1, 2] = sf * stt
    E[:, 2, 2] = ct
    return np.stack([phi, theta, psi], axis=-1), E


def wrench_to_generalized_zyz(wrench: NDArray, R: NDArray) -> NDArray:
    """The paper's Q_7..Q_12 (conjugate to x, y, z, φ, θ, ψ) from plate wrenches [F, N_P] in `base` (eqs 22, 24)."""
    _, E = zyz_rate_matrix(R)
    out = np.empty_like(wrench)
    out[:, :3] = wrench[:, :3]
    out[:, 3:] = np.einsum("nab,na->nb", E, wrench[:, 3:])
    return out


def chain_jacobian(prm: HexaDynamicParameters, zeta: NDArray, p: NDArray, R: NDArray) -> NDArray:
    """J_ζ (N, 6, 6) with ζ̇ = J_ζ·V: row i = [d_i, r_i × d_i] / (l_a d_i·∂u_i/∂ζ_i) (differentiated eq 15)."""
    return _Geometry(prm, np.atleast_2d(zeta), np.atleast_2d(p), R.reshape(-1, 3, 3)).j


def loop_constraints(prm: HexaDynamicParameters, zeta: NDArray, p: NDArray, R: NDArray) -> NDArray:
    """f_i = |B_i − C_i|² − l_d² = b_i cos ζ_i + c_i sin ζ_i − a_i (eqs 15, 17, 19), (N, 6)."""
    g = _Geometry(prm, np.atleast_2d(zeta), np.atleast_2d(p), R.reshape(-1, 3, 3))
    return g.dd - prm.l_d**2


def motion_from_joint_rates(
    prm: HexaDynamicParameters,
    zeta: NDArray,
    zeta_dot: NDArray,
    pose: NDArray,
    zeta_ddot: NDArray | None = None,
) -> MotionState:
    """Plate twist (and acceleration) from arm rates: V = J_ζ⁻¹ ζ̇, V̇ = J_ζ⁻¹ (ζ̈ − J̇_ζ V).

    pose: (N, 6) [x, y, z, α, β, γ] consistent with zeta (from FK or the camera). Raises DynamicsError at a
    parallel (type II) singularity where J_ζ cannot be inverted.
    """
    zeta = np.atleast_2d(np.asarray(zeta, dtype=float))
    zeta_dot = np.atleast_2d(np.asarray(zeta_dot, dtype=float))
    p, R = pose_to_position_rotation(pose)
    g = _Geometry(prm, zeta, p, R)
    V = _solve(g.j, zeta_dot)
    state = MotionState(zeta=zeta, zeta_dot=zeta_dot, p=p, R=R, V=V)
    if zeta_ddot is not None:
        zeta_ddot = np.atleast_2d(np.asarray(zeta_ddot, dtype=float))
        vel = _Velocity(prm, g, V)
        state.zeta_ddot = zeta_ddot
        state.V_dot = _solve(g.j, zeta_ddot - np.einsum("nik,nk->ni", vel.jdot, V))
    return state


def motion_from_plate(
    prm: HexaDynamicParameters,
    zeta: NDArray,
    pose: NDArray,
    twist: NDArray,
    twist_dot: NDArray | None = None,
) -> MotionState:
    """Motion from the plate twist V = [ṗ, ω] (and V̇): ζ̇ = J_ζ V, ζ̈ = J_ζ V̇ + J̇_ζ V."""
    zeta = np.atleast_2d(np.asarray(zeta, dtype=float))
    p, R = pose_to_position_rotation(pose)
    V = np.atleast_2d(np.asarray(twist, dtype=float))
    g = _Geometry(prm, zeta, p, R)
    zeta_dot = np.einsum("nik,nk->ni", g.j, V)
    state = MotionState(zeta=zeta, zeta_dot=zeta_dot, p=p, R=R, V=V)
    if twist_dot is not None:
        Vd = np.atleast_2d(np.asarray(twist_dot, dtype=float))
        vel = _Velocity(prm, g, V)
        state.V_dot = Vd
        state.zeta_ddot = np.einsum("nik,nk->ni", g.j, Vd) + np.einsum("nik,nk->ni", vel.jdot, V)
    return state


def _solve(J: NDArray, b: NDArray) -> NDArray:
    try:
        return np.linalg.solve(J, b[..., None])[..., 0]
    except np.linalg.LinAlgError as exc:
        raise DynamicsError(f"J_ζ is singular (type II singularity): {exc}") from exc


class _Velocity:
    """Velocity-level quantities given the twist V (N, 6): ζ̇, Ċ_i, Ḃ_i, ḋ_i, j̇_i, rod and plate velocities."""

    __slots__ = ("zd", "Cd", "Bd", "ddot", "jdot", "w", "wxr", "rho", "v_p", "v_r", "om_r")
    rho: NDArray    # plate terms: set only when R is given (the arm-only callers never read them)
    v_p: NDArray

    def __init__(self, prm: HexaDynamicParameters, g: _Geometry, V: NDArray, R: NDArray | None = None) -> None:
        v, w = V[:, :3], V[:, 3:]
        self.w = w
        self.zd = np.einsum("nik,nk->ni", g.j, V)
        self.wxr = _cross(w[:, None, :], g.r)
        self.Cd = v[:, None, :] + self.wxr
        self.Bd = prm.l_a * g.up * self.zd[..., None]
        self.ddot = self.Cd - self.Bd
        Ddot = prm.l_a * (_dot(self.ddot, g.up) - self.zd * _dot(g.d, g.u))
        jd = np.empty_like(g.j)
        jd[..., :3] = self.ddot
        jd[..., 3:] = _cross(self.wxr, g.d) + _cross(g.r, self.ddot)
        self.jdot = (jd - g.j * Ddot[..., None]) / g.D[..., None]
        self.v_r = (1.0 - prm.kappa) * self.Bd + prm.kappa * self.Cd
        self.om_r = _cross(g.d, self.ddot) / g.dd[..., None]
        if R is not None:
            self.rho = R @ prm.c_p
            self.v_p = v + _cross(w, self.rho)


def _inertia_world(prm: HexaDynamicParameters, R: NDArray) -> NDArray:
    return R @ prm.I_p @ np.swapaxes(R, -1, -2)


def generalized_momentum(prm: HexaDynamicParameters, state: MotionState) -> NDArray:
    """π = M̃(q)·V = Σ_b J_bᵀ h_b (N, 6): the generalized momentum of eq 23 in twist coordinates."""
    g = _Geometry(prm, state.zeta, state.p, state.R)
    vel = _Velocity(prm, g, state.V, state.R)
    return _momentum(prm, g, vel, state.R)


def _momentum(prm: HexaDynamicParameters, g: _Geometry, vel: _Velocity, R: NDArray) -> NDArray:
    hp = prm.m_p * vel.v_p
    Lp = np.einsum("nab,nb->na", _inertia_world(prm, R), vel.w)
    pi = np.empty((R.shape[0], 6))
    pi[:, :3] = hp
    pi[:, 3:] = _cross(vel.rho, hp) + Lp
    # arms: ½ J_a ζ̇² → J_a ζ̇_i j_i
    pi += np.einsum("ni,nik->nk", prm.J_a * vel.zd, g.j)
    # rods: linear momentum at the COM split to C and B, angular momentum as a couple
    hr = prm.m_r * vel.v_r
    wc = _cross(prm.I_r * vel.om_r, g.d) / g.dd[..., None]
    pi += _jc_t(prm.kappa * hr + wc, g.r) + _jb_t(prm, g, (1.0 - prm.kappa) * hr - wc)
    return pi


def _gravity_wrench(prm: HexaDynamicParameters, g: _Geometry, rho: NDArray) -> NDArray:
    """G(q) = Σ_b J_bᵀ m_b g: the gravity term of the reduced equations (−∂U/∂q in twist coordinates)."""
    n = rho.shape[0]
    G = np.empty((n, 6))
    G[:, :3] = prm.m_p * prm.gravity
    G[:, 3:] = _cross(rho, prm.m_p * prm.gravity[None, :])
    arm = prm.m_a * prm.s_a * (g.up @ prm.gravity)  # −∂U_arm/∂ζ_i
    G += np.einsum("ni,nik->nk", arm, g.j)
    fr = np.broadcast_to(prm.m_r * prm.gravity, g.d.shape)
    G += _jc_t(prm.kappa * fr, g.r) + _jb_t(prm, g, (1.0 - prm.kappa) * fr)
    return G


@dataclass
class MomentumTerms:
    """Terms of dπ/dt = J_ζᵀτ + G + β − J_ζᵀ b ζ̇ + W for a batch (all (N, 6), `base`, moments about P)."""

    momentum: NDArray  # π
    drive: NDArray  # J_ζᵀ τ − J_ζᵀ b ζ̇ (actuators minus viscous friction)
    gravity: NDArray  # G
    beta: NDArray  # Σ J̇_bᵀ h_b

    @property
    def known_rate(self) -> NDArray:
        """dπ/dt minus the external wrench: what the observer integrates."""
        return self.drive + self.gravity + self.beta


def momentum_terms(prm: HexaDynamicParameters, state: MotionState, tau: NDArray) -> MomentumTerms:
    """π and the known part of dπ/dt (eqs 23–24 on the reduced system), no acceleration needed."""
    tau = np.atleast_2d(np.asarray(tau, dtype=float))
    g = _Geometry(prm, state.zeta, state.p, state.R)
    vel = _Velocity(prm, g, state.V, state.R)
    return _momentum_terms(prm, g, vel, state.R, tau)


def _momentum_terms(prm, g: _Geometry, vel: _Velocity, R: NDArray, tau: NDArray) -> MomentumTerms:
    pi = _momentum(prm, g, vel, R)
    drive = np.einsum("ni,nik->nk", tau - prm.arm_damping * vel.zd, g.j)
    G = _gravity_wrench(prm, g, vel.rho)
    # β = Σ_b J̇_bᵀ h_b
    hp = prm.m_p * vel.v_p
    beta = np.zeros_like(pi)
    beta[:, 3:] = _cross(_cross(vel.w, vel.rho), hp)  # plate: J̇v = [0, −[ω×ρ]×]
    beta += np.einsum("ni,nik->nk", prm.J_a * vel.zd, vel.jdot)  # arms
    hr = prm.m_r * vel.v_r
    L = prm.I_r * vel.om_r
    wc = _cross(L, g.d) / g.dd[..., None]
    fc = prm.kappa * hr + wc
    fb = (1.0 - prm.kappa) * hr - wc
    # J̇_Cᵀ f = [0, (ω×r)×f];  J̇_Bᵀ f = l_a(−ζ̇ (u·f) j + (u'·f) j̇)
    beta[:, 3:] += _cross(vel.wxr, fc).sum(axis=1)
    beta += np.einsum("ni,nik->nk", prm.l_a * (-vel.zd * _dot(g.u, fb)), g.j)
    beta += np.einsum("ni,nik->nk", prm.l_a * _dot(g.up, fb), vel.jdot)
    # angular part of the rods: J̇ω = ([ḋ]×(J_C−J_B) + [d]×(J̇_C−J̇_B))/|d|² − 2(d·ḋ)/|d|⁴ [d]×(J_C−J_B)
    ac = (_cross(L, vel.ddot) - (2.0 * _dot(g.d, vel.ddot) / g.dd)[..., None] * _cross(L, g.d)) / g.dd[..., None]
    beta += _jc_t(ac, g.r) - _jb_t(prm, g, ac)
    return MomentumTerms(momentum=pi, drive=drive, gravity=G, beta=beta)


def mass_matrix(prm: HexaDynamicParameters, state: MotionState) -> NDArray:
    """M̃(q) (N, 6, 6), the inertia of the reduced system on V: π = M̃ V (T = ½ Vᵀ M̃ V)."""
    n = state.n
    eye = np.broadcast_to(np.eye(6), (n, 6, 6)).reshape(n * 6, 6)
    rep = lambda a: np.repeat(a, 6, axis=0)  # noqa: E731
    g = _Geometry(prm, rep(state.zeta), rep(state.p), rep(state.R))
    vel = _Velocity(prm, g, eye, rep(state.R))
    pi = _momentum(prm, g, vel, rep(state.R))
    return pi.reshape(n, 6, 6).swapaxes(1, 2)


def mechanical_energy(prm: HexaDynamicParameters, state: MotionState) -> tuple[NDArray, NDArray]:
    """Kinetic T = ½ Vᵀπ and potential U (zero at the base plane) of the whole robot, (N,) each."""
    g = _Geometry(prm, state.zeta, state.p, state.R)
    vel = _Velocity(prm, g, state.V, state.R)
    T = 0.5 * _dot(_momentum(prm, g, vel, state.R), state.V)
    gv = prm.gravity
    arm_com = prm.A[None] + prm.s_a * g.u
    rod_com = g.B + prm.kappa * g.d
    U = -(prm.m_p * (state.p + vel.rho) @ gv + prm.m_a * (arm_com @ gv).sum(1) + prm.m_r * (rod_com @ gv).sum(1))
    return T, U


@dataclass
class InverseDynamicsResult:
    """λ (eq 21), the external plate wrench W = [F, N_P] in `base` and the paper's Q_7..Q_12 (eq 22); (N, 6) each."""

    lam: NDArray
    wrench: NDArray
    Q: NDArray
    zeta_ddot: NDArray


def inverse_dynamics(prm: HexaDynamicParameters, state: MotionState, tau: NDArray) -> InverseDynamicsResult:
    """λ from the arm equations (eq 21) and Q_7..Q_12 from the plate equations (eq 22), with body accelerations.

    Needs state.V_dot (plate acceleration); ζ̈ follows from it (differentiated eq 15). tau = K_t·I (N, 6).
    """
    if state.V_dot is None:
        raise DynamicsError("inverse_dynamics needs the plate acceleration V_dot (or ζ̈ via motion_from_joint_rates)")
    tau = np.atleast_2d(np.asarray(tau, dtype=float))
    g = _Geometry(prm, state.zeta, state.p, state.R)
    vel = _Velocity(prm, g, state.V, state.R)
    acc = _accelerations(prm, g, vel, state.V, state.V_dot, state.R)
    # arm generalized inertial+gravity+friction force on ζ_i (fixed-axis rotation)
    arm = prm.J_a * acc.zdd - prm.m_a * prm.s_a * (g.up @ prm.gravity) + prm.arm_damping * vel.zd
    # rod inertial minus gravity, split into forces at B_i and C_i
    fc, fb = acc.rod_fc, acc.rod_fb
    # eq 21: λ_i ∂f_i/∂ζ_i = (d/dt ∂L/∂ζ̇_i − ∂L/∂ζ_i) − τ_i with ∂f_i/∂ζ_i = −2 l_a d_i·u'_i
    lam = (arm + prm.l_a * _dot(g.up, fb) - tau) / (-2.0 * g.D)
    # eq 22: Q = (plate + rods' pose part) − Σ λ_i ∂f_i/∂x, ∂f_i/∂V = 2[d_i, r_i × d_i]
    W = acc.plate_gen + _jc_t(fc, g.r)
    dfdx = np.empty_like(g.j)
    dfdx[..., :3] = 2.0 * g.d
    dfdx[..., 3:] = 2.0 * _cross(g.r, g.d)
    W = W - np.einsum("ni,nik->nk", lam, dfdx)
    return InverseDynamicsResult(lam=lam, wrench=W, Q=wrench_to_generalized_zyz(W, state.R), zeta_ddot=acc.zdd)


class _Accelerations:
    """Body accelerations and inertial-minus-gravity loads of a batch (filled by `_accelerations`)."""

    __slots__ = ("zdd", "Cdd", "Bdd", "a_r", "alpha_r", "a_p", "plate_gen", "rod_fc", "rod_fb", "rod_F", "rod_M",
                 "plate_F", "plate_M")
    zdd: NDArray
    Cdd: NDArray
    Bdd: NDArray
    a_r: NDArray
    alpha_r: NDArray
    a_p: NDArray
    plate_gen: NDArray
    rod_fc: NDArray
    rod_fb: NDArray
    rod_F: NDArray
    rod_M: NDArray
    plate_F: NDArray
    plate_M: NDArray


def _accelerations(prm, g: _Geometry, vel: _Velocity, V: NDArray, Vd: NDArray, R: NDArray) -> _Accelerations:
    """Body accelerations and inertial-minus-gravity loads (eq 27) given V and V̇."""
    a = _Accelerations()
    w, vd, wd = V[:, 3:], Vd[:, :3], Vd[:, 3:]
    a.zdd = np.einsum("nik,nk->ni", g.j, Vd) + np.einsum("nik,nk->ni", vel.jdot, V)
    a.Cdd = vd[:, None, :] + _cross(wd[:, None, :], g.r) + _cross(w[:, None, :], vel.wxr)
    a.Bdd = prm.l_a * (g.up * a.zdd[..., None] - g.u * (vel.zd**2)[..., None])
    dd2 = a.Cdd - a.Bdd
    a.a_r = (1.0 - prm.kappa) * a.Bdd + prm.kappa * a.Cdd
    dxdd = _cross(g.d, vel.ddot)
    a.alpha_r = (_cross(g.d, dd2) - (2.0 * _dot(g.d, vel.ddot) / g.dd)[..., None] * dxdd) / g.dd[..., None]
    a.rod_F = prm.m_r * (a.a_r - prm.gravity)  # inertia minus gravity (eq 27 F_ri with gravity)
    a.rod_M = prm.I_r * a.alpha_r  # eq 27 M_ri (ω×Iω = 0 for a slender rod)
    wc = _cross(a.rod_M, g.d) / g.dd[..., None]
    a.rod_fc = prm.kappa * a.rod_F + wc
    a.rod_fb = (1.0 - prm.kappa) * a.rod_F - wc
    rho = vel.rho
    a.a_p = vd + _cross(wd, rho) + _cross(w, _cross(w, rho))
    Iw = _inertia_world(prm, R)
    a.plate_F = prm.m_p * (a.a_p - prm.gravity)
    a.plate_M = np.einsum("nab,nb->na", Iw, wd) + _cross(w, np.einsum("nab,nb->na", Iw, w))
    pg = np.empty_like(V)
    pg[:, :3] = a.plate_F
    pg[:, 3:] = _cross(rho, a.plate_F) + a.plate_M
    a.plate_gen = pg
    return a
