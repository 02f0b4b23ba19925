"""Rotations written once for the whole project: quaternions (x, y, z, w, the ROS order) and rotation matrices."""
from __future__ import annotations

import math

import numpy as np


def quaternion_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method: the largest pivot, no cancellation)."""
    R = np.asarray(R, dtype=float)
    t = R[0, 0] + R[1, 1] + R[2, 2]
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        q = ((R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s)
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = (0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s)
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = ((R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s)
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = ((R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s)
    qa = np.array(q)
    return qa / np.linalg.norm(qa)


def matrix_from_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a quaternion (x, y, z, w), normalised first.

    Raises:
        ValueError: the quaternion is zero or not finite.
    """
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(n) or n == 0.0:
        raise ValueError(f"invalid quaternion ({x}, {y}, {z}, {w})")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def quaternion_from_zyx(alpha: float, beta: float, gamma: float) -> np.ndarray:
    """Quaternion (x, y, z, w) of Rz(α)·Ry(β)·Rx(γ), the Z-Y-X Tait–Bryan angles of seed 000 eq 38."""
    ca, sa = math.cos(alpha / 2), math.sin(alpha / 2)
    cb, sb = math.cos(beta / 2), math.sin(beta / 2)
    cg, sg = math.cos(gamma / 2), math.sin(gamma / 2)
    return np.array([ca * cb * sg - sa * sb * cg, ca * sb * cg + sa * cb * sg, sa * cb * cg - ca * sb * sg,
                     ca * cb * cg + sa * sb * sg])


def pose6_from_transform(T: np.ndarray) -> np.ndarray:
    """[x y z α β γ] (Z-Y-X angles, seed 000 eq 38) of a 4x4 homogeneous transform."""
    R = T[:3, :3]
    return np.array([T[0, 3], T[1, 3], T[2, 3], math.atan2(R[1, 0], R[0, 0]),
                     math.asin(float(np.clip(-R[2, 0], -1.0, 1.0))), math.atan2(R[2, 1], R[2, 2])])


def transform_from_pose6(pose: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform of [x y z α β γ] (Z-Y-X angles, seed 000 eq 38)."""
    a, b, g = (float(v) for v in pose[3:6])
    ca, sa, cb, sb, cg, sg = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(g), math.sin(g)
    T = np.eye(4)
    T[:3, :3] = [[ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg],
                 [sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg],
                 [-sb, cb * sg, cb * cg]]
    T[:3, 3] = [float(v) for v in pose[:3]]
    return T
