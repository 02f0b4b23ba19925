"""hexa_ros.realtime: SCHED_FIFO for every thread of a process (the ones already running and the ones started later),
a clear reason and unchanged scheduling when the process may not raise itself, 0 = leave it as it is."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from hexa_ros.realtime import (apply_requested_priority, realtime_priority_of, request_realtime_priority,
                               set_realtime_priority)

CHILD = textwrap.dedent("""
    import json, os, resource, sys, threading, time
    from hexa_ros.realtime import set_realtime_priority
    if sys.argv[2] == "unprivileged":
        resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
        if os.getuid() == 0:
            os.setresgid(65534, 65534, 65534)
            os.setresuid(65534, 65534, 65534)
    stop = threading.Event()
    before = threading.Thread(target=stop.wait)
    before.start()
    why = set_realtime_priority(int(sys.argv[1]))
    after = threading.Thread(target=stop.wait)
    after.start()
    def policy(tid):
        return [os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority]
    out = {"why": why, "main": policy(threading.get_native_id()), "before": policy(before.native_id),
           "after": policy(after.native_id)}
    stop.set()
    print(json.dumps(out))
""")


def _child(priority: int, mode: str = "privileged") -> dict:
    import json

    res = subprocess.run([sys.executable, "-c", CHILD, str(priority), mode], capture_output=True, text=True,
                         timeout=60, check=True)
    return json.loads(res.stdout)


def _may_raise_priority() -> bool:
    import resource

    return os.geteuid() == 0 or resource.getrlimit(resource.RLIMIT_RTPRIO)[0] >= 10


@pytest.mark.skipif(not _may_raise_priority(), reason="needs root or an rtprio limit >= 10 (ulimit -r)")
def test_every_thread_runs_fifo_at_the_priority_asked_for_also_the_ones_started_later():
    out = _child(10)
    assert out["why"] == ""
    for thread in ("main", "before", "after"):
        assert out[thread] == [os.SCHED_FIFO, 10], thread


def test_priority_zero_leaves_the_scheduling_as_it_is():
    out = _child(0)
    assert out["why"] == ""
    assert out["main"] == out["before"] == out["after"] == [os.sched_getscheduler(0), 0]


@pytest.mark.skipif(os.geteuid() != 0, reason="dropping to an unprivileged user needs root")
def test_without_permission_it_says_why_and_the_process_keeps_normal_scheduling():
    out = _child(10, "unprivileged")
    assert "not granted" in out["why"] and "ulimit -r" in out["why"] and "normal priority" in out["why"]
    for thread in ("main", "before", "after"):
        assert out[thread] == [os.SCHED_OTHER, 0], thread


@pytest.mark.skipif(not _may_raise_priority(), reason="needs root or an rtprio limit >= 10 (ulimit -r)")
def test_another_process_is_raised_by_its_pid():
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert realtime_priority_of(proc.pid) == 0
        assert set_realtime_priority(7, proc.pid) == ""
        assert realtime_priority_of(proc.pid) == 7
    finally:
        proc.kill()
        proc.wait()


@pytest.mark.parametrize("bad", [-1, 100])
def test_a_priority_outside_0_99_is_refused(bad):
    with pytest.raises(ValueError, match="0..99"):
        set_realtime_priority(bad)


class _Logged:
    """What apply_requested_priority needs of a node: a logger that keeps the lines."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def get_logger(self):
        node = self

        class _Logger:
            def info(self, text):
                node.lines.append(("info", text))

            def warning(self, text):
                node.lines.append(("warning", text))

        return _Logger()


def test_a_node_only_asks_the_entry_point_that_owns_the_process_raises_it():
    """request_realtime_priority leaves the process alone (a node built in a test or a script must not put that
    program under SCHED_FIFO); apply_requested_priority, which hexa_ros.node.run calls, raises it to the highest
    priority asked for and each node that asked logs it."""
    before = realtime_priority_of()
    asking, quiet = _Logged(), _Logged()
    request_realtime_priority(asking, 12)
    assert realtime_priority_of() == before
    code = textwrap.dedent("""
        import json, sys
        sys.path.insert(0, sys.argv[1])
        from test_realtime_priority import _Logged
        from hexa_ros.realtime import apply_requested_priority, request_realtime_priority
        a, b, c = _Logged(), _Logged(), _Logged()
        request_realtime_priority(a, 12)
        request_realtime_priority(b, 20)
        got = apply_requested_priority([a, b, c])
        print(json.dumps({"got": got, "a": a.lines, "b": b.lines, "c": c.lines}))
    """)
    import json
    from pathlib import Path

    out = json.loads(subprocess.run([sys.executable, "-c", code, str(Path(__file__).parent)], capture_output=True,
                                    text=True, timeout=60, check=True).stdout)
    if _may_raise_priority():
        assert out["got"] == 20
        assert out["a"] == out["b"] == [["info", "realtime_priority: SCHED_FIFO 20"]]
    else:
        assert out["got"] == 0 and out["a"][0][0] == "warning" and "not granted" in out["a"][0][1]
    assert out["c"] == []
    assert apply_requested_priority([quiet]) == before      # nobody asked: nothing changes, nothing said
    assert quiet.lines == []
