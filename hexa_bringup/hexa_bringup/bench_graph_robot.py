"""Robot mode of `hexa bench graph`: the graph `hexa bringup robot` starts, without the simulator and the
trajectory node, at 1× wall time on emulated hardware.

Both camera nodes run in `folder` source on the frames of the bag taken while the robot was at rest (the same
`_publish` path a RealSense frame takes, stamped with the host clock), the driver talks to the Uno and Mega emulators
of hexa.protocol.emulator on pseudo-terminals (their own process), the Mega streaming the bag's rest currents at the
driver's `stream_rate_hz`, and the measuring subscriber publishes a hold command at the rest pose (no trajectory
node: the robot stays where the frames show it, so the observer has no reason for a collision).

Latencies: frame → plate_pose from the frame's stamp (the camera node stamps each frame with the host clock just
before it publishes colour, depth and their camera_info; the stamp mapped to the monotonic clock) to the arrival of
the `plate_pose` that carries it. The subscriber reads the top camera's depth camera_info (the frame's last message)
for the frames' stamps, not the images: the robot PC runs no such subscriber, and one that took in 1.5 MB per frame at
the safety path's priority would take that CPU from the pose node it measures. Sample →
motor_currents and sample → residual from the instant the Mega measured the sample (the emulator's clock zero plus
its board time, on the monotonic clock). Without sim time the observer stamps a residual with the sample's board
time plus a host offset it tracks (hexa.dynamics.monitor.SampleClock), which no subscriber can reproduce exactly
(its state depends on the first sample the observer heard) but which moves by microseconds per sample and which the
observer says in /diagnostics: each residual is matched to its sample by following that offset from residual to
residual (hexa_bringup.bench_graph_analysis.match_tracked_offset), so its latency is exact.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hexa.benchmarks import BenchRow
from hexa_bringup.bench_graph import (CAMERA_TOPICS, CAMERAS, OUTPUTS, TARGET_P95, TOP_FRAME_INFO, BagInputs,
                                      BenchGraphError, Children, CpuSampler, Probe, bag_identity, cpu_rows,
                                      frame_pose_latency, graph_specs, latency_rows, node_names, parse_outputs,
                                      safety_priority, say)
from hexa_bringup.bench_graph_analysis import cdr_stamp_ns, match_tracked_offset

#: the Mega's stream rates measured
ROBOT_RATES = (1000, 200)
#: seconds between the graph being up and the measuring window
WARM_UP = 2.0


@dataclass
class RestScene:
    """The bag's camera frames, currents and commanded angles while the robot was at rest."""

    frames: Path
    amps: list[float]
    zeta: list[float]
    fps: float
    n_frames: int


