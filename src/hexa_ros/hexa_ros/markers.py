"""RViz / Foxglove markers the nodes publish, drawn one way: force arrows and contact points."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker

#: arrow shaft and head diameters, head length (m)
ARROW_SCALE = (0.006, 0.012, 0.015)


def point(p: Sequence[float]) -> Point:
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def arrow(ns: str, frame_id: str, stamp: Any, start: Sequence[float], end: Sequence[float],
          rgba: tuple[float, float, float, float]) -> Marker:
    """An ARROW marker from `start` to `end` (m, in `frame_id`)."""
    m = Marker(ns=ns, id=0, type=Marker.ARROW, action=Marker.ADD)
    m.header.stamp, m.header.frame_id = stamp, frame_id
    m.points = [point(start), point(end)]
    m.pose.orientation.w = 1.0
    m.scale.x, m.scale.y, m.scale.z = ARROW_SCALE
    m.color.r, m.color.g, m.color.b, m.color.a = rgba
    return m


def sphere(ns: str, frame_id: str, stamp: Any, centre: Sequence[float], diameter: float,
           rgba: tuple[float, float, float, float]) -> Marker:
    """A SPHERE marker at `centre` (m, in `frame_id`)."""
    m = Marker(ns=ns, id=0, type=Marker.SPHERE, action=Marker.ADD)
    m.header.stamp, m.header.frame_id = stamp, frame_id
    m.pose.position = point(centre)
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = float(diameter)
    m.color.r, m.color.g, m.color.b, m.color.a = rgba
    return m
