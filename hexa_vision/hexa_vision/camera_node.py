"""hexa-camera: publishes one RGB-D camera in the realsense-ros layout from a PNG folder, a bag, or a RealSense.

Topics (relative to the node namespace, e.g. /hexa): `<camera>/color/image_raw` (rgb8), `<camera>/color/camera_info`,
`<camera>/aligned_depth_to_color/image_raw` (16UC1 mm, 0 invalid), frame `<camera>_color_optical_frame`;
sensor-data QoS. The simulator publishes the same topics itself (no camera node needed in sim mode).

Parameters: source ("folder" | "bag" | "realsense"), camera ("cam_top"), path (folder or bag), rate (Hz for folder;
playback speed factor for bag), loop (bool), robot_description (YAML path; intrinsics for folder sources).
Folder layout: color_<n>.png (8-bit RGB) + depth_<n>.png (16-bit, mm) pairs, sorted by <n>; optional
camera_info.yaml (width, height, k[9]) overrides the description's intrinsics.
"""
from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import rclpy
import yaml
from hexa_bringup.rosenv import apply_defaults
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

from hexa.vision.camera import CameraModel
from hexa_vision.common import SENSOR_QOS, camera_info_msg, description_cameras, image_msg


class SourceError(RuntimeError):
    """A camera source cannot start (missing folder/bag/library); the message says what to do."""


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
    """RGB uint8 and depth uint16 (mm) from a PNG pair."""
    bgr = cv2.imread(str(color), cv2.IMREAD_COLOR)
    dep = cv2.imread(str(depth), cv2.IMREAD_UNCHANGED)
    if bgr is None or dep is None:
        raise SourceError(f"cannot read {color} / {depth}")
    if dep.dtype != np.uint16:
        raise SourceError(f"{depth} must be a 16-bit PNG (mm), got {dep.dtype}")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dep