def rest_scene(info: BagInputs, cache: Path) -> RestScene:
    """Export the camera frames of the bag's rest period (before the first command change) as folder-source PNGs
    with camera_info.yaml, cached per bag; the rest currents and commanded angles (medians).

    Raises:
        BenchGraphError: the bag has no command, no current or no frame before the robot moves.
    """
    import cv2
    import yaml

    from hexa_bringup.bag import read_bag, typestore

    key = hashlib.sha256(json.dumps(bag_identity(info.path)).encode()).hexdigest()[:12]
    root = cache / "graph_frames" / key
    meta = root / "rest.json"
    if meta.exists():
        m = json.loads(meta.read_text())
        return RestScene(root, m["amps"], m["zeta"], m["fps"], m["n_frames"])
    store = typestore()
    pos: list[tuple[float, np.ndarray]] = []
    rest_end = None
    for _topic, msgtype, _s, data in read_bag(info.path, [f"{info.ns}/joint_states"]):
        m = store.deserialize_cdr(data, msgtype)
        p = np.asarray(m.position, dtype=float)
        if p.size != 6 or not np.all(np.isfinite(p)):
            continue
        t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        if pos and np.max(np.abs(p - pos[0][1])) > 1e-3:
            rest_end = t
            break
        pos.append((t, p))
    if not pos:
        raise BenchGraphError(f"bag {info.path}: no joint_states with six finite positions (no command recorded)")
    if rest_end is None:
        rest_end = pos[-1][0]
    zeta = np.median(np.stack([p for _, p in pos]), axis=0)
    amps = [np.asarray(store.deserialize_cdr(d, mt).current, dtype=float)
            for _t, mt, _s, d in read_bag(info.path, [f"{info.ns}/motor_currents"])
            if cdr_stamp_ns(d) * 1e-9 < rest_end]
    if not amps:
        raise BenchGraphError(f"bag {info.path}: no motor_currents before the robot moved at {rest_end:.2f} s")
    tmp = root.with_name(root.name + ".tmp")
    if tmp.exists():
        shutil.rmtree(tmp)
    counts = {}
    for cam in CAMERAS:
        d = tmp / cam
        d.mkdir(parents=True)
        color: dict[int, Any] = {}
        depth: dict[int, Any] = {}
        info_msg = None
        for topic, mt, _s, data in read_bag(info.path, [f"{info.ns}/{cam}/{t}" for t in CAMERA_TOPICS]):
            stamp = cdr_stamp_ns(data)
            if stamp * 1e-9 >= rest_end:
                continue
            m = store.deserialize_cdr(data, mt)
            if topic.endswith("camera_info"):
                info_msg = m
            elif topic.endswith("aligned_depth_to_color/image_raw"):
                depth.setdefault(stamp, np.frombuffer(m.data, np.uint16).reshape(m.height, m.width))
            else:
                color.setdefault(stamp, np.frombuffer(m.data, np.uint8).reshape(m.height, m.width, -1))
        both = sorted(set(color) & set(depth))
        if not both or info_msg is None:
            raise BenchGraphError(f"bag {info.path}: no {cam} frame before the robot moved at {rest_end:.2f} s")
        for k, s in enumerate(both):
            cv2.imwrite(str(d / f"color_{k:04d}.png"), cv2.cvtColor(color[s], cv2.COLOR_RGB2BGR))
            cv2.imwrite(str(d / f"depth_{k:04d}.png"), depth[s])
        (d / "camera_info.yaml").write_text(yaml.safe_dump({
            "width": int(info_msg.width), "height": int(info_msg.height), "k": [float(v) for v in info_msg.k],
            "d": [float(v) for v in info_msg.d]}))
        counts[cam] = len(both)
    m = {"amps": np.median(np.stack(amps), axis=0).tolist(), "zeta": zeta.tolist(), "fps": info.camera_fps,
         "n_frames": min(counts.values()), "rest_end": rest_end}
    (tmp / "rest.json").write_text(json.dumps(m))
    if root.exists():
        shutil.rmtree(root)
    tmp.rename(root)
    return RestScene(root, m["amps"], m["zeta"], m["fps"], m["n_frames"])


@dataclass
class RobotResult:
    stream_hz: int
    window: tuple[float, float]
    cpu: dict[str, float]
    nodes: dict[str, list[str]]
    pids: dict[str, int]
    processing: list[str]
    sources: list[str]
    rates: dict[str, float]
    counts: dict[str, int]
    frame_latency: list[float]
    residual_latency: list[float]                 # estimated (module docstring)
    driver_latency: list[float]                   # sample → motor_currents arrival
    residual_matched: int                         # residuals in the window matched to their sample
    events: int
    contacts: int
    boards: dict[str, Any]
    fps: float
    diagnostics: dict[str, dict[str, str]]


