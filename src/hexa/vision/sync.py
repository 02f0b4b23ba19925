"""Pairing of colour, depth and camera_info by stamp (no message_filters here), with reject counters; decoding on
demand (`ImagePairer` pairs undecoded images, `FrameAssembler.assemble` decodes a pair when it is needed)."""
from __future__ import annotations

from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation  # imported with the module, not in the first collision

from hexa.vision.camera import CameraModel, CameraModelError
from hexa.vision.images import ImageConversionError, ImageData, depth_to_meters, image_to_numpy, to_rgb


@dataclass
class RGBDFrame:
    """An aligned colour/depth pair of one camera: RGB uint8, depth in m (NaN invalid), stamp (s), camera model."""

    stamp: float
    rgb: np.ndarray
    depth: np.ndarray
    camera: CameraModel


@dataclass(frozen=True)
class RawImage:
    """The fields of a sensor_msgs/Image, not decoded: stamp (s) and `data` as any buffer (a zero-copy numpy view of
    the message's data keeps the message's memory alive and copies nothing)."""

    stamp: float
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: ImageData


@dataclass(frozen=True)
class RawFrame:
    """A colour and a depth image of one camera with matching stamps, not decoded (`FrameAssembler.assemble`)."""

    stamp: float
    color: RawImage
    depth: RawImage


class ImagePairer:
    """Pairs the colour and depth images of one camera by stamp without decoding them.

    Args:
        tolerance: largest colour/depth stamp difference (s) to pair.
        keep: how many unpaired images of each kind to keep.
    """

    def __init__(self, tolerance: float = 0.005, keep: int = 5) -> None:
        self.tolerance = tolerance
        self._color: deque[RawImage] = deque(maxlen=keep)
        self._depth: deque[RawImage] = deque(maxlen=keep)
        self.frames = 0

    def add(self, image: RawImage, color: bool) -> RawFrame | None:
        """Store a colour (`color` True) or depth image; the pair it completes, or None."""
        mine, other = (self._color, self._depth) if color else (self._depth, self._color)
        for j, partner in enumerate(other):
            if abs(partner.stamp - image.stamp) <= self.tolerance:
                del other[j]
                self.frames += 1
                c, d = (image, partner) if color else (partner, image)
                return RawFrame(c.stamp, c, d)
        mine.append(image)
        return None


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
        self._info: tuple = ()
        self._color: deque[tuple[float, np.ndarray]] = deque(maxlen=keep)
        self._depth: deque[tuple[float, np.ndarray]] = deque(maxlen=keep)
        self.rejects: Counter[str] = Counter()
        self.frames = 0
        self._waiting: tuple[float, np.ndarray, np.ndarray] | None = None   # a pair that came before camera_info

    def set_camera_info(self, width: int, height: int, k: Sequence[float] | np.ndarray,
                        d: Sequence[float] | np.ndarray | None = None) -> RGBDFrame | None:
        """Update the intrinsics from CameraInfo fields (bad ones are counted and ignored; a repeat of the current
        ones costs a comparison). Returns the frame that was paired before the first camera_info arrived (a
        camera publishes a frame's images before its camera_info), now that it can be used, else None."""
        key = (int(width), int(height), tuple(k), tuple(d) if d is not None else ())
        if self.camera is not None and key == self._info:
            return None
        try:
            self.camera = CameraModel.from_camera_info(width, height, k, d, self.T, self.name,
                                                       self.name + "_color_optical_frame")
            self._info = key
        except CameraModelError:
            self.rejects["bad camera_info"] += 1
            return None
        waiting, self._waiting = self._waiting, None
        return None if waiting is None else self._emit(*waiting)

    def add_color(self, stamp: float, height: int, width: int, encoding: str, is_bigendian: int, step: int,
                  data: ImageData) -> RGBDFrame | None:
        rgb = self._rgb(height, width, encoding, is_bigendian, step, data)
        if rgb is None:
            return None
        self._keep(self._color, (stamp, rgb), "unpaired colour image")
        return self._match()

    def add_depth(self, stamp: float, height: int, width: int, encoding: str, is_bigendian: int, step: int,
                  data: ImageData) -> RGBDFrame | None:
        depth = self._depth_m(height, width, encoding, is_bigendian, step, data)
        if depth is None:
            return None
        self._keep(self._depth, (stamp, depth), "unpaired depth image")
        return self._match()

    def _keep(self, queue: deque, item: tuple[float, np.ndarray], reason: str) -> None:
        """Queue an image for pairing; the oldest one, whose partner never came, is dropped and counted."""
        if len(queue) == queue.maxlen:
            self.rejects[reason] += 1
        queue.append(item)

    def assemble(self, raw: RawFrame) -> RGBDFrame | None:
        """Decode a paired colour/depth frame (bad input is counted in `rejects` like `add_color`/`add_depth`;
        without camera_info nothing is decoded)."""
        if self.camera is None:
            self.rejects["no camera_info"] += 1
            return None
        c, d = raw.color, raw.depth
        rgb = self._rgb(c.height, c.width, c.encoding, c.is_bigendian, c.step, c.data)
        depth = self._depth_m(d.height, d.width, d.encoding, d.is_bigendian, d.step, d.data)
        if rgb is None or depth is None:
            return None
        return self._emit(raw.stamp, rgb, depth)

    def _rgb(self, height: int, width: int, encoding: str, is_bigendian: int, step: int, data: ImageData
             ) -> np.ndarray | None:
        try:
            return np.ascontiguousarray(to_rgb(image_to_numpy(height, width, encoding, is_bigendian, step, data),
                                               encoding))
        except ImageConversionError:
            self.rejects["bad colour image"] += 1
            return None

    def _depth_m(self, height: int, width: int, encoding: str, is_bigendian: int, step: int, data: ImageData
                 ) -> np.ndarray | None:
        try:
            depth = depth_to_meters(image_to_numpy(height, width, encoding, is_bigendian, step, data), encoding)
        except ImageConversionError:
            self.rejects["bad depth image"] += 1
            return None
        if not np.any(np.isfinite(depth)):
            self.rejects["empty depth"] += 1
            return None
        return depth

    def _match(self) -> RGBDFrame | None:
        for i, (tc, rgb) in enumerate(self._color):
            for j, (td, depth) in enumerate(self._depth):
                if abs(tc - td) <= self.tolerance:
                    del self._color[i]
                    del self._depth[j]
                    if self.camera is None:      # held for set_camera_info; an older held pair is lost
                        if self._waiting is not None:
                            self.rejects["no camera_info"] += 1
                        self._waiting = (tc, rgb, depth)
                        return None
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

    def before(self, stamp: float) -> tuple[float, np.ndarray] | None:
        """The newest pose at or before `stamp` as (stamp, 4x4), or None."""
        for t, T in reversed(self._poses):
            if t <= stamp:
                return t, T
        return None

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
    s = float(np.clip(s, 0.0, 1.0))
    out = np.eye(4)
    r01 = Rotation.from_matrix(T0[:3, :3].T @ T1[:3, :3]).as_rotvec()
    out[:3, :3] = T0[:3, :3] @ Rotation.from_rotvec(s * r01).as_matrix()
    out[:3, 3] = (1 - s) * T0[:3, 3] + s * T1[:3, 3]
    return out
