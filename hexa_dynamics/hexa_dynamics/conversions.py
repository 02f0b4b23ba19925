"""Message <-> core conversions shared by the dynamics nodes (plain numpy on message fields)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

UPSRPU_JOINTS = ("limb_1", "limb_2", "limb_3", "limb_4")


def quaternion_from_matrix(R: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) unit quaternion of a rotation matrix (Shepperd's method)."""
    t = R[0, 0] + R[1, 1] + R[2, 2]
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        w, x, y, z = 0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        w, x, y, z = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        w, x, y, z = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        w, x, y, z = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return x / n, y / n, z / n, w / n


def matrix_from_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a (not necessarily normalised) quaternion (x, y, z, w).

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


def upsrpu_pose_to_msg_fields(X: np.ndarray) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """(position, quaternion) of the 3UPS+RPU pose X = (x_m, z_m, theta, psi) in the fixed frame."""
    from hexa.kinematics.upsrpu import rotation_yz

    return (float(X[0]), 0.0, float(X[1])), quaternion_from_matrix(rotation_yz(X[2], X[3]))


def upsrpu_pose_from_msg(pose: Any) -> np.ndarray:
    """X = (x_m, z_m, theta, psi) from a geometry_msgs/Pose (projected on the robot's four DOF)."""
    from hexa.srm.tracking import pose_from_transform

    o = pose.orientation
    R = matrix_from_quaternion(o.x, o.y, o.z, o.w)
    p = pose.position
    return pose_from_transform(R, np.array([p.x, p.y, p.z]))


def hexa_pose_from_msg(pose: Any) -> np.ndarray:
    """Hexa pose (x, y, z, alpha, beta, gamma) (Z-Y-X, seed 000 eq 38) from a geometry_msgs/Pose."""
    from hexa.kinematics.hexa6rus import rotation_to_zyx

    o = pose.orientation
    a, b, g = rotation_to_zyx(matrix_from_quaternion(o.x, o.y, o.z, o.w))
    p = pose.position
    return np.array([p.x, p.y, p.z, float(a), float(b), float(g)])


def points_from_pose_array(msg: Any) -> np.ndarray:
    """(N, 3) marker positions from a geometry_msgs/PoseArray (orientations ignored)."""
    return np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses], dtype=float).reshape(-1, 3)
