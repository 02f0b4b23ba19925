"""The QoS profiles of the hexa graph, named after what flows on them."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

#: camera images and camera_info: best effort, keep last 5 (realsense-ros' default)
SENSOR = qos_profile_sensor_data
#: outputs and low-rate inputs: reliable, keep last 10
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
#: the driver's 1 kHz streams: reliable with room for half a second of samples (a subscriber stalled by a GC pause
#: or a camera frame catches up instead of losing samples)
STREAM = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
#: discrete events (collision START/END, contacts, wrenches): reliable, keep last 20
EVENT = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
#: states a late subscriber must see at once: reliable, transient local, keep last 1
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /tf: reliable, keep last 100, volatile (tf2_ros' TransformBroadcaster)
TF = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
#: /tf_static: reliable, transient local, keep last 1 (tf2_ros' StaticTransformBroadcaster: one message holds every
#: static transform of the node)
TF_STATIC = LATCHED
#: the `image_qos` choices of a camera publisher (realsense-ros' `<stream>_qos`): best effort (SENSOR) or reliable
IMAGE_QOS = ("best_effort", "reliable")


def image_profile(name: str) -> QoSProfile:
    """The publisher QoS of camera images for `name` in IMAGE_QOS (keep last 5 either way; a SENSOR subscriber
    receives from both).

    Raises:
        ValueError: `name` is not one of IMAGE_QOS.
    """
    if name not in IMAGE_QOS:
        raise ValueError(f"image_qos must be one of {', '.join(IMAGE_QOS)}; got {name!r}")
    if name == "best_effort":
        return SENSOR
    return QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
