"""Real-time scheduling of a node's process: the 1 kHz safety path (driver → observer) preempts the vision nodes.

On the 2-core robot PC a camera frame costs the pose node several ms of CPU; at normal priority a current sample
that arrives meanwhile waits for the kernel's next time slice, so the sample → residual latency's tail grows with
the vision's load (docs/realtime.md has the figures with and without). ros2_control's controller manager does the
same (`thread_priority`, SCHED_FIFO 50). The kernel's real-time throttling (sched_rt_runtime_us, 95 % of each second by
default) keeps a runaway FIFO process from freezing the machine.

Nodes ask (`request_realtime_priority`); the entry point that owns the process (hexa_ros.node.run) raises it
(`apply_requested_priority`), so a node built inside a test or a script leaves that program's scheduling alone.
A process may raise itself to SCHED_FIFO as root or within its `rtprio` limit (`ulimit -r`; on the robot PC:
`@realtime - rtprio 98` in /etc/security/limits.conf and the operator in group `realtime`). Without either the node
runs at normal priority and says so (log warning and diagnostics), it never fails to start for it.
"""
from __future__ import annotations

import os
from typing import Any

from hexa_ros.node import REQUESTED_PRIORITY, Param

#: the parameter every node on the 1 kHz safety path declares
REALTIME_PRIORITY = "realtime_priority"
#: the priority recommended for the safety path (driver, observer) on the robot PC: ros2_control's
SAFETY_PRIORITY = 50
REALTIME_PRIORITY_PARAM = Param(
    0, "SCHED_FIFO priority (1-99) of this node's process, all its threads, so the 1 kHz path preempts the vision "
       "nodes (50 on the robot PC); 0 = normal scheduling (the default). Needs root or an rtprio limit "
       "(docs/running.md); without, the node runs at normal priority and warns", range=(0, 99))


def in_range(priority: int) -> bool:
    """`priority` is 0 (normal scheduling) or a SCHED_FIFO priority (`REALTIME_PRIORITY_PARAM.range`)."""
    low, high = REALTIME_PRIORITY_PARAM.range or (0, 99)
    return low <= int(priority) <= high


def set_realtime_priority(priority: int, pid: int | None = None) -> str:
    """Put every thread of process `pid` (default: this one) under SCHED_FIFO at `priority` (1-99); threads started
    later inherit it from the thread that starts them. `priority` 0 leaves the scheduling as it is.

    Returns:
        "" when granted (or 0 asked), else why not (the process keeps its scheduling).

    Raises:
        ValueError: `priority` outside 0..99.
    """
    if not in_range(priority):
        raise ValueError(f"realtime priority must be 0..99, got {priority!r}")
    if priority == 0:
        return ""
    pid = os.getpid() if pid is None else int(pid)
    try:
        tids = sorted(int(t) for t in os.listdir(f"/proc/{pid}/task"))
    except OSError:
        tids = [pid]
    param = os.sched_param(int(priority))
    for tid in tids:
        try:
            os.sched_setscheduler(tid, os.SCHED_FIFO, param)
        except ProcessLookupError:      # the thread ended meanwhile
            continue
        except OSError as exc:          # EPERM: neither root nor within the rtprio limit
            return (f"SCHED_FIFO {priority} not granted ({exc.strerror}; `ulimit -r` is "
                    f"{_rtprio_limit()}): running at normal priority")
    return ""


def realtime_priority_of(pid: int | None = None) -> int:
    """The SCHED_FIFO/SCHED_RR priority of process `pid`'s main thread (0: normal scheduling)."""
    pid = os.getpid() if pid is None else int(pid)
    policy = os.sched_getscheduler(pid)
    return os.sched_getparam(pid).sched_priority if policy in (os.SCHED_FIFO, os.SCHED_RR) else 0


def request_realtime_priority(node: Any, priority: int) -> None:
    """Note that `node` wants its process at SCHED_FIFO `priority`. The process is raised by the entry point that
    owns it (`apply_requested_priority`, from hexa_ros.node.run), never by a node built inside another program (a
    test, a script), which would put that whole program under SCHED_FIFO."""
    setattr(node, REQUESTED_PRIORITY, int(priority))


def apply_requested_priority(nodes: list[Any]) -> int:
    """Raise this process to the highest priority its `nodes` asked for (`request_realtime_priority`), logged by
    each node that asked; the priority the process runs at."""
    asks = [(node, int(getattr(node, REQUESTED_PRIORITY, 0))) for node in nodes]
    wanted = max((p for _, p in asks), default=0)
    why = set_realtime_priority(wanted) if wanted > 0 else ""
    for node, p in asks:
        if p and why:
            node.get_logger().warning(f"{REALTIME_PRIORITY} {p}: {why}")
        elif p:
            node.get_logger().info(f"{REALTIME_PRIORITY}: SCHED_FIFO {wanted}")
    return realtime_priority_of()


def _rtprio_limit() -> str:
    import resource

    soft, _ = resource.getrlimit(resource.RLIMIT_RTPRIO)
    return "unlimited" if soft == resource.RLIM_INFINITY else str(soft)
