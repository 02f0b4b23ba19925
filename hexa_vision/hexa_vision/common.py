"""Shared helpers of the vision nodes: Image/CameraInfo/Contact filling and the description's cameras (stamps, QoS and
diagnostics are hexa_ros')."""
from __future__ import annotations

from typing import Any

import numpy as np

from hexa.vision.camera import CameraModel
from hexa.vision.images import numpy_to_image
from hexa_ros.qos import RELIABLE as RELIABLE_QOS  # noqa: F401 - the tests' name for hexa_ros.qos.RELIABLE
from hexa_ros.stamps import fill_stamp

CAMERAS = ("cam_top", "cam_side")


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


def camera_info_msg(cam: CameraModel, frame_id: str, stamp: Any, fields: dict | None = None):
    """sensor_msgs/CameraInfo (plumb_bob, no distortion) of a camera model, or of `fields` when given (e.g. a
    RealSense's own, hexa.vision.sources.realsense_camera_info_fields)."""
    from sensor_msgs.msg import CameraInfo

    f = fields or cam.camera_info_fields()
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


def contact_msg(found: Any):
    """hexa_msgs/Contact of an isolated pair (hexa.vision.isolation_scheduler.Located): stamped with the pair's
    stamp, point in `base` (m), the push direction where measured (zeros otherwise)."""
    from hexa_msgs.msg import Contact

    est, msg = found.estimate, Contact()
    fill_stamp(msg.header.stamp, found.work.stamp)
    msg.header.frame_id = "base"
    msg.collision_id = found.work.collision_id
    msg.link, msg.chain = int(est.link), int(est.chain)
    msg.point.x, msg.point.y, msg.point.z = (float(v) for v in est.point)
    msg.pixel_u, msg.pixel_v = (float(v) for v in est.pixel)
    msg.camera, msg.confidence = est.camera, float(est.confidence)
    if np.all(np.isfinite(est.push_direction)):
        msg.push_direction.x, msg.push_direction.y, msg.push_direction.z = (float(v) for v in est.push_direction)
    return msg


def description_cameras(path: str | None = None) -> dict[str, CameraModel]:
    """Camera models (intrinsics + extrinsics) from the robot description's `cameras` section."""
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim.config import sim_config_of

    desc = load_hexa(path or None)
    cfg = sim_config_of(desc)
    return {name: CameraModel(c.K, c.width, c.height, c.T_base_camera, name, c.frame_id)
            for name, c in cfg.cameras.items()}
