"""hexa-view: serves the running graph to Foxglove over WebSocket (foxglove-sdk), the layout in config/.

Channels (Foxglove topic names are the ROS names): `<ns>/cam_{top,side}/color/image_raw/compressed`
(foxglove.CompressedImage, JPEG, at most `image_rate_hz` per camera), `/tf` (foxglove.FrameTransforms: the ROS /tf
and /tf_static when tf2_msgs is installed, and `base`→`plate` from `plate_pose`, `base`→`plate_estimate` from
`plate_pose_estimate`), `<ns>/markers` and `<ns>/contact_markers` (foxglove.SceneUpdate from the MarkerArrays'
arrows and spheres), and the hexa messages as JSON, field by field as in ROS: `residual` (with its thresholds),
`collision`, `contact`, `contact_wrench`, `external_wrench`, `singularity`, `/diagnostics`.
Parameters: `port` (8765; 0 = any free port, printed), `host` ("127.0.0.1"; "0.0.0.0" to serve the network),
`image_rate_hz` (10), `jpeg_quality` (80). Images are only encoded while a client is subscribed.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

import hexa_ros.node
from hexa_bringup.foxglove_messages import frame_transforms, json_payload, ns_time, scene_from_markers
from hexa_bringup.msgutil import get_message_class
from hexa_ros import diagnostics, qos
from hexa_ros.cdr import CdrError, image_from_cdr

LAYOUT = Path(__file__).resolve().parent / "config" / "foxglove_layout.json"
CAMERAS = ("cam_top", "cam_side")
#: relative topic → ROS type, forwarded as JSON
JSON_TOPICS = {"residual": "hexa_msgs/msg/Residual", "collision": "hexa_msgs/msg/CollisionEvent",
               "contact": "hexa_msgs/msg/Contact", "contact_wrench": "hexa_msgs/msg/ContactWrench",
               "external_wrench": "geometry_msgs/msg/WrenchStamped",
               "singularity": "hexa_msgs/msg/SingularityIndices", "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}
MARKER_TOPICS = ("markers", "contact_markers")
POSE_FRAMES = {"plate_pose": "plate", "plate_pose_estimate": "plate_estimate"}


class ViewNode(Node):
    """ROS subscriptions → foxglove-sdk channels on one WebSocket server."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("view", **kwargs)
        try:
            import foxglove
        except ImportError as exc:
            raise ValueError("needs foxglove-sdk: pip install -r requirements/core.txt") from exc
        from foxglove.channels import CompressedImageChannel, FrameTransformsChannel, SceneUpdateChannel
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import Image
        from visualization_msgs.msg import MarkerArray

        def param(name: str, default: Any, text: str) -> Any:
            return self.declare_parameter(name, default, ParameterDescriptor(description=text, read_only=True)).value

        port = int(param("port", 8765, "WebSocket port (0: any free port, printed at start)"))
        host = str(param("host", "127.0.0.1", "address to serve on (0.0.0.0: every interface)"))
        self.image_period = 1.0 / max(float(param("image_rate_hz", 10.0, "JPEG frames per camera per second")), 1e-3)
        self.jpeg_quality = int(param("jpeg_quality", 80, "JPEG quality 1-100"))
        if not 0 <= port <= 65535:
            raise ValueError(f"port must be 0..65535, got {port}")
        self.server = foxglove.start_server(name="hexa", host=host, port=port)
        self.get_logger().info(f"Foxglove WebSocket on ws://{host}:{self.server.port} (layout: {LAYOUT})")
        print(f"hexa view: ws://{host}:{self.server.port}", flush=True)
        ns = self.get_namespace().rstrip("/")
        self.counters = {"forwarded": 0, "rejected_images_malformed": 0, "rejected_images_encoding": 0}
        self._last_image: dict[str, float] = {}
        self.tf = FrameTransformsChannel("/tf")
        for cam in CAMERAS:
            ch = CompressedImageChannel(f"{ns}/{cam}/color/image_raw/compressed")
            self.create_subscription(Image, f"{cam}/color/image_raw",
                                     lambda b, cam=cam, ch=ch: self._on_image(cam, ch, b), qos.SENSOR, raw=True)
        for topic, type_name in JSON_TOPICS.items():
            ch = foxglove.Channel(topic if topic.startswith("/") else f"{ns}/{topic}", message_encoding="json")
            self.create_subscription(get_message_class(type_name), topic,
                                     lambda m, ch=ch: self._log(ch, m), qos.EVENT)
        for topic in MARKER_TOPICS:
            ch = SceneUpdateChannel(f"{ns}/{topic}")
            self.create_subscription(MarkerArray, topic, lambda m, ch=ch: self._markers(ch, m), qos.RELIABLE)
        for topic, child in POSE_FRAMES.items():
            self.create_subscription(PoseStamped, topic, lambda m, child=child: self._on_pose(child, m), qos.RELIABLE)
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            self.get_logger().info("tf2_msgs not installed: /tf carries the plate poses only")
        else:
            self.create_subscription(TFMessage, "/tf", self._on_tf, qos.RELIABLE)
            self.create_subscription(TFMessage, "/tf_static", self._on_tf, qos.LATCHED)
        self.pub_diag = self.create_publisher(diagnostics.DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.create_timer(1.0, self._diagnostics)

    def _diagnostics(self) -> None:
        st = diagnostics.counter_status(f"{self.get_fully_qualified_name()}: Foxglove view", self.counters,
                                        f"serving on port {self.server.port}")
        self.pub_diag.publish(diagnostics.array(self, [st]))

    def _log(self, ch: Any, msg: Any) -> None:
        if ch.has_sinks():
            header = getattr(msg, "header", None)
            when = {"log_time": ns_time(header.stamp)} if header is not None else {}
            ch.log(json_payload(msg), **when)
            self.counters["forwarded"] += 1

    def _on_image(self, cam: str, ch: Any, buf: bytes) -> None:
        import cv2
        from foxglove.messages import CompressedImage, Timestamp

        from hexa.vision.images import ImageConversionError, image_to_numpy, to_rgb

        if not ch.has_sinks():
            return
        try:
            f = image_from_cdr(buf)
        except CdrError:
            self.counters["rejected_images_malformed"] += 1
            return
        if f.stamp - self._last_image.get(cam, -1e9) < self.image_period:
            return
        try:
            rgb = to_rgb(image_to_numpy(f.height, f.width, f.encoding, f.is_bigendian, f.step, f.data), f.encoding)
        except ImageConversionError:
            self.counters["rejected_images_encoding"] += 1
            return
        self._last_image[cam] = f.stamp
        ok, jpg = cv2.imencode(".jpg", np.ascontiguousarray(rgb[:, :, ::-1]),
                               [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
        ch.log(CompressedImage(timestamp=Timestamp(sec=f.stamp_sec, nsec=f.stamp_nanosec), frame_id=f.frame_id,
                               data=jpg.tobytes(), format="jpeg"), log_time=int(round(f.stamp * 1e9)))
        self.counters["forwarded"] += 1

    def _markers(self, ch: Any, msg: Any) -> None:
        if ch.has_sinks() and msg.markers:
            ch.log(scene_from_markers(msg), log_time=ns_time(msg.markers[0].header.stamp))

    def _transforms(self, items: list[tuple[Any, str, str, Any, Any]]) -> None:
        if self.tf.has_sinks() and items:
            self.tf.log(frame_transforms(items), log_time=ns_time(items[0][0]))

    def _on_pose(self, child: str, msg: Any) -> None:
        self._transforms([(msg.header.stamp, msg.header.frame_id or "base", child, msg.pose.position,
                           msg.pose.orientation)])

    def _on_tf(self, msg: Any) -> None:
        self._transforms([(t.header.stamp, t.header.frame_id, t.child_frame_id, t.transform.translation,
                           t.transform.rotation) for t in msg.transforms])

    def close(self) -> None:
        self.server.stop()


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(ViewNode, "view", argv)


if __name__ == "__main__":
    sys.exit(main())
