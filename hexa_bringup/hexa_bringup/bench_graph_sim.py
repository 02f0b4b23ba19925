"""Sim mode of `hexa bench graph`: the whole graph `hexa bringup sim` starts (simulator with both cameras at 30 fps,
driver on the virtual boards, trajectory, pose, observer, isolation, rnea, singularity), the simulator asked for
1× real time; a subscriber compares the /clock it receives with its own wall clock.

The achieved real-time factor is Δ(sim time) / Δ(wall time) between the first and the last /clock of the measuring
window, both read at the subscriber. The simulator never catches up lost time in a burst (hexa.sim.pacing.Pacer),
so a factor below the requested one is what the machine could do, not a transient.
"""
from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexa.benchmarks import BenchRow
from hexa_bringup.bench_graph import (BenchGraphError, Children, CpuSampler, Probe, cpu_rows, graph_specs,
                                      node_names, safety_priority, say)
from hexa_bringup.bench_graph_analysis import cdr_stamp_ns

#: wall seconds between the graph being up and the measuring window (the serial links connect, the arms settle)
WARM_UP = 5.0
#: the real-time factor `hexa bringup sim` must reach with the whole graph (both cameras at 30 fps)
TARGET_RTF = 0.5
#: the processing nodes (the rest of the sim graph feeds them: simulator, driver, trajectory)
PROCESSING = ("pose", "observer", "isolation", "rnea", "singularity")


@dataclass
class SimResult:
    rtf: float
    window: float
    cpu: dict[str, float]
    nodes: dict[str, list[str]]
    pids: dict[str, int]
    counts: dict[str, int]


def sim_once(env: dict[str, str], params: Path, work: Path, duration: float, ready_timeout: float,
             compose: bool = False, priority: int | None = None) -> SimResult:
    """Bring up the sim graph, wait for /clock, measure `duration` wall seconds after WARM_UP, stop it (`priority`:
    `--realtime-priority`)."""
    link_dir = f"/tmp/hexa_bench_sim_{os.getpid()}"
    node_args = {"sim": ["-p", "real_time_factor:=1.0", "-p", f"link_dir:={link_dir}"],
                 "driver": ["-p", f"uno_port:={link_dir}/uno", "-p", f"mega_port:={link_dir}/mega"]}
    specs = graph_specs("sim", "/hexa", params, node_args, compose=compose, priority=priority)
    nodes = {s.name: node_names(s.cmd, s.name) for s in specs}
    ns = "/hexa"
    spec = {"ns": ns, "topics": [{"topic": "/clock", "type": "rosgraph_msgs/msg/Clock", "qos": "reliable",
                                  "keep": 0, "count": True},
                                 {"topic": f"{ns}/residual", "type": "hexa_msgs/msg/Residual", "qos": "reliable",
                                  "keep": 16, "count": False},
                                 {"topic": f"{ns}/plate_pose", "type": "geometry_msgs/msg/PoseStamped",
                                  "qos": "reliable", "keep": 16, "count": False}],
            "nodes": [n for names in nodes.values() for n in names], "ready_publishers": [f"{ns}/residual"],
            "ready_messages": ["/clock"]}
    work.mkdir(parents=True, exist_ok=True)
    try:
        received, pids, cpu_pct, t0, t1 = _measure(env, specs, nodes, spec, work, duration, ready_timeout,
                                                   safety_priority(params, priority=priority))
    finally:
        shutil.rmtree(link_dir, ignore_errors=True)     # the virtual boards' serial links
    clocks = [(t_ns * 1e-9, cdr_stamp_ns(data) * 1e-9) for t_ns, data in received.get("/clock", [])]
    win = np.array([c for c in clocks if t0 <= c[0] <= t1])
    if len(win) < 2:
        raise BenchGraphError(f"sim mode: fewer than two /clock messages in the measuring window (logs in {work})")
    rtf = float((win[-1, 1] - win[0, 1]) / (win[-1, 0] - win[0, 0]))

    def in_window(topic: str) -> int:
        return sum(1 for t_ns, _ in received.get(topic, []) if t0 <= t_ns * 1e-9 <= t1)

    return SimResult(rtf=rtf, window=t1 - t0, cpu=cpu_pct, nodes=nodes, pids=pids,
                     counts={"clock": len(win), "residual": in_window(f"{ns}/residual"),
                             "plate_pose": in_window(f"{ns}/plate_pose")})


def _measure(env: dict[str, str], specs: list, nodes: dict, spec: dict, work: Path, duration: float,
             ready_timeout: float, priority: int) -> tuple[dict, dict, dict, float, float]:
    """Start the graph and the probe (at SCHED_FIFO `priority`, the safety path's), measure `duration` wall s after
    WARM_UP, stop them: what the probe received, the pids, CPU % per process over the window, and the window's
    ends."""
    with Children(env) as ch:
        probe = Probe(ch, work, spec, priority=priority)
        for s in specs:
            ch.start(s.name, s.cmd, log=work / f"{s.name}.log")
        say(f"sim mode: starting {len(specs)} node processes ({', '.join(nodes)}) and waiting for /clock")
        probe.wait_ready(ready_timeout, "sim mode")
        pids = {s.name: ch.procs[s.name].pid for s in specs}
        say(f"sim mode: {WARM_UP:g} s warm-up, then {duration:g} s measured")
        with CpuSampler(pids) as cpu:
            time.sleep(WARM_UP)
            t0 = time.monotonic()
            end = t0 + duration
            while time.monotonic() < end:
                dead = ch.dead()
                if dead:
                    raise BenchGraphError(f"sim mode: {dead[0]} exited:\n{ch.log_tail(dead[0])}")
                time.sleep(0.2)
            t1 = time.monotonic()
        ch.stop([s.name for s in specs])
        received = probe.finish()
    return received, pids, {n: cpu.percent(n, t0, t1) for n in pids}, t0, t1


def sim_rows(r: SimResult) -> list[BenchRow]:
    rows = [BenchRow("sim: real-time factor reached", r.rtf, "x", f">= {TARGET_RTF:g}x", r.rtf >= TARGET_RTF,
                     f"/clock against the subscriber's wall clock over {r.window:.1f} s; the simulator asked for 1x")]
    processing = [n for n in r.pids if any(x in PROCESSING for x in r.nodes[n])]
    rows += cpu_rows(r.cpu, r.nodes, r.pids, processing, [n for n in r.pids if n not in processing], {})
    sim_s = r.rtf * r.window
    rows.append(BenchRow("sim: residuals per sim second", r.counts["residual"] / max(sim_s, 1e-9), "Hz", "", None,
                         "the driver's stream rate when every sample gets its residual"))
    rows.append(BenchRow("sim: plate_pose per sim second", r.counts["plate_pose"] / max(sim_s, 1e-9), "Hz", "", None,
                         "30 when every top-camera frame gets its pose"))
    return rows
