#!/usr/bin/env python3
"""Consecutive `hexa bringup sim` start-ups with no collision scenario, counting false collision STARTs.

    .venv/bin/python scripts/startup_false_starts.py [-n 20] [--trajectory circle] [--rtf 0.3] [--sim-seconds 4]
                                                      [--wall-limit 150] [--out DIR] [--json] [--stall-driver MS]

Each run is the set-up for free motion of docs/troubleshooting.md: the shipped parameters with the simulator's
`scenario: none` and its `trajectory` set to the trajectory node's (the robot starts at rest at the trajectory's start
pose), at real-time factor `--rtf`, until `--sim-seconds` of sim time (the simulator's `duration` ends the graph).
Every START the observer logs is false (nothing touches the robot); those with an onset before the trajectory has run
for 1 s (its start blend) count as start-up STARTs, later ones are the loaded host's (docs/troubleshooting.md). Per
run it prints the STARTs (axis, onset in sim s), the observer's `monitoring` transitions and the trajectory's states,
read from the node logs; at the end the totals. Exit code 1 when a run had a start-up START. With `--stall-driver MS`
the run's driver process is stopped for MS of wall time once the trajectory runs (a silent board): `monitoring` turns
LOST naming the silent streams and the trajectory holds (it stays held: nothing calls resume). docs/monitoring.md has
the figures.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
START = re.compile(r"collision (\d+) START on (\w+): (-?[\d.]+) \(peak (-?[\d.]+), onset ([\d.]+) s\)")
MONITORING = re.compile(r"monitoring (OK|DEGRADED|LOST)(?: at ([\d.]+) s)?")
STATE = re.compile(r"trajectory state (\w+) at ([\d.]+) s")
LOST_REASON = re.compile(r"monitoring LOST at ([\d.]+) s: (.*)")
#: sim s after the trajectory starts running that still count as start-up (its start_blend is 1 s)
START_UP = 1.0


def params_file(base: Path, out: Path, trajectory: str, rtf: float, sim_seconds: float, link_dir: str) -> Path:
    """The shipped parameters with the free-motion start-up of docs/troubleshooting.md."""
    p = yaml.safe_load(base.read_text())
    sim = p["/**/sim"]["ros__parameters"]
    sim.update(scenario="none", trajectory=trajectory, real_time_factor=rtf, duration=sim_seconds, link_dir=link_dir)
    p["/**/trajectory"]["ros__parameters"]["trajectory"] = trajectory
    drv = p.setdefault("/**/driver", {}).setdefault("ros__parameters", {})
    drv.update(uno_port=f"{link_dir}/uno", mega_port=f"{link_dir}/mega")
    out.write_text(yaml.safe_dump(p, sort_keys=False))
    return out


def one_run(k: int, args: argparse.Namespace, env: dict[str, str], root: Path) -> dict:
    from hexa_bringup.graphs import DEFAULT_PARAMS, build_graph
    from hexa_bringup.supervisor import Supervisor

    run_dir = root / f"run{k:02d}"
    run_dir.mkdir(parents=True, exist_ok=True)
    params = params_file(DEFAULT_PARAMS, run_dir / "params.yaml", args.trajectory, args.rtf, args.sim_seconds,
                         f"/tmp/hexa_sim_startup_{os.getpid()}")
    t0 = time.monotonic()
    # `hexa bringup sim`'s graph and parameters; the simulator's end (its `duration`) ends the graph
    specs = build_graph("sim", "/hexa", params)
    for spec in specs:
        if spec.name == "sim":
            spec.ends_graph, spec.respawn = True, False
    stall: dict = {}
    if args.stall_driver > 0:
        threading.Thread(target=stall_driver, args=(run_dir, args.stall_driver / 1000.0, stall), daemon=True).start()
    with open(run_dir / "supervisor.log", "w") as out, contextlib.redirect_stdout(out), \
            contextlib.redirect_stderr(out):
        rc = Supervisor(specs, env, log_dir=str(run_dir / "logs"), status_every=1e9).run(duration=args.wall_limit)
    wall = time.monotonic() - t0
    logs = run_dir / "logs"
    obs = (logs / "observer.log").read_text(errors="replace") if (logs / "observer.log").exists() else ""
    traj = (logs / "trajectory.log").read_text(errors="replace") if (logs / "trajectory.log").exists() else ""
    starts = [{"id": int(m[0]), "axis": m[1], "value": float(m[2]), "onset": float(m[4])} for m in START.findall(obs)]
    monitoring = [(m[0], float(m[1]) if m[1] else None) for m in MONITORING.findall(obs)]
    states = [(m[0], float(m[1])) for m in STATE.findall(traj)]
    # start-up: before the trajectory has run for START_UP s (later STARTs are the host's lag, docs/troubleshooting.md)
    running = next((t for st, t in states if st == "running"), math.inf)
    return {"run": k, "rc": rc, "wall_s": round(wall, 1),
            "startup_false_starts": [s for s in starts if s["onset"] < running + START_UP],
            "false_starts": starts, "first_ok": next((t for lv, t in monitoring if lv == "OK"), None),
            "running_at": None if running == math.inf else running,
            "lost": [t for lv, t in monitoring if lv == "LOST"], "monitoring": monitoring,
            "trajectory_states": states, "driver_stall": stall, "lost_reasons": LOST_REASON.findall(obs),
            "lost_after_stop_s": _after(stall, obs, "monitoring LOST"),
            "held_after_stop_s": _after(stall, traj, "state held"),
            "logs": str(logs)}


def _after(stall: dict, log: str, text: str) -> float | None:
    """Wall s from the driver's stop to the first log line with `text` after it (ROS log stamps: wall time)."""
    if "stopped_at" not in stall:
        return None
    for m in re.finditer(r"\[(\d+\.\d+)\] \[[^\]]+\]: (.*)", log):
        if float(m[1]) >= stall["stopped_at"] and text in m[2]:
            return round(float(m[1]) - stall["stopped_at"], 3)
    return None


