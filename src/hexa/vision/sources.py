"""RGB-D camera sources without ROS: PNG-folder pairs, a rosbag2 of camera topics, an Intel RealSense (pyrealsense2).

Each source yields what one RGB-D camera in the realsense-ros layout publishes: RGB uint8 colour and aligned depth
as uint16 millimetres (0 = invalid), with the camera's intrinsics.
"""
from __future__ import annotations

import threading
from typing import Any
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from hexa.vision.camera import CameraModel

#: the camera topics of a camera `c` (relative), as realsense-ros names them
TOPICS = ("color/image_raw", "color/camera_info", "aligned_depth_to_color/image_raw")


class SourceError(ValueError):
    """A camera source cannot start (missing folder, bag or library); the message says what to do."""


def folder_pairs(path: str | Path) -> list[tuple[Path, Path]]:
    """Sorted (colour, depth) PNG pairs of a folder (color_<n>.png + depth_<n>.png).

    Raises:
        SourceError: the folder is missing or holds no pair.
    """
    p = Path(path)
    if not p.is_dir():
        raise SourceError(f"folder {p} does not exist")
    pairs = []
    for c in sorted(p.glob("color_*.png")):
        d = c.with_name("depth_" + c.name[len("color_"):])
        if d.exists():
            pairs.append((c, d))
    if not pairs:
        raise SourceError(f"folder {p} holds no color_<n>.png / depth_<n>.png pair")
    return pairs


def read_pair(color: Path, depth: Path) -> tuple[np.ndarray, np.ndarray]:
    """RGB uint8 and depth uint16 (mm) from a PNG pair.

    Raises:
        SourceError: a file cannot be read, or the depth PNG is not 16-bit.
    """
    import cv2

    bgr = cv2.imread(str(color), cv2.IMREAD_COLOR)
    dep = cv2.imread(str(depth), cv2.IMREAD_UNCHANGED)
    if bgr is None or dep is None:
        raise SourceError(f"cannot read {color} / {depth}")
    if dep.dtype != np.uint16:
        raise SourceError(f"{depth} must be a 16-bit PNG (mm), got {dep.dtype}")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dep


