"""Shared helpers of the vision nodes: QoS, stamps, Image/CameraInfo filling, extrinsics, diagnostics."""
from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from hexa.vision.camera import CameraModel
from hexa.vision.images import numpy_to_image

SENSOR_QOS = qos_profile_sensor_data
RELIABLE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
CAMERAS = ("cam_top", "cam_side")


def stamp_to_sec(stamp: Any) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def sec_to_stamp(msg_stamp: Any, t: float) -> Any:
    msg_stamp.sec = int(np.floor(t))
    msg_stamp.nanosec = int(round((t - np.floor(t)) * 1e9)) % 1_000_000_000
    return msg_stamp


def image_msg(array: np.ndarray, encoding: str, frame_id: str, stamp: Any):
    """sensor_msgs/Image from an array (little-endian, no padding)."""
    from sensor_msgs.msg import Image

    f = numpy_to_image(array, encoding)
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width, msg.encoding = f.height, f.width, f.encoding
    msg.is_bigendian, msg.step = f.is_bigendian, f.step
    msg.data = f.data
    return msg


def camera_info_msg(cam: CameraModel, frame_id: str, stamp: Any):
    """sensor_msgs/CameraInfo (plumb_bob, no distortion) of a camera model."""
    from sensor_msgs.msg import CameraInfo

    f = cam.camera_info_fields()
    msg = CameraInfo()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.width, msg.height = f["width"], f["height"]
    msg.distortion_model = f["distortion_model"]
    msg.d = f["d"]
    msg.k = f["k"]
    msg.r = f["r"]
    msg.p = f["p"]
    return msg


def description_cameras(path: str | None = None) -> dict[str, CameraModel]:
    """Camera models (intrinsics + extrinsics) from the robot description's `cameras` section."""
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim.config import sim_config_of

    desc = load_hexa(path or None)
    cfg = sim_config_of(desc)
    return {name: CameraModel(c.K, c.width, c.height, c.T_base_camera, name, c.frame_id)
            for name, c in cfg.cameras.items()}


def diagnostic_status(name: str, hardware_id: str, counters: Counter | dict, ok_message: str,
                      warn_if_rejects: bool = True):
    """diagnostic_msgs/DiagnosticStatus with the counters as key/values (WARN when anything was rejected)."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    st = DiagnosticStatus()
    st.name, st.hardware_id = name, hardware_id
    rejected = sum(v for k, v in counters.items() if "reject" in k or any(r in k for r in _REJECT_KEYS))
    st.level = DiagnosticStatus.WARN if (warn_if_rejects and rejected) else DiagnosticStatus.OK
    st.message = f"{rejected} input(s) rejected" if rejected else ok_message
    st.values = [KeyValue(key=str(k), value=str(v)) for k, v in sorted(counters.items())]
    return st


_REJECT_KEYS = {"bad colour image", "bad depth image", "empty depth", "no camera_info", "colour/depth size mismatch",
                "frame/camera_info size mismatch", "bad camera_info", "no background", "isolation error",
                "marker fit rejected"}
