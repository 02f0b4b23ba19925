"""`hexa singularity`: det J_D and every Omega_ij (seed 003 sec 2.2-2.3) at a pose of the Hexa or the 3UPS+RPU."""
from __future__ import annotations

import argparse
import json
import math


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("singularity", help="type II singularity indices (det J_D, Omega_ij) at a pose",
                       description="Hexa pose: x y z alpha beta gamma (m, rad). 3UPS+RPU pose: x_m z_m theta psi "
                                   "(m, rad). Use --table3 N for a Table 3 singular pose of the 3UPS+RPU.")
    p.add_argument("--robot", choices=("hexa", "upsrpu"), required=True)
    p.add_argument("--pose", nargs="+", type=float, help="pose in SI units (m, rad)")
    p.add_argument("--table3", type=int, metavar="N", help="3UPS+RPU: use Table 3 trajectory N's singular pose")
    p.add_argument("--description", help="robot description YAML (default: the packaged one)")
    p.add_argument("--json", action="store_true", help="print JSON (SI units plus omega_deg)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from hexa import singularity

    if args.robot == "upsrpu":
        from hexa.robots.upsrpu_description import load_upsrpu

        desc = load_upsrpu(args.description)
        if args.table3 is not None:
            if not 1 <= args.table3 <= len(desc.singular_poses):
                raise SystemExit(f"hexa singularity: --table3 must be 1..{len(desc.singular_poses)}, "
                                 f"got {args.table3}")
            pose = np.array(desc.singular_poses[args.table3 - 1])
        elif args.pose is not None and len(args.pose) == 4:
            pose = np.array(args.pose)
        else:
            raise SystemExit("hexa singularity: --robot upsrpu needs --pose x_m z_m theta psi or --table3 N")
        report = singularity.upsrpu_indices(desc, pose)
        det_lim, om_lim = desc.det_jd_limit, desc.omega_limit
        names = ("x_m", "z_m", "theta", "psi")
    else:
        try:
            from hexa.robots.hexa_description import load_hexa
        except ImportError as exc:
            raise SystemExit(f"hexa singularity: the Hexa model is not available yet ({exc})") from exc
        if args.pose is None or len(args.pose) != 6:
            raise SystemExit("hexa singularity: --robot hexa needs --pose x y z alpha beta gamma")
        desc = load_hexa(args.description)
        pose = np.array(args.pose)
        try:
            report = singularity.hexa_indices(desc, pose)
        except ValueError as exc:
            raise SystemExit(f"hexa singularity: {exc}") from exc
        det_lim, om_lim = None, math.radians(1.8)
        names = ("x", "y", "z", "alpha", "beta", "gamma")
    out = report.as_dict()
    out["robot"] = args.robot
    out["pose"] = dict(zip(names, (float(v) for v in pose)))
    out["det_jd_limit"] = det_lim
    out["omega_limit"] = om_lim
    out["near"] = bool((det_lim is not None and abs(report.det_jd) < det_lim) or report.min_omega < om_lim)
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"robot {args.robot}  pose " + "  ".join(f"{k}={v:.4f}" for k, v in out["pose"].items()) + " (m, rad)")
    print(f"det J_D = {report.det_jd:.6g}" + (f"   (limit {det_lim:g})" if det_lim is not None else ""))
    for pair, deg in report.omega_deg().items():
        mark = "  <- min" if pair == report.min_pair else ""
        print(f"  Omega_{pair:5s} = {deg:8.3f} deg{mark}")
    print(f"min Omega = {math.degrees(report.min_omega):.3f} deg (pair {report.min_pair}, limit "
          f"{math.degrees(om_lim):.2f} deg)   near singularity: {'YES' if out['near'] else 'no'}")
    return 0
