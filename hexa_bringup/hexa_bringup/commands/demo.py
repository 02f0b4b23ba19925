"""`hexa demo`: the paper's three collision cases on the simulated robot with the whole node graph → report."""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from pathlib import Path

from hexa_bringup.graphs import DEFAULT_REALISM, DEMO_REAL_TIME_FACTOR


def rtf_line(asked: float, reached: float | None) -> str:
    """What the simulator reached against what was asked, in words."""
    if reached is None:
        return f"the real-time factor reached is unknown (no /clock seen; {asked:g}x asked)"
    return f"the simulator reached {reached:.2f}x real time ({asked:g}x asked; its pacing drops stalls)"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the paper's three collision cases on the simulated robot (bag, report, table)")
    p.add_argument("--case", choices=["plate", "arm", "rod", "all"], default="all")
    p.add_argument("--out", default="out/demo", help="output directory (bags, logs, report.md, PNGs)")
    p.add_argument("--seed", type=int, default=0, help="scenario seed (timings/positions drawn from it)")
    p.add_argument("--rtf", type=float, default=DEMO_REAL_TIME_FACTOR,
                   help="simulator real-time factor asked for (default %(default)s). The pacing drops the wall time "
                        "of host stalls, so the factor reached is lower; each case prints the one it reached")
    p.add_argument("--record-images", action="store_true", help="also record the camera topics (large bags)")
    p.add_argument("--contact-model", choices=["scripted", "physical"], default="scripted",
                   help="scripted: the scenario's force applied exactly along the object's axis (default); physical: "
                        "a capsule pushes through MuJoCo contacts with friction (truth = MuJoCo's contact force)")
    p.add_argument("--params", default=None,
                   help="node parameter YAML (default: the bundled hexa_bringup/config/hexa_params.yaml)")
    p.add_argument("--realism", choices=["ideal", "realistic"], default=DEFAULT_REALISM,
                   help=f"the simulated robot (default {DEFAULT_REALISM}): ideal (the nodes' model, set-points applied "
                        "at once) or realistic (a truth drawn from --seed within the documented tolerances, servo "
                        "friction, gear play, dead band, ACS712 noise, the 20 ms pulse frame; the nodes run a "
                        "calibration overlay identified on it, cached after the first run: docs/realism.md)")
    p.add_argument("--description", default=None, metavar="YAML",
                   help="robot description or calibration overlay of every node but the simulator, instead of the "
                        "one that goes with --realism (e.g. src/hexa/robots/hexa.yaml: the uncalibrated model on the "
                        "realistic robot)")
    p.add_argument("--ns", default="/hexa")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")
    p.set_defaults(func=run)


def watch_hint(domain: int, ns: str = "/hexa") -> str:
    """The lines that tell the user the demo's ROS_DOMAIN_ID and how to watch the graph from a second shell."""
    return (f"hexa demo: the graph runs in ROS_DOMAIN_ID={domain} (discovery on this host only). "
            f"Watch it from a second shell:\n  ROS_DOMAIN_ID={domain} hexa topic echo {ns.rstrip('/')}/collision")


