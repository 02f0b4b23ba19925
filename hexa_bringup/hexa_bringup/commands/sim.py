"""`hexa sim snapshot`: run a scripted collision case offline and write each camera's view at the collision instant."""
from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sim", help="the simulated Hexa (MuJoCo): snapshots of the scripted collision cases")
    ssub = p.add_subparsers(dest="sim_command", metavar="SIM_COMMAND")
    ssub.required = True
    s = ssub.add_parser("snapshot", help="PNG of each camera (colour + depth) at the collision's force peak")
    s.add_argument("--case", choices=["plate", "arm", "rod", "all"], default="all")
    s.add_argument("--out", default="docs/img", help="output directory (default docs/img)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--randomize", action="store_true", help="draw the collision from the scenario's ranges")
    s.add_argument("--at", choices=["onset", "peak"], default="peak", help="instant of the snapshot")
    s.add_argument("--no-noise", action="store_true", help="render without the colour/depth noise models")
    s.add_argument("--json", action="store_true", help="print JSON (files, ground truth in SI units)")
    s.set_defaults(func=run)


def _depth_png(depth_mm):
    import cv2
    import numpy as np

    valid = depth_mm > 0
    vis = np.zeros(depth_mm.shape + (3,), np.uint8)
    if valid.any():
        lo, hi = np.percentile(depth_mm[valid], [1, 99])
        scaled = np.clip((depth_mm.astype(float) - lo) / max(hi - lo, 1.0), 0, 1)
        vis = cv2.applyColorMap((255 * (1 - scaled)).astype(np.uint8), cv2.COLORMAP_TURBO)
        vis[~valid] = 0
    return vis


def run(args: argparse.Namespace) -> int:
    import cv2

    from hexa.sim import Simulator

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cases = ["plate", "arm", "rod"] if args.case == "all" else [args.case]
    report = []
    for case in cases:
        with Simulator(seed=args.seed, scenario=case, randomize=args.randomize) as sim:
            c = sim.collision
            t_snap = c.peak_time if args.at == "peak" else c.onset + 0.05
            sim.run_until(t_snap)
            truth = sim.ground_truth()
            files = {}
            for cam in ("cam_top", "cam_side"):
                rgb, depth = sim.render(cam, noise=not args.no_noise)
                f_rgb = out / f"sim_{case}_{cam}.png"
                f_depth = out / f"sim_{case}_{cam}_depth.png"
                cv2.imwrite(str(f_rgb), rgb[:, :, ::-1])
                cv2.imwrite(str(f_depth), _depth_png(depth))
                files[cam] = {"rgb": str(f_rgb), "depth": str(f_depth)}
            report.append({"case": case, "time": truth.time, "link": truth.link, "chain": truth.chain,
                           "point": truth.point.tolist(), "force": truth.force.tolist(), "files": files})
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for r in report:
            p = [round(1000 * v, 1) for v in r["point"]]
            f = [round(v, 2) for v in r["force"]]
            print(f"{r['case']:5s} t={r['time']:.3f} s  {r['link']} chain {r['chain']}  point {p} mm  force {f} N")
            for cam, fs in r["files"].items():
                print(f"      {cam}: {fs['rgb']}  {fs['depth']}")
    return 0
