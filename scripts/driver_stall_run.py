#!/usr/bin/env python3
"""Free motion in the live simulated graph while the driver process is stopped (SIGSTOP) now and then.

    .venv/bin/python scripts/driver_stall_run.py [--trajectory circle] [--duration 16] [--stall-ms 300]
                                                  [--every 3] [--domain 91]

Runs test/test_observer_node_free_motion.py's `free_motion_run` (the whole graph at real-time factor 0.3, looping
the trajectory, no collision scenario) and, from 15 s of wall time on (the graph is up by then), stops every
hexa driver process for `--stall-ms` of wall time every `--every` s — what a starved or paused robot PC does to the
driver. Prints the run's JSON (collision events, residual peaks, samples over a threshold, the longest run of them)
and the wall times of the stalls. docs/driver_timing.md ("Which command a sample carries") has the figures.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trajectory", default="circle", choices=("circle", "helix", "ellipse"))
    ap.add_argument("--duration", type=float, default=16.0, help="sim seconds of trajectory (default 16)")
    ap.add_argument("--stall-ms", type=float, default=300.0, help="wall ms the driver is stopped (default 300)")
    ap.add_argument("--every", type=float, default=3.0, help="wall s between stalls (default 3)")
    ap.add_argument("--domain", type=int, default=91, help="ROS_DOMAIN_ID (default 91)")
    args = ap.parse_args()
    sys.path.insert(0, str(REPO / "test"))
    from test_observer_node_free_motion import free_motion_run

    stalls: list[float] = []
    done = threading.Event()

    def staller() -> None:
        t0 = time.time()
        while not done.wait(args.every):
            if time.time() - t0 < 15.0:
                continue
            found = subprocess.run(["pgrep", "-f", "hexa_driver.driver_node"], capture_output=True, text=True)
            pids = [int(p) for p in found.stdout.split()]
            for p in pids:
                os.kill(p, signal.SIGSTOP)
            try:
                time.sleep(args.stall_ms / 1000.0)
            finally:
                for p in pids:
                    os.kill(p, signal.SIGCONT)
            if pids:
                stalls.append(round(time.time() - t0, 2))

    thread = threading.Thread(target=staller, daemon=True)
    thread.start()
    try:
        result = free_motion_run(args.trajectory, Path(tempfile.mkdtemp(prefix="hexa_stall_")), args.domain,
                                 args.duration)
    finally:
        done.set()
        thread.join()
    result["stalls_wall_s"] = stalls
    print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
