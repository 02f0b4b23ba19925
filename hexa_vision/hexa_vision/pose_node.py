"""hexa-vision-pose: plate detector + coloured markers on the top camera → plate_detections, plate_pose.

Subscribes (sensor-data QoS) `<camera>/color/image_raw`, `<camera>/aligned_depth_to_color/image_raw`,
`<camera>/color/camera_info`; publishes `plate_detections` (hexa_msgs/PlateDetections), `plate_pose`
(geometry_msgs/PoseStamped in `base`), `plate_pose_cov` (PoseWithCovarianceStamped: the same pose with the fit's 6x6
covariance), `/diagnostics` (frames, fits, rejects by reason). Bad input is counted and skipped, never fatal.
Parameters: camera ("cam_top"), robot_description (YAML path, "" = default), detector ("auto" | "onnx" | "torch" |
"off"), roi_from_detector (true: search markers only in the best box, padded by 20 %).
"""
from __future__ import annotations

import sys
from collections import Counter

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from hexa_bringup.rosenv import apply_defaults
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

from hexa.vision.markers import MarkerDetector, MarkerError, MarkerLayout, quaternion_from_matrix
from hexa.vision.sync import FrameAssembler, RGBDFrame
from hexa_msgs.msg import PlateDetection, PlateDetections
from hexa_vision.common import RELIABLE_QOS, SENSOR_QOS, description_cameras, diagnostic_status, stamp_to_sec


class PoseNode(Node):
    def __init__(self) -> None:
        super().__init__("hexa_vision_pose")
        self.cam_name = self.declare_parameter("camera", "cam_top").value
        desc_path = self.declare_parameter("robot_description", "").value
        backend = self.declare_parameter("detector", "auto").value
        self.roi_from_detector = bool(self.declare_parameter("roi_from_detector", True).value)
        from hexa.robots.hexa_description import load_hexa

        desc = load_hexa(desc_path or None)
        cams = description_cameras(desc_path)
        self.T = cams[self.cam_name].T_base_camera
        self.layout = MarkerLayout.from_description(desc)
        self.assembler = FrameAssembler(self.cam_name, self.T)
        self.markers: MarkerDetector | None = None
        self.detector = None
        if backend != "off":
            try:
                from hexa.vision.detector import PlateDetector

                self.detector = PlateDetector(backend)
                self.get_logger().info(f"plate detector back-end: {self.detector.backend}")
            except Exception as exc:  # noqa: BLE001 - markers still work without the detector
                self.get_logger().warning(f"plate detector unavailable ({exc}); markers searched in the whole frame")
        self.counters: Counter[str] = Counter()
        c = self.cam_name
        self.create_subscription(Image, f"{c}/color/image_raw", self._on_color, SENSOR_QOS)
        self.create_subscription(Image, f"{c}/aligned_depth_to_color/image_raw", self._on_depth, SENSOR_QOS)
        self.create_subscription(CameraInfo, f"{c}/color/camera_info", self._on_info, SENSOR_QOS)
        self.pub_det = self.create_publisher(PlateDetections, "plate_detections", 10)
        self.pub_pose = self.create_publisher(PoseStamped, "plate_pose", 10)
        self.pub_cov = self.create_publisher(PoseWithCovarianceStamped, "plate_pose_cov", 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE_QOS)
        self.create_timer(1.0, self._diagnostics)

    def _on_info(self, msg: CameraInfo) -> None:
        self.assembler.set_camera_info(msg.width, msg.height, msg.k, msg.d)
        if self.assembler.camera is not None and not self.assembler.camera.same_as(
                self.markers.camera if self.markers else None):
            self.markers = MarkerDetector(self.layout, self.assembler.camera)

    def _on_color(self, msg: Image) -> None:
        self._process(self.assembler.add_color(stamp_to_sec(msg.header.stamp), msg.height, msg.width, msg.encoding,
                                               msg.is_bigendian, msg.step, msg.data), msg)

    def _on_depth(self, msg: Image) -> None:
        self._process(self.assembler.add_depth(stamp_to_sec(msg.header.stamp), msg.height, msg.width, msg.encoding,
                                               msg.is_bigendian, msg.step, msg.data), msg)

    def _process(self, frame: RGBDFrame | None, msg: Image) -> None:
        if frame is None:
            return
        self.counters["frames"] += 1
        stamp = msg.header.stamp
        roi = None
        if self.detector is not None:
            dets = self.detector.detect(frame.rgb)
            out = PlateDetections()
            out.header.stamp = stamp
            out.header.frame_id = f"{self.cam_name}_color_optical_frame"
            for d in dets:
                cx, cy = d.center
                w, h = d.size
                out.detections.append(PlateDetection(center_x=float(cx), center_y=float(cy), size_x=float(w),
                                                     size_y=float(h), score=float(d.score), class_id=d.class_id))
            self.pub_det.publish(out)
            self.counters["detections"] += len(dets)
            if dets and self.roi_from_detector:
                b = dets[0].box
                pw, ph = 0.2 * (b[2] - b[0]), 0.2 * (b[3] - b[1])
                roi = (b[0] - pw, b[1] - ph, b[2] + pw, b[3] + ph)
        if self.markers is None:
            self.counters["no camera_info"] += 1
            return
        try:
            fit, _ = self.markers.estimate(frame.rgb, frame.depth, roi)
            if not fit.ok and roi is not None:
                fit, _ = self.markers.estimate(frame.rgb, frame.depth, None)
        except MarkerError:
            self.counters["reject: marker input"] += 1
            return
        if not fit.ok:
            self.counters["marker fit rejected"] += 1
            return
        self.counters["poses"] += 1
        if fit.rejected:
            self.counters["markers rejected as outliers"] += len(fit.rejected)
        q = quaternion_from_matrix(fit.R)
        ps = PoseStamped()
        ps.header.stamp = stamp
        ps.header.frame_id = "base"
        ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = (float(v) for v in fit.t)
        ps.pose.orientation.x, ps.pose.orientation.y, ps.pose.orientation.z, ps.pose.orientation.w = (
            float(v) for v in q)
        self.pub_pose.publish(ps)
        pc = PoseWithCovarianceStamped()
        pc.header = ps.header
        pc.pose.pose = ps.pose
        cov = np.nan_to_num(fit.covariance, nan=1e6)
        pc.pose.covariance = [float(v) for v in cov.reshape(-1)]
        self.pub_cov.publish(pc)

    def _diagnostics(self) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        counters = Counter(self.counters)
        counters.update(self.assembler.rejects)
        arr.status.append(diagnostic_status("hexa_vision: pose", self.cam_name, counters, "markers tracked"))
        self.pub_diag.publish(arr)


def main(args: list[str] | None = None) -> int:
    apply_defaults()
    rclpy.init(args=args)
    node = PoseNode()
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
