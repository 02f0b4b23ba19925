"""`hexa ik --robot R --pose …`: closed-form inverse kinematics → {"joints": [...]}
(rad for the Hexa, m for the 3UPS+RPU)."""
from __future__ import annotations

import argparse
import json
import math


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ik", help="inverse kinematics at a pose",
                       description="Hexa: --pose x y z alpha beta gamma (m, rad; Z-Y-X of seed 000 eq 38) → arm "
                                   "angles zeta (rad). 3UPS+RPU: --pose x_m z_m theta psi (m, rad) → actuator "
                                   "lengths q (m). Exit status 2 when the pose is unreachable.")
    p.add_argument("--robot", choices=("hexa", "upsrpu"), required=True)
    p.add_argument("--pose", nargs="+", type=float, required=True, help="pose in SI units (m, rad)")
    p.add_argument("--description", help="robot description YAML (default: the packaged one)")
    p.add_argument("--json", action="store_true", help="print JSON (SI units)")
    p.set_defaults(func=run)


def solve(robot: str, pose: list[float], path: str | None = None) -> dict:
    """{"robot", "pose", "joints"} for `pose`; raises the kinematics module's UnreachablePoseError."""
    import numpy as np

    if robot == "hexa":
        from hexa.kinematics import hexa6rus
        from hexa.robots.hexa_description import load_hexa

        if len(pose) != 6:
            raise SystemExit("hexa ik: --robot hexa needs --pose x y z alpha beta gamma")
        zeta = hexa6rus.inverse_kinematics(load_hexa(path), np.array(pose))
        return {"robot": robot, "pose": dict(zip(("x", "y", "z", "alpha", "beta", "gamma"), pose)),
                "joints": [float(v) for v in zeta], "unit": "rad"}
    from hexa.kinematics import upsrpu
    from hexa.robots.upsrpu_description import load_upsrpu

    if len(pose) != 4:
        raise SystemExit("hexa ik: --robot upsrpu needs --pose x_m z_m theta psi")
    q = upsrpu.inverse_kinematics(load_upsrpu(path), np.array(pose), check_limits=True)
    return {"robot": robot, "pose": dict(zip(("x_m", "z_m", "theta", "psi"), pose)),
            "joints": [float(v) for v in q], "unit": "m"}


def run(args: argparse.Namespace) -> int:
    from hexa.robots.schema import RobotDescriptionError

    try:
        out = solve(args.robot, args.pose, args.description)
    except RobotDescriptionError as exc:
        raise SystemExit(f"hexa ik: {exc}") from exc
    except ValueError as exc:  # both robots' UnreachablePoseError derive from ValueError
        err = {"robot": args.robot, "error": str(exc), "chain": getattr(exc, "chain", None),
               "reason": getattr(exc, "reason", None)}
        if args.json:
            print(json.dumps(err))
        else:
            print(f"hexa ik: unreachable: {exc}")
        return 2
    if args.json:
        print(json.dumps(out))
    elif args.robot == "hexa":
        print("zeta (deg): " + "  ".join(f"{math.degrees(v):8.3f}" for v in out["joints"]))
    else:
        print("q (mm): " + "  ".join(f"{v * 1000:8.2f}" for v in out["joints"]))
    return 0
