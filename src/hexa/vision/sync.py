"""Pairing of colour, depth and camera_info by stamp (no message_filters here), with reject counters."""
from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from hexa.vision.camera import CameraModel, CameraModelError
from hexa.vision.images import ImageConversionError, depth_to_meters, image_to_numpy, to_rgb


@dataclass
class RGBDFrame:
    """An aligned colour/depth pair of one camera: RGB uint8, depth in m (NaN invalid), stamp (s), camera model."""

    stamp: float
    rgb: np.ndarray
    depth: np.ndarray
    camera: CameraModel


class FrameAssembler:
    """Collects colour, depth and camera_info fields of one camera and emits RGB-D frames whose stamps match.

    Bad input (unknown encoding, size mismatch, missing camera_info, empty depth) is counted in `rejects` by reason
    and skipped — never raised.

    Args:
        name: camera name ("cam_top").
        T_base_camera: extrinsics of the colour optical frame (4x4).
        tolerance: largest colour/depth stamp difference (s) to pair.
        keep: how many unpaired messages of each kind to keep.
    """

    def __init__(self, name: str, T_base_camera: np.ndarray, tolerance: float = 0.005, keep: int = 5) -> None:
        self.name = name
        self.T = np.asarray(T_base_camera, float)
        self.tolerance = tolerance
        self.camera: CameraModel | None = None
        self._color: deque[tuple[float, np.ndarray]] = deque(maxlen=keep)
        self._depth: deque[tuple[float, np.ndarray]] = deque(maxlen=keep)
        self.rejects: Counter[str] = Counter()
        self.frames = 0

    def set_camera_info(self, width: int, height: int, k: Any, d: Any = None) -> None:
        """Update the intrinsics from CameraInfo fields (bad ones are counted and ignored)."""
        try:
            self.camera = CameraModel.from_camera_info(width, height, k, d, self.T, self.name,
                                                       self.name + "_color_optical_frame")
        except CameraModelError:
            self.rejects["bad camera_info"] += 1

    def add_color(self, stamp: float, height: int, width: int, encoding: str, is_bigendian: int, step: int,
                  data: Any) -> RGBDFrame | None:
        try:
            rgb = np.ascontiguousarray(to_rgb(image_to_numpy(height, width, encoding, is_bigendian, step, data),
                                              encoding))
        except ImageConversionError:
            self.rejects["bad colour image"] += 1
            return None
        self._color.append((stamp, rgb))
        return self._match()

    def add_depth(self, stamp: float, height: int, width: int, encoding: str, is_bigendian: int, step: int,
                  data: Any) -> RGBDFrame | None:
        try:
            depth = depth_to_meters(image_to_numpy(height, width, encoding, is_bigendian, step, data), encoding)
        except ImageConversionError:
            self.rejects["bad depth image"] += 1
            return None
        if not np.any(np.isfinite(depth)):
            self.rejects["empty depth"] += 1
            return None
        self._depth.append((stamp, depth))
        return self._match()

    def _match(self) -> RGBDFrame | None:
        for i, (tc, rgb) in enumerate(self._color):
            for j, (td, depth) in enumerate(self._depth):
                if abs(tc - td) <= self.tolerance:
                    del self._color[i]
                    del self._depth[j]
                    return self._emit(tc, rgb, depth)
        return None

    def _emit(self, stamp: float, rgb: np.ndarray, depth: np.ndarray) -> RGBDFrame | None:
        if self.camera is None:
            self.rejects["no camera_info"] += 1
            return None
        if rgb.shape[:2] != depth.shape:
            self.rejects["colour/depth size mismatch"] += 1
            return None
        if depth.shape != (self.camera.height, self.camera.width):
            self.rejects["frame/camera_info size mismatch"] += 1
            return None
        self.frames += 1
        return RGBDFrame(stamp, rgb, depth, self.camera)


class PoseBuffer:
    """Plate poses (4x4 in base) by stamp, looked up at a camera frame's stamp.

    The live graph's pose node lags the cameras (0.3 s median, > 1 s under load on two cores): the pose of a frame
    arrives well after the frame. Drawing the robot mask from the newest pose available *at that moment* puts the
    links where they were earlier, and the uncovered robot pixels become a phantom object touching a link. So a
    frame is evaluated only once the buffer `covers` its stamp (a pose at or after it has arrived); `at` then
    interpolates between the two poses around the stamp (position linearly, rotation along the geodesic).

    Args:
        keep: how many poses to keep.
    """

    def __init__(self, keep: int = 400) -> None:
        self._poses: deque[tuple[float, np.ndarray]] = deque(maxlen=keep)

    def __len__(self) -> int:
        return len(self._poses)

    def add(self, stamp: float, T: np.ndarray) -> None:
        """Store a pose; out-of-order stamps are inserted in order."""
        T = np.asarray(T, float)
        if self._poses and stamp < self._poses[-1][0]:
            items = sorted([*self._poses, (stamp, T)], key=lambda p: p[0])
            self._poses.clear()
            self._poses.extend(items)
        else:
            self._poses.append((stamp, T))

    @property
    def latest(self) -> float | None:
        """Stamp of the newest pose, or None."""
        return self._poses[-1][0] if self._poses else None

    def covers(self, stamp: float, tolerance: float = 1e-3) -> bool:
        """True when a pose at or after `stamp` (less `tolerance` s) has arrived."""
        return bool(self._poses) and self._poses[-1][0] >= stamp - tolerance

    def at(self, stamp: float, max_gap: float) -> np.ndarray | None:
        """The pose at `stamp`: interpolated between the poses around it when they are at most `max_gap` s apart,
        else the nearest pose when it is within `max_gap` s, else None."""
        if not self._poses:
            return None
        stamps = np.fromiter((p[0] for p in self._poses), float, len(self._poses))
        k = int(np.searchsorted(stamps, stamp))
        if 0 < k < len(stamps) and stamps[k] - stamps[k - 1] <= max_gap:
            t0, T0 = self._poses[k - 1]
            t1, T1 = self._poses[k]
            s = 0.0 if t1 - t0 <= 1e-12 else (stamp - t0) / (t1 - t0)
            return interpolate_pose(T0, T1, s)
        j = int(np.argmin(np.abs(stamps - stamp)))
        if abs(stamps[j] - stamp) <= max_gap:
            return self._poses[j][1].copy()
        return None


def interpolate_pose(T0: np.ndarray, T1: np.ndarray, s: float) -> np.ndarray:
    """Pose a fraction s ∈ [0, 1] of the way from T0 to T1: position linear, rotation R0·exp(s·log(R0ᵀR1))."""
    from scipy.spatial.transform import Rotation

    s = float(np.clip(s, 0.0, 1.0))
    out = np.eye(4)
    r01 = Rotation.from_matrix(T0[:3, :3].T @ T1[:3, :3]).as_rotvec()
    out[:3, :3] = T0[:3, :3] @ Rotation.from_rotvec(s * r01).as_matrix()
    out[:3, 3] = (1 - s) * T0[:3, 3] + s * T1[:3, 3]
    return out
