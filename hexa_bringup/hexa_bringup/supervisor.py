"""Process supervisor for the hexa graph: one process per node, status table, respawn with back-off, signal
forwarding, non-zero exit when a required node cannot start. ROS-free (it only manages processes)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import Callable, TextIO

from hexa_ros.node import DUMP_STACKS_SIGNAL


class SupervisorError(RuntimeError):
    """A required node could not be started (missing module, or it keeps dying at start-up)."""


@dataclass
class NodeSpec:
    """How to run one node.

    Args are the node's name, its command line, whether the graph is useless without it (`required`), and whether
    a crash is answered by a restart (`respawn`); a node with `ends_graph` (a bag player) stops the whole graph when
    it finishes.
    """

    name: str
    cmd: list[str]
    required: bool = True
    respawn: bool = True
    ends_graph: bool = False


@dataclass
class _NodeState:
    spec: NodeSpec
    proc: subprocess.Popen | None = None
    started_at: float = 0.0
    restarts: int = 0
    next_start: float = 0.0
    backoff: float = 0.0
    state: str = "pending"  # pending | running | backoff | exited | failed
    last_rc: int | None = None
    quick_failures: int = 0
    log_path: str = ""
    history: list[str] = field(default_factory=list)


class Supervisor:
    """Starts `specs`, keeps them alive, and stops them all on SIGINT/SIGTERM.

    A node that exits is restarted after a back-off doubling from `backoff_initial` to `backoff_max` seconds (reset
    after `stable_after` seconds of uptime). A required node that dies within `stable_after` seconds
    `max_quick_failures` times in a row is declared unable to start: everything is stopped and run() returns 1.
    """

    def __init__(self, specs: list[NodeSpec], env: dict[str, str], log_dir: str | None = None,
                 out: TextIO = sys.stdout, status_every: float = 5.0, backoff_initial: float = 0.5,
                 backoff_max: float = 30.0, stable_after: float = 5.0, max_quick_failures: int = 3,
                 clock: Callable[[], float] = time.monotonic,
                 progress: Callable[[], str] | None = None) -> None:
        if not specs:
            raise SupervisorError("nothing to supervise: the graph has no nodes")
        names = [s.name for s in specs]
        if len(set(names)) != len(names):
            raise SupervisorError(f"node names must be unique, got {names}")
        self.nodes = [_NodeState(s) for s in specs]
        self.env = env
        self.log_dir = log_dir
        self.out = out
        self.status_every = status_every
        self.backoff_initial = backoff_initial
        self.backoff_max = backoff_max
        self.stable_after = stable_after
        self.max_quick_failures = max_quick_failures
        self.clock = clock
        self.progress = progress
        self._stop_signal: int | None = None
        self._finished = False
        self.failure: str | None = None

    # -- lifecycle ---------------------------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        print(f"[hexa bringup {time.strftime('%H:%M:%S')}] {text}", file=self.out, flush=True)

    def _start(self, node: _NodeState) -> None:
        stdout = None
        if self.log_dir:
            os.makedirs(self.log_dir, exist_ok=True)
            node.log_path = os.path.join(self.log_dir, f"{node.spec.name}.log")
            stdout = open(node.log_path, "ab")  # noqa: SIM115 - owned by the child
        try:
            node.proc = subprocess.Popen(node.spec.cmd, env=self.env, stdout=stdout,
                                         stderr=subprocess.STDOUT if stdout else None, start_new_session=True)
        except OSError as exc:
            node.state = "failed"
            node.history.append(f"cannot exec: {exc}")
            self._say(f"{node.spec.name}: cannot start {node.spec.cmd[0]!r}: {exc}")
            if node.spec.required:
                self.failure = f"required node {node.spec.name} cannot start: {exc}"
            return
        finally:
            if stdout is not None:
                stdout.close()
        node.started_at = self.clock()
        node.state = "running"
        self._say(f"{node.spec.name}: started pid {node.proc.pid}" + (f" (restart {node.restarts})"
                                                                      if node.restarts else ""))

    def _check(self, node: _NodeState, now: float) -> None:
        if node.state == "backoff" and now >= node.next_start:
            node.restarts += 1
            self._start(node)
            return
        if node.state != "running" or node.proc is None:
            return
        rc = node.proc.poll()
        if rc is None:
            if now - node.started_at > self.stable_after:
                node.quick_failures = 0
                node.backoff = 0.0
            return
        node.last_rc = rc
        uptime = now - node.started_at
        quick = uptime < self.stable_after and rc != 0
        node.quick_failures = node.quick_failures + 1 if quick else 0
        if node.spec.required and node.spec.respawn and node.quick_failures >= self.max_quick_failures:
            node.state = "failed"
            self.failure = (f"required node {node.spec.name} exited with code {rc} {node.quick_failures} times "
                            f"within {self.stable_after:g} s of starting" +
                            (f"; see {node.log_path}" if node.log_path else ""))
            self._say(self.failure)
            return
        if node.spec.ends_graph or not node.spec.respawn:
            node.state = "exited"
            self._say(f"{node.spec.name}: exited with code {rc} (not respawned)")
            if node.spec.required and rc != 0:
                self.failure = f"required node {node.spec.name} exited with code {rc}"
            elif node.spec.ends_graph:
                self._finished = True
            return
        node.backoff = self.backoff_initial if node.backoff == 0 else min(self.backoff_max, node.backoff * 2)
        node.next_start = now + node.backoff
        node.state = "backoff"
        node.history.append(f"exit {rc} after {uptime:.1f} s")
        self._say(f"{node.spec.name}: exited with code {rc} after {uptime:.1f} s; respawning in {node.backoff:.1f} s")

    def status_table(self) -> str:
        """A fixed-width table: node, state, pid, restarts, uptime, last exit code."""
        now = self.clock()
        rows = [f"{'node':20s} {'state':8s} {'pid':>7s} {'restarts':>8s} {'uptime':>8s} {'last rc':>7s}"]
        for n in self.nodes:
            pid = str(n.proc.pid) if n.proc is not None and n.state == "running" else "-"
            up = f"{now - n.started_at:.0f}s" if n.state == "running" else "-"
            rc = "-" if n.last_rc is None else str(n.last_rc)
            rows.append(f"{n.spec.name:20s} {n.state:8s} {pid:>7s} {n.restarts:>8d} {up:>8s} {rc:>7s}")
        return "\n".join(rows)

    def request_stop(self, signum: int = signal.SIGINT) -> None:
        """Ask run() to stop all nodes (called from a signal handler)."""
        self._stop_signal = signum

    def stop_all(self, signum: int = signal.SIGINT, timeout: float = 10.0) -> None:
        """Forward `signum` to every node's process group, wait up to `timeout`, then SIGKILL what is left (after
        asking it to write its threads' stacks to its log: hexa_ros.node.install_signal_handlers)."""
        live = [n for n in self.nodes if n.proc is not None and n.proc.poll() is None]
        for n in live:
            try:
                os.killpg(n.proc.pid, signum)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + timeout
        for n in live:
            try:
                n.proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                self._say(f"{n.spec.name}: did not stop within {timeout:g} s; killing (its threads' stacks are at "
                          "the end of its log)")
                try:
                    os.killpg(n.proc.pid, DUMP_STACKS_SIGNAL)   # hexa_ros.node: each thread's stack to its log
                    n.proc.wait(timeout=0.5)
                except (ProcessLookupError, subprocess.TimeoutExpired):
                    pass
                try:
                    os.killpg(n.proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                n.proc.wait(timeout=5)
            n.state = "exited"
            n.last_rc = n.proc.returncode

    def run(self, duration: float = 0.0, install_signal_handlers: bool = True) -> int:
        """Start the graph and supervise it until a signal, `duration` seconds (0 = forever) or a failure.
        With `install_signal_handlers`, SIGINT/SIGTERM stop the graph while it runs (`stopped_by`); the process's
        previous handlers are back when this returns, so a Ctrl-C after the graph stopped reaches the caller.

        Returns:
            0 after a requested stop or the duration; 1 when a required node could not be kept running.
        """
        previous = {}
        if install_signal_handlers:
            for sig in (signal.SIGINT, signal.SIGTERM):
                previous[sig] = signal.signal(sig, lambda s, f: self.request_stop(s))
        try:
            return self._supervise(duration)
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, signal.SIG_DFL if handler is None else handler)   # None: set outside Python

    @property
    def stopped_by(self) -> int | None:
        """The signal that stopped the graph (`request_stop`), None when it ended by itself, its duration or a
        failure."""
        return self._stop_signal

    def _supervise(self, duration: float) -> int:
        for n in self.nodes:
            self._start(n)
        start = self.clock()
        next_status = start
        try:
            while self._stop_signal is None and self.failure is None and not self._finished:
                now = self.clock()
                for n in self.nodes:
                    self._check(n, now)
                if now >= next_status:
                    print(self.status_table(), file=self.out, flush=True)
                    if self.progress is not None:
                        self._say(self.progress())
                    next_status = now + self.status_every
                if duration and now - start >= duration:
                    break
                time.sleep(0.05)
        finally:
            sig = self._stop_signal or signal.SIGINT
            self._say(f"stopping {len(self.nodes)} nodes (signal {signal.Signals(sig).name})")
            self.stop_all(sig)
            print(self.status_table(), file=self.out, flush=True)
        if self.failure:
            self._say(f"FAILED: {self.failure}")
            return 1
        return 0
