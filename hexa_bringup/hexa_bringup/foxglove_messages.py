"""ROS messages → Foxglove messages (foxglove-sdk schemas) and JSON payloads, for `hexa view`."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from hexa_bringup.msgutil import message_to_dict
from hexa_ros.stamps import to_sec


def json_payload(msg: Any) -> dict:
    """The message's fields as JSON-safe plain data; a one-byte `byte` field (a diagnostic level) as an integer."""
    d = json_safe(message_to_dict(msg))
    if hasattr(msg, "status") and isinstance(d.get("status"), list):      # diagnostic_msgs/DiagnosticArray
        for st, s in zip(d["status"], msg.status):
            st["level"] = int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else int(s.level)
    return d


def json_safe(value: Any) -> Any:
    """`value` with every NaN or infinite float as None (JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [json_safe(v) for v in value]
    return value


def ns_time(stamp: Any) -> int:
    return int(round(to_sec(stamp) * 1e9))


def timestamp(stamp: Any) -> Any:
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
        entities.append(SceneEntity(timestamp=timestamp(m.header.stamp), frame_id=m.header.frame_id,
                                    id=f"{m.ns}/{m.id}", arrows=arrows, spheres=spheres))
    return SceneUpdate(entities=entities)


def frame_transforms(items: list[tuple[Any, str, str, Any, Any]]) -> Any:
    """foxglove.FrameTransforms of (stamp, parent, child, translation, rotation) items (ROS Vector3 / Quaternion)."""
    from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Vector3

    return FrameTransforms(transforms=[
        FrameTransform(timestamp=timestamp(st), parent_frame_id=parent, child_frame_id=child,
                       translation=Vector3(x=t.x, y=t.y, z=t.z), rotation=Quaternion(x=q.x, y=q.y, z=q.z, w=q.w))
        for st, parent, child, t, q in items])