def robot_once(info: BagInputs, scene: RestScene, stream_hz: int, env: dict[str, str], params: Path, work: Path,
               duration: float, ready_timeout: float, compose: bool = False, priority: int | None = None
               ) -> RobotResult:
    """The robot graph on emulated boards and folder cameras, measured for `duration` s after a warm-up (`priority`:
    `--realtime-priority`)."""
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    ns = info.ns
    links = Path(f"/tmp/hexa_bench_{os.getpid()}")
    links.mkdir(exist_ok=True)
    uno, mega = links / "uno", links / "mega"
    node_args = {"driver": ["-p", f"uno_port:={uno}", "-p", f"mega_port:={mega}",
                            "-p", f"stream_rate_hz:={int(stream_hz)}"]}
    for name, cam in (("camera_top", "cam_top"), ("camera_side", "cam_side")):
        node_args[name] = ["-p", "source:=folder", "-p", f"camera:={cam}", "-p", f"path:={scene.frames / cam}",
                           "-p", f"rate:={scene.fps:g}", "-p", "loop:=true"]
    specs = [s for s in graph_specs("robot", ns, params, node_args, compose, priority) if s.name != "trajectory"]
    replay_nodes = {n for s in graph_specs("replay", ns, params) for n in node_names(s.cmd, s.name)}
    nodes = {s.name: node_names(s.cmd, s.name) for s in specs}
    specs = [s for s in specs if "trajectory" not in nodes[s.name]]
    processing = [s.name for s in specs if set(nodes[s.name]) & replay_nodes]
    sources = [s.name for s in specs if not set(nodes[s.name]) & replay_nodes]
    topics = [{"topic": f"{ns}/{t}", "type": ty, "qos": "reliable",
               "keep": 0 if t in ("collision", "contact", "contact_wrench") else 16, "count": True}
              for t, ty in OUTPUTS.items()]
    topics += [{"topic": f"{ns}/joint_states", "type": "sensor_msgs/msg/JointState", "qos": "reliable", "keep": 16},
               {"topic": f"{ns}/motor_currents", "type": "hexa_msgs/msg/MotorCurrents", "qos": "reliable"},
               {"topic": f"{ns}/{TOP_FRAME_INFO}", "type": "sensor_msgs/msg/CameraInfo", "qos": "sensor",
                "keep": 16},
               {"topic": "/diagnostics", "type": "diagnostic_msgs/msg/DiagnosticArray", "qos": "reliable"}]
    probe_spec = {"ns": ns, "topics": topics, "nodes": [n for names in nodes.values() for n in names],
                  "ready_publishers": [f"{ns}/{t}" for t in OUTPUTS],
                  "ready_messages": [f"{ns}/residual", f"{ns}/plate_pose"], "hold_command": scene.zeta}
    what = f"robot mode, currents at {stream_hz} Hz"
    priority = safety_priority(params, ns, priority)   # the boards and the subscriber at the safety path's
    try:
        with Children(env) as ch:
            boards = ch.start("boards", [sys.executable, "-m", "hexa_bringup.bench_graph_probe", "boards", str(uno),
                                         str(mega), "--amps", *[f"{a:.6f}" for a in scene.amps]],
                              log=work / "boards.log", pipe=True, priority=priority)
            assert boards.stdout is not None
            line = boards.stdout.readline().strip()
            if not line.startswith("READY "):
                raise BenchGraphError(f"{what}: the board emulators did not start:\n{ch.log_tail('boards')}")
            clock_zero = float(json.loads(line[6:])["mega_clock_zero"])
            probe = Probe(ch, work, probe_spec, priority=priority)
            for s in specs:
                ch.start(s.name, s.cmd, log=work / f"{s.name}.log")
            say(f"{what}: starting {len(specs)} node processes ({', '.join(nodes)}) and waiting for the first "
                f"residual and plate_pose")
            probe.wait_ready(ready_timeout, what)
            pids = {s.name: ch.procs[s.name].pid for s in specs}
            pids["boards"], pids["probe"] = boards.pid, probe.proc.pid
            with CpuSampler(pids) as cpu:
                time.sleep(WARM_UP)
                w0 = time.monotonic()
                say(f"{what}: measuring for {duration:g} s")
                while time.monotonic() < w0 + duration:
                    dead = ch.dead()
                    if dead:
                        raise BenchGraphError(f"{what}: {dead[0]} exited during the run:\n{ch.log_tail(dead[0])}")
                    time.sleep(0.1)
                w1 = time.monotonic()
                clock_offset_ns = time.time_ns() - time.monotonic_ns()   # host clock (the stamps) - monotonic
            ch.stop([s.name for s in specs])
            received = probe.finish()
            ch.stop(["boards"])
            stats = [ln for ln in (boards.stdout.read() or "").splitlines() if ln.startswith("STATS ")]
            board_stats = json.loads(stats[-1][6:]) if stats else {}
    finally:
        shutil.rmtree(links, ignore_errors=True)
    out = parse_outputs(received, ns)

    def in_window(t: np.ndarray) -> np.ndarray:
        return (t >= w0) & (t < w1)

    span = w1 - w0
    rates, counts = {}, {}
    for name in ("joint_states", "motor_currents", "residual", "plate_pose", TOP_FRAME_INFO):
        recv = out[name]["recv"] if name == "motor_currents" else out[name][0]
        n = int(np.count_nonzero(in_window(recv)))
        rates[name], counts[name] = n / span, n
    _info_t, f_stamp = out[TOP_FRAME_INFO]
    f_time = (f_stamp - clock_offset_ns) * 1e-9             # the frames' stamps on the monotonic clock
    sel = in_window(f_time)
    fl, _n_frames, _n_posed = frame_pose_latency(f_stamp[sel], f_time[sel], out)
    m = out["motor_currents"]
    sample_t = clock_zero + m["board"]       # the monotonic time the Mega measured each sample
    sel_m = in_window(m["recv"])
    dl = (m["recv"] - sample_t)[sel_m].tolist()
    r_recv, r_stamp = out["residual"]
    # the observer's offset (its residual stamp − the sample's board time) as it said it last in the window, at the
    # residual that arrived just before; the residuals are traced to their samples from there
    said = [(at, off) for at, off in out["board_clock_offsets"] if w0 <= at < w1 + 1.0]
    if said and r_recv.size:
        at, guess = said[-1]
        idx = match_tracked_offset(r_stamp * 1e-9, m["board"], guess, max(int(np.searchsorted(r_recv, at)) - 1, 0))
    else:
        idx = np.full(r_recv.size, -1, dtype=np.int64)
    sel_r = in_window(r_recv) & (idx >= 0)
    rl = (r_recv[sel_r] - sample_t[idx[sel_r]]).tolist()
    return RobotResult(
        stream_hz=stream_hz, window=(w0, w1), cpu={n: cpu.percent(n, w0, w1) for n in pids}, nodes=nodes, pids=pids,
        processing=processing, sources=sources, rates=rates, counts=counts, frame_latency=fl, residual_latency=rl,
        driver_latency=dl, residual_matched=int(np.count_nonzero(sel_r)),
        events=sum(1 for e in out["collision"] if e["kind"] == "START"), contacts=len(out["contact"]),
        boards=board_stats, fps=scene.fps, diagnostics=out["diagnostics"])


