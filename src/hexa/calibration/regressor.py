"""The Hexa's servo-space dynamic regressor: servo torques of free motion, linear in the inertial parameters.

The free-motion servo torques of the model of hexa.dynamics.lagrange (seed 000 eqs 19–22 with W = 0) are linear in

    θ_sym = [m_p, m_p c_x, m_p c_y, m_p c_z, I_xx, I_yy, I_zz, I_xy, I_xz, I_yz,   m_r, m_r κ, K_r]

— the plate's mass, first moment and inertia about its origin P in {P} (the barycentric parameters of Khalil &
Dombre), the rods' mass, first moment about B_i over l_d, and K_r = m_r κ² + I_r / l_d² (a slender rod's second
moment about B_i over l_d²; m_r κ² and I_r enter only in this sum because |B_i C_i| is constant) — and in the per-servo
terms [J_i ζ̈_i, −(ms)_i u'_i·g, f_c,i s(ζ̇_i), f_v,i ζ̇_i, (ms_y)_i u_i·g]: the arm's (and rotor's) inertia J_i about
its motor axis, its first moment (ms)_i along the arm, Coulomb and viscous friction, and its first moment (ms_y)_i
across the arm (a COM off the arm's line, in its plane of rotation: along u'_i). So

    τ = Y_sym(q, V, V̇) θ_sym + Y_servo(ζ, ζ̇, ζ̈) θ_servo        (Gautier's inverse dynamic identification model)

Y_sym is computed column by column from `inverse_dynamics` itself (the model is affine in θ_sym, so a parameter
difference gives its column exactly): one regressor, one model, never a second copy of the equations.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.dynamics.lagrange import (HexaDynamicParameters, MotionState, _Geometry, inverse_dynamics)

if TYPE_CHECKING:
    from numpy.typing import NDArray

SYM_NAMES = ("m_p", "mc_px", "mc_py", "mc_pz", "I_pxx", "I_pyy", "I_pzz", "I_pxy", "I_pxz", "I_pyz",
             "m_r", "mk_r", "K_r")
SERVO_GROUPS = ("J", "ms", "coulomb", "viscous", "ms_y")
#: the base columns of θ_sym (Gautier's regrouping): a rod's mass at B_i acts as more first moment and inertia of
#: arm i (the per-servo (ms)_i and J_i take it), its mass at C_i as plate mass at C_i (m_p, m_p c_p and I_P take it),
#: so m_r and m_r κ are not identifiable beside them and stay at the description's values
BASE_SYM = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 12)
#: rad/s: Coulomb friction's sign is smoothed as tanh(ζ̇ / COULOMB_SPEED): a servo at rest has no defined sign, and
#: a servo's friction grows from rest to its Coulomb value over a range of speeds (on the realistic simulated robot
#: ≈ 35 % at 0.02 rad/s, ≈ 70 % at 0.05 rad/s, all of it above ≈ 0.2 rad/s: MuJoCo's regularised friction loss),
#: which tanh(ζ̇ / 0.04) follows
COULOMB_SPEED = 0.04


def sym_from_params(prm: HexaDynamicParameters) -> NDArray:
    """θ_sym of `prm` (module docstring): plate inertia moved from its COM to P (parallel axis), rod sums."""
    m, c = prm.m_p, prm.c_p
    I_P = prm.I_p + m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    return np.array([m, *(m * c), I_P[0, 0], I_P[1, 1], I_P[2, 2], I_P[0, 1], I_P[0, 2], I_P[1, 2],
                     prm.m_r, prm.m_r * prm.kappa, prm.m_r * prm.kappa ** 2 + prm.I_r / prm.l_d ** 2])


def plate_inertia_about_com(theta: NDArray) -> tuple[float, NDArray, NDArray]:
    """(mass, COM in {P}, inertia about the COM) of the plate part of θ_sym."""
    m = float(theta[0])
    c = np.asarray(theta[1:4], dtype=float) / m
    I_P = np.array([[theta[4], theta[7], theta[8]], [theta[7], theta[5], theta[9]], [theta[8], theta[9], theta[6]]])
    return m, c, I_P - m * (float(c @ c) * np.eye(3) - np.outer(c, c))


def params_with_sym(prm: HexaDynamicParameters, theta: NDArray, J_a: float | None = None,
                    ms_a: float | None = None) -> HexaDynamicParameters:
    """`prm` with θ_sym (and optionally the arm's J_a and m_a s_a) replaced; the inverse of `sym_from_params`."""
    import dataclasses

    m_p, c_p, I_p = plate_inertia_about_com(theta)
    m_r, mk, K_r = (float(v) for v in theta[10:13])
    kappa = mk / m_r
    changes: dict[str, Any] = dict(m_p=m_p, c_p=c_p, I_p=I_p, m_r=m_r, kappa=min(max(kappa, 0.0), 1.0),
                   I_r=prm.l_d ** 2 * (K_r - mk * mk / m_r))
    if J_a is not None:
        changes["J_a"] = float(J_a)
    if ms_a is not None:
        changes["s_a"] = float(ms_a) / prm.m_a
    return dataclasses.replace(prm, **changes)


def free_motion_torques(prm: HexaDynamicParameters, state: MotionState) -> NDArray:
    """τ (N, 6) that moves the model along `state` with no external wrench: W(τ) = W(0) − J_ζᵀ τ = 0 (eqs 21–22)."""
    W0 = inverse_dynamics(prm, state, np.zeros((state.n, 6))).wrench
    j = _Geometry(prm, state.zeta, state.p, state.R).j          # rows j_i: ζ̇_i = j_i·V
    return np.linalg.solve(np.swapaxes(j, 1, 2), W0[..., None])[..., 0]


@dataclass
class Regressor:
    """Y_sym (N, 6, 13) and the per-servo columns of a batch of motion (module docstring): `zeta_ddot`, `gravity`
    (−u'_i·g, the column of (ms)_i), `sign` (tanh(ζ̇/COULOMB_SPEED)), `zeta_dot` and `gravity_y` (u_i·g, the column
    of (ms_y)_i), each (N, 6)."""

    Y_sym: NDArray
    zeta_ddot: NDArray
    gravity: NDArray
    sign: NDArray
    zeta_dot: NDArray
    gravity_y: NDArray

    def servo_columns(self) -> NDArray:
        """(N, 6, 30): per-servo columns of [J | ms | coulomb | viscous | ms_y] (6 each), zero off their servo."""
        n = self.Y_sym.shape[0]
        out = np.zeros((n, 6, 30))
        idx = np.arange(6)
        for g, col in enumerate((self.zeta_ddot, self.gravity, self.sign, self.zeta_dot, self.gravity_y)):
            out[:, idx, 6 * g + idx] = col
        return out

    def torques(self, theta_sym: NDArray, J: NDArray, ms: NDArray, coulomb: NDArray, viscous: NDArray,
                ms_y: NDArray | float = 0.0) -> NDArray:
        """Model servo torques (N, 6) of free motion for these parameters."""
        return (self.Y_sym @ theta_sym + J * self.zeta_ddot + ms * self.gravity + coulomb * self.sign
                + viscous * self.zeta_dot + ms_y * self.gravity_y)


def regressor(prm: HexaDynamicParameters, state: MotionState) -> Regressor:
    """The regressor of `state` (needs accelerations: V_dot and zeta_ddot) for the geometry of `prm`.

    Raises:
        hexa.dynamics.lagrange.DynamicsError: no accelerations, or a singular configuration.
    """
    from hexa.dynamics.lagrange import DynamicsError

    if state.V_dot is None or state.zeta_ddot is None:
        raise DynamicsError("the regressor needs accelerations (V_dot and zeta_ddot)")
    # base point: nominal plate and rods, the arms' own terms off (they are the per-servo columns)
    base = params_with_sym(prm, sym_from_params(prm), J_a=0.0, ms_a=0.0)
    base = _with_arm_damping(base, 0.0)
    theta0 = sym_from_params(base)
    tau0 = free_motion_torques(base, state)
    cols = np.empty((state.n, 6, theta0.size))
    for k in range(theta0.size):
        step = 1e-3 * max(abs(theta0[k]), 1e-4)
        th = theta0.copy()
        th[k] += step
        cols[..., k] = (free_motion_torques(params_with_sym(base, th, J_a=0.0, ms_a=0.0), state) - tau0) / step
    g = _Geometry(prm, state.zeta, state.p, state.R)
    return Regressor(Y_sym=cols, zeta_ddot=np.asarray(state.zeta_ddot, dtype=float), gravity=-(g.up @ prm.gravity),
                     sign=np.tanh(state.zeta_dot / COULOMB_SPEED), zeta_dot=np.asarray(state.zeta_dot, dtype=float),
                     gravity_y=g.u @ prm.gravity)


def _with_arm_damping(prm: HexaDynamicParameters, damping: float) -> HexaDynamicParameters:
    import dataclasses

    return dataclasses.replace(prm, arm_damping=float(damping))
