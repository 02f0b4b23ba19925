"""Contact force at a known point by Newton–Euler (seed 000 §3.3, eqs 27–36), for the plate, any arm or any rod.

Per chain i without external load (eqs 28–30, made explicit):
- rod i, moments about B_i: d_i × f_Ci = −κ d_i × F_ri − M_ri fixes f_Ci's part perpendicular to the rod;
- arm i, moments about its motor axis e_i (the bearing takes the other two components, so only this one is known):
  J_a ζ̈_i = τ_i − l_a u'_i·f_Bi + m_a s_a u'_i·g − b ζ̇_i, with f_Bi = f_Ci + F_ri (rod force balance, eq 29) fixes
  the rod's axial force.
Here F_ri = m_r (a_ri − g) and M_ri = I_r ω̇_ri are the rod's inertial loads (eq 27, gravity included), f_Ci the force
of rod i on the plate, f_Bi the force of arm i on rod i, d_i = C_i − B_i.

- Plate hit (eqs 28–31): F_e = F_p − Σ_i f_Ci, F_p = m_p (a_p − g). Rank 3 always; the plate's moment balance is
  not needed and its mismatch (with the given point D) is reported as `residual_norm` (N·m).
- Arm k hit (eqs 32–33): f_Ck = F_p − Σ_{i≠k} f_Ci, f_Bk = f_Ck + F_rk, then e_k·((D − A_k) × F_e) = J_a ζ̈_k − τ_k +
  l_a u'_k·f_Bk − m_a s_a u'_k·g + b ζ̇_k. One equation: only the component of F_e along e_k × (D − A_k) (the arm's
  direction of motion) is observable — the motor bearing takes the rest. Rank 1, `observable` False, the two
  unobservable directions are returned. (The paper's eq 33 treats n_A as known in 3-D; a real hinge does not.)
- Rod k hit (eqs 34–36): f_Ck as in eq 32; rod moments about B_k: (D − B_k) × F_e = d_k × f_Ck + κ d_k × F_rk + M_rk
  (rank 2: a force along the rod is invisible in it) and the arm's axis equation u'_k·(f_Ck + F_rk − F_e) = s_Bk
  (one more). Least squares on the 4×3 system (moment rows divided by |D − B_k| so all rows are in N): rank 3 unless
  the arm's motion direction u'_k is perpendicular to the rod (serial singularity) or D = B_k.

Least squares by SVD; directions with a singular value below `rcond`·σ_max are reported unobservable and get no
force (minimum-norm solution), never noise.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexa.dynamics.lagrange import (DynamicsError, HexaDynamicParameters, MotionState, _accelerations, _cross,
                                    _dot, _Geometry, _Velocity)

if TYPE_CHECKING:
    from numpy.typing import NDArray

LINKS = ("plate", "arm", "rod")


class IdentificationError(ValueError):
    """Bad identification request (unknown link, chain out of 1..6, no accelerations); the message names it."""


@dataclass(frozen=True)
class ContactForceEstimate:
    """Identified contact force F_e (N, `base`) at `point` on `link` (chain 1..6; 0 for the plate).

    rank / singular_values / condition describe the least-squares system (rows in N); observable is False when
    some direction of F_e cannot be seen (listed as unit vectors in unobservable_directions, its force component set
    to 0); residual_norm is the least-squares residual (plate: the moment balance mismatch in N·m).
    chain_forces: f_Ci (6, 3), the forces of the rods on the plate.
    """

    force: NDArray
    link: str
    chain: int
    point: NDArray
    rank: int
    singular_values: NDArray
    condition: float
    observable: bool
    unobservable_directions: NDArray
    residual_norm: float
    chain_forces: NDArray


def _lstsq(A: NDArray, b: NDArray, rcond: float) -> tuple[NDArray, int, NDArray, float, NDArray, float]:
    U, s, Vt = np.linalg.svd(A, full_matrices=True)
    smax = s[0] if s.size else 0.0
    keep = s > rcond * smax if smax > 0 else np.zeros_like(s, dtype=bool)
    rank = int(keep.sum())
    x = np.zeros(A.shape[1])
    for k in range(rank):
        x += (U[:, k] @ b) / s[k] * Vt[k]
    svals = np.zeros(A.shape[1])
    svals[: s.size] = s
    cond = float(svals[0] / svals[-1]) if svals[-1] > 0 else float("inf")
    null = Vt[rank:]
    res = float(np.linalg.norm(A @ x - b))
    return x, rank, svals, cond, null, res


def identify_contact_force(params: HexaDynamicParameters, state: MotionState, tau: NDArray, link: str,
                           chain: int, point: NDArray, rcond: float = 1e-3) -> ContactForceEstimate:
    """Contact force at `point` (base, m) on `link` of `chain` from one sample (seed 000 eqs 27–36).

    state: one sample (N = 1) with accelerations (motion_from_joint_rates(..., zeta_ddot) or motion_from_plate with
    twist_dot); tau: servo torques K_t·I (6,) in N·m.

    Raises:
        IdentificationError: unknown link, chain not in 1..6 for an arm/rod, missing accelerations, bad point.
    """
    if link not in LINKS:
        raise IdentificationError(f"link must be one of {LINKS}, got {link!r}")
    if link != "plate" and not (isinstance(chain, (int, np.integer)) and 1 <= int(chain) <= 6):
        raise IdentificationError(f"chain must be 1..6 for link {link!r}, got {chain!r}")
    if state.V_dot is None or state.n != 1:
        raise IdentificationError("identification needs one sample (N = 1) with accelerations (V_dot)")
    D = np.asarray(point, dtype=float).reshape(-1)
    if D.shape != (3,) or not np.all(np.isfinite(D)):
        raise IdentificationError(f"point must be 3 finite coordinates (m), got {point!r}")
    tau = np.asarray(tau, dtype=float).reshape(6)
    prm = params
    g = _Geometry(prm, state.zeta, state.p, state.R)
    vel = _Velocity(prm, g, state.V, state.R)
    acc = _accelerations(prm, g, vel, state.V, state.V_dot, state.R)
    d, up = g.d[0], g.up[0]
    rod_F, rod_M = acc.rod_F[0], acc.rod_M[0]
    dd = g.dd[0]
    # rod: perpendicular part of f_C from the moments about B (eq 30)
    m_B = -prm.kappa * _cross(d, rod_F) - rod_M
    fC_perp = _cross(m_B, d) / dd[:, None]
    # arm: u'·f_B from the motor-axis moment (eq 28 projected on the axis)
    s_B = (tau - prm.J_a * acc.zdd[0] + prm.m_a * prm.s_a * (up @ prm.gravity)
           - prm.arm_damping * vel.zd[0]) / prm.l_a
    dhat = d / np.sqrt(dd)[:, None]
    den = _dot(up, dhat)
    if np.any(np.abs(den) < 1e-9):
        raise DynamicsError(f"chain {int(np.argmin(np.abs(den))) + 1} is at a serial singularity (u'·d = 0)")
    t_ax = (s_B - _dot(up, fC_perp + rod_F)) / den
    fC = t_ax[:, None] * dhat + fC_perp  # (6, 3) forces of the rods on the plate, chains without load
    plate_F = acc.plate_F[0]
    rho = vel.rho[0]
    r = g.r[0]
    P = state.p[0]
    if link == "plate":
        F = plate_F - fC.sum(axis=0)  # eq 31
        need = _cross(rho, plate_F) + acc.plate_M[0] - _cross(r, fC).sum(axis=0)
        res = float(np.linalg.norm(np.cross(D - P, F) - need))
        return ContactForceEstimate(force=F, link=link, chain=0, point=D, rank=3, singular_values=np.ones(3),
                                    condition=1.0, observable=True, unobservable_directions=np.zeros((0, 3)),
                                    residual_norm=res, chain_forces=fC)
    k = int(chain) - 1
    fC = fC.copy()
    fC[k] = plate_F - np.delete(fC, k, axis=0).sum(axis=0)  # eq 32
    fB_k = fC[k] + rod_F[k]
    if link == "arm":
        lever = D - prm.A[k]
        row = np.cross(g.e[k], lever)  # e·(lever × F) = (e × lever)·F
        rhs = (prm.J_a * acc.zdd[0, k] - tau[k] + prm.l_a * up[k] @ fB_k - prm.m_a * prm.s_a * (up[k] @ prm.gravity)
               + prm.arm_damping * vel.zd[0, k])  # eq 33 on the motor axis
        A = row[None, :] / max(np.linalg.norm(lever), 1e-12)
        b = np.array([rhs]) / max(np.linalg.norm(lever), 1e-12)
    else:
        lever = D - g.B[0, k]
        L = max(float(np.linalg.norm(lever)), 1e-12)
        mom = _cross(d[k], fC[k]) + prm.kappa * _cross(d[k], rod_F[k]) + rod_M[k]  # eq 36
        Kx = np.array([[0.0, -lever[2], lever[1]], [lever[2], 0.0, -lever[0]], [-lever[1], lever[0], 0.0]])
        A = np.vstack([Kx / L, -up[k][None, :]])  # eqs 35–36 and the arm's axis equation (eq 34)
        b = np.concatenate([mom / L, [s_B[k] - up[k] @ (fC[k] + rod_F[k])]])
    x, rank, sv, cond, null, res = _lstsq(A, b, rcond)
    return ContactForceEstimate(force=x, link=link, chain=k + 1, point=D, rank=rank, singular_values=sv,
                                condition=cond, observable=rank == 3, unobservable_directions=null,
                                residual_norm=res, chain_forces=fC)
