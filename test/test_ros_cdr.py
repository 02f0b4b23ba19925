"""hexa_ros.cdr: serialized sensor_msgs/Image read in place equals rclpy's own deserialization; bad bytes are named."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")


@pytest.mark.parametrize("frame_id, encoding, shape, dtype", [
    ("cam_top_color_optical_frame", "rgb8", (48, 64, 3), np.uint8),
    ("", "16UC1", (30, 40), np.uint16),
    ("abc", "mono8", (7, 5), np.uint8),
    ("x" * 13, "32FC1", (3, 9), np.float32),
])
def test_image_read_in_place_equals_rclpy(frame_id, encoding, shape, dtype):
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Image

    from hexa.vision.images import numpy_to_image
    from hexa_ros.cdr import image_from_cdr

    rng = np.random.default_rng(1)
    arr = (rng.random(shape) * 200).astype(dtype)
    f = numpy_to_image(arr, encoding)
    msg = Image(height=f.height, width=f.width, encoding=f.encoding, is_bigendian=f.is_bigendian, step=f.step,
                data=f.data)
    msg.header.stamp, msg.header.frame_id = Time(sec=-3, nanosec=123_456_789), frame_id
    raw = serialize_message(msg)
    ref = deserialize_message(raw, Image)
    got = image_from_cdr(raw)
    assert (got.stamp_sec, got.stamp_nanosec, got.frame_id) == (-3, 123_456_789, frame_id)
    assert (got.height, got.width, got.encoding, got.is_bigendian, got.step) == (
        ref.height, ref.width, ref.encoding, ref.is_bigendian, ref.step)
    assert got.data.tobytes() == bytes(ref.data)
    assert np.shares_memory(got.data, np.frombuffer(raw, np.uint8)) or isinstance(raw, bytes)


def test_truncated_or_foreign_bytes_are_refused_naming_why():
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image

    from hexa_ros.cdr import CdrError, image_from_cdr

    raw = serialize_message(Image(height=2, width=300, encoding="mono8", step=300, data=bytes(600)))
    with pytest.raises(CdrError, match="does not fit"):
        image_from_cdr(raw[:400])                      # cut inside the pixels
    for cut in range(5, 40):                           # cut inside every field before them
        with pytest.raises(CdrError, match="does not fit|ends inside"):
            image_from_cdr(raw[:cut])
    with pytest.raises(CdrError, match="representation"):
        image_from_cdr(b"\x00\x07\x00\x00" + raw[4:])
    with pytest.raises(CdrError, match="shorter"):
        image_from_cdr(b"\x00")
