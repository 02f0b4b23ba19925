"""One ROS_DOMAIN_ID per running test, held by an flock on /tmp so concurrent test runs never share a domain."""
from __future__ import annotations

import fcntl
import os
from contextlib import contextmanager
from typing import Iterable, Iterator


class NoFreeDomain(RuntimeError):
    """Every domain in 1..100 is held (too many ROS tests at once)."""


@contextmanager
def held_ros_domain(order: Iterable[int] | None = None) -> Iterator[int]:
    """The first ROS_DOMAIN_ID of `order` (default: all of 1..100 from a pid-dependent start) that no other test
    holds right now; held until the block ends.

    Raises:
        NoFreeDomain: all are held.
    """
    if order is None:
        start = (os.getpid() * 7) % 100
        order = [(start + k) % 100 + 1 for k in range(100)]
    for domain in order:
        fd = os.open(f"/tmp/hexa_ros_domain_{domain}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        try:
            yield domain
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
        return
    raise NoFreeDomain("no free ROS_DOMAIN_ID in 1..100 (too many ROS tests running at once?)")
