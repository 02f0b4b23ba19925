"""False STARTs in free motion on a calibrated realistic robot under host timing trouble: commands that reach the
servo board late (exponential delays, in order on one link) and bursts of lost current samples.

    python scripts/command_jitter_study.py [--robot 5] [--seconds 60] [--trajectories circle,random:5]
        [--command-mean 0.02] [--command-max 0.07] [--loss-rate 0.002] [--loss-max 0.07]

Runs each trajectory three times through `hexa.eval.campaign.simulate` (the nodes' core classes, no ROS): the
realistic preset, the preset with lost-sample bursts, the preset with late commands. The nodes run the calibration
overlay identified on the same robot from the default excitation design (cached as `hexa demo` caches it). Prints
the live detector's STARTs, the longest gap in the residual's sample times and the channels of the first STARTs.
"""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", type=int, default=5, help="the simulated robot's seed")
    p.add_argument("--seconds", type=float, default=60.0, help="free motion per run (s)")
    p.add_argument("--trajectories", default="circle,random:5")
    p.add_argument("--command-mean", type=float, default=0.02, help="mean command delay (s, exponential)")
    p.add_argument("--command-max", type=float, default=0.07, help="largest command delay (s)")
    p.add_argument("--loss-rate", type=float, default=0.002, help="per sample: probability a loss burst starts")
    p.add_argument("--loss-max", type=float, default=0.07, help="longest loss burst (s)")
    a = p.parse_args()

    from hexa.calibration.simulated import simulated_calibration
    from hexa.eval.campaign import simulate
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim.realism import RealismConfig

    base = RealismConfig.realistic()
    nodes = load_hexa(simulated_calibration(a.robot, base, log=print))
    variants = {
        "preset": base,
        "lost samples": dataclasses.replace(base, jitter=dataclasses.replace(
            base.jitter, loss_rate=a.loss_rate, loss_max=a.loss_max)),
        "late commands": dataclasses.replace(base, jitter=dataclasses.replace(
            base.jitter, command_mean=a.command_mean, command_max=a.command_max)),
    }
    print(f"robot {a.robot}, {a.seconds:g} s per run; lost samples: {a.loss_rate:g} per sample, up to "
          f"{a.loss_max * 1e3:g} ms; late commands: mean {a.command_mean * 1e3:g} ms, up to {a.command_max * 1e3:g} ms")
    for traj in a.trajectories.split(","):
        for name, realism in variants.items():
            rec = simulate(None, traj, a.seconds, realism, seed=1000 + a.robot, identify=False, nodes_desc=nodes,
                           robot_seed=a.robot)
            starts = [e for e in rec.events if e[1] == "START"]
            gap = float(np.diff(rec.t).max()) if len(rec.t) > 1 else float("nan")
            print(f"{traj:12s} {name:14s} STARTs {len(starts):3d}  longest gap {gap * 1e3:5.0f} ms  first: "
                  + ", ".join(f"{t:.2f} s {axis}" for t, _, _, axis in starts[:4]), flush=True)


if __name__ == "__main__":
    main()
