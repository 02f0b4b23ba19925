"""Kinematics of the 3UPS+RPU (seed 003 sec 2.1-2.2): IK q(X), J_D = dq/dX, Newton-Raphson FK, joint angles.

Pose X = (x_m, z_m, theta, psi): platform centre O_m = (x_m, 0, z_m) and orientation R = R_y(theta) R_z(psi),
both in the fixed frame O_f X_F Y_F Z_F. Actuators q_ind = (q13, q23, q33, q42):
q_i = |O_m + R p_i - b_i| for the UPS limbs i = 1..3 (p_i = A1, B1, C1; b_i = A0, B0, C0) and q_4 = |O_m - D0|.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hexa.robots.upsrpu_description import UpsrpuDescription

__all__ = [
    "UnreachablePoseError", "ForwardKinematicsError", "rotation_yz", "inverse_kinematics",
    "inverse_kinematics_batch", "jacobian_jd", "forward_kinematics", "platform_joints_base",
    "spherical_joint_angles", "limb_unit_vectors", "actuators_within_limits", "transmission_wrench_screws",
    "constraint_wrench_screws", "forward_kinematics_terms", "spherical_angles_from", "jd_and_screws",
    "wrenches_from", "reference_data_dir", "load_reference_trajectory", "constant_velocity_path",
    "table3_trajectory",
]


class UnreachablePoseError(ValueError):
    """A pose needs an actuator length outside the feasible stroke of Table 2 (the message names the limb)."""


class ForwardKinematicsError(RuntimeError):
    """Newton-Raphson forward kinematics did not converge (singular J_D or too far from the initial pose)."""


def rotation_yz(theta: float, psi: float) -> np.ndarray:
    """Platform orientation R = R_y(theta) R_z(psi) (seed 003, Figure 1 angles)."""
    ct, st, cp, sp = math.cos(theta), math.sin(theta), math.cos(psi), math.sin(psi)
    return np.array([[ct * cp, -ct * sp, st],
                     [sp, cp, 0.0],
                     [-st * cp, st * sp, ct]])


def platform_joints_base(desc: UpsrpuDescription, X: np.ndarray) -> np.ndarray:
    """A1, B1, C1 in the fixed frame (3, 3) for pose X."""
    R = rotation_yz(X[2], X[3])
    return np.array([X[0], 0.0, X[1]]) + desc.platform_joints @ R.T


def _limb_vectors(desc: UpsrpuDescription, X: np.ndarray) -> np.ndarray:
    """Vectors from each fixed joint to its mobile joint (4, 3): A0A1, B0B1, C0C1, D0O_m."""
    R = rotation_yz(X[2], X[3])
    om = np.array([X[0], 0.0, X[1]])
    d = np.empty((4, 3))
    d[:3] = om + desc.platform_joints @ R.T - desc.base_joints[:3]
    d[3] = om - desc.base_joints[3]
    return d


def limb_unit_vectors(desc: UpsrpuDescription, X: np.ndarray) -> np.ndarray:
    """Unit vectors along the four limbs (fixed joint towards mobile joint), (4, 3)."""
    d = _limb_vectors(desc, X)
    return d / np.linalg.norm(d, axis=1)[:, None]


def actuators_within_limits(desc: UpsrpuDescription, q: np.ndarray) -> bool:
    """True when every actuator length lies strictly inside (q_min, q_max) of Table 2."""
    return bool(np.all(q > desc.q_min) and np.all(q < desc.q_max))


def inverse_kinematics(desc: UpsrpuDescription, X: np.ndarray, check_limits: bool = False) -> np.ndarray:
    """Actuator lengths q_ind (4,) in m for pose X = (x_m, z_m, theta, psi).

    Example: the home pose (0, 0.7, 0, 0) gives q ~ (0.7071, 0.7459, 0.7548, 0.7159).

    Raises:
        UnreachablePoseError: with `check_limits`, a length is outside [q_min, q_max] (names the limb).
    """
    X = np.asarray(X, dtype=float)
    q = np.linalg.norm(_limb_vectors(desc, X), axis=1)
    if check_limits:
        for i in range(4):
            if not desc.q_min[i] <= q[i] <= desc.q_max[i]:
                raise UnreachablePoseError(
                    f"pose {X.tolist()} needs limb {i + 1} length {q[i]:.4f} m outside its stroke "
                    f"[{desc.q_min[i]:.3f}, {desc.q_max[i]:.3f}] m")
    return q


def inverse_kinematics_batch(desc: UpsrpuDescription, X: np.ndarray) -> np.ndarray:
    """Actuator lengths (N, 4) for poses X (N, 4), vectorised (no limit check)."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    ct, st, cp, sp = np.cos(X[:, 2]), np.sin(X[:, 2]), np.cos(X[:, 3]), np.sin(X[:, 3])
    R = np.empty((len(X), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = ct * cp, -ct * sp, st
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = sp, cp, 0.0
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -st * cp, st * sp, ct
    om = np.zeros((len(X), 3))
    om[:, 0], om[:, 2] = X[:, 0], X[:, 1]
    ups = om[:, None, :] + np.einsum("nij,kj->nki", R, desc.platform_joints) - desc.base_joints[None, :3]
    q = np.empty((len(X), 4))
    q[:, :3] = np.linalg.norm(ups, axis=2)
    q[:, 3] = np.linalg.norm(om - desc.base_joints[3], axis=1)
    return q


def _q_and_jd(desc: UpsrpuDescription, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(q (4,), J_D (4, 4), unit limb vectors u (4, 3), mobile joints in base (4, 3) with O_m last) in one pass."""
    ct, st, cp, sp = math.cos(X[2]), math.sin(X[2]), math.cos(X[3]), math.sin(X[3])
    P = desc.platform_joints
    # rows of R, dR/dtheta, dR/dpsi stacked: R = Ry(theta) Rz(psi)
    M = np.array([[ct * cp, -ct * sp, st], [sp, cp, 0.0], [-st * cp, st * sp, ct],
                  [-st * cp, st * sp, ct], [0.0, 0.0, 0.0], [-ct * cp, ct * sp, -st],
                  [-ct * sp, -ct * cp, 0.0], [cp, -sp, 0.0], [st * sp, st * cp, 0.0]])
    PM = P @ M.T                                  # (3, 9): R p, dR/dtheta p, dR/dpsi p per limb
    pts = np.empty((4, 3))
    pts[:3] = PM[:, :3]
    pts[:3, 0] += X[0]
    pts[:3, 2] += X[1]
    pts[3] = (X[0], 0.0, X[1])
    d = pts - desc.base_joints
    q = np.sqrt(np.einsum("ij,ij->i", d, d))
    u = d / q[:, None]
    J = np.zeros((4, 4))
    J[:, 0] = u[:, 0]
    J[:, 1] = u[:, 2]
    J[:3, 2] = np.einsum("ij,ij->i", u[:3], PM[:, 3:6])
    J[:3, 3] = np.einsum("ij,ij->i", u[:3], PM[:, 6:9])
    return q, J, u, pts


def jacobian_jd(desc: UpsrpuDescription, X: np.ndarray) -> np.ndarray:
    """Forward Jacobian J_D = dq_ind/dX (4, 4), analytic (seed 003 eq 2 with Phi = q - q(X)).

    Row i is u_i . d(limb vector)/dX with u_i the limb's unit vector; columns follow (x_m, z_m, theta, psi).
    """
    return _q_and_jd(desc, np.asarray(X, dtype=float))[1]


def forward_kinematics(desc: UpsrpuDescription, q: np.ndarray, X0: np.ndarray, tol: float = 1e-12,
                       max_iter: int = 30, max_step: float = 0.05) -> np.ndarray:
    """Pose X with q(X) = q by Newton-Raphson from the initial pose X0 (Algorithm 1: "X_c as initial condition").

    Starting from X0 keeps the assembly branch continuous with it. Each step is clipped to `max_step`
    (m or rad) so the iteration does not jump to another branch.

    Raises:
        ForwardKinematicsError: J_D is singular on the way or the residual is still above `tol` (m).
    """
    return forward_kinematics_terms(desc, q, X0, tol, max_iter, max_step)[0]


def forward_kinematics_terms(desc: UpsrpuDescription, q: np.ndarray, X0: np.ndarray, tol: float = 1e-12,
                             max_iter: int = 30, max_step: float = 0.05
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`forward_kinematics` also returning the unit limb vectors (4, 3), the mobile joints (4, 3) and J_D at the
    solution (for the SRM's candidate checks without recomputing them)."""
    q = np.asarray(q, dtype=float)
    X = np.array(X0, dtype=float)
    for _ in range(max_iter):
        qx, J, u, pts = _q_and_jd(desc, X)
        r = q - qx
        if float(np.max(np.abs(r))) < tol:
            return X, u, pts, J
        try:
            dX = np.linalg.solve(J, r)
        except np.linalg.LinAlgError as exc:
            raise ForwardKinematicsError(f"singular J_D at X = {X.tolist()} solving FK for q = {q.tolist()}") from exc
        m = float(np.max(np.abs(dX)))
        if m > max_step:
            dX *= max_step / m
        X += dX
    qx, J, u, pts = _q_and_jd(desc, X)
    if float(np.max(np.abs(q - qx))) < max(tol, 1e-10):
        return X, u, pts, J
    raise ForwardKinematicsError(
        f"FK for q = {q.tolist()} from X0 = {np.asarray(X0).tolist()} did not converge: residual "
        f"{float(np.max(np.abs(q - qx))):.3e} m after {max_iter} iterations")


def spherical_joint_angles(desc: UpsrpuDescription, X: np.ndarray) -> np.ndarray:
    """Angles (3,) in rad between each UPS limb and the platform normal R e_z (compare with spherical_max)."""
    return spherical_angles_from(limb_unit_vectors(desc, X), X[2])


def spherical_angles_from(u: np.ndarray, theta: float) -> np.ndarray:
    """Spherical-joint angles from the unit limb vectors u (rows 0-2 used) and theta (R e_z = (sin, 0, cos))."""
    c = u[:3, 0] * math.sin(theta) + u[:3, 2] * math.cos(theta)
    return np.arccos(np.clip(c, -1.0, 1.0))


def transmission_wrench_screws(desc: UpsrpuDescription, X: np.ndarray) -> np.ndarray:
    """Unit transmission wrench screws of the four actuators (4, 6), rows (f; m) with m about the fixed origin.

    Seed 003 eq 8: UPS limb i = unit force along the limb through its spherical joint (A1, B1, C1); RPU limb =
    unit force along D0 -> O_m through O_m. (The paper takes moments about O_m; the angles Omega only use the
    angular parts of the output twists, which do not depend on the reference point.)
    """
    _, _, u, pts = _q_and_jd(desc, np.asarray(X, dtype=float))
    return wrenches_from(u, pts)


def wrenches_from(u: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Transmission wrench screws (4, 6) from unit limb vectors and mobile joints (O_m last), about the origin."""
    out = np.empty((4, 6))
    out[:, :3] = u
    out[:, 3] = pts[:, 1] * u[:, 2] - pts[:, 2] * u[:, 1]     # pts x u (np.cross is slow on tiny arrays)
    out[:, 4] = pts[:, 2] * u[:, 0] - pts[:, 0] * u[:, 2]
    out[:, 5] = pts[:, 0] * u[:, 1] - pts[:, 1] * u[:, 0]
    return out


def jd_and_screws(desc: UpsrpuDescription, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(J_D, transmission wrenches (4, 6), constraint wrenches (2, 6)) at X in one pass."""
    X = np.asarray(X, dtype=float)
    _, J, u, pts = _q_and_jd(desc, X)
    return J, wrenches_from(u, pts), constraint_wrench_screws(desc, X)


def constraint_wrench_screws(desc: UpsrpuDescription, X: np.ndarray) -> np.ndarray:
    """The two constraint wrenches of the RPU limb (2, 6), rows (f; m) about the fixed origin.

    The RPU limb (R about Y_F at D0, P along the limb, U at O_m with axes Y_F and R_y(theta) Z_F) has a
    4-system of twists, so it transmits a 2-system of constraint wrenches: a force along Y_F through O_m
    (keeps O_m in the plane y = 0) and a couple about R_y(theta) X_F (forbids the third rotation).
    """
    c = np.zeros((2, 6))
    c[0, 1] = 1.0
    c[0, 3:] = (-X[1], 0.0, X[0])                   # O_m x e_y with O_m = (x_m, 0, z_m)
    c[1, 3:] = (math.cos(X[2]), 0.0, -math.sin(X[2]))
    return c


# --- Rehabilitation trajectories (seed 003 Table 3) and the authors' reference trajectories -------------------

REFERENCE_NAMES = ("TR15", "TRR0")


def reference_data_dir() -> Path | None:
    """Folder of the authors' reference trajectories: $HEXA_UPSRPU_DATA, else ../shared/data/upsrpu next to the
    repository root; None when absent."""
    env = os.environ.get("HEXA_UPSRPU_DATA")
    cands = [Path(env)] if env else []
    cands.append(Path(__file__).resolve().parents[3].parent / "shared" / "data" / "upsrpu")
    for c in cands:
        if c.is_dir():
            return c
    return None


def load_reference_trajectory(name: str = "TR15", rate: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    """The authors' Cartesian reference `ref_cart_<name>.txt` (columns x_m z_m theta psi, 100 Hz) as (t, X).

    Raises:
        FileNotFoundError: the data folder or file is absent (the message says where it was looked for).
    """
    folder = reference_data_dir()
    if folder is None:
        raise FileNotFoundError("reference trajectories not found: set HEXA_UPSRPU_DATA or provide "
                                "../shared/data/upsrpu next to the repository")
    f = folder / f"ref_cart_{name}.txt"
    if not f.is_file():
        raise FileNotFoundError(f"reference trajectory {f} does not exist")
    X = np.loadtxt(f, dtype=float, ndmin=2)
    if X.shape[1] != 4:
        raise ValueError(f"reference trajectory {f} must have 4 columns (x_m z_m theta psi), got {X.shape[1]}")
    return np.arange(len(X)) / rate, X


def constant_velocity_path(start: np.ndarray, end: np.ndarray, v_translation: float, v_rotation: float,
                           dt: float = 0.01, dwell_start: float = 0.0, dwell_end: float = 0.0
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Move one DOF after the other (x_m, z_m, theta, psi) from `start` to `end` at constant velocity.

    Translations move at `v_translation` (m/s), rotations at `v_rotation` (rad/s), as the authors' reference
    ref_cart_TR15.txt does. Returns (t (N,), X (N, 4)) sampled every `dt` s, with optional dwell at both ends.
    """
    start = np.asarray(start, dtype=float)
    end = np.asarray(end, dtype=float)
    speeds = np.array([v_translation, v_translation, v_rotation, v_rotation])
    durations = np.abs(end - start) / speeds
    t_switch = dwell_start + np.concatenate([[0.0], np.cumsum(durations)])
    total = t_switch[-1] + dwell_end
    t = np.arange(int(math.floor(total / dt + 1e-9)) + 1) * dt
    X = np.empty((len(t), 4))
    for k in range(4):
        frac = np.clip((t - t_switch[k]) / durations[k], 0.0, 1.0) if durations[k] > 0 else np.ones_like(t)
        X[:, k] = start[k] + frac * (end[k] - start[k])
    if t[-1] < total - 1e-12 or not np.allclose(X[-1], end):
        t = np.append(t, total)
        X = np.vstack([X, end])
    return t, X


def table3_trajectory(desc: UpsrpuDescription, number: int, dt: float = 0.01, dwell_end: float = 0.0
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Table 3 trajectory `number` (1..5): from the home pose to its singular end pose at constant velocity.

    Raises:
        ValueError: `number` is not a Table 3 trajectory.
    """
    if not 1 <= number <= len(desc.singular_poses):
        raise ValueError(f"trajectory number must be 1..{len(desc.singular_poses)}, got {number}")
    return constant_velocity_path(desc.home, desc.singular_poses[number - 1], desc.v_translation,
                                  desc.v_rotation, dt=dt, dwell_start=desc.dwell_start, dwell_end=dwell_end)
