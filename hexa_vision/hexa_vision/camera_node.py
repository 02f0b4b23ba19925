"""hexa-camera: publishes one RGB-D camera in the realsense-ros layout from a PNG folder, a bag, or a RealSense.

Topics (relative to the node namespace, e.g. /hexa): `<camera>/color/image_raw` (rgb8), `<camera>/color/camera_info`,
`<camera>/aligned_depth_to_color/image_raw` (16UC1 mm, 0 invalid) and `<camera>/aligned_depth_to_color/camera_info`
(the colour stream's, as realsense-ros publishes it), frame `<camera>_color_optical_frame`; QoS from `image_qos`
(best_effort as sensor data, or reliable); `/diagnostics` (the source's state: an absent RealSense is named by its
serial and retried). The simulator publishes the same topics itself (no camera node needed in sim mode).
Parameters: PARAMETERS below (start-up only, read-only); with source realsense, `path` names a librealsense
recording (.db3/.bag) played instead of a device.
Folder layout: color_<n>.png (8-bit RGB) + depth_<n>.png (16-bit, mm) pairs, sorted by <n>; optional
camera_info.yaml (width, height, k[9]) overrides the description's intrinsics. The sources are hexa.vision.sources'.
"""
from __future__ import annotations

import sys
import threading

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

import hexa_ros.node
from hexa.vision.camera import CameraModel
from hexa.vision.sources import BagSource, FolderSource, RealSenseSource, SourceError
from hexa_ros import diagnostics, qos
from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param, declare_parameters
from hexa_ros.cdr import image_to_cdr
from hexa_vision.common import camera_info_msg, description_cameras

from hexa import frames

PARAMETERS = {"source": Param("folder", "where the frames come from", choices=("folder", "bag", "realsense")),
              "camera": Param("cam_top", "camera name: topic prefix and frames <camera>_link, ..."),
              "path": Param("", "folder of color_<n>.png + depth_<n>.png (16-bit mm) pairs, or a bag"),
              "rate": Param(15.0, "Hz for a folder; playback speed factor for a bag", range=(0.01, 1000.0)),
              "loop": Param(True, "restart the folder or bag at its end"),
              # dynamic typing: ROS parses `serial:=123456789012` as an integer; a serial is a string of digits
              "serial": Param("", "RealSense serial number; empty = the first device", dynamic_typing=True),
              "image_qos": Param("best_effort", "image and camera_info reliability (realsense-ros <stream>_qos)",
                                 choices=qos.IMAGE_QOS),
              DESCRIPTION: DESCRIPTION_PARAM}


class CameraNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("hexa_camera", **kwargs)
        v = declare_parameters(self, PARAMETERS)
        self.source, self.cam_name, self.path, self.serial = v["source"], v["camera"], v["path"], str(v["serial"] or "")
        self.rate, self.loop, desc_path = float(v["rate"]), bool(v["loop"]), v[DESCRIPTION]
        self.frame = frames.camera_optical_frame(self.cam_name)
        c, image_qos = self.cam_name, qos.image_profile(v["image_qos"])
        self.pub_color = self.create_publisher(Image, f"{c}/color/image_raw", image_qos)
        self.pub_info = self.create_publisher(CameraInfo, f"{c}/color/camera_info", image_qos)
        self.pub_depth = self.create_publisher(Image, f"{c}/aligned_depth_to_color/image_raw", image_qos)
        self.pub_depth_info = self.create_publisher(CameraInfo, f"{c}/aligned_depth_to_color/camera_info", image_qos)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self._said = ""
        self.published = 0
        self._bag: BagSource | None = None
        self._realsense: RealSenseSource | None = None
        if self.source == "folder":
            self._folder = FolderSource(self.path, c, self.loop, lambda: description_cameras(desc_path)[c])
            self.create_timer(1.0 / max(self.rate, 1e-3), self._tick_folder)
        elif self.source == "bag":
            self._bag = BagSource(self.path, c, self.rate, self.loop)
            self._bag_pubs = {"color/image_raw": self.pub_color, "color/camera_info": self.pub_info,
                              "aligned_depth_to_color/image_raw": self.pub_depth,
                              "aligned_depth_to_color/camera_info": self.pub_depth_info}
            threading.Thread(target=self._run_bag, daemon=True).start()
        elif self.source == "realsense":
            self._realsense = RealSenseSource(c, self.serial, playback=self.path, loop=self.loop)
            self.create_timer(1.0 / 60.0, self._tick_realsense)
            self.create_timer(1.0, self._diagnostics)
        else:
            raise SourceError(f"unknown source {self.source!r}; use folder, bag or realsense")

    def _publish(self, rgb: np.ndarray, depth_mm: np.ndarray, model: CameraModel, fields: dict | None = None) -> None:
        stamp = self.get_clock().now().to_msg()
        info = camera_info_msg(model, self.frame, stamp, fields)
        self.pub_color.publish(image_to_cdr(stamp.sec, stamp.nanosec, self.frame, rgb, "rgb8"))   # serialized:
        self.pub_info.publish(info)                                       # one copy of the pixels
        self.pub_depth.publish(image_to_cdr(stamp.sec, stamp.nanosec, self.frame, depth_mm, "16UC1"))
        self.pub_depth_info.publish(info)
        self.published += 1

    def _tick_folder(self) -> None:
        try:
            pair = self._folder.next()
        except SourceError as exc:
            self.get_logger().warning(str(exc))
            return
        if pair is not None:
            self._publish(*pair, self._folder.model)

    def _run_bag(self) -> None:
        try:
            for key, msgtype, cdr in self._bag.messages():
                want = "sensor_msgs/msg/Image" if key.endswith("image_raw") else "sensor_msgs/msg/CameraInfo"
                if msgtype != want:
                    raise SourceError(f"{key} holds {msgtype} in the bag, not {want}")
                self._bag_pubs[key].publish(bytes(cdr))       # the recorded bytes as they are
                self.published += 1
        except Exception as exc:  # noqa: BLE001 - an unreadable bag, or the publishers gone at shutdown
            if not self._bag.stopped:
                self.get_logger().error(f"bag playback ended: {exc}")

    def _tick_realsense(self) -> None:
        rs = self._realsense
        pair = rs.poll()
        if rs.status != self._said:       # each change of state once on the console (absent, streaming, lost)
            (self.get_logger().info if rs.connected else self.get_logger().warning)(f"{self.cam_name}: {rs.status}")
            self._said = rs.status
        if pair is not None:
            self._publish(*pair, rs.model, rs.info_fields)

    def _diagnostics(self) -> None:
        rs = self._realsense
        level = diagnostics.OK if rs.connected else diagnostics.ERROR
        st = diagnostics.status(f"{self.get_fully_qualified_name()}: {self.cam_name} RealSense", level, rs.status,
                                {"serial": self.serial or "(first device)", "attempts": rs.attempts,
                                 "frames": rs.frames, "published": self.published}, hardware_id=self.serial)
        self.pub_diag.publish(diagnostics.array(self, [st]))

    def close(self) -> None:
        if self._bag is not None:
            self._bag.stop()
        if self._realsense is not None:
            self._realsense.stop()


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(CameraNode, "camera", argv)


if __name__ == "__main__":
    sys.exit(main())