class CameraNode(Node):
    def __init__(self) -> None:
        super().__init__("hexa_camera")
        self.source = self.declare_parameter("source", "folder").value
        self.cam_name = self.declare_parameter("camera", "cam_top").value
        self.path = self.declare_parameter("path", "").value
        self.rate = float(self.declare_parameter("rate", 15.0).value)
        self.loop = bool(self.declare_parameter("loop", True).value)
        self.serial = str(self.declare_parameter("serial", "").value)  # RealSense serial number ("" = first device)
        desc_path = self.declare_parameter("robot_description", "").value
        self.frame = f"{self.cam_name}_color_optical_frame"
        c = self.cam_name
        self.pub_color = self.create_publisher(Image, f"{c}/color/image_raw", SENSOR_QOS)
        self.pub_info = self.create_publisher(CameraInfo, f"{c}/color/camera_info", SENSOR_QOS)
        self.pub_depth = self.create_publisher(Image, f"{c}/aligned_depth_to_color/image_raw", SENSOR_QOS)
        self.published = 0
        if self.source == "folder":
            self.pairs = folder_pairs(self.path)
            self.model = self._folder_model(desc_path)
            self.index = 0
            self.create_timer(1.0 / max(self.rate, 1e-3), self._tick_folder)
        elif self.source == "bag":
            self._start_bag()
        elif self.source == "realsense":
            self._start_realsense()
        else:
            raise SourceError(f"unknown source {self.source!r}; use folder, bag or realsense")

    # ------------------------------------------------------------------ folder
    def _folder_model(self, desc_path: str) -> CameraModel:
        info = Path(self.path) / "camera_info.yaml"
        if info.exists():
            d = yaml.safe_load(info.read_text())
            return CameraModel.from_camera_info(d["width"], d["height"], d["k"], d.get("d"), name=self.cam_name)
        try:
            return description_cameras(desc_path)[self.cam_name]
        except Exception as exc:
            raise SourceError(f"no camera_info.yaml in {self.path} and no intrinsics for {self.cam_name} in the "
                              f"robot description ({exc})") from exc

    def _publish(self, rgb: np.ndarray, depth_mm: np.ndarray, model: CameraModel) -> None:
        stamp = self.get_clock().now().to_msg()
        self.pub_color.publish(image_msg(rgb, "rgb8", self.frame, stamp))
        self.pub_depth.publish(image_msg(depth_mm, "16UC1", self.frame, stamp))
        self.pub_info.publish(camera_info_msg(model, self.frame, stamp))
        self.published += 1

    def _tick_folder(self) -> None:
        if self.index >= len(self.pairs):
            if not self.loop:
                return
            self.index = 0
        c, d = self.pairs[self.index]
        self.index += 1
        try:
            rgb, dep = read_pair(c, d)
        except SourceError as exc:
            self.get_logger().warning(str(exc))
            return
        self._publish(rgb, dep, self.model)

    # ------------------------------------------------------------------ bag
    def _start_bag(self) -> None:
        import threading

        from hexa_bringup.bag import read_bag

        if not Path(self.path).exists():
            raise SourceError(f"bag {self.path} does not exist")
        c = self.cam_name
        self._bag_topics = {f"{c}/color/image_raw": self.pub_color, f"{c}/color/camera_info": self.pub_info,
                            f"{c}/aligned_depth_to_color/image_raw": self.pub_depth}
        self._reader = read_bag
        threading.Thread(target=self._run_bag, daemon=True).start()

    def _run_bag(self) -> None:
        from hexa_bringup.bag import paced
        from rclpy.serialization import deserialize_message

        while rclpy.ok():
            for topic, msgtype, _, cdr in paced(self._reader(self.path), self.rate if self.rate > 0 else 1.0):
                key = next((k for k in self._bag_topics if topic.endswith(k)), None)
                if key is None:
                    continue
                cls = Image if msgtype.endswith("/Image") else CameraInfo
                self._bag_topics[key].publish(deserialize_message(cdr, cls))
                self.published += 1
            if not self.loop:
                break

    # ------------------------------------------------------------------ RealSense
    def _start_realsense(self) -> None:
        try:
            import pyrealsense2 as rs  # type: ignore[import-not-found]
        except ImportError as exc:
            raise SourceError("source 'realsense' needs the optional pyrealsense2 package (pip install "
                              "pyrealsense2; not installed here) — use source:=folder or source:=bag") from exc
        self._rs = rs
        self._pipe = rs.pipeline()
        cfg = rs.config()
        if self.serial:  # two cameras on one PC: each node opens its own device
            cfg.enable_device(self.serial)
        cfg.enable_stream(rs.stream.color, 640, 480, rs.format.rgb8, 30)
        cfg.enable_stream(rs.stream.depth, 640, 480, rs.format.z16, 30)
        profile = self._pipe.start(cfg)
        self._align = rs.align(rs.stream.color)
        intr = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
        K = np.array([[intr.fx, 0, intr.ppx], [0, intr.fy, intr.ppy], [0, 0, 1.0]])
        self.model = CameraModel(K, intr.width, intr.height, name=self.cam_name)
        self._depth_scale_mm = profile.get_device().first_depth_sensor().get_depth_scale() * 1000.0
        self.create_timer(1.0 / 60.0, self._tick_realsense)

    def _tick_realsense(self) -> None:
        frames = self._pipe.poll_for_frames()
        if not frames:
            return
        frames = self._align.process(frames)
        color, depth = frames.get_color_frame(), frames.get_depth_frame()
        if not color or not depth:
            return
        rgb = np.asanyarray(color.get_data())
        dep = np.asanyarray(depth.get_data()).astype(np.float32) * self._depth_scale_mm
        self._publish(rgb, np.clip(np.rint(dep), 0, 65535).astype(np.uint16), self.model)


def main(args: list[str] | None = None) -> int:
    apply_defaults()
    rclpy.init(args=args)
    try:
        node = CameraNode()
    except SourceError as exc:
        print(f"hexa-camera: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
