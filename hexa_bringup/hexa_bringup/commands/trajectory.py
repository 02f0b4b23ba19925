"""`hexa trajectory NAME [--out FILE]`: a plate trajectory's servo peaks, and its pose file for the trajectory node
(`hexa bringup sim|robot --trajectory FILE`) — the paper's three or a random one of `hexa eval` (docs/eval.md)."""
from __future__ import annotations

import argparse
import json
import math
from typing import Any


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("trajectory", help="a trajectory's servo peaks and its pose file (circle | helix | ellipse | "
                                          "random:SEED)",
                       description="Checks a plate trajectory against the robot (inverse kinematics all along, peak "
                                   "servo speed, acceleration and the nominal model's torque) and writes it as the "
                                   "pose file the trajectory node plays: `hexa bringup sim --trajectory FILE`. "
                                   "random:SEED is the random smooth reachable trajectory `hexa eval` runs under "
                                   "that name (its report lists them).")
    p.add_argument("name", help="circle | helix | ellipse (seed 000) | random:SEED (hexa.random_trajectory), or "
                                "names joined by '+' played in turn, cross-faded over 2 s (circle+helix+ellipse)")
    p.add_argument("--out", default=None, metavar="FILE", help="write the pose file (CSV t x y z alpha beta gamma, "
                                                                 "SI) here")
    p.add_argument("--cycles", type=int, default=None,
                   help="random: periods in the file (default 2, its run length in `hexa eval`); the paper's: 5 s "
                        "turns (default 2)")
    p.add_argument("--rate", type=float, default=100.0, help="rows per second of the file (default 100)")
    p.add_argument("--description", default=None,
                   help="robot description YAML the random trajectory must fit (default: the packaged one)")
    p.add_argument("--json", action="store_true", help="print the result as JSON (SI units)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    import numpy as np

    from hexa.random_trajectory import RandomTrajectoryError, RandomTrajectorySettings, random_trajectory
    from hexa.robots.hexa_description import load_hexa
    from hexa.robots.schema import RobotDescriptionError
    from hexa.servo_motion import motion_peaks
    from hexa.trajectories import (OMEGA, SEQUENCE_SEPARATOR, TRAJECTORIES, random_seed_of, trajectory_named,
                                   write_pose_file)

    if not (math.isfinite(args.rate) and args.rate > 0):
        raise SystemExit(f"--rate must be > 0, got {args.rate}")
    if args.cycles is not None and args.cycles < 1:
        raise SystemExit(f"--cycles must be >= 1, got {args.cycles}")
    try:
        desc = load_hexa(args.description)
        seed = None if SEQUENCE_SEPARATOR in args.name else random_seed_of(args.name)
        traj: Any
        if SEQUENCE_SEPARATOR in args.name:
            if args.cycles not in (None, 1):
                raise ValueError("--cycles: a sequence is played once (its parts' own lengths)")
            traj, duration = trajectory_named(args.name)
            period = duration
        elif seed is not None:
            settings = RandomTrajectorySettings()
            if args.cycles is not None:
                settings = dataclasses.replace(settings, cycles=args.cycles)
            traj = random_trajectory(seed, desc, settings)
            period, duration = traj.period, traj.duration
        elif args.name in TRAJECTORIES:
            traj = TRAJECTORIES[args.name]
            period = 2.0 * math.pi / OMEGA
            duration = period * (args.cycles or 2)
        else:
            raise ValueError(f"trajectory must be one of {sorted(TRAJECTORIES)}, random:SEED or such names joined "
                             f"by '+', got {args.name!r}")
    except (RobotDescriptionError, RandomTrajectoryError, ValueError) as exc:
        raise SystemExit(f"{exc}") from None
    t = np.arange(int(round(duration * args.rate)) + 1) / args.rate
    peaks = motion_peaks(desc, *traj(t))
    out: dict[str, Any] = {"name": args.name, "period": period, "duration": duration, **peaks.as_dict(),
                           "speed_max": float(desc.speed_max), "torque_max": float(desc.torque_max)}
    if args.out:
        try:
            if seed is not None:
                path = traj.write(args.out, args.rate)
            else:
                path = write_pose_file(args.out, traj, duration, args.rate,
                                       [f"hexa trajectory {args.name}: seed 000, {duration:g} s"])  # one or a sequence
        except OSError as exc:
            raise SystemExit(f"cannot write {args.out}: {exc}") from None
        out["file"] = str(path)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"{args.name}: period {period:.3f} s, {duration:.3f} s; peak |ζ̇| {peaks.speed:.3f} rad/s "
          f"(servo {desc.speed_max:g}), |ζ̈| {peaks.accel:.3f} rad/s², |τ| {peaks.torque:.3f} N·m (nominal model; "
          f"stall {desc.torque_max:g}){'' if peaks.reachable else '; UNREACHABLE: ' + peaks.unreachable}")
    if args.out:
        print(f"pose file: {out['file']}\nplay it: hexa bringup sim --trajectory {out['file']}")
    return 0