def run(args: argparse.Namespace) -> int:
    from hexa.report.collision_demo import (compute_metrics, markdown_table, plate_equivalent_truth, plot_case,
                                            write_report)
    from hexa_bringup.demo_run import CASES, DEFAULT_PARAMS, case_data_from_bag, nodes_description, run_case
    from hexa_bringup.rosenv import ros_env
    from hexa_bringup.supervisor import SupervisorError

    from hexa.sim.pacing import MAX_REAL_TIME_FACTOR

    if not 0.0 < args.rtf <= MAX_REAL_TIME_FACTOR:      # NaN fails too
        print(f"hexa demo: --rtf must be > 0 and <= {MAX_REAL_TIME_FACTOR:g} (sim seconds per wall second), "
              f"got {args.rtf}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    domain = int(os.environ.get("ROS_DOMAIN_ID", str(100 + os.getpid() % 100)))
    env = ros_env(domain)  # localhost discovery: the demo never talks to other machines
    os.environ.update(env)  # the progress display in this process joins the same graph
    print(watch_hint(domain, args.ns), flush=True)
    cases = list(CASES) if args.case == "all" else [args.case]
    rtf = args.rtf
    params = DEFAULT_PARAMS if args.params is None else Path(args.params)
    if not params.is_file():
        print(f"hexa demo: parameter file {params} not found", file=sys.stderr)
        return 2
    if args.description is not None:
        description: Path | None = Path(args.description)
        if not description.is_file():
            print(f"hexa demo: description {description} not found", file=sys.stderr)
            return 2
    else:
        try:
            description = nodes_description(args.realism, args.seed, log=lambda line: print(f"hexa demo: {line}",
                                                                                            flush=True))
        except ValueError as exc:   # CalibrationError, RecordingError
            print(f"hexa demo: cannot calibrate the simulated robot: {exc}", file=sys.stderr)
            return 2
    print(f"hexa demo: the {args.realism} simulated robot (seed {args.seed}); the nodes' model: "
          f"{description or 'the packaged description'}", flush=True)
    metrics, plots, problems = [], {}, []
    reached: dict[str, float | None] = {}
    for i, case in enumerate(cases, 1):
        print(f"\n=== hexa demo: case {i}/{len(cases)}: {case} (scenario {CASES[case][0]}, trajectory "
              f"{CASES[case][1]}, {CASES[case][2]:.1f} s of sim time at {rtf:g}x real time) ===", flush=True)
        try:
            run = run_case(case, out, env, ns=args.ns, seed=args.seed, real_time_factor=rtf,
                           record_images=args.record_images, contact_model=args.contact_model,
                           params=params, realism=args.realism, description=description)
        except SupervisorError as exc:
            print(f"hexa demo: cannot start the graph: {exc}", file=sys.stderr)
            return 2
        if run.stopped_by is not None:   # Ctrl-C: a case cut short has no result to report
            print(f"hexa demo: stopped during case {case} (signal {signal.Signals(run.stopped_by).name}); no report "
                  f"written. The case's bag and node logs so far: {run.bag}, {run.log_dir}", file=sys.stderr)
            return 130
        if run.returncode != 0:
            problems.append(f"{case}: the graph did not run cleanly (see {run.log_dir})")
        try:
            data = case_data_from_bag(case, run.bag, args.ns)
            W = plate_equivalent_truth(data) if data.truth_pose is not None else None   # once: metrics and plot
            m = compute_metrics(data, plate_equivalent=W)
        except Exception as exc:  # noqa: BLE001 - report the case as failed, go on with the others
            problems.append(f"{case}: no metrics ({exc})")
            continue
        metrics.append(m)
        plots[case] = plot_case(data, m, out / f"{case}.png", plate_equivalent=W)
        reached[case] = run.reached_rtf
        print(f"case {case} done in {run.wall_s:.0f} s wall; {rtf_line(rtf, run.reached_rtf)}", flush=True)
    notes = "\n".join(f"- {p}" for p in problems)
    robot = (f"Simulated robot: {args.realism}, seed {args.seed}; the nodes' model: "
             f"{description or 'the packaged description'}.\n\nReal time: "
             + "; ".join(f"{c}: {rtf_line(rtf, r)}" for c, r in reached.items()) + ".")
    report = write_report(metrics, plots, out, notes=robot + ("\n\nProblems:\n" + notes if problems else ""))
    if args.json:
        print(json.dumps({"report": str(report), "cases": [m.as_dict() for m in metrics], "problems": problems,
                          "real_time_factor": {"asked": rtf, "reached": reached}}))
    else:
        print("\n" + markdown_table(metrics))
        if problems:
            print("\nProblems:\n" + notes)
        print(f"\nreport: {report}")
    return 0 if metrics and not problems else 1