class FolderSource:
    """The PNG pairs of a folder in order, from the start again when `loop`.

    Decoding a VGA colour + 16-bit depth PNG pair costs ≈ 10 ms of CPU, a third of a core at 30 fps; a looped
    folder keeps the decoded pairs (read-only arrays) up to `cache_bytes` and serves later cycles from memory.

    The intrinsics come from the folder's camera_info.yaml (width, height, k[9], optional d) or, without it, from
    `fallback()` (e.g. the robot description's camera).

    Raises:
        SourceError: the folder is missing or empty, or no intrinsics are found.
    """

    def __init__(self, path: str | Path, name: str, loop: bool = True,
                 fallback: Callable[[], CameraModel] | None = None, cache_bytes: int = 512 << 20) -> None:
        self.path = Path(path)
        self.pairs = folder_pairs(self.path)
        self.loop = loop
        self.index = 0
        self.cache_bytes = int(cache_bytes) if loop else 0
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._cached_bytes = 0
        info = self.path / "camera_info.yaml"
        if info.exists():
            import yaml

            d = yaml.safe_load(info.read_text())
            self.model = CameraModel.from_camera_info(d["width"], d["height"], d["k"], d.get("d"), name=name)
            return
        try:
            if fallback is None:
                raise SourceError("no fallback intrinsics given")
            self.model = fallback()
        except Exception as exc:
            raise SourceError(f"no camera_info.yaml in {self.path} and no intrinsics for {name} in the robot "
                              f"description ({exc})") from exc

    def next(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The next (rgb, depth mm) pair, or None once the folder is played (without `loop`).

        Raises:
            SourceError: the pair cannot be read (it is skipped; the next call reads the following one).
        """
        if self.index >= len(self.pairs):
            if not self.loop:
                return None
            self.index = 0
        i = self.index
        self.index += 1
        pair = self._cache.get(i)
        if pair is None:
            pair = read_pair(*self.pairs[i])
            size = pair[0].nbytes + pair[1].nbytes
            if self._cached_bytes + size <= self.cache_bytes:
                for a in pair:
                    a.flags.writeable = False
                self._cache[i] = pair
                self._cached_bytes += size
        return pair


class BagSource:
    """The colour, depth and camera_info messages of one camera from a rosbag2, as recorded (CDR), at `rate` times
    the recorded pace, from the start again when `loop`; `stop()` ends the iteration.

    Raises:
        SourceError: the bag does not exist.
    """

    def __init__(self, path: str | Path, camera: str, rate: float = 1.0, loop: bool = True) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise SourceError(f"bag {self.path} does not exist")
        self.suffixes = tuple(f"{camera}/{t}" for t in TOPICS)
        self.rate = rate if rate > 0 else 1.0
        self.loop = loop
        self._stop = threading.Event()

    def stop(self) -> None:
        self._stop.set()

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def messages(self) -> Iterator[tuple[str, str, bytes]]:
        """(topic suffix as in TOPICS after `<camera>/`, msgtype, cdr) of the camera's messages.

        Raises:
            hexa.bags.BagError: the bag is unreadable.
        """
        from hexa.bags import paced, read_bag

        while not self._stop.is_set():
            for topic, msgtype, _t, cdr in paced(read_bag(self.path), self.rate):
                if self._stop.is_set():
                    return
                key = next((k for k in self.suffixes if topic.endswith(k)), None)
                if key is not None:
                    yield key.split("/", 1)[1], msgtype, cdr
            if not self.loop:
                return


def depth_to_mm(depth: np.ndarray, scale_mm: float) -> np.ndarray:
    """uint16 millimetres of raw depth units times `scale_mm` (mm per unit), rounded and clipped to 0..65535."""
    d = np.asarray(depth).astype(np.float32) * scale_mm
    return np.clip(np.rint(d), 0, 65535).astype(np.uint16)


def realsense_camera_info_fields(intr) -> dict:
    """sensor_msgs/CameraInfo fields of a pyrealsense2 intrinsics as realsense-ros fills them (base_realsense_node:
    K and P from fx, fy, ppx, ppy; R identity; "equidistant" with 4 coefficients for Kannala-Brandt, else "plumb_bob"
    with 5). The aligned depth's camera_info is the colour stream's: depth is resampled onto the colour image."""
    k = [intr.fx, 0.0, intr.ppx, 0.0, intr.fy, intr.ppy, 0.0, 0.0, 1.0]
    p = [intr.fx, 0.0, intr.ppx, 0.0, 0.0, intr.fy, intr.ppy, 0.0, 0.0, 0.0, 1.0, 0.0]
    kb4 = "kannala" in str(intr.model).lower()
    n = 4 if kb4 else 5
    return {"width": int(intr.width), "height": int(intr.height),
            "distortion_model": "equidistant" if kb4 else "plumb_bob", "d": [float(c) for c in list(intr.coeffs)[:n]],
            "k": [float(v) for v in k], "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], "p": [float(v) for v in p]}


class RealSenseSource:
    """An Intel RealSense (pyrealsense2): colour (rgb8) and depth (z16) at `width`x`height`, `fps`, depth aligned to
    colour with rs.align as realsense-ros' `align_depth` does; or a librealsense recording (`playback`, .db3/.bag).

    A camera that is absent (or pyrealsense2 missing) does not raise: `poll()` retries every `retry_period` seconds
    and `status` says what is missing, naming the serial number, until the device streams.

    Args:
        name: camera name (for the model).
        serial: device serial number as a string ("" = the first device; leading zeros matter).
        playback: a librealsense recording to play instead of a device (once, or looping with `loop`).
    """

    def __init__(self, name: str, serial: str = "", width: int = 640, height: int = 480, fps: int = 30,
                 playback: str = "", loop: bool = False, retry_period: float = 2.0,
                 clock: Callable[[], float] | None = None) -> None:
        import time

        self.name, self.serial, self.playback, self.loop = name, str(serial), str(playback), bool(loop)
        self.size, self.fps, self.retry_period = (int(width), int(height)), int(fps), float(retry_period)
        self._clock = clock or time.monotonic
        # rs.pipeline while streaming; Any, not Optional: `poll` uses it after `_open` set it, which mypy cannot see
        self._pipe: Any = None
        self._next_try = 0.0
        self.model: CameraModel | None = None
        self.info_fields: dict | None = None
        self.attempts = 0
        self.frames = 0
        self.device = ""
        self.status = f"RealSense {self.serial or '(first device)'}: not opened yet"

    @property
    def connected(self) -> bool:
        return self._pipe is not None

    def _open(self) -> None:
        try:
            import pyrealsense2 as rs
        except ImportError as exc:
            raise SourceError(f"RealSense {self.serial or '(first device)'}: source 'realsense' needs the optional "
                              "pyrealsense2 package (make setup-robot, or pip install -r requirements/robot.txt)"
                              ) from exc
        cfg = rs.config()
        if self.playback:
            if not Path(self.playback).is_file():
                raise SourceError(f"RealSense recording {self.playback} does not exist")
            cfg.enable_device_from_file(self.playback, repeat_playback=self.loop)
        else:
            serials = [d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()]
            if self.serial and self.serial not in serials:
                raise SourceError(f"RealSense {self.serial} not found (connected: {', '.join(serials) or 'none'})")
            if not serials:
                raise SourceError("no RealSense connected")
            if self.serial:
                cfg.enable_device(self.serial)
            w, h = self.size
            cfg.enable_stream(rs.stream.color, w, h, rs.format.rgb8, self.fps)
            cfg.enable_stream(rs.stream.depth, w, h, rs.format.z16, self.fps)
        pipe = rs.pipeline()
        try:
            profile = pipe.start(cfg)
        except RuntimeError as exc:
            raise SourceError(f"RealSense {self.serial or self.playback or '(first device)'}: {exc}") from exc
        self._align = rs.align(rs.stream.color)
        intr = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
        self.info_fields = realsense_camera_info_fields(intr)
        K = np.array(self.info_fields["k"]).reshape(3, 3)
        self.model = CameraModel(K, intr.width, intr.height, name=self.name)
        dev = profile.get_device()
        self.device = dev.get_info(rs.camera_info.serial_number)
        self._depth_scale_mm = dev.first_depth_sensor().get_depth_scale() * 1000.0
        self._pipe = pipe

    def poll(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The newest (rgb, depth mm aligned to colour) pair, or None when no new frame set has arrived or the device
        is not (yet) there; an absent device is retried every `retry_period` s."""
        if self._pipe is None:
            now = self._clock()
            if now < self._next_try:
                return None
            self._next_try = now + self.retry_period
            self.attempts += 1
            try:
                self._open()
            except SourceError as exc:
                self.status = f"{exc}; retrying every {self.retry_period:g} s"
                return None
            self.status = f"RealSense {self.device} streaming"
        try:
            frames = self._pipe.poll_for_frames()
        except RuntimeError as exc:     # unplugged while streaming: close and retry
            self.stop()
            self.status = f"RealSense {self.device or self.serial}: {exc}; retrying every {self.retry_period:g} s"
            return None
        if not frames:
            return None
        frames = self._align.process(frames)
        color, depth = frames.get_color_frame(), frames.get_depth_frame()
        if not color or not depth:
            return None
        self.frames += 1
        rgb = np.asanyarray(color.get_data())
        return rgb, depth_to_mm(np.asanyarray(depth.get_data()), self._depth_scale_mm)

    def stop(self) -> None:
        if self._pipe is not None:
            try:
                self._pipe.stop()
            except RuntimeError:
                pass
            self._pipe = None
