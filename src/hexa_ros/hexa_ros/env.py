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
    """The variables hexa sets when they are unset: RMW implementation, the Fast DDS profile file, one thread
    for numpy's BLAS and OpenCV's loops, and glibc's malloc thresholds (`MALLOC_THRESHOLDS`).

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
        **{f"MALLOC_{k}_": str(v) for k, v in MALLOC_THRESHOLDS.items()},
    }


#: glibc malloc: blocks up to 16 MB come from the heap and up to 64 MB of free heap top is kept. glibc's default
#: maps every block above 128 kB (an image message, a full-frame mask) freshly from the kernel and unmaps it when
#: freed, so each one page-faults in again: taking a 640x480 image from its DDS reader cost 0.2-0.65 ms with the
#: default, 0.15-0.19 ms with these; isolating a frame pair 15 % less CPU.
MALLOC_THRESHOLDS = {"MMAP_THRESHOLD": 16 << 20, "TRIM_THRESHOLD": 64 << 20}
_MALLOPT = {"MMAP_THRESHOLD": -3, "TRIM_THRESHOLD": -1}     # mallopt's parameter numbers (malloc.h)


def tune_malloc() -> bool:
    """Apply `MALLOC_THRESHOLDS` to this process (glibc reads the variables only at start-up); False where malloc
    is not glibc's."""
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    return all(mallopt(_MALLOPT[k], v) == 1 for k, v in MALLOC_THRESHOLDS.items())


def apply_defaults() -> None:
    """Set the defaults in os.environ (keeping anything the user set) and this process's malloc thresholds. Call
    before rclpy.init()."""
    for key, value in defaults().items():
        os.environ.setdefault(key, value)
    tune_malloc()


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
