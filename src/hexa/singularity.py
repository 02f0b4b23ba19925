"""Type II singularity indices (seed 003 sec 2.2-2.3): det J_D and the angles Omega_ij between output twist screws.

Screws are 6-vectors about one common reference point: wrenches $T = (f; m), twists $O = (omega; v). The
reciprocal product is $T o $O = f . v + m . omega. For a robot with F actuators and 6 - F constraint wrenches
(the 3UPS+RPU: F = 4 and the RPU limb's two constraint wrenches), the output twist screw of actuator i
is the platform twist obtained with every other actuator locked (seed 003 eq 5): reciprocal to every
transmission wrench $T_j (j != i) and to every constraint wrench. With the 6 x 6 matrix W whose rows are the
swapped wrenches (m; f), $O_i spans the null space of W without row i, which is column i of adj(W)
(computed from one SVD, so it stays well defined at and near det W = 0).

Omega_ij (seed 003 eq 7) is the angle between the lines of the angular parts of $O_i and $O_j, in [0, pi/2].
An OTS whose angular part vanishes (pure translation, screw axis at infinity) is compared by its linear part
with another pure translation, and counts as 90 deg from a rotation (a rotation and a translation cannot be
linearly dependent). At an exact singularity of rank 5 only the OTS of the limbs in the dependency are defined
(they all equal the uncontrolled twist, so their Omega is 0); pairs with an undefined OTS are reported as 90 deg
so that the minimum still names the implicated limbs. With rank <= 4 nothing is defined and every Omega is 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations
from typing import TYPE_CHECKING, Any, cast

import numpy as np

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription
    from hexa.robots.upsrpu_description import UpsrpuDescription

__all__ = [
    "SingularityError", "SingularityMonitor", "SingularityReport", "output_twist_screws", "omega_angles", "limb_pairs",
    "indices_from_screws", "hexa_indices", "upsrpu_indices", "upsrpu_indices_from_screws",
    "upsrpu_indices_with_jd",
]

_PURE_TRANSLATION = 1e-9
_UNDEFINED = 1e-12


class SingularityError(ValueError):
    """Screw sets of the wrong shape (the message names the shape)."""


@dataclass(frozen=True)
class SingularityReport:
    """det J_D, every Omega_ij (rad) with its pair name "i-j" (limbs from 1), and the smallest one."""

    det_jd: float
    omega: np.ndarray
    pairs: tuple[str, ...]
    min_omega: float
    min_pair: str

    @property
    def min_index(self) -> int:
        """Index of the minimum in `omega` (Algorithm 1's position in V_Omega, from 0)."""
        return self.pairs.index(self.min_pair)

    def omega_deg(self) -> dict[str, float]:
        """{"1-2": Omega_12 in degrees, ...}."""
        return {p: math.degrees(float(w)) for p, w in zip(self.pairs, self.omega)}

    def near(self, det_jd_limit: float, omega_limit: float) -> bool:
        """True when |det J_D| < det_jd_limit or min Omega < omega_limit (Algorithm 1's test)."""
        return abs(self.det_jd) < det_jd_limit or self.min_omega < omega_limit

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dict in SI (rad) plus the degrees the paper reports."""
        return {"det_jd": float(self.det_jd), "omega": [float(w) for w in self.omega], "pairs": list(self.pairs),
                "omega_deg": self.omega_deg(), "min_pair": self.min_pair, "min_omega": float(self.min_omega),
                "min_omega_deg": math.degrees(float(self.min_omega))}


def limb_pairs(n: int) -> tuple[tuple[int, int], ...]:
    """Pairs (i, j), i < j, from 0, in the paper's V_Omega order (1-2, 1-3, 1-4, 2-3, 2-4, 3-4 for n = 4)."""
    return tuple(combinations(range(n), 2))


def output_twist_screws(wrenches: np.ndarray, constraints: np.ndarray | None = None) -> np.ndarray:
    """Output twist screws $O_i (F, 6), rows (omega; v), normalised to |omega| = 1 (seed 003 eqs 4-5).

    Args:
        wrenches: the F unit transmission wrench screws (F, 6), rows (f; m).
        constraints: the 6 - F constraint wrench screws, rows (f; m) (None when F = 6).
    Returns:
        $O_i reciprocal to every $T_j (j != i) and every constraint wrench; a pure translation is normalised
        to |v| = 1; an undefined OTS (rank of W below 5) is all zeros.
    Raises:
        SingularityError: the wrenches do not add up to six.
    """
    T = np.asarray(wrenches, dtype=float)
    W = T if constraints is None or len(constraints) == 0 else np.vstack([T, np.asarray(constraints, float)])
    if W.ndim != 2 or W.shape != (6, 6):
        raise SingularityError(f"transmission + constraint wrenches must form a (6, 6) set, got {W.shape}")
    F = T.shape[0]
    Ws = np.empty((6, 6))
    Ws[:, :3] = W[:, 3:]                      # rows (m; f): Ws @ (omega; v) = reciprocal products
    Ws[:, 3:] = W[:, :3]
    U, s, Vt = np.linalg.svd(Ws)
    # adj(Ws) = det(U) det(V) V diag(prod_{l != k} s_l) U^T; the common sign is irrelevant for screw lines.
    if s[0] > 0:
        s = s / s[0]
    p = np.ones(6)
    acc = 1.0
    for k in range(5):                        # prefix and suffix products without division (s may hold zeros)
        acc *= s[k]
        p[k + 1] = acc
    acc = 1.0
    for k in range(5, 0, -1):
        acc *= s[k]
        p[k - 1] *= acc
    O = (U[:F] * p) @ Vt                      # row i = column i of adj(Ws)
    nw = np.sqrt(np.einsum("ij,ij->i", O[:, :3], O[:, :3]))
    nv = np.sqrt(np.einsum("ij,ij->i", O[:, 3:], O[:, 3:]))
    full = np.sqrt(nw * nw + nv * nv)
    if np.all(nw > _PURE_TRANSLATION * nv) and full.min() > _UNDEFINED * full.max():
        return O / nw[:, None]
    rot = nw > _PURE_TRANSLATION * nv
    norm = np.where(rot, nw, nv)
    norm[full <= _UNDEFINED * full.max()] = np.inf    # undefined OTS (exact singularity elsewhere) -> zeros
    return O / norm[:, None]


_PAIR_CACHE: dict[int, tuple[np.ndarray, np.ndarray, tuple[str, ...]]] = {}


def _pair_index(n: int) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    if n not in _PAIR_CACHE:
        pairs = limb_pairs(n)
        _PAIR_CACHE[n] = (np.array([i for i, _ in pairs], dtype=int), np.array([j for _, j in pairs], dtype=int),
                          tuple(f"{i + 1}-{j + 1}" for i, j in pairs))
    return _PAIR_CACHE[n]


def omega_angles(twists: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
    """Omega_ij for every pair of output twist screws (seed 003 eq 7), rad in [0, pi/2], and the pair names."""
    O = np.asarray(twists, dtype=float)
    ii, jj, names = _pair_index(O.shape[0])
    nw = np.sqrt(np.einsum("ij,ij->i", O[:, :3], O[:, :3]))
    if np.all(nw > 0.5):                      # usual case: every OTS is a normalised rotation
        D = O[:, :3] @ O[:, :3].T
        return np.arccos(np.minimum(np.abs(D[ii, jj]), 1.0)), names
    nv = np.sqrt(np.einsum("ij,ij->i", O[:, 3:], O[:, 3:]))
    rot = nw > 0.5
    dirs = np.where(rot[:, None], O[:, :3], O[:, 3:])
    n = np.where(rot, nw, nv)
    defined = n > 0
    n = np.where(defined, n, 1.0)
    c = np.abs(np.einsum("ij,ij->i", dirs[ii], dirs[jj])) / (n[ii] * n[jj])
    om = np.arccos(np.minimum(c, 1.0))
    om = np.where(rot[ii] != rot[jj], np.pi / 2, om)
    if not defined.any():                     # rank <= 4: every pair singular
        return np.zeros(len(ii)), names
    om = np.where(defined[ii] & defined[jj], om, np.pi / 2)   # undefined OTS: not the implicated pair
    return om, names


def indices_from_screws(det_jd: float, wrenches: np.ndarray, constraints: np.ndarray | None = None
                        ) -> SingularityReport:
    """SingularityReport from det J_D and the transmission (and constraint) wrench screws."""
    om, names = omega_angles(output_twist_screws(wrenches, constraints))
    k = int(np.argmin(om))
    return SingularityReport(det_jd=float(det_jd), omega=om, pairs=names, min_omega=float(om[k]),
                             min_pair=names[k])


def _report(det_jd: float, om: np.ndarray, names: tuple[str, ...]) -> SingularityReport:
    k = int(np.argmin(om))
    return SingularityReport(det_jd=float(det_jd), omega=om, pairs=names, min_omega=float(om[k]), min_pair=names[k])


def _angles_between_rows(A: np.ndarray) -> np.ndarray | None:
    """Omega for every pair of rows of A (angular parts of the OTS, any common basis), or None when a row
    vanishes (pure-translation OTS: the caller falls back to the screw computation)."""
    n = np.sqrt(np.einsum("ij,ij->i", A, A))
    if n.min() <= 1e-12 * n.max():
        return None
    ii, jj, _ = _pair_index(A.shape[0])
    U = A / n[:, None]
    c = np.abs(np.einsum("ij,ij->i", U[ii], U[jj]))
    return np.arccos(np.minimum(c, 1.0))


def _well_conditioned(J: np.ndarray, det: float) -> bool:
    """|det J| is far from zero relative to Hadamard's bound (so inv(J) columns are accurate directions)."""
    return abs(det) > 1e-7 * float(np.prod(np.sqrt(np.einsum("ij,ij->i", J, J))))


def upsrpu_indices(desc: UpsrpuDescription, X: np.ndarray) -> SingularityReport:
    """det J_D (J_D = dq/dX) and the six Omega_ij of the 3UPS+RPU at pose X (seed 003 eqs 2, 7, 8).

    The four transmission wrenches (eq 8) are completed by the RPU limb's two constraint wrenches so that each
    OTS is a single, well-defined screw of the platform's 4-DOF motion. Equivalent fast form used here: the
    twists compatible with the constraints are X_dot mapped to omega = theta_dot Y_F + psi_dot R_y(theta) Z_F, and
    $T_j o twist = (J_D X_dot)_j, so OTS i is the twist of X_dot = J_D^-1 e_i and its angular part has the
    coordinates (theta_dot, psi_dot) = rows 3-4 of column i of J_D^-1 in the orthonormal basis (Y_F,
    R_y(theta) Z_F). Near an exact singularity (or for a pure-translation OTS) the screw computation of
    `output_twist_screws` (adjugate by SVD) is used instead; tests check both agree.
    """
    from hexa.kinematics import upsrpu as kin

    X = np.asarray(X, dtype=float)
    return upsrpu_indices_with_jd(desc, X, kin.jacobian_jd(desc, X))


def upsrpu_indices_with_jd(desc: UpsrpuDescription, X: np.ndarray, J: np.ndarray) -> SingularityReport:
    """`upsrpu_indices` when J_D at X is already known (e.g. from the last Newton-Raphson iteration)."""
    from hexa.kinematics import upsrpu as kin

    det = np.linalg.det(J)
    if _well_conditioned(J, det):
        om = _angles_between_rows(np.linalg.inv(J)[2:4].T)
        if om is not None:
            return _report(det, om, _pair_index(4)[2])
    _, T, C = kin.jd_and_screws(desc, X)
    return indices_from_screws(det, T, C)


def upsrpu_indices_from_screws(desc: UpsrpuDescription, X: np.ndarray) -> SingularityReport:
    """`upsrpu_indices` computed from the screws only (transmission + constraint wrenches -> OTS -> Omega)."""
    from hexa.kinematics import upsrpu as kin

    J, T, C = kin.jd_and_screws(desc, np.asarray(X, dtype=float))
    return indices_from_screws(np.linalg.det(J), T, C)


def hexa_indices(desc: HexaDescription, pose: np.ndarray, zeta: np.ndarray | None = None) -> SingularityReport:
    """det J_D and the fifteen Omega_ij of the Hexa at `pose` (x, y, z, alpha, beta, gamma).

    Transmission wrench screws: unit force along each rod through its spherical joint (DESIGN.md). The
    `constraint_jacobians` rows [n_i, r_i x n_i] are exactly these screws with moments about the plate centre
    (hexa6rus `rod_wrench_screws` gives the same screws about the base origin; Omega does not depend on the
    reference point, see the tests), so one call yields both J_D and the wrenches. `zeta` defaults to the IK.
    Since J_D t = J_I zeta_dot with t = (v_P, omega), OTS i is column i of J_D^-1 and its angular part is rows
    4-6; near an exact singularity the adjugate (SVD) form of `output_twist_screws` is used instead.
    """
    from hexa.kinematics import hexa6rus as kin

    pose = np.asarray(pose, dtype=float)
    if zeta is None:
        zeta = kin.inverse_kinematics(desc, pose)
    J_D, _ = kin.constraint_jacobians(desc, pose, zeta)
    det = np.linalg.det(J_D)
    if _well_conditioned(J_D, det):
        om = _angles_between_rows(np.linalg.inv(J_D)[3:6].T)
        if om is not None:
            return _report(det, om, _pair_index(6)[2])
    return indices_from_screws(det, J_D)


class SingularityMonitor:
    """The indices of measured poses of one robot, with its near-singularity limits.

    Args:
        robot: "hexa" (pose x y z α β γ) or "upsrpu" (X = x_m, z_m, θ, ψ).
        description: robot description YAML path (None = the packaged one).

    The limits start at the robot's defaults: the 3UPS+RPU's det J_D and Ω limits from its description (seed 003
    Table 2); for the Hexa no det J_D limit and Ω 1.8°. Set `det_jd_limit` / `omega_limit` to change them.

    Raises:
        SingularityError: an unknown robot.
    """

    def __init__(self, robot: str, description: str | None = None) -> None:
        if robot == "upsrpu":
            from hexa.robots.upsrpu_description import load_upsrpu

            self.desc: UpsrpuDescription | HexaDescription = load_upsrpu(description)
            self.det_jd_limit, self.omega_limit = float(self.desc.det_jd_limit), float(self.desc.omega_limit)
        elif robot == "hexa":
            from hexa.robots.hexa_description import load_hexa

            self.desc = load_hexa(description)
            self.det_jd_limit, self.omega_limit = 0.0, math.radians(1.8)
        else:
            raise SingularityError(f"robot must be 'hexa' or 'upsrpu', got {robot!r}")
        self.robot = robot

    def report(self, pose: np.ndarray) -> SingularityReport:
        """det J_D and every Ω at `pose`.

        Raises:
            ValueError: the pose is unreachable (Hexa) or the indices are undefined there.
        """
        if self.robot == "upsrpu":
            return upsrpu_indices(cast("UpsrpuDescription", self.desc), pose)
        return hexa_indices(cast("HexaDescription", self.desc), pose)

    def near(self, report: SingularityReport) -> bool:
        """True when `report` is within the limits (Algorithm 1's test)."""
        return report.near(self.det_jd_limit, self.omega_limit)
