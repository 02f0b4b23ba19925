"""The type II singularity release module, SRM-V1 and SRM-V2 (seed 003 sec 2.5, Algorithm 1, Table 2)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from hexa.kinematics import upsrpu as kin
from hexa.singularity import SingularityReport, limb_pairs, upsrpu_indices, upsrpu_indices_with_jd

if TYPE_CHECKING:
    from hexa.robots.upsrpu_description import UpsrpuDescription

__all__ = ["M_INC", "SrmError", "SrmStepInfo", "SingularityReleaseModule", "implicated_limbs"]

#: Seed 003 eq 10 with its minus signs restored (DESIGN.md): the eight non-zero pairs of {-1, 0, 1}^2 in the
#: authors' order; column c is the (first limb, second limb) increment of candidate c.
M_INC = np.array([[1, -1, 1, -1, 1, -1, 0, 0],
                  [1, -1, -1, 1, 0, 0, 1, -1]], dtype=int)
M_INC.setflags(write=False)

_PAIRS = limb_pairs(4)          # V_Omega order: 1-2, 1-3, 1-4, 2-3, 2-4, 3-4


class SrmError(ValueError):
    """Bad SRM input: unknown variant or vector of the wrong length (the message names it)."""


def _clipped(dX: np.ndarray, max_step: float = 0.05) -> np.ndarray:
    m = float(np.max(np.abs(dX)))
    return dX * (max_step / m) if m > max_step else dX


def implicated_limbs(min_index: int) -> tuple[np.ndarray, np.ndarray]:
    """(i_ch, i_nc) from the position of min Omega in V_Omega (Algorithm 1's IF chain), indices from 0."""
    i, j = _PAIRS[min_index]
    i_ch = np.array([i, j])
    i_nc = np.array([k for k in range(4) if k not in (i, j)])
    return i_ch, i_nc


@dataclass
class SrmStepInfo:
    """What one SRM call decided (for logs, plots and tests)."""

    active: bool = False                 # the enable pin was set and a limit was violated
    i_ch: tuple[int, ...] = ()           # limbs implicated by min Omega (from 0)
    moved: tuple[int, ...] = ()          # limbs whose Delta rows changed (i_ch for V1, i_nc for V2)
    v_omega_ch: np.ndarray = field(default_factory=lambda: np.zeros(M_INC.shape[1]))
    feasible: np.ndarray = field(default_factory=lambda: np.zeros(M_INC.shape[1], dtype=bool))
    column: int = -1                     # chosen column of M_inc, -1 when none


class SingularityReleaseModule:
    """Algorithm 1: q_ind^d = q_ind^r + nu_d t_s Delta, Delta updated while the enable pin is set and the
    measured pose X_c is near a type II singularity (min Omega < Omega_lim or |det J_D| < |J_D|_lim).

    Variant 1 moves the two limbs implicated by min Omega (i_ch); variant 2 (lines * and ** of Algorithm 1)
    moves the other two (i_nc) while still scoring each candidate by Omega of the implicated pair i_ch.
    One deviation from the literal pseudocode: when no candidate is feasible (every q_ch outside the strokes,
    FK failing or a spherical joint over its limit), argmax over a vector of zeros would pick column 1 anyway;
    here Delta is then left unchanged, so an infeasible candidate is never applied.
    """

    def __init__(self, desc: UpsrpuDescription, variant: int = 1) -> None:
        if variant not in (1, 2):
            raise SrmError(f"SRM variant must be 1 or 2, got {variant!r}")
        self.desc = desc
        self.variant = variant
        self.delta = np.zeros(4, dtype=int)          # persistent Delta_i (Table 2)
        self.step_size = desc.nu_d * desc.t_s         # nu_d t_s, m per sample
        self.last = SrmStepInfo()

    def reset(self) -> None:
        """Delta = 0 (Algorithm 1's initialisation)."""
        self.delta[:] = 0
        self.last = SrmStepInfo()

    def desired(self, q_ref: np.ndarray) -> np.ndarray:
        """q_ind^d = q_ind^r + nu_d t_s Delta (seed 003 eq 9)."""
        return np.asarray(q_ref, dtype=float) + self.step_size * self.delta

    def step(self, q_ref: np.ndarray, X_c: np.ndarray, enable: bool,
             report: SingularityReport | None = None) -> np.ndarray:
        """One controller sample of Algorithm 1; returns q_ind^d (4,) in m.

        Args:
            q_ref: the reference actuator lengths q_ind^r (m).
            X_c: the measured pose (x_m, z_m, theta, psi) from the 3D tracking system.
            enable: the enable pin e_pin.
            report: the indices at X_c (computed here when None).
        Raises:
            SrmError: q_ref or X_c is not a 4-vector.
        """
        q_ref = np.asarray(q_ref, dtype=float)
        X_c = np.asarray(X_c, dtype=float)
        if q_ref.shape != (4,) or X_c.shape != (4,):
            raise SrmError(f"q_ref and X_c must have shape (4,), got {q_ref.shape} and {X_c.shape}")
        d = self.desc
        q_d = self.desired(q_ref)
        self.last = SrmStepInfo()
        if not enable:
            return q_d
        if report is None:
            report = upsrpu_indices(d, X_c)
        if not (report.min_omega < d.omega_limit or abs(report.det_jd) < d.det_jd_limit):
            return q_d
        k_min = int(np.argmin(report.omega))                     # first minimum, as the IF chain
        i_ch, i_nc = implicated_limbs(k_min)
        moved = i_ch if self.variant == 1 else i_nc
        n_ch = M_INC.shape[1]
        v_omega_ch = np.zeros(n_ch)
        feasible = np.zeros(n_ch, dtype=bool)
        # The first Newton-Raphson step from X_c is shared by all candidates (same q(X_c) and J_D(X_c)), so
        # each FK below is exactly "FK of q_ch with X_c as initial condition", one iteration cheaper.
        q_xc = kin.inverse_kinematics(d, X_c)
        try:
            J_inv = np.linalg.inv(kin.jacobian_jd(d, X_c))
        except np.linalg.LinAlgError:
            J_inv = None
        for c1 in range(n_ch):
            q_ch = q_d.copy()
            q_ch[moved] += self.step_size * M_INC[:, c1]         # V1: rows i_ch; V2 (**): rows i_nc
            if not (np.all(d.q_min < q_ch) and np.all(q_ch < d.q_max)):
                continue
            try:
                X_1 = X_c if J_inv is None else X_c + _clipped(J_inv @ (q_ch - q_xc))
                X_ch, u, _, J_ch = kin.forward_kinematics_terms(d, q_ch, X_1)   # X_c as initial condition
            except kin.ForwardKinematicsError:
                continue
            alpha_ch = kin.spherical_angles_from(u, X_ch[2])
            if not np.all(alpha_ch < d.spherical_max):
                continue
            feasible[c1] = True
            v_omega_ch[c1] = upsrpu_indices_with_jd(d, X_ch, J_ch).omega[k_min]  # Omega_ij, i, j = i_ch
        info = SrmStepInfo(active=True, i_ch=tuple(int(i) for i in i_ch), v_omega_ch=v_omega_ch,
                           feasible=feasible)
        if feasible.any():
            c1 = int(np.argmax(np.where(feasible, v_omega_ch, -np.inf)))
            self.delta[moved] += M_INC[:, c1]
            info.column = c1
            info.moved = tuple(int(i) for i in moved)
        self.last = info
        return self.desired(q_ref)
