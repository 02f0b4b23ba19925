#!/usr/bin/env python3
"""The real-time factor the simulator's stepping loop reaches with its cameras rendered inline or on the camera
worker's thread (docs/simulator.md, "Benchmarks").

    .venv/bin/python scripts/bench_sim_cameras.py [--duration 5] [--rtf 1] [--mode both|inline|worker]

Runs hexa.sim.pacing.SimRunner over the plate scenario for `--duration` sim seconds, paced at `--rtf` with the sim
node's max_lag, the clock at 250 Hz, the ground truth read at 100 Hz and both cameras at 30 fps; each frame is
serialized as the sim node publishes it (hexa_ros.cdr.image_to_cdr), without ROS. `inline` renders at the camera
instant on the stepping thread (Simulator.render), `worker` hands the instant to hexa.sim.camera_worker. Prints per
mode the real-time factor reached (sim s / wall s after the model is built), the process's CPU over that time (% of
a core), the wall time dropped by the pacer and the time the loop spent in the cameras.
"""
from __future__ import annotations

import argparse
import time

from hexa.sim import Simulator
from hexa.sim.camera_worker import CameraFrame, CameraWorker
from hexa.sim.config import CAMERA_NAMES
from hexa.sim.pacing import Pacer, SimRunner
from hexa_ros.cdr import image_to_cdr


def _serialize(rgb, depth) -> None:
    image_to_cdr(0, 0, "cam", rgb, "rgb8")
    image_to_cdr(0, 0, "cam", depth, "16UC1")


class _Outputs:
    """SimRunner's outputs without ROS: the truth read, the frames rendered and serialized."""

    def __init__(self, sim: Simulator, worker: CameraWorker | None) -> None:
        self.sim, self.worker, self.in_cameras = sim, worker, 0.0

    def clock(self) -> None:
        pass

    def truth(self) -> None:
        self.sim.state()
        self.sim.ground_truth()

    def cameras(self) -> None:
        t0 = time.perf_counter()
        if self.worker is not None:
            self.worker.submit(self.sim.frame_state(), CAMERA_NAMES)
        else:
            for cam in CAMERA_NAMES:
                _serialize(*self.sim.render(cam))
        self.in_cameras += time.perf_counter() - t0

    def spin(self) -> None:
        pass


def run(mode: str, duration: float, rtf: float) -> None:
    with Simulator(seed=0, scenario="plate") as sim:
        def deliver(frame: CameraFrame) -> None:
            if frame.rgb is not None and frame.depth is not None:
                _serialize(frame.rgb, frame.depth)

        worker = CameraWorker(sim, deliver) if mode == "worker" else None
        pacer = Pacer(rtf)
        runner = SimRunner(sim, pacer, 250.0, 100.0, 30.0, duration=duration)
        out = _Outputs(sim, worker)
        wall0, cpu0 = time.perf_counter(), time.process_time()
        try:
            runner.run(out, lambda: True)
        finally:
            if worker is not None:
                worker.close()
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        print(f"{mode:6s}: {sim.time / wall:.3f}x real time ({sim.time:.2f} sim s in {wall:.2f} wall s), "
              f"CPU {100 * cpu / wall:.0f} % of a core, {pacer.stalls} stalls over max_lag, {pacer.dropped:.2f} s "
              f"dropped, {out.in_cameras:.2f} s in cameras()")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=5.0, help="sim seconds per run (default 5)")
    ap.add_argument("--rtf", type=float, default=1.0, help="real-time factor asked for (default 1)")
    ap.add_argument("--mode", choices=("both", "inline", "worker"), default="both")
    args = ap.parse_args()
    for mode in ("inline", "worker") if args.mode == "both" else (args.mode,):
        run(mode, args.duration, args.rtf)


if __name__ == "__main__":
    main()
