"""`hexa fk --robot R --joints … [--ann]`: forward kinematics → {"pose": {...}} (SI units)."""
from __future__ import annotations

import argparse
import json
import math


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fk", help="forward kinematics from joint values",
                       description="Hexa: --joints zeta_1..zeta_6 (rad) → pose x y z alpha beta gamma by damped "
                                   "Newton–Raphson (or --ann: the paper's neural network, seed 000 §2.2.2). "
                                   "3UPS+RPU: --joints q_1..q_4 (m) → x_m z_m theta psi by Newton–Raphson from "
                                   "--guess (default the home pose).")
    p.add_argument("--robot", choices=("hexa", "upsrpu"), required=True)
    p.add_argument("--joints", nargs="+", type=float, required=True, help="joint values (rad or m)")
    p.add_argument("--ann", action="store_true", help="Hexa: use the trained network instead of Newton–Raphson")
    p.add_argument("--guess", nargs="+", type=float, help="initial pose for Newton–Raphson (default: home)")
    p.add_argument("--description", help="robot description YAML (default: the packaged one)")
    p.add_argument("--json", action="store_true", help="print JSON (SI units)")
    p.set_defaults(func=run)


HEXA_NAMES = ("x", "y", "z", "alpha", "beta", "gamma")
UPSRPU_NAMES = ("x_m", "z_m", "theta", "psi")


def solve(robot: str, joints: list[float], ann: bool = False, guess: list[float] | None = None,
          path: str | None = None) -> dict:
    """{"robot", "method", "pose": {...}, "residual"} for `joints` (raises the module's errors)."""
    import numpy as np

    if robot == "hexa":
        from hexa.kinematics import hexa6rus
        from hexa.robots.hexa_description import load_hexa

        if len(joints) != 6:
            raise SystemExit("hexa fk: --robot hexa needs --joints with six arm angles (rad)")
        desc = load_hexa(path)
        zeta = np.array(joints)
        if ann:
            from hexa.kinematics.hexa_ann import load_ann_fk

            pose = load_ann_fk(desc=desc).predict(zeta)
            method = "ann"
        else:
            if guess is not None and len(guess) != 6:
                raise SystemExit("hexa fk: --guess needs x y z alpha beta gamma")
            pose = hexa6rus.forward_kinematics(desc, zeta, None if guess is None else np.array(guess))
            method = "newton-raphson"
        residual = float(np.max(np.abs(hexa6rus.loop_closure_residual(desc, pose, zeta))))
        return {"robot": robot, "method": method, "joints": joints,
                "pose": dict(zip(HEXA_NAMES, (float(v) for v in pose))), "residual": residual}
    if ann:
        raise SystemExit("hexa fk: --ann exists only for the Hexa")
    from hexa.kinematics import upsrpu
    from hexa.robots.upsrpu_description import load_upsrpu

    if len(joints) != 4:
        raise SystemExit("hexa fk: --robot upsrpu needs --joints q_1 q_2 q_3 q_4 (m)")
    desc = load_upsrpu(path)
    X0 = np.array(guess if guess is not None else desc.home, dtype=float)
    X = upsrpu.forward_kinematics(desc, np.array(joints), X0)
    residual = float(np.max(np.abs(upsrpu.inverse_kinematics(desc, X) - np.array(joints))))
    return {"robot": robot, "method": "newton-raphson", "joints": joints,
            "pose": dict(zip(UPSRPU_NAMES, (float(v) for v in X))), "residual": residual}


def run(args: argparse.Namespace) -> int:
    from hexa.robots.schema import RobotDescriptionError

    try:
        out = solve(args.robot, args.joints, args.ann, args.guess, args.description)
    except RobotDescriptionError as exc:
        raise SystemExit(f"hexa fk: {exc}") from exc
    except (ValueError, RuntimeError) as exc:  # ForwardKinematicsError of either robot
        if args.json:
            print(json.dumps({"robot": args.robot, "error": str(exc)}))
        else:
            print(f"hexa fk: no solution: {exc}")
        return 2
    if args.json:
        print(json.dumps(out))
        return 0
    p = out["pose"]
    if args.robot == "hexa":
        print(f"pose ({out['method']}): x y z = {p['x'] * 1000:.3f} {p['y'] * 1000:.3f} {p['z'] * 1000:.3f} mm, "
              f"alpha beta gamma = {math.degrees(p['alpha']):.3f} {math.degrees(p['beta']):.3f} "
              f"{math.degrees(p['gamma']):.3f} deg (loop residual {out['residual'] * 1000:.2g} mm)")
    else:
        print(f"pose: x_m = {p['x_m'] * 1000:.3f} mm, z_m = {p['z_m'] * 1000:.3f} mm, theta = "
              f"{math.degrees(p['theta']):.3f} deg, psi = {math.degrees(p['psi']):.3f} deg")
    return 0
