"""rosbag2 reading without ROS (rosbags): recorded CDR messages in time order, replayed at their recorded pace."""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path


class BagError(RuntimeError):
    """A bag cannot be written or read (path exists, unknown type, corrupt file)."""


def read_bag(path: str | Path, topics: list[str] | None = None) -> Iterator[tuple[str, str, int, bytes]]:
    """Yield (topic, msgtype, timestamp_ns, cdr) in time order.

    Raises:
        BagError: the bag is missing or unreadable.
    """
    from rosbags.rosbag2 import Reader

    p = Path(path)
    if not p.exists():
        raise BagError(f"bag {p} does not exist")
    try:
        with Reader(p) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            for conn, stamp, data in reader.messages(connections=conns):
                yield conn.topic, conn.msgtype, stamp, bytes(data)
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types; name the bag
        if isinstance(exc, BagError):
            raise
        raise BagError(f"cannot read bag {p}: {exc}") from exc


def paced(messages: Iterator[tuple[str, str, int, bytes]], rate: float,
          sleep: Callable[[float], None] = time.sleep) -> Iterator[tuple[str, str, int, bytes]]:
    """Re-yield `messages` at `rate` times their recorded pace (rate <= 0: as fast as possible)."""
    t_wall0 = None
    t_bag0 = None
    for item in messages:
        stamp = item[2]
        if rate > 0:
            if t_wall0 is None:
                t_wall0, t_bag0 = time.monotonic(), stamp
            due = t_wall0 + (stamp - t_bag0) / 1e9 / rate
            delay = due - time.monotonic()
            if delay > 0:
                sleep(delay)
        yield item
