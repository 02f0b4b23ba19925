"""builtin_interfaces/Time <-> float seconds, written once for every node."""
from __future__ import annotations

import math
from typing import Any


def to_sec(stamp: Any) -> float:
    """Seconds of a builtin_interfaces/Time (or anything with sec and nanosec)."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def to_stamp(t: float) -> Any:
    """builtin_interfaces/Time of `t` seconds (nanoseconds rounded, never 10⁹).

    Raises:
        ValueError: t is not finite.
    """
    from builtin_interfaces.msg import Time

    if not math.isfinite(t):
        raise ValueError(f"cannot stamp a non-finite time {t!r}")
    ns = int(round(t * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_parts(t: float) -> tuple[int, int]:
    """(sec, nanosec) of `t` seconds as to_stamp rounds them, without building a message (per-sample outputs written
    as bytes)."""
    ns = int(round(t * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000


def fill_stamp(msg_stamp: Any, t: float) -> Any:
    """Write `t` seconds into an existing stamp field and return it."""
    ns = int(round(t * 1e9))
    msg_stamp.sec, msg_stamp.nanosec = ns // 1_000_000_000, ns % 1_000_000_000
    return msg_stamp
