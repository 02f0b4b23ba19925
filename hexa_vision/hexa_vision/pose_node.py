"""hexa-vision-pose: plate detector + coloured markers on the top camera → plate_detections, plate_pose.

Subscribes (sensor-data QoS) `<camera>/color/image_raw`, `<camera>/aligned_depth_to_color/image_raw`,
`<camera>/color/camera_info`; publishes `plate_detections` (hexa_msgs/PlateDetections), `plate_pose`
(geometry_msgs/PoseStamped in `base`), `plate_pose_cov` (PoseWithCovarianceStamped: the same pose with the fit's 6x6
covariance), `/diagnostics` (frames, fits, rejects by reason). Bad input is counted and skipped, never fatal.
`plate_detections` and `plate_pose_cov` are built only while someone subscribes to them (the detector itself runs
only when its box is used or its boxes are subscribed). The work is hexa.vision.plate_pose.PlatePoseEstimator's.
Parameters: PARAMETERS below (start-up only, read-only). While the plate is tracked (the last fit at most
0.1 s old) the markers are searched around the last pose's markers, else in the detector's best box padded by 20 %.
"""
from __future__ import annotations

import sys
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from builtin_interfaces.msg import Time
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

import hexa_ros.node
from hexa import frames
from hexa.vision.plate_pose import PlatePose, PlatePoseEstimator
from hexa_msgs.msg import PlateDetection, PlateDetections
from hexa_ros import diagnostics, qos
from hexa_ros.cdr import CdrError, image_from_cdr
from hexa_ros.conversions import fill_pose_msg
from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param, declare_parameters
from hexa_ros.stamps import to_stamp
from hexa_vision.common import description_cameras

# `-p detector:=off` arrives as YAML false: any type is accepted
PARAMETERS = {"camera": Param("cam_top", "camera whose images are read (topic prefix)"),
              "detector": Param("auto", "plate detector back-end: auto | onnx | torch | off", dynamic_typing=True),
              "roi_from_detector": Param(True, "search markers only in the best detector box, padded by 20 %"),
              DESCRIPTION: DESCRIPTION_PARAM}


class PoseNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("hexa_vision_pose", **kwargs)
        v = declare_parameters(self, PARAMETERS)
        self.cam_name, desc_path, roi_from_detector = v["camera"], v[DESCRIPTION], bool(v["roi_from_detector"])
        backend = "off" if v["detector"] is False else str(v["detector"])
        from hexa.robots.hexa_description import load_hexa
        from hexa.vision.markers import MarkerLayout

        layout = MarkerLayout.from_description(load_hexa(desc_path or None))
        T = description_cameras(desc_path)[self.cam_name].T_base_camera
        detector = None
        if backend != "off":
            try:
                from hexa.vision.detector import PlateDetector

                detector = PlateDetector(backend)
                self.get_logger().info(f"plate detector back-end: {detector.backend}")
            except Exception as exc:  # noqa: BLE001 - markers still work without the detector
                self.get_logger().warning(f"plate detector unavailable ({exc}); markers searched in the whole frame")
        self.estimator = PlatePoseEstimator(layout, self.cam_name, T, detector, roi_from_detector)
        self.det_frame = frames.camera_optical_frame(self.cam_name)
        c = self.cam_name
        self.create_subscription(Image, f"{c}/color/image_raw", self._on_color, qos.SENSOR, raw=True)
        self.create_subscription(Image, f"{c}/aligned_depth_to_color/image_raw", self._on_depth, qos.SENSOR, raw=True)
        self.create_subscription(CameraInfo, f"{c}/color/camera_info", self._on_info, qos.SENSOR)
        self.pub_det = self.create_publisher(PlateDetections, "plate_detections", qos.RELIABLE)
        self.pub_pose = self.create_publisher(PoseStamped, "plate_pose", qos.RELIABLE)
        self.pub_cov = self.create_publisher(PoseWithCovarianceStamped, "plate_pose_cov", qos.RELIABLE)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.create_timer(1.0, self._diagnostics)

    def _on_info(self, msg: CameraInfo) -> None:
        want = self.pub_det.get_subscription_count() > 0
        result = self.estimator.set_camera_info(msg.width, msg.height, msg.k, msg.d, want)
        if result is not None:   # the first frame, paired before its camera_info arrived
            self._publish(result, to_stamp(result.stamp), want)

    def _on_color(self, data: bytes) -> None:
        self._on_image(data, self.estimator.add_color)

    def _on_depth(self, data: bytes) -> None:
        self._on_image(data, self.estimator.add_depth)

    def _on_image(self, data: bytes, add: Any) -> None:
        """A serialized image (raw subscription): its pixels stay a view of the delivered bytes."""
        try:
            m = image_from_cdr(data)
        except CdrError:
            self.estimator.count_reject("malformed image")
            return
        want = self.pub_det.get_subscription_count() > 0
        result = add(m.stamp, m.height, m.width, m.encoding, m.is_bigendian, m.step, m.data, want)
        self._publish(result, Time(sec=m.stamp_sec, nanosec=m.stamp_nanosec), want)

    def _publish(self, result: PlatePose | None, stamp: Any, detections_wanted: bool) -> None:
        if result is None:
            return
        if self.estimator.detector is not None and detections_wanted:
            out = PlateDetections()
            out.header.stamp, out.header.frame_id = stamp, self.det_frame
            for d in result.detections:
                (cx, cy), (w, h) = d.center, d.size
                out.detections.append(PlateDetection(center_x=float(cx), center_y=float(cy), size_x=float(w),
                                                     size_y=float(h), score=float(d.score), class_id=d.class_id))
            self.pub_det.publish(out)
        fit = result.fit
        if fit is None:
            return
        ps = PoseStamped()
        ps.header.stamp, ps.header.frame_id = stamp, "base"
        fill_pose_msg(ps.pose, fit.R, fit.t)
        self.pub_pose.publish(ps)
        if self.pub_cov.get_subscription_count() > 0:
            pc = PoseWithCovarianceStamped()
            pc.header, pc.pose.pose = ps.header, ps.pose
            pc.pose.covariance = np.nan_to_num(fit.covariance, nan=1e6).reshape(-1).tolist()
            self.pub_cov.publish(pc)

    def _diagnostics(self) -> None:
        n = self.estimator.rejected()
        level, message = (diagnostics.WARN, f"{n} input(s) rejected") if n else (diagnostics.OK, "markers tracked")
        st = diagnostics.status("hexa_vision: pose", level, message, dict(sorted(self.estimator.counters().items())),
                                self.cam_name)
        self.pub_diag.publish(diagnostics.array(self, [st]))


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(PoseNode, "vision-pose", argv)


if __name__ == "__main__":
    sys.exit(main())
