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