def stall_driver(run_dir: Path, seconds: float, out: dict) -> None:
    """2 s of wall time after this run's trajectory runs, stop this run's driver process (SIGSTOP) for `seconds`:
    the board goes silent for the graph, as on a starved or hung driver."""
    log = run_dir / "logs" / "trajectory.log"
    end = time.monotonic() + 300
    while time.monotonic() < end and not (log.exists() and "trajectory state running" in log.read_text()):
        time.sleep(0.2)
    time.sleep(2.0)
    found = subprocess.run(["pgrep", "-f", f"driver_node.*{run_dir}/params.yaml"], capture_output=True, text=True)
    pids = [int(p) for p in found.stdout.split()]
    stopped = time.time()
    for pid in pids:
        os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(seconds)
    finally:
        for pid in pids:
            os.kill(pid, signal.SIGCONT)
    out.update(pids=pids, seconds=seconds, stopped_at=stopped)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=20, help="consecutive bringups (default 20)")
    ap.add_argument("--trajectory", default="circle", choices=("circle", "helix", "ellipse"))
    ap.add_argument("--rtf", type=float, default=0.3, help="the simulator's real-time factor (default 0.3)")
    ap.add_argument("--sim-seconds", type=float, default=4.0, help="sim s per run (default 4: 1 s at rest, 3 moving)")
    ap.add_argument("--wall-limit", type=float, default=150.0, help="wall s after which a run is stopped")
    ap.add_argument("--out", default=None, help="directory for the runs' parameters and logs (default: a temp dir)")
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: a free one)")
    ap.add_argument("--json", action="store_true", help="print each run as one JSON line")
    ap.add_argument("--stall-driver", type=float, default=0.0, metavar="MS",
                    help="stop this run's driver for MS of wall time, 2 s after the trajectory runs (0 = no)")
    args = ap.parse_args()
    from hexa_ros.env import held_ros_domain, ros_env

    root = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="hexa_startup_"))
    runs = []
    with held_ros_domain(range(args.domain, args.domain + 1) if args.domain else range(90, 0, -1)) as domain:
        env = ros_env(domain)
        for k in range(args.n):
            r = one_run(k, args, env, root)
            runs.append(r)
            if args.json:
                print(json.dumps(r), flush=True)
            else:
                print(f"run {k + 1:2d}/{args.n}: rc {r['rc']}, {r['wall_s']:5.1f} s wall, first OK at "
                      f"{r['first_ok']} s, running at {r['running_at']} s, false STARTs "
                      f"{[(s['axis'], s['onset']) for s in r['false_starts']]}, LOST at {r['lost']}",
                      flush=True)
    bad = sum(1 for r in runs if r["startup_false_starts"])
    print(json.dumps({"runs": len(runs), "runs_with_startup_false_start": bad,
                      "startup_false_starts": sum(len(r["startup_false_starts"]) for r in runs),
                      "false_starts": sum(len(r["false_starts"]) for r in runs),
                      "runs_with_lost": sum(1 for r in runs if r["lost"]),
                      "failed_runs": sum(1 for r in runs if r["rc"] != 0), "out": str(root)}))
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