def robot_rows(r: RobotResult) -> list[BenchRow]:
    """The robot-mode figures beside their targets."""
    rows = cpu_rows(r.cpu, r.nodes, r.pids, r.processing, r.sources, {"boards": "board emulators",
                                                                        "probe": "measuring subscriber"})
    hz = float(r.stream_hz)
    span = r.window[1] - r.window[0]
    for name in ("joint_states", "motor_currents", "residual"):
        v = r.rates[name]
        rows.append(BenchRow(f"rate {name}", v, "Hz", f">= {0.99 * hz:g} Hz", v >= 0.99 * hz,
                             f"{r.counts[name]} in {span:.1f} s"))
    v = r.rates["plate_pose"]
    rows.append(BenchRow("rate plate_pose", v, "Hz", f">= {0.99 * r.fps:.3g} Hz", v >= 0.99 * r.fps,
                         f"top camera frames reached the subscriber at {r.rates[TOP_FRAME_INFO]:.1f} Hz "
                         f"(folder source set to {r.fps:.1f} Hz)"))
    n_cur, n_res = r.counts["motor_currents"], r.counts["residual"]
    rows.append(BenchRow("observer: residuals per current sample", n_res / n_cur if n_cur else float("nan"), "ratio",
                         ">= 0.99", n_cur > 0 and n_res >= 0.99 * n_cur,
                         f"{n_cur} motor_currents and {n_res} residuals arrived in the window"))
    rows += latency_rows("frame -> plate_pose", r.frame_latency, TARGET_P95["frame_pose"],
                         "the camera node stamps a top frame -> plate_pose with that stamp arrives")
    rows += latency_rows("sample -> residual", r.residual_latency, TARGET_P95["sample_residual"],
                         f"the Mega measures the sample -> its residual arrives ({r.residual_matched} residuals "
                         f"matched to their sample by the observer's tracked offset)")
    rows += latency_rows("sample -> motor_currents", r.driver_latency, None,
                         "the Mega measures the sample -> the driver's motor_currents arrives")
    rows.append(BenchRow("observer: collision STARTs at rest", r.events, "events", "0", r.events == 0,
                         f"{r.contacts} contacts; the robot holds its rest pose"))
    return rows
