"""`hexa bench`: run registered benchmarks, print a table and optionally JSON.

`hexa bench graph [BAG] ...` measures the live node graph instead (hexa_bringup.bench_graph): replay of a bag's
sensor inputs into the processing graph, and robot mode on emulated boards."""
from __future__ import annotations

import argparse
import json

GRAPH_OPTIONS = ("rate", "no_reference", "robot", "no_robot", "sim", "no_sim", "robot_duration", "cache", "params",
                 "domain_id", "compose", "stream_rate", "realtime_priority")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run benchmarks; print a table (and JSON with --json)",
                       description="ROS-free benchmarks by area (default: all), or `hexa bench graph [BAG]`: the live "
                                   "node graph on a bag's sensor inputs and on emulated hardware (docs/bench_graph.md)")
    p.add_argument("areas", nargs="*", help="areas to run (default: all); or `graph [BAG]`")
    p.add_argument("--quick", action="store_true", help="shorter runs (less precise)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    p.add_argument("--out", help="also write the JSON to this file")
    g = p.add_argument_group("hexa bench graph [BAG]",
                             "BAG: an MCAP bag with both cameras (colour, aligned depth, camera_info), motor_currents "
                             "and joint_states; default: the plate case of `hexa demo`, recorded on first use and "
                             "kept under --cache")
    g.add_argument("--rate", type=float, default=None, help="replay rate of the measured run (default 1.0)")
    g.add_argument("--no-reference", action="store_true",
                   help="skip the slow replay (rate 0.3) the outputs are compared with")
    g.add_argument("--robot", action="store_true",
                   help="only the robot-mode figures (emulated boards at 1 kHz and 200 Hz, folder cameras)")
    g.add_argument("--no-robot", action="store_true", help="skip the robot-mode figures")
    g.add_argument("--sim", action="store_true",
                   help="only the sim-mode figures (`hexa bringup sim`, the simulator asked for 1x: the real-time "
                        "factor it reaches, from /clock against wall time)")
    g.add_argument("--no-sim", action="store_true", help="skip the sim-mode figures")
    g.add_argument("--robot-duration", type=float, default=None, metavar="S",
                   help="seconds measured per robot-mode run (default 10; 5 with --quick)")
    g.add_argument("--cache", default=None, metavar="DIR",
                   help="the recorded bag, slow-replay results, exported frames and node logs (default out/bench)")
    g.add_argument("--params", default=None, help="node parameter YAML (default: the shipped hexa_params.yaml)")
    g.add_argument("--stream-rate", type=int, default=None, metavar="HZ",
                   help="without BAG: the current-sample rate of the simulated bag (default 1000; the driver's "
                        "default is 200)")
    g.add_argument("--realtime-priority", type=int, default=None, metavar="N",
                   help="the safety path (driver, observer) at SCHED_FIFO N, as `hexa bringup --realtime-priority`: "
                        "its stand-ins and the measuring subscriber too (default: the parameters file's, 0)")
    g.add_argument("--compose", action="store_true",
                   help="the graph as `hexa bringup --compose` starts it (several nodes per process; CPU per process)")
    g.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID of the bench's graph (default: a free one, held with a lock while it runs)")
    p.set_defaults(func=run)


def print_rows(area: str, rows: list) -> None:
    """One section of the table: name, measured value, unit, target, met, note."""
    print(f"\n## {area}")
    print(f"{'benchmark':44s} {'measured':>14s} {'unit':10s} {'target':16s} met")
    for r in rows:
        met = "-" if r.met is None else ("yes" if r.met else "NO")
        value = f"{r.value:14.4g}" if r.value == r.value else f"{'n/a':>14s}"
        print(f"{r.name:44s} {value} {r.unit:10s} {r.target:16s} {met}  {r.note}")


def run(args: argparse.Namespace) -> int:
    if args.areas and args.areas[0] == "graph":
        return run_graph(args)
    if "graph" in args.areas:
        raise SystemExit("hexa bench: run `hexa bench graph [BAG]` on its own (it starts the ROS graph)")
    used = [f"--{o.replace('_', '-')}" for o in GRAPH_OPTIONS if getattr(args, o) not in (None, False)]
    if used:
        raise SystemExit(f"hexa bench: {', '.join(used)} only apply to `hexa bench graph`")
    from hexa.benchmarks import discover

    registry = discover()
    unknown = [a for a in args.areas if a not in registry]
    if unknown:
        raise SystemExit(f"hexa bench: unknown area(s) {unknown}; known: {sorted(registry)} and graph")
    results: dict[str, list[dict]] = {}
    for area in args.areas or sorted(registry):
        rows = registry[area](args.quick)
        results[area] = [r.as_dict() for r in rows]
        if not args.json:
            print_rows(area, rows)
    text = json.dumps(results, indent=2)
    if args.json:
        print(text)
    else:
        print("\nJSON:")
        print(json.dumps(results))
    if args.out:
        with open(args.out, "w", encoding="utf-8") as f:
            f.write(text)
    return 0


def run_graph(args: argparse.Namespace) -> int:
    """`hexa bench graph [BAG]`."""
    import sys
    from pathlib import Path

    from hexa_bringup.bench_graph import Options, main

    rest = args.areas[1:]
    if len(rest) > 1:
        print(f"hexa bench graph: one BAG at most, got {rest}", file=sys.stderr)
        return 2
    if (args.robot and args.no_robot) or (args.sim and args.no_sim) or (args.robot and args.sim):
        print("hexa bench graph: --robot, --sim and their --no- forms: at most one of each, and --robot or --sim",
              file=sys.stderr)
        return 2
    duration = args.robot_duration if args.robot_duration is not None else (5.0 if args.quick else 10.0)
    if not duration > 0:
        print(f"hexa bench graph: --robot-duration must be > 0 s, got {duration}", file=sys.stderr)
        return 2
    opts = Options(bag=Path(rest[0]) if rest else None, rate=1.0 if args.rate is None else args.rate,
                   reference=not args.no_reference, replay=not (args.robot or args.sim),
                   robot=not (args.no_robot or args.sim), sim=not (args.no_sim or args.robot),
                   robot_duration=duration, cache=Path(args.cache) if args.cache else Path("out/bench"),
                   params=Path(args.params) if args.params else None, domain_id=args.domain_id,
                   compose=args.compose, stream_rate=1000 if args.stream_rate is None else args.stream_rate,
                   realtime_priority=args.realtime_priority)
    return main(opts, args.json, args.out, print_rows)
