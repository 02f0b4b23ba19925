"""`hexa srm`: seed 003 singularity release (SRM-V1/V2) of the 3UPS+RPU in simulation, with Table 4 metrics."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("srm", help="SRM-V1/V2 type II singularity release in simulation (MAE/MAPE/MDSR/AVR)",
                       description="Move the 3UPS+RPU to a Table 3 singular pose, wait 15 s, enable the SRM for "
                                   "15 s; report the seed 003 metrics. --all runs every trajectory with both "
                                   "variants and writes a report with plots.")
    p.add_argument("--trajectory", default="1", help="1..5 (Table 3) or TR15 / TRR0 (authors' references)")
    p.add_argument("--variant", choices=("v1", "v2"), default="v1")
    p.add_argument("--all", action="store_true", help="all trajectories, both variants; report + plots")
    p.add_argument("--out", default="out/srm", help="output folder for --all (default out/srm)")
    p.add_argument("--push", action="store_true", help="push the platform by hand during the wait")
    p.add_argument("--markers", action="store_true",
                   help="measure X_c through simulated noisy markers (tracking section of the description)")
    p.add_argument("--no-plots", action="store_true", help="with --all: skip the PNG figures")
    p.add_argument("--description", help="3UPS+RPU description YAML (default: the packaged one)")
    p.add_argument("--json", action="store_true", help="print JSON (SI units)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hexa.robots.upsrpu_description import load_upsrpu
    from hexa.srm.experiment import PAPER_TABLE4, run_release_experiment

    desc = load_upsrpu(args.description)
    if args.all:
        from hexa.srm.report import run_all, write_report

        results = run_all(desc, push=args.push)
        push_demo = run_release_experiment(desc, 1, 1, push=True)
        md = write_report(desc, results, Path(args.out), plots=not args.no_plots, push_demo=push_demo)
        if args.json:
            print(json.dumps({n: {f"v{v}": r.summary() for v, r in by.items()} for n, by in results.items()},
                             indent=2))
        else:
            print(md.read_text(encoding="utf-8").split("## Figures")[0])
            print(f"report: {md}")
        return 0
    traj = args.trajectory
    if traj.isdigit() and not 1 <= int(traj) <= len(desc.singular_poses):
        raise SystemExit(f"hexa srm: --trajectory must be 1..{len(desc.singular_poses)} or TR15/TRR0, got {traj}")
    variant = int(args.variant[1])
    try:
        noise = None
        if args.markers:
            from hexa.srm.tracking import tracking_model

            noise = tracking_model(desc).marker_noise
        r = run_release_experiment(desc, traj, variant, push=args.push, marker_noise=noise)
    except FileNotFoundError as exc:
        raise SystemExit(f"hexa srm: {exc}") from exc
    s = r.summary()
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    m = r.metrics
    print(f"trajectory {traj}  SRM-V{variant}: released {'yes' if r.released else 'NO'}"
          + (f" after {r.release_time:.2f} s" if r.release_time is not None else ""))
    print(f"  at e_pin: det J_D {r.det_jd[r.k]:.4f}, min Omega {math.degrees(r.min_omega[r.k]):.2f} deg "
          f"(pair {r.min_pair[r.k]}); end: det J_D {r.det_jd[-1]:.4f}, min Omega "
          f"{math.degrees(r.min_omega[-1]):.2f} deg")
    print(f"  implicated limbs {list(r.implicated)}, moved limbs {list(r.moved_limbs)}, final Delta "
          f"{list(r.final_delta)}")
    print(f"  MAE {m['mae_m'] * 1e3:.2f} mm  MAPE {m['mape_pct']:.2f} %  MDSR {m['mdsr_m'] * 1e3:.2f} mm  "
          f"AVR {m['avr_n']:.2f} N")
    if traj.isdigit():
        p = PAPER_TABLE4[int(traj)][variant]
        print(f"  paper (Table 4): MAE {p[0]:.2f} mm  MAPE {p[1]:.2f} %  MDSR {p[2]:.2f} mm")
    return 0
