"""`hexa bench graph`: the live node graph measured on recorded sensor data and on emulated hardware.

Replay: the sensor inputs of a bag (both cameras' colour, aligned depth and camera_info, `motor_currents`,
`joint_states`; /clock from the bag's time) are played by `hexa play` in its own process at a rate R into the
processing graph `hexa bringup replay` starts (hexa_bringup.graphs.build_graph("replay")). A measuring subscriber
(hexa_bringup.bench_graph_probe, its own process) notes when each output arrives; the player logs when it published
each input. The report: CPU per node process from /proc over the playing window, latencies (frame → plate_pose,
current sample → residual, collision START → first contact and first contact_wrench), inputs against outputs per
node, and the outputs against a slow replay (rate 0.3) of the same bag. The player stands in for the driver and
the measuring subscriber must not add its own wait to what it measures: both run at the observer's
`realtime_priority` (`safety_priority`: `--realtime-priority`, else the parameters file's; hexa_ros.realtime), as
the driver does.

Robot: the graph `hexa bringup robot` starts, without the simulator and the trajectory node, at 1× wall time: both
camera nodes in `folder` source on frames of the bag taken while the robot was at rest, the driver against the
emulated Uno and Mega (hexa.protocol.emulator) streaming the bag's rest currents at 1 kHz and at 200 Hz, a hold
command at the rest pose; the emulated boards (microcontrollers on the robot) and the measuring subscriber at the
observer's `realtime_priority`. The report: CPU per process, the rates achieved, frame → plate_pose and sample →
residual.

Without a BAG the bench records one first (the plate case of `hexa demo` with the camera topics, currents at 1 kHz)
and keeps it under the cache directory for the next runs.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import pickle
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from hexa.benchmarks import BenchRow
from hexa_bringup.bench_graph_analysis import (cdr_stamp_ns, compare_contacts, compare_events, fifo_pairs,
                                               latency_stats, match_nearest, unwrap_board_us, within_percent)
# the inputs played from a bag, relative to the graph's namespace: the replay graph's sensor inputs (one definition)
from hexa_bringup.graphs import CAMERA_TOPICS, CAMERAS  # noqa: F401 - bench_graph_robot takes them from here
from hexa_bringup.graphs import SENSOR_INPUTS as INPUTS
from hexa_ros.diagnostics import values_of
from hexa_ros.realtime import REALTIME_PRIORITY, REALTIME_PRIORITY_PARAM, set_realtime_priority


#: outputs of the processing graph the probe listens to: topic → message type
OUTPUTS = {"plate_pose": "geometry_msgs/msg/PoseStamped", "residual": "hexa_msgs/msg/Residual",
           "collision": "hexa_msgs/msg/CollisionEvent", "contact": "hexa_msgs/msg/Contact",
           "contact_wrench": "hexa_msgs/msg/ContactWrench", "singularity": "hexa_msgs/msg/SingularityIndices"}
#: rate of the slow reference replay (one the graph keeps up with on two cores)
REFERENCE_RATE = 0.3
#: targets (s, %) printed beside the figures
TARGET_P95 = {"frame_pose": 0.040, "sample_residual": 0.005, "start_contact": 0.100, "start_wrench": 0.120}
TARGET_CPU = 100.0
RECORD_CASE = "plate"
RECORD_STREAM_HZ = 1000


class BenchGraphError(RuntimeError):
    """The bench cannot run (missing bag or topics, a node that does not start); the message says what to do."""


@dataclass
class Options:
    """What `hexa bench graph` runs; see the command's --help."""

    bag: Path | None = None
    rate: float = 1.0
    reference: bool = True
    replay: bool = True
    robot: bool = True
    sim: bool = True
    robot_duration: float = 10.0
    cache: Path = Path("out/bench")
    params: Path | None = None
    domain_id: int | None = None
    ready_timeout: float = 120.0
    compose: bool = False
    stream_rate: int = RECORD_STREAM_HZ
    realtime_priority: int | None = None


