"""Free motion in the live simulated graph (issue 8 target: zero false alarms in 3 × 60 s): the whole graph
(simulator with no scenario, driver, trajectory, cameras, pose, observer, rnea, ...) runs each of the paper's three
trajectories at real-time factor 0.3; the observer must publish no collision event. CI runs 3 × 8 s of trajectory
(after the 1 s lead-in at rest); the 60 s figure is measured with the same function and reported in
docs/observer_node.md."""
from __future__ import annotations

import sys

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

TRAJECTORIES = ("circle", "helix", "ellipse")


def free_motion_run(trajectory: str, out_dir, domain: int, duration: float,
                    real_time_factor: float | None = None) -> dict:
    """Run the simulated graph with no collision scenario on `trajectory` for `duration` sim seconds; the collision
    events and the residual force (N) and moment (N·m) peaks the observer published, read from the recorded bag.

    At real-time factor 0.3 the whole graph (simulator, two rendered cameras, vision, dynamics, recorder) uses about
    60 % of this 2-core machine; at 0.5 it saturates both cores, and a starved driver then forwards commands in bursts
    that the observer rightly sees as unmodelled transients (docs/observer_node.md, Limits)."""
    from hexa_bringup import demo_run
    from hexa_bringup.bag import read_bag, typestore
    from hexa_bringup.rosenv import ros_env

    real_time_factor = demo_run.REAL_TIME_FACTOR if real_time_factor is None else real_time_factor
    case = f"free_{trajectory}"
    demo_run.CASES.setdefault(case, ("none", trajectory, duration))  # run_case's table, extended in this process
    run = demo_run.run_case(case, out_dir, ros_env(domain), duration=duration, status_every=1e9,
                            real_time_factor=real_time_factor)
    store = typestore()
    events, res = [], []
    for topic, msgtype, _t, data in read_bag(run.bag):
        if topic == "/hexa/collision":
            m = store.deserialize_cdr(data, msgtype)
            events.append((int(m.event), m.axis_name, m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                           float(m.peak)))
        elif topic == "/hexa/residual":
            m = store.deserialize_cdr(data, msgtype)
            f, q = m.wrench.force, m.wrench.torque
            res.append((f.x, f.y, f.z, q.x, q.y, q.z))
    peaks = np.abs(np.array(res)).max(axis=0).tolist() if res else None
    peak, peak_moment = (peaks[:3], peaks[3:]) if peaks else (None, None)
    return {"trajectory": trajectory, "events": events, "residuals": len(res), "peak": peak,
            "peak_moment": peak_moment, "rc": run.returncode,
            "real_time_factor": real_time_factor, "wall_s": round(run.wall_s, 1)}


@pytest.mark.parametrize("trajectory", TRAJECTORIES)
def test_free_motion_on_each_trajectory_raises_no_collision(trajectory, tmp_path, ros_domain_id):
    r = free_motion_run(trajectory, tmp_path, ros_domain_id, duration=8.0)
    assert r["residuals"] > 1000, r          # the observer ran at the current-sample rate (200 Hz) all along
    assert r["events"] == [], r
    assert r["rc"] == 0, r                   # the supervisor ended the graph normally (the simulator finished)


if __name__ == "__main__":  # the 60 s measurement: python test/test_observer_node_free_motion.py 60 [DOMAIN]
    import json
    import tempfile
    from pathlib import Path

    dur = float(sys.argv[1]) if len(sys.argv) > 1 else 60.0
    dom = int(sys.argv[2]) if len(sys.argv) > 2 else 63
    for traj in TRAJECTORIES:
        print(json.dumps(free_motion_run(traj, Path(tempfile.mkdtemp()), dom, dur)), flush=True)
