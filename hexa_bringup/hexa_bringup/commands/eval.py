"""`hexa eval`: randomized contacts and free motion on the simulated robot through the nodes' core classes (no ROS),
in parallel over the local cores or on Dask distributed; a Markdown + PNG report with JSON beside it (docs/eval.md)."""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="randomized collision campaign on the simulated robot → report, DET curve, JSON",
                       description="Random contacts (link, chain, point, direction, 1-10 N, profile, onset, "
                                   "trajectory: the paper's or a random one) and free motion, run through the "
                                   "observer's, estimator's and identification's core classes on the MuJoCo robot "
                                   "without ROS, faster than real time on a process pool. Writes report.md, "
                                   "report.json and PNGs.")
    p.add_argument("--cases", type=int, default=20, help="random contacts per robot (default 20)")
    size = p.add_mutually_exclusive_group()
    size.add_argument("--minutes", type=float, help="free motion per robot, minutes (default 2)")
    size.add_argument("--hours", type=float, help="free motion per robot, hours")
    p.add_argument("--seed", type=int, default=0, help="campaign seed: draws the contacts and seeds the simulators")
    p.add_argument("--realism", choices=["ideal", "realistic", "both"], default="both",
                   help="the simulated robot: ideal (the simulator is the model), realistic (docs/realism.md) or "
                        "both, each on the same contacts (default both)")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: the CPU count)")
    p.add_argument("--scheduler", metavar="local:N|ADDRESS", default=None,
                   help="run on Dask distributed instead of the local process pool: local:N starts a local cluster "
                        "of N workers, an address (tcp://host:8786) uses a running scheduler whose workers have "
                        "hexa installed")
    p.add_argument("--detector", choices=["cusum", "threshold"], default="threshold",
                   help="the live collision detector, as the observer node's `detector` parameter (default "
                        "threshold); the report replays both and the paper's on every run")
    p.add_argument("--trajectories", choices=["paper", "random", "all"], default="all",
                   help="the motion contacts and free motion are drawn over: the paper's three (circle, helix, "
                        "ellipse), random smooth reachable ones (one per case or free-motion chunk; write one with "
                        "`hexa trajectory random:SEED --out FILE`) or all (both: contacts alternate, free motion "
                        "split in halves; default)")
    p.add_argument("--isolation", choices=["rendered", "oracle"], default="rendered",
                   help="rendered: the isolation node's core on both cameras' frames rendered from the simulator "
                        "(default; needs a headless renderer, MUJOCO_GL=egl, else the oracle runs and says so); "
                        "oracle: the true contact at the START (isolation not measured)")
    p.add_argument("--calibrate", metavar="EXCITATION", default=None,
                   help="run each robot's nodes on a calibration overlay identified in-process on that robot from "
                        "this excitation file (`hexa calibrate excite`; two runs of it per robot, ≈ 10–30 s); "
                        "default: the description's nominal model")
    p.add_argument("--robots", type=int, default=0, metavar="N",
                   help="run the jobs on N simulated robots in turn, each calibrated once first with --calibrate "
                        "(default 0: a robot drawn for every job, each calibrated in its job)")
    p.add_argument("--stream-rate", type=float, default=None, metavar="HZ",
                   help="the currents' rate (the driver's stream_rate_hz; default its 200 Hz)")
    p.add_argument("--no-identify", action="store_true", help="skip the force identification (no RMSE)")
    p.add_argument("--no-plots", action="store_true", help="no PNG figures")
    p.add_argument("--out", default="out/eval", help="output folder (default out/eval)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (SI units, delays in ms)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hexa.eval import CampaignConfig, ProgressBar, isolation_mode, jobs_of, run_campaign
    from hexa.eval.report import summarize, write_report

    hours = args.hours if args.hours is not None else (args.minutes if args.minutes is not None else 2.0) / 60.0
    realisms = ("ideal", "realistic") if args.realism == "both" else (args.realism,)
    try:
        if not math.isfinite(hours) or hours < 0:
            raise ValueError(f"free motion must be >= 0, got {hours} h")
        cfg = CampaignConfig(cases=args.cases, free_seconds=hours * 3600.0, realisms=realisms, seed=args.seed,
                             workers=args.workers, identify=not args.no_identify, scheduler=args.scheduler,
                             detector=args.detector, trajectories=args.trajectories, isolation=args.isolation,
                             calibrate=args.calibrate, stream_rate_hz=args.stream_rate, robots=args.robots)
    except ValueError as exc:
        print(f"hexa eval: {exc}", file=sys.stderr)
        return 2
    note = isolation_mode(cfg.isolation)[1] if cfg.cases else ""
    if note:   # run_campaign falls back to the oracle and the report says so too
        print(f"hexa eval: {note}", file=sys.stderr)
    jobs = jobs_of(cfg)
    bar = ProgressBar(len(jobs), sum(j.get("seconds", 8.0) for _, j in jobs))
    from hexa_ros.node import install_signal_handlers

    install_signal_handlers()     # SIGTERM (`kill`) as Ctrl-C: KeyboardInterrupt, and run_campaign stops the workers
    try:
        result = run_campaign(cfg, progress=bar.update)
    except (ValueError, OSError) as exc:   # Dask missing, or its scheduler unreachable
        print(f"\nhexa eval: {exc}", file=sys.stderr)
        return 2
    md = write_report(result, Path(args.out), plots=not args.no_plots)
    summary = summarize(result)
    if args.json:
        print(json.dumps(summary, indent=1, default=float))
    else:
        print(md.read_text(encoding="utf-8").split("## Figures")[0])
        print(f"report: {md}")
    return 0
