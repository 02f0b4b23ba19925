"""Fast DDS shared-memory files in /dev/shm: which are in use, and which a process left behind when it ended without
closing them (killed, crashed).

Fast DDS keeps every participant's shared-memory segment (`fastrtps_<16 hex>`, 35 MB with hexa's profile) and every
port (`fastrtps_port<N>`, with a `sem.fastrtps_port<N>_mutex` semaphore) as files in /dev/shm, each beside a lock file
(`…_el` or `…_sl`) that its owner holds with flock while it lives. A process killed with SIGKILL leaves its files
behind, unlocked, and they stay until the next boot: on a test machine hundreds of them take gigabytes of RAM. A file
whose lock can be taken has no living owner; removing it is what Fast DDS's own `fastdds shm clean` does.
"""
from __future__ import annotations

import fcntl
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

SHM_DIR = Path("/dev/shm")
_SEGMENT_LOCK = re.compile(r"^fastrtps_[0-9a-z]{16}_(el|sl)$")
_PORT_LOCK = re.compile(r"^fastrtps_port\d{1,5}_(el|sl)$")


@dataclass
class ShmReport:
    """Fast DDS files in a shared-memory folder: `in_use` segments and ports a living process holds, `stale_owners`
    segments and ports none holds, their `stale` files (segments, lock files, port mutexes) and the RAM they take
    (`stale_bytes`)."""

    in_use: int = 0
    stale_owners: int = 0
    stale: list[Path] = field(default_factory=list)
    stale_bytes: int = 0


def _held(lock: Path) -> bool:
    """Whether a living process holds `lock` (flock): an exclusive lock cannot be taken without blocking."""
    try:
        with open(lock, "ab") as f:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(f, fcntl.LOCK_UN)
        return False
    except OSError:
        return True


def scan(folder: Path = SHM_DIR) -> ShmReport:
    """Sort the Fast DDS files of `folder` into in use and stale (see the module docstring): a segment or port is
    stale when none of its lock files is held."""
    report = ShmReport()
    try:
        names = set(os.listdir(folder))
    except FileNotFoundError:
        return report
    owners: dict[str, list[Path]] = {}
    for name in sorted(names):
        if _PORT_LOCK.match(name) or _SEGMENT_LOCK.match(name):
            owners.setdefault(name[:-3], []).append(folder / name)
    for base, locks in owners.items():
        if any(_held(lock) for lock in locks):
            report.in_use += 1
            continue
        report.stale_owners += 1
        extra = [f"sem.{base}_mutex"] if base.startswith("fastrtps_port") else []
        for f in [*locks, *(folder / n for n in [base, *extra] if n in names)]:
            try:
                report.stale_bytes += f.stat().st_blocks * 512     # the RAM it holds, not its sparse size
                report.stale.append(f)
            except FileNotFoundError:
                pass
    return report


def remove_stale(folder: Path = SHM_DIR) -> ShmReport:
    """Remove the stale Fast DDS files of `folder` (scan); returns what was found, the removed files as `stale`.
    A file that another cleaner removed first is skipped."""
    report = scan(folder)
    removed = []
    for f in report.stale:
        try:
            f.unlink()
            removed.append(f)
        except FileNotFoundError:
            pass
    report.stale = removed
    return report
