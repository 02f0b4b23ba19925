"""The Hexa's coordinate frames (REP-105 style, docs/frames.md): their names, and each one's pose in its parent.

One place names every frame the graph publishes on TF or writes in a header. Transforms are 4x4 matrices
`T_parent_child` that map points in the child frame to the parent frame (the convention of
geometry_msgs/TransformStamped: header.frame_id = parent, child_frame_id = child).

Cameras follow realsense-ros: `<cam>_link` (x forward, y left, z up) at the camera, its colour, depth and
aligned-depth frames (same axes) and their optical frames (REP-103 optical: z forward, x right, y down). The robot
description gives the colour optical frame's pose in `base` (`cameras.<cam>`: position, look_at, up); the link and
the other sensor frames sit at that optical centre (the simulated depth is rendered at the colour camera; a real
D435's depth-to-colour baseline would be a calibrated offset of `<cam>_depth_frame`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

BASE = "base"
PLATE = "plate"
CONTACT = "contact"
#: columns: the optical frame's axes (x right, y down, z forward) in the link frame (x forward, y left, z up)
R_LINK_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
#: the sensor frames under each `<cam>_link` (realsense-ros names, after the camera's name)
CAMERA_SENSORS = ("color", "depth", "aligned_depth_to_color")


def arm(i: int) -> str:
    """The frame of arm i (1..6): origin at the motor A_i, x along the arm, z the motor axis (seed 000, eq 10)."""
    return f"arm_{i}"


def rod(i: int) -> str:
    """The frame of rod i (1..6): origin at the elbow B_i, x along the rod towards C_i (seed 000, eqs 11-13)."""
    return f"rod_{i}"


def camera_link(cam: str) -> str:
    return f"{cam}_link"


def camera_frame(cam: str, sensor: str = "color") -> str:
    return f"{cam}_{sensor}_frame"


def camera_optical_frame(cam: str, sensor: str = "color") -> str:
    return f"{cam}_{sensor}_optical_frame"


def transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The 4x4 transform with rotation R and translation t."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def camera_transforms(cam: str, T_base_optical: np.ndarray) -> list[tuple[str, str, np.ndarray]]:
    """(parent, child, T_parent_child) of one camera's frames, from its colour optical frame's pose in base."""
    link_optical = transform(R_LINK_OPTICAL, np.zeros(3))
    T_base_link = T_base_optical @ np.linalg.inv(link_optical)
    out = [(BASE, camera_link(cam), T_base_link)]
    for sensor in CAMERA_SENSORS:
        out.append((camera_link(cam), camera_frame(cam, sensor), np.eye(4)))
        out.append((camera_frame(cam, sensor), camera_optical_frame(cam, sensor), link_optical))
    return out


def static_transforms(desc: HexaDescription) -> list[tuple[str, str, np.ndarray]]:
    """Every fixed frame of the robot description: each camera's link, sensor and optical frames (for /tf_static).

    Raises:
        hexa.sim.config.SimConfigError: the description's `cameras` section is missing or invalid, or a camera's
            `frame_id` is not its colour optical frame (`<cam>_color_optical_frame`, the images' frame).
    """
    from hexa.sim.config import SimConfigError, sim_config_of

    out: list[tuple[str, str, np.ndarray]] = []
    for cam in sim_config_of(desc).cameras.values():
        if cam.frame_id != camera_optical_frame(cam.name):
            raise SimConfigError(f"cameras.{cam.name}.frame_id {cam.frame_id!r} must be "
                                 f"{camera_optical_frame(cam.name)!r} (realsense-ros naming, docs/frames.md)")
        out += camera_transforms(cam.name, cam.T_base_camera)
    return out


def robot_transforms(desc: HexaDescription, pose: np.ndarray, zeta: np.ndarray) -> list[tuple[str, str, np.ndarray]]:
    """The moving frames at plate pose (x, y, z, α, β, γ) and arm angles ζ: base → plate, arm_i, rod_i (for /tf)."""
    from hexa.kinematics.hexa6rus import arm_rotations, elbows, rod_rotations, rotation_zyx

    pose, zeta = np.asarray(pose, dtype=float), np.asarray(zeta, dtype=float)
    out = [(BASE, PLATE, transform(rotation_zyx(*pose[3:6]), pose[:3]))]
    R_arm, B = arm_rotations(desc, zeta), elbows(desc, zeta)
    R_rod = rod_rotations(desc, pose, zeta)[0]
    out += [(BASE, arm(i + 1), transform(R_arm[i], desc.A[i])) for i in range(6)]
    out += [(BASE, rod(i + 1), transform(R_rod[i], B[i])) for i in range(6)]
    return out
