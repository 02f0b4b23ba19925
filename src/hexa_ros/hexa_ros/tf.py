"""TF for hexa nodes: the frames of hexa.frames as tf2_msgs/TFMessage on /tf and /tf_static (as tf2_ros sends them).

tf2_ros has no wheel; tf2_msgs is built in the venv (third_party/tf2_msgs), so the messages are the standard type
any tf2 listener, RViz or Foxglove reads.
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from hexa.rotations import quaternion_from_matrix
from hexa_ros import qos


def transform_msg(parent: str, child: str, T: np.ndarray, stamp: Any) -> TransformStamped:
    """geometry_msgs/TransformStamped of T_parent_child (4x4) at `stamp` (builtin_interfaces/Time)."""
    m = TransformStamped(child_frame_id=child)
    m.header.frame_id, m.header.stamp = parent, stamp
    tr, q = m.transform.translation, quaternion_from_matrix(T[:3, :3])
    tr.x, tr.y, tr.z = (float(v) for v in T[:3, 3])
    r = m.transform.rotation
    r.x, r.y, r.z, r.w = (float(v) for v in q)
    return m


class TfPublisher:
    """Publishes a node's transforms: `send` on /tf, `send_static` on /tf_static (latched, all in one message)."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.pub = node.create_publisher(TFMessage, "/tf", qos.TF)
        self.pub_static: Any = None
        self.static: dict[str, TransformStamped] = {}

    def send(self, transforms: Iterable[tuple[str, str, np.ndarray]], stamp: Any) -> None:
        """Publish (parent, child, T_parent_child) on /tf at `stamp`."""
        self.pub.publish(TFMessage(transforms=[transform_msg(p, c, T, stamp) for p, c, T in transforms]))

    def send_static(self, transforms: Iterable[tuple[str, str, np.ndarray]]) -> None:
        """Add (parent, child, T) to this node's static transforms and publish them all on /tf_static (stamp: now)."""
        if self.pub_static is None:
            self.pub_static = self.node.create_publisher(TFMessage, "/tf_static", qos.TF_STATIC)
        stamp = self.node.get_clock().now().to_msg()
        self.static.update({c: transform_msg(p, c, T, stamp) for p, c, T in transforms})
        self.pub_static.publish(TFMessage(transforms=list(self.static.values())))
