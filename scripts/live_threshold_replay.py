#!/usr/bin/env python3
"""Free motion in the live simulated graph, its published residuals replayed through the threshold detector at
scaled thresholds: the false STARTs the observer node would raise with lower thresholds.

    .venv/bin/python scripts/live_threshold_replay.py [--realism realistic|ideal] [--seconds 60] [--domain 71]
                                                     [--scales 0.6,0.7,0.8,0.9,1]

One graph (`hexa_bringup.demo_run.run_case`, no collision scenario) runs the paper's three trajectories in turn, as
the CI free-motion test does, at the demo's real-time factor; on the realistic robot the nodes run its calibration
overlay (`demo_run.nodes_description`). The recorded `residual` (plate-axis wrench and servo torques, each sample's
stamp; read by `demo_run.case_data_from_bag`) is fed to `hexa.dynamics.observer.CollisionDetector` with the node's
thresholds × each scale (`hexa.eval.campaign.DetectorSpec.config`, as the campaign's DET) and its min_duration.
Until a first START the graph does not depend on the thresholds, so a replay without START is what the node would
have done live at that scale. Prints one JSON line: samples, the live collision events, STARTs per scale.
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from hexa.dynamics.observer import CollisionDetector, ObserverConfig
from hexa.eval.campaign import threshold_spec


def starts_at(t: np.ndarray, wrench: np.ndarray, servo: np.ndarray, scale: float) -> int:
    """STARTs of the node's threshold detector at `scale` × its default thresholds on the residual samples (stamps
    t, plate-axis wrench and servo torques; NaN servo torques are not checked, as in the node)."""
    base = ObserverConfig()
    det = CollisionDetector(threshold_spec(base).config(base, scale))
    return sum(e.kind == "START" for k in range(len(t)) for e in det.update(float(t[k]), wrench[k], servo[k])[1])


def scales_of(text: str) -> list[float]:
    """Comma-separated positive threshold scales."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"scales must be numbers separated by commas, got {text!r}") from None
    if not values or not all(v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"scales must be positive, got {text!r}")
    return values


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realism", default="realistic", choices=("realistic", "ideal"))
    ap.add_argument("--seconds", type=float, default=60.0, help="sim seconds of free motion")
    ap.add_argument("--domain", type=int, default=71, help="ROS_DOMAIN_ID of the graph")
    ap.add_argument("--scales", type=scales_of, default="0.6,0.7,0.8,0.9,1", help="threshold scales, comma-separated")
    a = ap.parse_args()
    from hexa_bringup import demo_run
    from hexa_bringup.graphs import DEMO_REAL_TIME_FACTOR
    from hexa_bringup.rosenv import ros_env

    case = "free_sequence"
    demo_run.CASES.setdefault(case, ("none", "circle+helix+ellipse", a.seconds))
    run = demo_run.run_case(case, Path(tempfile.mkdtemp()), ros_env(a.domain), duration=a.seconds,
                            status_every=1e9, real_time_factor=DEMO_REAL_TIME_FACTOR, loop=True,
                            realism=a.realism, description=demo_run.nodes_description(a.realism, 0))
    d = demo_run.case_data_from_bag(case, run.bag)
    out = {"realism": a.realism, "seconds": a.seconds, "samples": len(d.residual_t), "live_events": len(d.events),
           "rc": run.returncode,
           "starts": {f"{s:g}": starts_at(d.residual_t, d.residual, d.residual_servo, s) for s in a.scales}}
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
