"""The 3D tracking system of seed 003 sec 2.4: platform pose X_c from marker sets, and simulated markers.

Each platform carries a rigid body of markers (three define its frame, one is redundant). The measured
positions (world frame of the tracking system) are registered to the marker model with the weighted
Kabsch fit; X_c is the mobile frame expressed in the fixed frame, projected on the robot's four DOF
(x_m, z_m, theta, psi) with R = R_y(theta) R_z(psi).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexa.kinematics.upsrpu import rotation_yz
from hexa.robots.schema import RobotDescriptionError, require_array, require_float

if TYPE_CHECKING:
    from hexa.robots.upsrpu_description import UpsrpuDescription

__all__ = ["TrackingModel", "MarkerTracker", "tracking_model", "pose_from_transform", "pose_from_markers",
           "markers_from_pose"]


@dataclass(frozen=True)
class TrackingModel:
    """Marker models of both platforms, the simulated world placement of the fixed frame and marker noise."""

    fixed_markers: np.ndarray       # (N, 3) in O_f
    mobile_markers: np.ndarray      # (M, 3) in O_m
    world_R_fixed: np.ndarray       # (3, 3)
    world_p_fixed: np.ndarray       # (3,)
    marker_noise: float


def tracking_model(desc: UpsrpuDescription) -> TrackingModel:
    """The `tracking` section of the 3UPS+RPU description.

    Raises:
        RobotDescriptionError: naming the missing or malformed key.
    """
    sec = {"tracking": desc.section("tracking")}
    fixed = np.asarray(sec["tracking"].get("fixed_markers", []), dtype=float)
    mobile = np.asarray(sec["tracking"].get("mobile_markers", []), dtype=float)
    for key, arr in (("fixed_markers", fixed), ("mobile_markers", mobile)):
        if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 3:
            raise RobotDescriptionError(f"key 'tracking.{key}' must be a list of >= 3 points (x, y, z), "
                                        f"got shape {arr.shape}")
    place = require_array(sec, "tracking.fixed_in_world", (4,))
    noise = require_float(sec, "tracking.marker_noise", nonneg=True)
    c, s = math.cos(place[3]), math.sin(place[3])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return TrackingModel(fixed, mobile, R, np.array(place[:3]), noise)


def pose_from_transform(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """X = (x_m, z_m, theta, psi) from the mobile frame's rotation R and origin p in the fixed frame.

    With R = R_y(theta) R_z(psi): psi = atan2(R21, R22), theta = atan2(R13, R33) (1-based indices); the
    robot's constrained coordinates (y of O_m, the third rotation) are dropped.
    """
    return np.array([p[0], p[2], math.atan2(R[0, 2], R[2, 2]), math.atan2(R[1, 0], R[1, 1])])


def pose_from_markers(model: TrackingModel, fixed_world: np.ndarray, mobile_world: np.ndarray
                      ) -> tuple[np.ndarray, float]:
    """X_c and the worse of the two registration RMS residuals (m) from measured marker positions (world).

    Raises:
        hexa.vision.rigid.RigidFitError: a marker set is degenerate or does not match its model.
    """
    from hexa.vision.rigid import fit_rigid_transform

    Rf, tf, rms_f = fit_rigid_transform(model.fixed_markers, fixed_world)
    Rm, tm, rms_m = fit_rigid_transform(model.mobile_markers, mobile_world)
    R = Rf.T @ Rm
    p = Rf.T @ (tm - tf)
    return pose_from_transform(R, p), max(rms_f, rms_m)


def markers_from_pose(model: TrackingModel, X: np.ndarray, rng: np.random.Generator | None = None,
                      noise: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Simulated marker positions (world) of both platforms at pose X, with Gaussian noise (std `noise`, m)."""
    X = np.asarray(X, dtype=float)
    R = rotation_yz(X[2], X[3])
    om = np.array([X[0], 0.0, X[1]])
    fixed = model.fixed_markers @ model.world_R_fixed.T + model.world_p_fixed
    mobile = (model.mobile_markers @ R.T + om) @ model.world_R_fixed.T + model.world_p_fixed
    sigma = model.marker_noise if noise is None else noise
    if sigma > 0:
        rng = rng or np.random.default_rng()
        fixed = fixed + rng.normal(0.0, sigma, fixed.shape)
        mobile = mobile + rng.normal(0.0, sigma, mobile.shape)
    return fixed, mobile


class MarkerTracker:
    """X_c from the tracking system's two marker streams as they arrive: the newest fixed set is kept, each mobile
    set gives a pose."""

    def __init__(self, model: TrackingModel) -> None:
        self.model = model
        self.fixed: np.ndarray | None = None

    def add_fixed(self, points: np.ndarray) -> None:
        """Keep the fixed platform's measured markers (N, 3) (world)."""
        self.fixed = np.asarray(points, dtype=float)

    def add_mobile(self, points: np.ndarray) -> np.ndarray | None:
        """X_c from the mobile platform's measured markers (M, 3) and the newest fixed set; None before any fixed set.

        Raises:
            hexa.vision.rigid.RigidFitError: a marker set is degenerate or does not match its model.
        """
        if self.fixed is None:
            return None
        return pose_from_markers(self.model, self.fixed, np.asarray(points, dtype=float))[0]
