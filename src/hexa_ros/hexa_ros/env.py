"""The ROS environment every hexa process runs in: rmw_fastrtps with hexa's Fast DDS profile."""
from __future__ import annotations

import fcntl
import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

PROFILE = Path(__file__).resolve().parent / "config" / "fastdds_profile.xml"
RMW = "rmw_fastrtps_cpp"


def defaults() -> dict[str, str]:
    """The variables hexa sets when they are unset: RMW implementation, the Fast DDS profile file, and one thread
    for numpy's BLAS and OpenCV's loops.

    A node shares two cores with the rest of the graph: a BLAS or OpenCV thread pool per process spins on cores
    the other nodes need (the isolation of a frame pair took ≈ 120 ms of CPU with OpenBLAS's threads, ≈ 55 ms
    with one, on this 2-core machine). Both libraries read these at load: set before numpy / cv2 are imported
    (`hexa_ros.start` does, and every child started with `ros_env()`).
    """
    return {
        "RMW_IMPLEMENTATION": RMW,
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(PROFILE),
        "FASTDDS_DEFAULT_PROFILES_FILE": str(PROFILE),
        "RCUTILS_COLORIZED_OUTPUT": "0",
        "OPENBLAS_NUM_THREADS": "1",
        "OPENCV_FOR_THREADS_NUM": "1",
    }


def apply_defaults() -> None:
    """Set the defaults in os.environ (keeping anything the user set). Call before rclpy.init()."""
    for key, value in defaults().items():
        os.environ.setdefault(key, value)


def ros_env(domain_id: int | None = None, localhost_only: bool = True, base: dict[str, str] | None = None
            ) -> dict[str, str]:
    """A copy of the environment for a child ROS process.

    Args:
        domain_id: ROS_DOMAIN_ID to use (0..101 are safe with default ports); None keeps the current one.
        localhost_only: restrict discovery to this host (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).
        base: environment to start from (default os.environ).

    Returns:
        The environment dict with hexa's defaults applied.
    """
    env = dict(os.environ if base is None else base)
    for key, value in defaults().items():
        env.setdefault(key, value)
    if domain_id is not None:
        if not 0 <= int(domain_id) <= 232:
            raise ValueError(f"ROS_DOMAIN_ID must be in 0..232, got {domain_id}")
        env["ROS_DOMAIN_ID"] = str(int(domain_id))
    if localhost_only:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


class NoFreeDomain(RuntimeError):
    """Every domain in 1..100 is held (too many ROS tests or benches at once)."""


@contextmanager
def held_ros_domain(order: Iterable[int] | None = None) -> Iterator[int]:
    """The first ROS_DOMAIN_ID of `order` (default: all of 1..100 from a pid-dependent start) that no other hexa test
    or bench on this machine holds right now (an flock on /tmp/hexa_ros_domain_<id>.lock), held until the block ends.

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
    raise NoFreeDomain("no free ROS_DOMAIN_ID in 1..100 (too many ROS tests or benches running at once?)")
