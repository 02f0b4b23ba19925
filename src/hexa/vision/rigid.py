"""Rigid registration of point sets (Kabsch / Umeyama): plate markers from depth, or motion-capture marker sets."""
from __future__ import annotations

import numpy as np


class RigidFitError(ValueError):
    """The point sets cannot define a rigid transform (too few, mismatched, non-finite or degenerate)."""


def fit_rigid_transform(model_pts: np.ndarray, measured_pts: np.ndarray, weights: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray, float]:
    """Rotation R and translation t minimising Σ w_i |R·m_i + t − p_i|² (weighted Kabsch / Umeyama, no scale).

    Used for the plate's coloured markers lifted from depth (seed 000 §5.1.2) and for the 3UPS+RPU's
    motion-capture rigid bodies (seed 003 §2.4: three markers per platform plus one redundant).

    Args:
        model_pts: (N, 3) marker positions in the body frame (m), N ≥ 3.
        measured_pts: (N, 3) the same markers measured in the reference frame (m).
        weights: optional (N,) non-negative weights (e.g. inverse variances); at least 3 must be positive.

    Returns:
        (R (3, 3) proper rotation, t (3,), rms) with measured ≈ R @ model + t; rms is the (weighted) RMS residual (m).

    Raises:
        RigidFitError: shapes differ, fewer than 3 usable points, non-finite values, or collinear points.

    Example:
        >>> m = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
        >>> R, t, rms = fit_rigid_transform(m, m + [0.1, 0, 0])
        >>> np.round(t, 6).tolist(), round(rms, 9)
        ([0.1, 0.0, 0.0], 0.0)
    """
    P = np.asarray(model_pts, dtype=float)
    Q = np.asarray(measured_pts, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape != Q.shape:
        raise RigidFitError(f"point sets must both be (N, 3); got model {P.shape} and measured {Q.shape}")
    n = P.shape[0]
    if weights is None:
        w = np.ones(n)
    else:
        w = np.asarray(weights, dtype=float).reshape(-1)
        if w.shape[0] != n:
            raise RigidFitError(f"weights has {w.shape[0]} entries for {n} points")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise RigidFitError(f"weights must be finite and non-negative; got {w.tolist()}")
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(Q))):
        raise RigidFitError("point sets contain non-finite values")
    used = w > 0
    if int(used.sum()) < 3:
        raise RigidFitError(f"need at least 3 points with positive weight; got {int(used.sum())}")
    ws = w.sum()
    cp = (w[:, None] * P).sum(axis=0) / ws
    cq = (w[:, None] * Q).sum(axis=0) / ws
    Pc = P - cp
    Qc = Q - cq
    H = (w[:, None] * Pc).T @ Qc
    U, _, Vt = np.linalg.svd(H)
    # Model points must span at least a plane: the second singular value of the model's own scatter.
    sp = np.linalg.svd((np.sqrt(w)[:, None] * Pc), compute_uv=False)
    if sp.shape[0] < 2 or sp[1] <= 1e-9 * max(sp[0], 1e-12) or sp[0] == 0.0:
        raise RigidFitError(f"model points are collinear or coincident (singular values {sp.tolist()})")
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    if d == 0:
        d = 1.0
    D = np.diag([1.0, 1.0, d])
    R = Vt.T @ D @ U.T
    t = cq - R @ cp
    res = Q - (P @ R.T + t)
    rms = float(np.sqrt((w * (res ** 2).sum(axis=1)).sum() / ws))
    return R, t, rms


def residuals(R: np.ndarray, t: np.ndarray, model_pts: np.ndarray, measured_pts: np.ndarray) -> np.ndarray:
    """Per-point distances |R·m_i + t − p_i| (m) of a fitted transform."""
    P = np.asarray(model_pts, dtype=float)
    Q = np.asarray(measured_pts, dtype=float)
    return np.linalg.norm(Q - (P @ np.asarray(R).T + np.asarray(t)), axis=1)


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle (rad) of the relative rotation R_aᵀ·R_b."""
    c = (np.trace(np.asarray(R_a).T @ np.asarray(R_b)) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def fit_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares plane through points given as columns (3, N), N ≥ 3: (centroid c, unit normal n).

    n is the eigenvector of the smallest eigenvalue of the 3×3 scatter matrix Σ (p − c)(p − c)ᵀ — the last right-
    singular vector of the centred points, from a 3×3 problem instead of an SVD of the N×3 matrix (the same plane to
    rounding). Its sign is arbitrary; callers orient it.

    Raises:
        RigidFitError: fewer than 3 points or non-finite values.

    Example:
        >>> c, n = fit_plane(np.array([[0., 1, 0, 1], [0, 0, 1, 1], [2, 2, 2, 2]]))
        >>> c.tolist(), np.abs(n).round(12).tolist()
        ([0.5, 0.5, 2.0], [0.0, 0.0, 1.0])
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[0] != 3 or P.shape[1] < 3:
        raise RigidFitError(f"need points as columns (3, N) with N >= 3; got {P.shape}")
    if not np.all(np.isfinite(P)):
        raise RigidFitError("points contain non-finite values")
    c = P.mean(axis=1)
    D = P - c[:, None]
    _, v = np.linalg.eigh(D @ D.T)
    return c, v[:, 0]
