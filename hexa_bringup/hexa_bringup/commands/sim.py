"""`hexa sim snapshot|run`: scripted collision cases offline — camera PNGs at the collision, or the ground truth."""
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
    s.add_argument("--contact-model", choices=["scripted", "physical"], default="scripted")
    s.add_argument("--json", action="store_true", help="print JSON (files, ground truth in SI units)")
    s.set_defaults(func=run)
    r = ssub.add_parser("run", help="simulate a case (physics only) and report the ground-truth contact; --out "
                        "writes every step's truth as .npz")
    r.add_argument("--case", default="plate", help="plate | arm | rod | a scenario YAML path")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--randomize", action="store_true", help="draw the collision from the scenario's ranges")
    r.add_argument("--duration", type=float, default=None, help="sim seconds (default: 1 s after the release)")
    r.add_argument("--out", help="write the truth log (time, force, point, link, chain, plate_pose, zeta, tau) here")
    r.add_argument("--contact-model", choices=["scripted", "physical"], default="scripted",
                   help="scripted: exact wrench at the point; physical: a pusher through MuJoCo contacts")
    r.add_argument("--json", action="store_true", help="print JSON (SI units)")
    r.set_defaults(func=run_case)


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
        with Simulator(seed=args.seed, scenario=case, randomize=args.randomize,
                       contact_model=args.contact_model) as sim:
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


def run_case(args: argparse.Namespace) -> int:
    import numpy as np

    from hexa import trajectories
    from hexa.sim import Simulator

    with Simulator(seed=args.seed, scenario=args.case, randomize=args.randomize, cameras=False,
                   contact_model=args.contact_model) as sim:
        c = sim.collision
        sim.run_until(args.duration if args.duration is not None else c.end_time + 1.0)
        log = sim.truth_log()
    if args.out:
        np.savez_compressed(args.out, **log)
    f = np.linalg.norm(log["force"], axis=1)
    k = int(np.argmax(f))
    touching = f > 0
    ref = np.asarray(trajectories.TRAJECTORIES[c.trajectory](log["time"])[0])
    dev = np.linalg.norm(log["plate_pose"][:, :3] - ref[:, :3], axis=1)
    out = {"case": c.name, "trajectory": c.trajectory, "link": c.link, "chain": c.chain, "seed": args.seed,
           "onset": float(log["time"][touching][0]) if touching.any() else None,
           "peak_time": float(log["time"][k]), "peak_force": float(f[k]), "force_at_peak": log["force"][k].tolist(),
           "point_at_peak": log["point"][k].tolist(), "plate_pose_at_peak": log["plate_pose"][k].tolist(),
           "max_tracking_error": float(dev.max()), "max_abs_tau": float(np.abs(log["tau"]).max()),
           "steps": int(len(log["time"])), "out": args.out}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        p = [round(1000 * v, 1) for v in out["point_at_peak"]]
        print(f"{out['case']} on {out['trajectory']}: {out['link']} chain {out['chain']}, onset {out['onset']:.3f} s, "
              f"peak {out['peak_force']:.2f} N at {out['peak_time']:.3f} s, point {p} mm, "
              f"force {[round(v, 2) for v in out['force_at_peak']]} N")
        print(f"max plate deviation from the trajectory {1000 * out['max_tracking_error']:.1f} mm, "
              f"max |tau| {out['max_abs_tau']:.2f} N*m" + (f"; truth log -> {args.out}" if args.out else ""))
    return 0