def say(text: str) -> None:
    """Progress on stderr."""
    print(f"[hexa bench graph {time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------------------------
# processes


@contextmanager
def held_domain(forced: int | None = None) -> Iterator[int]:
    """A ROS_DOMAIN_ID (1..100) no other hexa test or bench holds (hexa_ros.env.held_ros_domain), held until the
    block ends; `forced` is used as given."""
    from hexa_ros.env import NoFreeDomain, held_ros_domain

    if forced is not None:
        yield int(forced)
        return
    try:
        with held_ros_domain() as domain:
            yield domain
    except NoFreeDomain as exc:
        raise BenchGraphError(f"{exc}; pass --domain-id N") from exc


class Children:
    """Child processes, each in its own session; stop_all() (also on leaving the `with` block) sends SIGINT to each
    process group, waits, and kills what is left. A child started with a `priority` runs under SCHED_FIFO at it from
    its first instruction (hexa_ros.realtime; not granted: normal priority, said once)."""

    def __init__(self, env: dict[str, str]) -> None:
        self.env = env
        self.procs: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, Path] = {}
        self._said_priority = False

    def start(self, name: str, cmd: list[str], log: Path | None = None, pipe: bool = False,
              priority: int = 0) -> subprocess.Popen:
        out: Any = subprocess.PIPE if pipe else subprocess.DEVNULL
        err: Any = subprocess.DEVNULL
        fh = None
        if log is not None:
            log.parent.mkdir(parents=True, exist_ok=True)
            fh = open(log, "wb")  # noqa: SIM115 - the child owns it
            err = fh
            if not pipe:
                out = fh
            self.logs[name] = log
        try:
            proc = subprocess.Popen(cmd, env=self.env, stdout=out, stderr=err, start_new_session=True,
                                    text=pipe or None)
        except OSError as exc:
            raise BenchGraphError(f"cannot start {name} ({cmd[0]}): {exc}") from exc
        finally:
            if fh is not None:
                fh.close()
        self.procs[name] = proc
        why = set_realtime_priority(priority, proc.pid)
        if why and not self._said_priority:
            say(f"{name}: {why}")
            self._said_priority = True
        return proc

    def dead(self) -> list[str]:
        """Names of children that have exited."""
        return [n for n, p in self.procs.items() if p.poll() is not None]

    def log_tail(self, name: str, lines: int = 8) -> str:
        path = self.logs.get(name)
        if path is None or not path.exists():
            return ""
        text = path.read_text(errors="replace").strip().splitlines()
        return "\n".join("    " + line for line in text[-lines:])

    def stop(self, names: list[str], timeout: float = 10.0) -> None:
        live = [(n, self.procs[n]) for n in names if n in self.procs and self.procs[n].poll() is None]
        for _n, p in live:
            try:
                os.killpg(p.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + timeout
        for _n, p in live:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(p.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                p.wait(timeout=5)

    def stop_all(self, timeout: float = 10.0) -> None:
        self.stop(list(self.procs), timeout)

    def __enter__(self) -> "Children":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_all()


class CpuSampler:
    """Cumulative CPU seconds (utime + stime from /proc/<pid>/stat) of named processes, sampled in a thread."""

    def __init__(self, pids: dict[str, int], period: float = 0.1) -> None:
        self.pids = dict(pids)
        self.period = period
        self.tick = float(os.sysconf("SC_CLK_TCK"))
        self.t: list[float] = []
        self.cpu: dict[str, list[float]] = {n: [] for n in pids}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._last: dict[str, float] = {n: 0.0 for n in pids}

    def _read(self, pid: int) -> float | None:
        try:
            with open(f"/proc/{pid}/stat", "rb") as f:
                fields = f.read().rsplit(b")", 1)[1].split()
        except OSError:
            return None
        return (int(fields[11]) + int(fields[12])) / self.tick  # utime, stime (fields 14, 15 of stat)

    def sample(self) -> None:
        t = time.monotonic()
        for name, pid in self.pids.items():
            v = self._read(pid)
            if v is not None:
                self._last[name] = v
            self.cpu[name].append(self._last[name])
        self.t.append(t)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.sample()
            self._stop.wait(self.period)

    def __enter__(self) -> "CpuSampler":
        self.sample()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.sample()

    def seconds(self, name: str, t0: float, t1: float) -> float:
        """CPU seconds `name` used between monotonic times t0 and t1 (interpolated between samples)."""
        t = np.asarray(self.t)
        c = np.asarray(self.cpu[name])
        return float(np.interp(t1, t, c) - np.interp(t0, t, c))

    def percent(self, name: str, t0: float, t1: float) -> float:
        """Mean CPU of `name` between t0 and t1 in % of one core."""
        return 100.0 * self.seconds(name, t0, t1) / max(t1 - t0, 1e-9)


class Probe:
    """The measuring subscriber process (hexa_bringup.bench_graph_probe probe) and its stdout."""

    def __init__(self, children: Children, work: Path, spec: dict, name: str = "probe",
                 priority: int = 0) -> None:
        work.mkdir(parents=True, exist_ok=True)
        self.spec_path = work / "probe_spec.json"
        self.out_path = work / "probe.pickle"
        if self.out_path.exists():
            self.out_path.unlink()
        self.spec_path.write_text(json.dumps(spec))
        self.children, self.name = children, name
        self.proc = children.start(name, [sys.executable, "-m", "hexa_bringup.bench_graph_probe", "probe",
                                          str(self.spec_path), str(self.out_path)], log=work / "probe.log", pipe=True,
                                    priority=priority)
        self.lines: queue.Queue[str] = queue.Queue()
        self.ready = False
        self.subscribers: dict[str, int] = {}    # input topic → its readers in the graph, said before READY
        self.waiting: list[str] = []
        self.rx = 0
        self.rx_changed = time.monotonic()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            line = line.strip()
            if line == "READY":
                self.ready = True
            elif line.startswith("SUBSCRIBERS "):
                self.subscribers = json.loads(line[12:])
            elif line.startswith("WAITING "):
                self.waiting = json.loads(line[8:])
            elif line.startswith("RX "):
                n = int(line[3:])
                if n != self.rx:
                    self.rx, self.rx_changed = n, time.monotonic()

    def wait_ready(self, timeout: float, what: str) -> None:
        """Until READY; raises BenchGraphError naming what is missing, or the child that died (with its log)."""
        deadline = time.monotonic() + timeout
        next_note = time.monotonic() + 15.0
        while not self.ready:
            dead = self.children.dead()
            if dead:
                name = dead[0]
                rc = self.children.procs[name].returncode
                raise BenchGraphError(f"{what}: {name} exited with code {rc} before the graph was up:\n"
                                      f"{self.children.log_tail(name)}")
            if time.monotonic() > deadline:
                raise BenchGraphError(f"{what}: the graph was not up within {timeout:.0f} s; still missing: "
                                      f"{', '.join(self.waiting) or '?'} (logs in {self.spec_path.parent})")
            if time.monotonic() > next_note:
                say(f"{what}: waiting for {', '.join(self.waiting) or 'the graph'}")
                next_note = time.monotonic() + 15.0
            time.sleep(0.1)

    def wait_quiet(self, quiet: float = 2.0, limit: float = 60.0) -> None:
        """Until no output arrived for `quiet` s (at most `limit` s)."""
        end = time.monotonic() + limit
        while time.monotonic() < end and time.monotonic() - self.rx_changed < quiet:
            time.sleep(0.1)

    def finish(self) -> dict[str, list[tuple[int, bytes]]]:
        """Stop the probe and load what it received."""
        self.children.stop([self.name], timeout=20.0)
        if not self.out_path.exists():
            raise BenchGraphError(f"the measuring subscriber wrote no data (log: {self.spec_path.parent}/probe.log)")
        with open(self.out_path, "rb") as f:
            return pickle.load(f)


def node_names(cmd: list[str], default: str) -> list[str]:
    """The node names a process runs: its `__node:=NAME` (or `node:__node:=NAME`) remaps and the NAME of each
    NAME=MODULE:CLASS of a composed process (hexa_ros.compose), else `default`."""
    import re

    cut = cmd.index("--ros-args") if "--ros-args" in cmd else len(cmd)
    names = [m.group(1) for a in cmd[:cut] if (m := re.match(r"^([A-Za-z_]\w*)=[A-Za-z_][\w.]*:[A-Za-z_]\w*$", a))]
    names += [a.split(":=", 1)[1] for a in cmd[cut:] if a.startswith("__node:=") or ":__node:=" in a]
    return names or [default]


def safety_priority(params: Path, ns: str = "/hexa", priority: int | None = None) -> int:
    """The SCHED_FIFO priority of the observer: `priority` (`--realtime-priority`) when given, else what `params`
    gives it (`realtime_priority`; the node's default without one). The bench's stand-ins for the driver and the
    boards, and its measuring subscriber, run at it too."""
    import yaml

    if priority is not None:
        return int(priority)

    from hexa_bringup.commands.service import node_parameters

    try:
        data = yaml.safe_load(params.read_text(encoding="utf-8")) if params.is_file() else None
    except (OSError, yaml.YAMLError):
        data = None
    given = node_parameters(data, f"{ns.rstrip('/')}/observer") if isinstance(data, dict) else {}
    return int(given.get(REALTIME_PRIORITY, REALTIME_PRIORITY_PARAM.default))


def graph_specs(mode: str, ns: str, params: Path, node_args: dict[str, list[str]] | None = None,
                compose: bool = False, priority: int | None = None) -> list:
    """hexa_bringup.graphs.build_graph(...), as `hexa bringup MODE [--compose] [--realtime-priority priority]` builds
    it (in sim mode with the calibration overlay of the simulated robot for every node but the simulator).

    Raises:
        BenchGraphError: a required node is not installed, composition is asked of a builder without it, or the
        simulated robot cannot be calibrated.
    """
    from hexa_bringup.commands.bringup import with_nodes_description, with_realtime_priority
    from hexa_bringup.graphs import build_graph
    from hexa_bringup.supervisor import SupervisorError

    try:
        if priority is not None:
            node_args = with_realtime_priority(node_args or {}, priority)     # a new dict
        node_args = with_nodes_description(mode, ns, params, dict(node_args or {}),   # stdout: the bench's table
                                           log=lambda line: print(f"hexa bench graph: {line}", file=sys.stderr))
        if compose:
            return build_graph(mode, ns, params, node_args, compose=True)
        return build_graph(mode, ns, params, node_args)
    except TypeError as exc:
        raise BenchGraphError(f"this checkout's graph builder cannot compose nodes ({exc})") from exc
    except SupervisorError as exc:
        raise BenchGraphError(str(exc)) from exc


# ---------------------------------------------------------------------------------------------------------------
# the bag


@dataclass
class BagInputs:
    """The sensor inputs of a bag: what is played and what it holds."""

    path: Path
    ns: str
    topics: list[str]
    duration: float
    counts: dict[str, int]
    stream_period: float
    camera_fps: float
    board_coverage: float

    def rel(self, topic: str) -> str:
        return topic[len(self.ns) + 1:] if topic.startswith(self.ns + "/") else topic


def bag_inputs(bag: Path) -> BagInputs:
    """The input topics of `bag` (namespace from its motor_currents topic) and a few figures about them.

    Raises:
        BenchGraphError: the bag is missing, unreadable, or lacks an input topic.
    """
    from hexa_bringup.bag import bag_topics, read_bag, typestore

    if not bag.exists():
        raise BenchGraphError(f"bag {bag} does not exist (omit BAG to record the default bag)")
    try:
        topics = bag_topics(bag)
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types
        raise BenchGraphError(f"cannot read bag {bag}: {exc}") from exc
    ns_cands = sorted(t[: -len("/motor_currents")] for t in topics if t.endswith("/motor_currents"))
    if not ns_cands:
        raise BenchGraphError(f"bag {bag} has no motor_currents topic; the bench needs the sensor inputs "
                              f"{', '.join(INPUTS)} (record them with `hexa demo --case plate --record-images`)")
    ns = ns_cands[0] or "/"
    wanted = [f"{ns.rstrip('/')}/{t}" for t in INPUTS]
    missing = [t for t in wanted if t not in topics or topics[t][1] == 0]
    if missing:
        raise BenchGraphError(f"bag {bag} lacks the input topic(s) {', '.join(missing)}; the bench needs both "
                              f"cameras (colour, aligned depth, camera_info), motor_currents and joint_states "
                              f"(`hexa demo --case plate --record-images` records them)")
    store = typestore()
    board, stamps, top = [], [], []
    for topic, msgtype, stamp, data in read_bag(bag, [wanted[-2], wanted[0]]):
        stamps.append(stamp)
        if topic == wanted[-2]:
            board.append(store.deserialize_cdr(data, msgtype).board_time_us)
        else:
            top.append(cdr_stamp_ns(data) * 1e-9)
    b = unwrap_board_us(board)
    period = float(np.median(np.diff(b))) if b.size > 1 else 1e-3
    span = float(b[-1] - b[0]) if b.size > 1 else 0.0
    coverage = b.size / (span / period + 1) if span > 0 else 1.0
    dt = np.diff(np.unique(top))
    fps = 1.0 / float(np.median(dt)) if dt.size else 30.0
    return BagInputs(bag, ns.rstrip("/") or "/", wanted, (max(stamps) - min(stamps)) * 1e-9,
                     {t: topics[t][1] for t in wanted}, period, fps, coverage)


def bag_identity(bag: Path) -> list:
    """Name, size and mtime of every file of a bag (a cache key part)."""
    files = sorted(bag.rglob("*")) if bag.is_dir() else [bag]
    return [(str(f.relative_to(bag) if bag.is_dir() else f.name), f.stat().st_size, f.stat().st_mtime_ns)
            for f in files if f.is_file()]


def record_default_bag(cache: Path, stream_rate: int = RECORD_STREAM_HZ) -> Path:
    """The default bag (cache/graph_bag, or graph_bag_<rate>hz): the plate case of `hexa demo`, made by the
    simulator alone with the currents at `stream_rate` Hz and both cameras at 30 fps (hexa_bringup.bench_bag), when
    it is not there yet."""
    from hexa_bringup.bench_bag import synthesize

    target = cache / ("graph_bag" if stream_rate == RECORD_STREAM_HZ else f"graph_bag_{stream_rate}hz")
    if target.exists():
        return target
    work = target.with_name(target.name + ".partial")
    if work.exists():
        shutil.rmtree(work)
    cache.mkdir(parents=True, exist_ok=True)
    say(f"no bag given and none cached: simulating the '{RECORD_CASE}' case with both cameras and currents at "
        f"{stream_rate} Hz into {target} (about half a minute)")
    t0 = time.monotonic()
    synthesize(work, RECORD_CASE, stream_rate_hz=stream_rate, progress=say)
    work.rename(target)
    say(f"made {target} in {time.monotonic() - t0:.0f} s")
    return target


def input_index(info: BagInputs) -> dict[str, dict[str, np.ndarray]]:
    """Per input topic: bag stamps (ns), header stamps (ns) and, for motor_currents, board times (s, unwrapped), in
    the order the player publishes them."""
    from hexa_bringup.bag import read_bag, typestore

    store = typestore()
    rows: dict[str, dict[str, list]] = {t: {"bag": [], "stamp": [], "board_us": []} for t in info.topics}
    currents = f"{info.ns}/motor_currents"
    for topic, msgtype, stamp, data in read_bag(info.path, info.topics):
        r = rows[topic]
        r["bag"].append(stamp)
        r["stamp"].append(cdr_stamp_ns(data))
        if topic == currents:
            r["board_us"].append(store.deserialize_cdr(data, msgtype).board_time_us)
    out = {}
    for t, r in rows.items():
        out[t] = {"bag": np.asarray(r["bag"], dtype=np.int64), "stamp": np.asarray(r["stamp"], dtype=np.int64)}
        if t == currents:
            out[t]["board"] = unwrap_board_us(r["board_us"])
    return out


def player_times(log: Path, index: dict[str, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Per input topic, the monotonic time (s) at which the player published each message of `index` (NaN when it
    did not)."""
    from collections import defaultdict, deque

    slots: dict[tuple[str, int], deque] = defaultdict(deque)
    if log.exists():
        with open(log, encoding="utf-8") as f:
            for line in f:
                parts = line.split()
                if len(parts) == 3:
                    slots[(parts[2], int(parts[1]))].append(int(parts[0]) * 1e-9)
    out = {}
    for topic, r in index.items():
        w = np.full(r["bag"].size, np.nan)
        for k, s in enumerate(r["bag"]):
            q = slots.get((topic, int(s)))
            if q:
                w[k] = q.popleft()
        out[topic] = w
    return out


def published_topics(log: Path) -> dict[str, int]:
    """Messages per topic in a player log."""
    from collections import Counter

    c: Counter[str] = Counter()
    if log.exists():
        with open(log, encoding="utf-8") as f:
            for line in f:
                parts = line.split()
                if len(parts) == 3:
                    c[parts[2]] += 1
    return dict(c)


# ---------------------------------------------------------------------------------------------------------------
# outputs


#: the top camera's last message of each frame: robot mode's measuring subscriber reads it for the frames' stamps
#: instead of the images (hexa_bringup.bench_graph_robot)
TOP_FRAME_INFO = "cam_top/aligned_depth_to_color/camera_info"


def parse_outputs(received: dict[str, list[tuple[int, bytes]]], ns: str) -> dict[str, Any]:
    """Arrival times (monotonic s) and contents of the outputs the probe received."""
    from hexa_bringup.bag import typestore

    store = typestore()
    t = f"{ns.rstrip('/')}/"
    out: dict[str, Any] = {}
    for name in ("plate_pose", "residual", "singularity", "joint_states", TOP_FRAME_INFO):
        rows = received.get(t + name, [])
        out[name] = (np.asarray([r * 1e-9 for r, _ in rows]), np.asarray([cdr_stamp_ns(d) for _, d in rows],
                                                                          dtype=np.int64))
    cur = received.get(t + "motor_currents", [])
    msgs = [store.deserialize_cdr(d, "hexa_msgs/msg/MotorCurrents") for _, d in cur]
    board_us = [int(m.board_time_us) for m in msgs]
    out["motor_currents"] = {"recv": np.asarray([r * 1e-9 for r, _ in cur]), "board": unwrap_board_us(board_us),
                             "board_us": board_us,
                             "stamp": np.asarray([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs])}
    out["collision"] = []
    for r, d in received.get(t + "collision", []):
        m = store.deserialize_cdr(d, OUTPUTS["collision"])
        out["collision"].append({"recv": r * 1e-9, "kind": "START" if m.event == 0 else "END", "id": int(m.id),
                                 "onset": m.onset.sec + m.onset.nanosec * 1e-9,
                                 "stamp": m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, "axis": m.axis_name})
    for name in ("contact", "contact_wrench"):
        out[name] = []
        for r, d in received.get(t + name, []):
            m = store.deserialize_cdr(d, OUTPUTS[name])
            out[name].append({"recv": r * 1e-9, "id": int(m.collision_id), "link": int(m.link), "chain": int(m.chain),
                              "stamp": m.header.stamp.sec + m.header.stamp.nanosec * 1e-9})
    diags: dict[str, dict[str, str]] = {}
    offsets: list[tuple[float, float]] = []     # (arrival, the observer's board_clock_offset_s)
    for r, d in received.get("/diagnostics", []):
        try:
            m = store.deserialize_cdr(d, "diagnostic_msgs/msg/DiagnosticArray")
        except Exception:  # noqa: BLE001 - diagnostics are informative only
            continue
        for st in m.status:
            diags[st.name] = values_of(st)
            said = diags[st.name].get("board_clock_offset_s", "") if st.name == f"{t}observer" else ""
            if said:
                offsets.append((r * 1e-9, float(said)))
    out["diagnostics"] = diags
    out["board_clock_offsets"] = offsets
    return out


def event_latency(outputs: dict[str, Any], what: str) -> list[float]:
    """Per collision, wall seconds from the arrival of its START to the arrival of its first `what`."""
    starts = {e["id"]: e["recv"] for e in outputs["collision"] if e["kind"] == "START"}
    first: dict[int, float] = {}
    for c in outputs[what]:
        first[c["id"]] = min(first.get(c["id"], math.inf), c["recv"])
    return [first[i] - t for i, t in starts.items() if i in first]


def frame_pose_latency(frames_stamp: np.ndarray, frames_time: np.ndarray, outputs: dict[str, Any]
                       ) -> tuple[list[float], int, int]:
    """Latencies frame → plate_pose (pose arrival − frame time, matched by stamp), the number of frames and of
    frames with a pose."""
    recv, stamps = outputs["plate_pose"]
    pairs = fifo_pairs(list(frames_stamp), list(stamps))
    return [float(recv[j] - frames_time[i]) for i, j in pairs], len(frames_stamp), len(pairs)


def top_frames(stamp_c: np.ndarray, time_c: np.ndarray, stamp_d: np.ndarray, time_d: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Complete (colour + depth) frames: their stamps and the time the later of the two was out."""
    pairs = fifo_pairs(list(stamp_c), list(stamp_d))
    ok = [(i, j) for i, j in pairs if np.isfinite(time_c[i]) and np.isfinite(time_d[j])]
    return (np.asarray([stamp_c[i] for i, _ in ok], dtype=np.int64),
            np.asarray([max(time_c[i], time_d[j]) for i, j in ok]))


# ---------------------------------------------------------------------------------------------------------------
# replay


@dataclass
class ReplayResult:
    rate: float
    window: tuple[float, float]
    bag_span: float                              # bag seconds played in the window
    achieved_rate: float                         # bag_span / window length
    cpu: dict[str, float]                        # process name → % of one core over the playing window
    cpu_after: dict[str, float]                  # process name → CPU seconds after the window (backlog)
    nodes: dict[str, list[str]]                  # process name → node names
    pids: dict[str, int]
    processing: list[str]                        # processes of the graph
    published: dict[str, int]                    # player log: topic → messages
    outputs: dict[str, Any]
    frames: int                                  # complete top-camera frames published
    frame_latency: list[float]
    poses_matched: int
    currents: int                                # motor_currents published
    residual_latency: list[float]
    residual_matched: int
    currents_after_first: int                    # samples from the one of the first residual on
    settling: int                                # samples before the first residual
    wall: float


def summary_for_reference(r: ReplayResult) -> dict:
    """What a comparison needs from a (reference) replay, JSON-ready."""
    strip = [{k: v for k, v in e.items() if k != "recv"} for e in r.outputs["collision"]]
    return {"rate": r.rate, "events": strip,
            "contacts": [{k: v for k, v in c.items() if k != "recv"} for c in r.outputs["contact"]],
            "wrenches": len(r.outputs["contact_wrench"]), "poses": int(r.outputs["plate_pose"][0].size),
            "wrench_stamps": sorted(w["stamp"] for w in r.outputs["contact_wrench"]),
            "residuals": int(r.outputs["residual"][0].size), "frames": r.frames, "currents": r.currents,
            "singularity": int(r.outputs["singularity"][0].size), "poses_matched": r.poses_matched,
            "residuals_missing": r.currents_after_first - r.residual_matched}


def replay_once(info: BagInputs, index: dict, rate: float, env: dict[str, str], params: Path, work: Path,
                ready_timeout: float, compose: bool = False, priority: int | None = None) -> ReplayResult:
    """Bring up the replay graph, wait for it, play the bag's inputs at `rate`, collect the outputs (`priority`:
    `--realtime-priority`)."""
    specs = graph_specs("replay", info.ns, params, compose=compose, priority=priority)
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    nodes = {s.name: node_names(s.cmd, s.name) for s in specs}
    ns = info.ns
    probe_spec = {"ns": ns, "topics": [{"topic": f"{ns}/{t}", "type": ty, "qos": "reliable",
                                        "keep": 0 if t in ("collision", "contact", "contact_wrench") else 16,
                                        "count": True} for t, ty in OUTPUTS.items()]
                  + [{"topic": "/diagnostics", "type": "diagnostic_msgs/msg/DiagnosticArray", "qos": "reliable"}],
                  "nodes": [n for names in nodes.values() for n in names],
                  "ready_publishers": [f"{ns}/{t}" for t in OUTPUTS], "subscribers_of": list(info.topics)}
    log = work / "player.log"
    what = f"replay at {rate:g}x"
    t_start = time.monotonic()
    with Children(env) as ch:
        priority = safety_priority(params, ns, priority)
        probe = Probe(ch, work, probe_spec, priority=priority)
        for s in specs:
            ch.start(s.name, s.cmd, log=work / f"{s.name}.log")
        say(f"{what}: starting {len(specs)} node processes ({', '.join(nodes)}) and waiting for them")
        probe.wait_ready(ready_timeout, what)
        pids = {s.name: ch.procs[s.name].pid for s in specs}
        player_cmd = [sys.executable, "-m", "hexa_bringup.cli", "play", str(info.path), "--clock", "--rate",
                      f"{rate:g}", "--wait", "30", "--wait-subscribers", "--log", str(log), "--topics",
                      *info.topics]
        shared = [f"{t}={n}" for t, n in probe.subscribers.items() if n > 1]
        if shared:   # every reader matched, not one of several: pose and isolation both read cam_top's images
            player_cmd += ["--subscribers", *shared]
        player = ch.start("player", player_cmd, log=work / "player.out", priority=priority)
        pids["player"] = player.pid
        pids["probe"] = probe.proc.pid
        say(f"{what}: playing {info.duration:.1f} s of sensor data ({len(info.topics)} topics + /clock)")
        with CpuSampler(pids) as cpu:
            limit = time.monotonic() + info.duration / rate + 120.0
            next_note = time.monotonic() + 10.0
            while player.poll() is None:
                if time.monotonic() > limit:
                    raise BenchGraphError(f"{what}: the player did not finish (log {work / 'player.out'})")
                dead = [n for n in ch.dead() if n not in ("player",)]
                if dead:
                    raise BenchGraphError(f"{what}: {dead[0]} exited during the replay:\n{ch.log_tail(dead[0])}")
                if time.monotonic() > next_note:
                    say(f"{what}: {time.monotonic() - t_start:.0f} s, {probe.rx} outputs received")
                    next_note = time.monotonic() + 10.0
                time.sleep(0.1)
            if player.returncode != 0:
                raise BenchGraphError(f"{what}: the player failed (exit {player.returncode}):\n"
                                      f"{ch.log_tail('player')}")
            probe.wait_quiet()
            t_end = time.monotonic()
        ch.stop([s.name for s in specs])
        received = probe.finish()
    published = published_topics(log)
    times = player_times(log, index)
    pub_t = np.concatenate([w[np.isfinite(w)] for w in times.values()] or [np.zeros(0)])
    if pub_t.size < 2:
        raise BenchGraphError(f"{what}: the player published nothing (log {work / 'player.out'})")
    w0, w1 = float(pub_t.min()), float(pub_t.max())
    bag_t = np.concatenate([index[t]["bag"][np.isfinite(w)] for t, w in times.items()])
    bag_span = float(bag_t.max() - bag_t.min()) * 1e-9
    names = list(pids)
    out = parse_outputs(received, ns)
    # frame → plate_pose
    c, d = index[f"{ns}/cam_top/color/image_raw"], index[f"{ns}/cam_top/aligned_depth_to_color/image_raw"]
    f_stamp, f_time = top_frames(c["stamp"], times[f"{ns}/cam_top/color/image_raw"], d["stamp"],
                                 times[f"{ns}/cam_top/aligned_depth_to_color/image_raw"])
    fl, n_frames, n_matched = frame_pose_latency(f_stamp, f_time, out)
    # sample → residual
    cur = index[f"{ns}/motor_currents"]
    cur_t = times[f"{ns}/motor_currents"]
    sent = np.isfinite(cur_t)
    board = cur["board"][sent]
    board_t = cur_t[sent]
    r_recv, r_stamp = out["residual"]
    idx = match_nearest(r_stamp * 1e-9, board)   # with sim time the observer's sample time is the board time
    ok = idx >= 0
    rl = (r_recv[ok] - board_t[idx[ok]]).tolist()
    first = int(idx[ok].min()) if ok.any() else board.size
    return ReplayResult(
        rate=rate, window=(w0, w1), bag_span=bag_span, achieved_rate=bag_span / max(w1 - w0, 1e-9),
        cpu={n: cpu.percent(n, w0, w1) for n in names},
        cpu_after={n: cpu.seconds(n, w1, t_end) for n in names}, nodes=nodes, pids=pids,
        processing=[s.name for s in specs], published=published, outputs=out, frames=n_frames, frame_latency=fl,
        poses_matched=n_matched, currents=int(board.size), residual_latency=rl,
        residual_matched=int(np.unique(idx[ok]).size), currents_after_first=int(board.size - first),
        settling=first, wall=time.monotonic() - t_start)


def reference_key(info: BagInputs, params: Path, compose: bool = False, priority: int | None = None) -> str:
    """Cache key of a reference replay: the bag's files, the replay graph's command lines, the parameters."""
    specs = graph_specs("replay", info.ns, params, compose=compose, priority=priority)
    h = hashlib.sha256()
    h.update(json.dumps({"v": 1, "rate": REFERENCE_RATE, "bag": str(info.path.resolve()),
                         "files": bag_identity(info.path), "graph": [[s.name, s.cmd] for s in specs],
                         "topics": info.topics}).encode())
    if params.is_file():
        h.update(params.read_bytes())
    return h.hexdigest()[:16]


# ---------------------------------------------------------------------------------------------------------------
# rows


def latency_rows(label: str, values: list[float], target: float | None, note: str) -> list[BenchRow]:
    s = latency_stats(values)
    nan = float("nan")
    rows = []
    for key in ("p50", "p95", "max"):
        v = s[key]
        tgt, met = "", None
        if key == "p95" and target is not None:
            tgt, met = f"<= {target:g} s", (v is not None and v <= target)
        rows.append(BenchRow(f"latency {label} {key}", nan if v is None else v, "s", tgt, met,
                             f"n = {s['n']}; {note}" if key == "p50" else ""))
    return rows


def cpu_rows(cpu: dict[str, float], nodes: dict[str, list[str]], pids: dict[str, int], processing: list[str],
              sources: list[str], extra: dict[str, str]) -> list[BenchRow]:
    rows = []
    for name in processing + sources:
        rows.append(BenchRow(f"CPU {name}", cpu[name], "% core", "", None,
                             f"pid {pids[name]}; nodes: {', '.join(nodes[name])}"))
    total = sum(cpu[n] for n in processing)
    rows.append(BenchRow("CPU processing nodes, total", total, "% core", f"<= {TARGET_CPU:g} %",
                         total <= TARGET_CPU, f"{', '.join(processing)}"))
    if sources:
        rows.append(BenchRow("CPU all nodes, total", total + sum(cpu[n] for n in sources), "% core", "", None,
                             f"processing + {', '.join(sources)}"))
    for name, label in extra.items():
        rows.append(BenchRow(f"CPU {label}", cpu[name], "% core", "", None, f"pid {pids[name]}; not a graph node"))
    return rows


def machine_speed_row(duration: float = 3.0) -> BenchRow:
    """The collision monitor's CPU per current sample in this process, now (`hexa bench realtime`'s first row on
    `duration` s of the plate case): this machine's speed varies by hour and day, and every CPU and latency figure of
    the graph moves with it, so each run says where it stood."""
    from hexa.benchmarks.realtime import monitor_cpu_per_sample, plate_case_stream

    stream = plate_case_stream(duration=duration)
    t = monitor_cpu_per_sample(stream, repeat=2)
    return BenchRow("machine: collision monitor per current sample (CPU, in-process)", t * 1e6, "us", "", None,
                    note=f"`hexa bench realtime`'s first row on {len(stream.samples)} samples; the graph's CPU "
                         f"figures move with it")


def replay_rows(r: ReplayResult, info: BagInputs, ref: dict | None, ref_note: str) -> list[BenchRow]:
    """The replay's figures beside their targets (and the reference replay's counts)."""
    out = r.outputs
    rows = cpu_rows(r.cpu, r.nodes, r.pids, r.processing, [], {"player": "player (hexa play)",
                                                                "probe": "measuring subscriber"})
    rows.append(BenchRow("player: achieved rate", r.achieved_rate, "x", f">= {0.95 * r.rate:g}x",
                         r.achieved_rate >= 0.95 * r.rate,
                         f"{r.bag_span:.2f} s of bag time in {r.window[1] - r.window[0]:.2f} s of wall time; below "
                         f"{r.rate:g}x the graph was fed slower than asked"))
    rows.append(BenchRow("bag: current samples present", 100.0 * info.board_coverage, "%", "", None,
                         f"{info.counts[info.ns + '/motor_currents']} samples at {1 / info.stream_period:.0f} Hz "
                         f"over the board-time span; a recording run that lost samples feeds fewer"))
    rows += latency_rows("frame -> plate_pose", r.frame_latency, TARGET_P95["frame_pose"],
                         "player publishes the frame (later of colour, depth) -> plate_pose arrives")
    rows += latency_rows("sample -> residual", r.residual_latency, TARGET_P95["sample_residual"],
                         "player publishes motor_currents -> residual arrives (stamp = board time)")
    rows += latency_rows("START -> contact", event_latency(out, "contact"), TARGET_P95["start_contact"],
                         "collision START arrives -> first contact of its id arrives")
    rows += latency_rows("START -> contact_wrench", event_latency(out, "contact_wrench"),
                         TARGET_P95["start_wrench"],
                         "collision START arrives -> first contact_wrench of its id arrives")
    n_pose = int(out["plate_pose"][0].size)
    ref_txt = (lambda k: f"; slow replay {ref[k]}") if ref else (lambda k: "")
    rows.append(BenchRow("pose: plate_pose per top frame", n_pose, "msgs", f"= {r.frames} frames",
                         r.poses_matched == r.frames,
                         f"{r.frames} complete top frames published, {r.poses_matched} with a pose{ref_txt('poses')}"))
    missing = r.currents_after_first - r.residual_matched
    rows.append(BenchRow("observer: current samples without a residual", missing, "samples", "0", missing == 0,
                         f"{r.currents} motor_currents published, {out['residual'][0].size} residuals, "
                         f"{r.residual_matched} matched; the first {r.settling} samples precede the first "
                         f"residual (the observer waits for a camera pose, its estimator settles)"
                         f"{ref_txt('residuals')}"))
    n_ev = len(out["collision"])
    n_c, n_w = len(out["contact"]), len(out["contact_wrench"])
    rows.append(BenchRow("observer: collision events", n_ev, "msgs", f"= {len(ref['events'])}" if ref else "",
                         (n_ev == len(ref["events"])) if ref else None,
                         "START + END; slow replay count as target" if ref else "START + END"))
    rows.append(BenchRow("isolation: contacts", n_c, "msgs", f"= {len(ref['contacts'])}" if ref else "",
                         (n_c == len(ref["contacts"])) if ref else None, "slow replay count as target" if ref else ""))
    rows.append(BenchRow("rnea: contact_wrench", n_w, "msgs", f"= {ref['wrenches']} +- 5 %" if ref else "",
                         within_percent(n_w, ref["wrenches"], 5.0) if ref else None,
                         "slow replay count as target" if ref else ""))
    n_s = int(out["singularity"][0].size)
    rows.append(BenchRow("singularity: indices per plate_pose", n_s, "msgs", f"= {n_pose}", n_s == n_pose,
                         f"one per plate_pose{ref_txt('singularity')}"))
    if ref:
        lost = ref.get("residuals_missing", 0)
        rows.append(BenchRow("slow replay: current samples without a residual", lost, "samples", "0", lost == 0,
                             f"{ref['frames']} top frames, {ref['poses']} plate_pose, {ref['residuals']} residuals of "
                             f"{ref['currents']} samples; a reference that lost data is no clean reference"))
        ok_e, note_e = compare_events(out["collision"], ref["events"], info.stream_period)
        ok_c, note_c = compare_contacts(out["contact"], ref["contacts"])
        diff = 100.0 * abs(n_w - ref["wrenches"]) / ref["wrenches"] if ref["wrenches"] else (0.0 if n_w == 0
                                                                                             else 100.0)
        rows.append(BenchRow("vs slow replay: collision events", float(ok_e), "same", "START/END, onset +-1 sample",
                             ok_e, note_e))
        rows.append(BenchRow("vs slow replay: contacts", float(ok_c), "same", "count, link, chain", ok_c, note_c))
        rows.append(BenchRow("vs slow replay: contact_wrench count", diff, "%", "<= 5 %", diff <= 5.0,
                             f"{n_w} vs {ref['wrenches']}; {ref_note}"))
        if "wrench_stamps" in ref:     # identified on the same sample times (within one sample of each other)
            near = match_nearest([w["stamp"] for w in out["contact_wrench"]], ref["wrench_stamps"],
                                 info.stream_period + 1e-6)
            same = int(np.count_nonzero(near >= 0))
            rows.append(BenchRow("vs slow replay: contact_wrench at the same sample times", same, "msgs", "", None,
                                 f"of {n_w} (reference {ref['wrenches']}), each within one sample of a reference "
                                 f"wrench's"))
    else:
        rows.append(BenchRow("vs slow replay", float("nan"), "", "", None, ref_note))
    return rows


# ---------------------------------------------------------------------------------------------------------------
# the command


def run(opts: Options) -> dict[str, Any]:
    """Run the bench; returns {section: [row dicts], ..., "info": {...}}. Raises BenchGraphError."""
    from hexa_bringup.graphs import DEFAULT_PARAMS
    from hexa_bringup.rosenv import ros_env

    params = opts.params if opts.params is not None else DEFAULT_PARAMS
    if not params.is_file():
        raise BenchGraphError(f"parameter file {params} not found")
    if opts.realtime_priority is not None:
        from hexa_bringup.commands.bringup import check_realtime_priority
        from hexa_bringup.supervisor import SupervisorError

        try:
            check_realtime_priority(opts.realtime_priority)
        except SupervisorError as exc:
            raise BenchGraphError(str(exc)) from exc
    if not opts.rate > 0:
        raise BenchGraphError(f"--rate must be > 0, got {opts.rate}")
    cache = opts.cache
    results: dict[str, Any] = {}
    info_out: dict[str, Any] = {}
    # SIGINT too: a process started in the background of a non-interactive shell inherits SIGINT ignored
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}

    def interrupt(_sig: int, _frm: Any) -> None:
        raise KeyboardInterrupt

    for s in previous:
        signal.signal(s, interrupt)
    try:
        with held_domain(opts.domain_id) as domain:
            env = ros_env(domain)
            info_out["ros_domain_id"] = domain
            say("the machine's speed now: the collision monitor in-process")
            results["graph machine"] = [machine_speed_row().as_dict()]
            if opts.replay or opts.robot:
                bag = opts.bag if opts.bag is not None else record_default_bag(cache, opts.stream_rate)
                info = bag_inputs(bag)
                info_out["bag"] = {"path": str(bag), "ns": info.ns, "duration_s": info.duration,
                                   "messages": {info.rel(t): n for t, n in info.counts.items()},
                                   "stream_rate_hz": 1.0 / info.stream_period, "camera_fps": info.camera_fps,
                                   "board_time_coverage": info.board_coverage}
                say(f"bag {bag}: {info.duration:.1f} s, currents at {1 / info.stream_period:.0f} Hz "
                    f"({100 * info.board_coverage:.0f} % of the board-time span present), cameras at "
                    f"{info.camera_fps:.0f} fps")
                if info.board_coverage < 0.95:
                    say(f"warning: the bag holds {100 * info.board_coverage:.0f} % of the current samples its "
                        f"board-time span had (the recording lost the rest); the replay feeds what is there"
                        + ("; delete it to record anew on a quieter machine" if opts.bag is None else ""))
                if opts.replay:
                    results.update(_replay_section(opts, info, env, params, cache, info_out))
                if opts.robot:
                    from hexa_bringup.bench_graph_robot import ROBOT_RATES, rest_scene, robot_once, robot_rows

                    scene = rest_scene(info, cache)
                    info_out["robot_scene"] = {"frames": str(scene.frames), "frames_per_camera": scene.n_frames,
                                               "rest_currents_a": scene.amps, "rest_zeta_rad": scene.zeta}
                    for hz in ROBOT_RATES:
                        r = robot_once(info, scene, hz, env, params, cache / "graph_logs" / f"robot_{hz}hz",
                                       opts.robot_duration, opts.ready_timeout, opts.compose, opts.realtime_priority)
                        results[f"graph robot {hz} Hz"] = [row.as_dict() for row in robot_rows(r)]
                        info_out[f"robot_{hz}hz"] = {
                            "boards": r.boards, "nodes": r.nodes, "pids": r.pids, "rates_hz": r.rates,
                            "counts": r.counts,
                            "diagnostics": r.diagnostics,
                            "latency": {"frame_pose": latency_stats(r.frame_latency),
                                        "sample_residual": latency_stats(r.residual_latency or []),
                                        "sample_currents": latency_stats(r.driver_latency)}}
            if opts.sim:
                from hexa_bringup.bench_graph_sim import sim_once, sim_rows

                r = sim_once(env, params, cache / "graph_logs" / "sim", opts.robot_duration, opts.ready_timeout,
                             opts.compose, opts.realtime_priority)
                results["graph sim 1x"] = [row.as_dict() for row in sim_rows(r)]
                info_out["sim"] = {"rtf": r.rtf, "window_s": r.window, "nodes": r.nodes, "pids": r.pids,
                                   "counts": r.counts}
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    results["info"] = info_out
    return results


def _replay_section(opts: Options, info: BagInputs, env: dict[str, str], params: Path, cache: Path,
                    info_out: dict[str, Any]) -> dict[str, Any]:
    say("indexing the bag's inputs")
    index = input_index(info)
    r = replay_once(info, index, opts.rate, env, params, cache / "graph_logs" / "replay", opts.ready_timeout,
                    opts.compose, opts.realtime_priority)
    say(f"replay at {opts.rate:g}x done in {r.wall:.0f} s")
    ref, ref_note = None, "no slow replay (--no-reference)"
    if opts.reference:
        key = reference_key(info, params, opts.compose, opts.realtime_priority)
        path = cache / "graph_reference" / f"{key}.json"
        if path.exists():
            ref = json.loads(path.read_text())
            ref_note = f"slow replay ({REFERENCE_RATE:g}x) from the cache {path}"
            say(f"slow replay ({REFERENCE_RATE:g}x) taken from the cache {path}")
        else:
            say(f"slow replay at {REFERENCE_RATE:g}x for the comparison (about {info.duration / REFERENCE_RATE:.0f} "
                f"s of playing; cached for the next runs)")
            rr = replay_once(info, index, REFERENCE_RATE, env, params, cache / "graph_logs" / "reference",
                             opts.ready_timeout, opts.compose, opts.realtime_priority)
            ref = summary_for_reference(rr)
            if ref["residuals_missing"] == 0:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(ref))
                ref_note = f"slow replay at {REFERENCE_RATE:g}x run now (cached in {path})"
            else:
                ref_note = f"slow replay at {REFERENCE_RATE:g}x run now, not cached: it lost samples itself"
    out = r.outputs
    info_out["replay"] = {
        "rate": r.rate, "achieved_rate": r.achieved_rate, "window_s": r.window[1] - r.window[0], "pids": r.pids,
        "nodes": r.nodes,
        "published": r.published, "cpu_s_after_window": r.cpu_after,
        "latency": {"frame_pose": latency_stats(r.frame_latency), "sample_residual":
                    latency_stats(r.residual_latency), "start_contact": latency_stats(event_latency(out, "contact")),
                    "start_wrench": latency_stats(event_latency(out, "contact_wrench"))},
        "counts": {"top_frames": r.frames, "plate_pose": int(out["plate_pose"][0].size), "currents": r.currents,
                   "residual": int(out["residual"][0].size), "collision": len(out["collision"]),
                   "contact": len(out["contact"]), "contact_wrench": len(out["contact_wrench"]),
                   "singularity": int(out["singularity"][0].size)},
        "events": [{k: v for k, v in e.items() if k != "recv"} for e in out["collision"]],
        "contacts": [{k: v for k, v in c.items() if k != "recv"} for c in out["contact"]],
        "diagnostics": out["diagnostics"], "reference": ref}
    return {f"graph replay {opts.rate:g}x": [row.as_dict() for row in replay_rows(r, info, ref, ref_note)]}


def _clean(obj: Any) -> Any:
    """NaN → None (strict JSON), numpy scalars → Python."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return None if not math.isfinite(float(obj)) else float(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def main(opts: Options, as_json: bool, out_file: str | None,
         print_rows: Callable[[str, list[BenchRow]], None]) -> int:
    """Run, print the table (or JSON), write --out; a user's mistake ends in a message and exit 2."""
    try:
        results = _clean(run(opts))
    except BenchGraphError as exc:
        print(f"hexa bench graph: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hexa bench graph: interrupted; child processes stopped", file=sys.stderr)
        return 130
    text = json.dumps(results, indent=2)
    if as_json:
        print(text)
    else:
        for section, rows in results.items():
            if section != "info":
                print_rows(section, [BenchRow(**{k: (float("nan") if k == "value" and v is None else v)
                                                 for k, v in row.items()}) for row in rows])
        print("\nJSON:")
        print(json.dumps(results))
    if out_file:
        Path(out_file).parent.mkdir(parents=True, exist_ok=True)
        Path(out_file).write_text(text)
    return 0


__all__ = ["BenchGraphError", "Options", "main", "run"]
