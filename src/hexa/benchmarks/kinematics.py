"""Hexa kinematics benchmarks: IK single and batched, Newton–Raphson FK, ANN FK, beside their targets."""
from __future__ import annotations

import time

import numpy as np

from hexa.benchmarks import BenchRow, register, time_per_call


@register("kinematics")
def bench(quick: bool) -> list[BenchRow]:
    from hexa import trajectories
    from hexa.kinematics import hexa6rus
    from hexa.robots.hexa_description import load_hexa

    min_time = 0.1 if quick else 0.3
    desc = load_hexa()
    rows: list[BenchRow] = []
    _, poses, _, _ = trajectories.sample("circle", rate_hz=100.0)
    pose = poses[37]

    t = time_per_call(lambda: hexa6rus.inverse_kinematics(desc, pose), min_time=min_time)
    rows.append(BenchRow("hexa IK single pose", t * 1e6, "us", "<= 20 us", t <= 20e-6))

    rng = np.random.default_rng(0)
    n = 100_000 if quick else 1_000_000
    batch = desc.home_pose + rng.uniform(-1, 1, (n, 6)) * [0.05, 0.05, 0.03, 0.2, 0.2, 0.2]
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        hexa6rus.inverse_kinematics_batch(desc, batch)
        best = min(best, time.perf_counter() - t0)
    rate = n / best
    rows.append(BenchRow(f"hexa IK batched ({n} poses)", rate, "poses/s", ">= 1e6 poses/s", rate >= 1e6))

    zetas = hexa6rus.inverse_kinematics_batch(desc, poses)
    k = 37
    # Warm start from the previous 10 ms sample of the circle (as the FK node runs) and cold start from home.
    t = time_per_call(lambda: hexa6rus.forward_kinematics(desc, zetas[k], poses[k - 1]), min_time=min_time)
    rows.append(BenchRow("hexa FK Newton-Raphson, warm start (1e-10)", t * 1e6, "us", "<= 200 us", t <= 200e-6))
    t = time_per_call(lambda: hexa6rus.forward_kinematics(desc, zetas[k]), min_time=min_time)
    rows.append(BenchRow("hexa FK Newton-Raphson, from home (1e-10)", t * 1e6, "us", "<= 200 us", t <= 200e-6))

    try:
        from hexa.kinematics.hexa_ann import load_ann_fk

        model = load_ann_fk(desc=desc)
    except ValueError as exc:
        rows.append(BenchRow("hexa FK ANN per call", float("nan"), "us", "", None, note=str(exc)[:120]))
        return rows
    t = time_per_call(lambda: model.predict(zetas[k]), min_time=min_time)
    rows.append(BenchRow("hexa FK ANN per call", t * 1e6, "us", "(paper: faster than NR)", None))
    err = model.predict(zetas) - poses
    pos = float(np.max(np.linalg.norm(err[:, :3], axis=1)) * 1000)
    ang = float(np.degrees(np.max(np.abs(err[:, 3:]))))
    rows.append(BenchRow("hexa FK ANN max position error on circle (eq 37)", pos, "mm", "", None))
    rows.append(BenchRow("hexa FK ANN max angle error on circle (eq 37)", ang, "deg", "", None))
    return rows
