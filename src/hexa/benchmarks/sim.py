"""Simulator benchmarks: physics-only real-time factor at 1 kHz, per-frame render, whole sim at 30 fps."""
from __future__ import annotations

import importlib.util
import os
import time

from hexa.benchmarks import BenchRow, register, time_per_call


def _simulator(cameras: bool):
    os.environ.setdefault("MUJOCO_GL", "egl")
    from hexa.sim import Simulator

    scenario = "plate" if importlib.util.find_spec("hexa.trajectories") is not None else None
    return Simulator(scenario=scenario, cameras=cameras, seed=0)


@register("sim")
def bench(quick: bool) -> list[BenchRow]:
    rows: list[BenchRow] = []
    sim_seconds = 1.0 if quick else 4.0
    sim = _simulator(cameras=False)
    n = int(round(sim_seconds / sim.timestep))
    t0 = time.perf_counter()
    sim.step(n)
    wall = time.perf_counter() - t0
    rtf = sim_seconds / wall
    rows.append(BenchRow("physics only, 1 kHz steps (plate case)", rtf, "x real time", ">= 5x", rtf >= 5.0,
                         f"first {sim_seconds:g} s of sim time (contact from 3.4 s); {1e6 * wall / n:.0f} us per step"))

    sim = _simulator(cameras=True)
    try:
        sim.run_until(3.8 if sim.collision is not None else 0.1)
        for cam in ("cam_top", "cam_side"):
            dt = time_per_call(lambda: sim.render(cam), min_time=0.2 if quick else 0.6)
            rows.append(BenchRow(f"render {cam} 640x480 RGB + depth (noisy)", 1e3 * dt, "ms/frame", "", None,
                                 "one GL pass, colour and depth read together"))
        dt_raw = time_per_call(lambda: sim.render_raw("cam_top"), min_time=0.2 if quick else 0.6)
        rows.append(BenchRow("render cam_top without the noise models", 1e3 * dt_raw, "ms/frame", "", None))

        duration = 1.0 if quick else 3.0
        steps_per_frame = int(round(1.0 / (sim.config.camera_rate_hz * sim.timestep)))
        frames = int(round(duration * sim.config.camera_rate_hz))
        t0 = time.perf_counter()
        for _ in range(frames):
            sim.step(steps_per_frame)
            sim.render("cam_top")
            sim.render("cam_side")
        wall = time.perf_counter() - t0
        rtf = frames * steps_per_frame * sim.timestep / wall
        rows.append(BenchRow("whole sim: 1 kHz physics + both cameras at 30 fps", rtf, "x real time", ">= 0.5x",
                             rtf >= 0.5, f"{duration:g} s of sim time, {2 * frames} frames"))
    finally:
        sim.close()
    return rows
