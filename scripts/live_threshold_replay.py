#!/usr/bin/env python3
"""Free motion in the live simulated graph, its published residuals replayed through the threshold detector at
scaled thresholds: the false STARTs the observer node would raise with lower thresholds.

    .venv/bin/python scripts/live_threshold_replay.py [--realism realistic|ideal] [--seconds 60] [--domain 71]
                                                     [--scales 0.6,0.7,0.8,0.9,1]

One graph (`hexa_bringup.demo_run.run_case`, no collision scenario) runs the paper's three trajectories in turn, as
the CI free-motion test does, at the demo's real-time factor; on the realistic robot the nodes run its calibration
overlay (`demo_run.nodes_description`). The recorded `residual` (plate-axis wrench and servo torques, each sample's
stamp) is fed to `hexa.dynamics.observer.CollisionDetector` with the node's thresholds × each scale and its
min_duration. Until a first START the graph does not depend on the thresholds, so a replay without START is what the
node would have done live at that scale. Prints one JSON line: samples, the live collision events, STARTs per scale.
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from hexa.dynamics.observer import CollisionDetector, ObserverConfig


def starts_at(rows: np.ndarray, scale: float) -> int:
    """STARTs of the threshold detector at `scale` × the node's default thresholds on (t, wrench 6, servo 6) rows."""
    base = ObserverConfig()
    det = CollisionDetector(ObserverConfig(thresholds=tuple(scale * v for v in base.thresholds),
                                           servo_thresholds=tuple(scale * v for v in base.servo_thresholds)))
    return sum(e.kind == "START" for row in rows for e in det.update(row[0], row[1:7], np.nan_to_num(row[7:13]))[1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realism", default="realistic", choices=("realistic", "ideal"))
    ap.add_argument("--seconds", type=float, default=60.0, help="sim seconds of free motion")
    ap.add_argument("--domain", type=int, default=71, help="ROS_DOMAIN_ID of the graph")
    ap.add_argument("--scales", default="0.6,0.7,0.8,0.9,1", help="threshold scales, comma-separated")
    a = ap.parse_args()
    from hexa_bringup import demo_run
    from hexa_bringup.bag import read_bag, typestore
    from hexa_bringup.rosenv import ros_env

    case = "free_sequence"
    demo_run.CASES.setdefault(case, ("none", "circle+helix+ellipse", a.seconds))
    run = demo_run.run_case(case, Path(tempfile.mkdtemp()), ros_env(a.domain), duration=a.seconds,
                            status_every=1e9, real_time_factor=demo_run.REAL_TIME_FACTOR, loop=True,
                            realism=a.realism, description=demo_run.nodes_description(a.realism, 0))
    store, rows, events = typestore(), [], 0
    for topic, msgtype, _t, data in read_bag(run.bag):
        if topic == "/hexa/residual":
            m = store.deserialize_cdr(data, msgtype)
            f, q = m.wrench.force, m.wrench.torque
            rows.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, f.x, f.y, f.z, q.x, q.y, q.z,
                         *[float(v) for v in m.servo_torque]))
        elif topic == "/hexa/collision":
            events += 1
    r = np.array(sorted(rows)).reshape(-1, 13)
    out = {"realism": a.realism, "seconds": a.seconds, "samples": len(r), "live_events": events,
           "rc": run.returncode, "starts": {s: starts_at(r, float(s)) for s in a.scales.split(",")}}
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
