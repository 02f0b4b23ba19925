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

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

import hexa_ros.node
from hexa_bringup.msgutil import get_message_class, message_to_dict
from hexa_ros import diagnostics, qos
from hexa_ros.cdr import CdrError, image_from_cdr
from hexa_ros.stamps import to_sec

LAYOUT = Path(__file__).resolve().parent / "config" / "foxglove_layout.json"
CAMERAS = ("cam_top", "cam_side")
#: relative topic → ROS type, forwarded as JSON
JSON_TOPICS = {"residual": "hexa_msgs/msg/Residual", "collision": "hexa_msgs/msg/CollisionEvent",
               "contact": "hexa_msgs/msg/Contact", "contact_wrench": "hexa_msgs/msg/ContactWrench",
               "external_wrench": "geometry_msgs/msg/WrenchStamped",
               "singularity": "hexa_msgs/msg/SingularityIndices", "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}
MARKER_TOPICS = ("markers", "contact_markers")
POSE_FRAMES = {"plate_pose": "plate", "plate_pose_estimate": "plate_estimate"}


def json_safe(value: Any) -> Any:
    """`value` with every NaN or infinite float as None (JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [json_safe(v) for v in value]
    return value


def _ns_time(stamp: Any) -> int:
    return int(round(to_sec(stamp) * 1e9))


def _ts(stamp: Any) -> Any:
    from foxglove.messages import Timestamp

    return Timestamp(sec=int(stamp.sec), nsec=int(stamp.nanosec))


def _pose(position: Any, orientation: Any) -> Any:
    from foxglove.messages import Pose, Quaternion, Vector3

    return Pose(position=Vector3(x=position.x, y=position.y, z=position.z),
                orientation=Quaternion(x=orientation.x, y=orientation.y, z=orientation.z, w=orientation.w))


def scene_from_markers(msg: Any) -> Any:
    """foxglove.SceneUpdate of a visualization_msgs/MarkerArray's ARROW (two points) and SPHERE markers."""
    from foxglove.messages import (ArrowPrimitive, Color, Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive,
                                   Vector3)

    entities = []
    for m in msg.markers:
        c = Color(r=m.color.r, g=m.color.g, b=m.color.b, a=m.color.a)
        arrows, spheres = [], []
        if m.type == m.ARROW and len(m.points) == 2:
            a, b = (np.array([p.x, p.y, p.z]) for p in m.points)
            d = b - a
            n = float(np.linalg.norm(d))
            if n > 0:      # the arrow's +x turned onto d: the shortest rotation, as a quaternion
                u = d / n
                axis, w = np.cross([1.0, 0.0, 0.0], u), 1.0 + u[0]
                q = np.array([*axis, w]) if w > 1e-9 else np.array([0.0, 0.0, 1.0, 0.0])
                q /= np.linalg.norm(q)
                head = min(m.scale.z, n)
                arrows.append(ArrowPrimitive(
                    pose=Pose(position=Vector3(x=a[0], y=a[1], z=a[2]),
                              orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])),
                    shaft_length=n - head, shaft_diameter=m.scale.x, head_length=head, head_diameter=m.scale.y,
                    color=c))
        elif m.type == m.SPHERE:
            spheres.append(SpherePrimitive(pose=_pose(m.pose.position, m.pose.orientation),
                                           size=Vector3(x=m.scale.x, y=m.scale.y, z=m.scale.z), color=c))
        entities.append(SceneEntity(timestamp=_ts(m.header.stamp), frame_id=m.header.frame_id, id=f"{m.ns}/{m.id}",
                                    arrows=arrows, spheres=spheres))
    return SceneUpdate(entities=entities)


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
            when = {"log_time": _ns_time(header.stamp)} if header is not None else {}
            ch.log(json_safe(message_to_dict(msg)), **when)
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
            ch.log(scene_from_markers(msg), log_time=_ns_time(msg.markers[0].header.stamp))

    def _transforms(self, items: list[tuple[Any, str, str, Any, Any]]) -> None:
        from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Vector3

        if not self.tf.has_sinks() or not items:
            return
        tfs = [FrameTransform(timestamp=_ts(st), parent_frame_id=parent, child_frame_id=child,
                              translation=Vector3(x=t.x, y=t.y, z=t.z), rotation=Quaternion(x=q.x, y=q.y, z=q.z, w=q.w))
               for st, parent, child, t, q in items]
        self.tf.log(FrameTransforms(transforms=tfs), log_time=_ns_time(items[0][0]))

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
