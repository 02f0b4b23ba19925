#!/usr/bin/env python3
"""The demo's cases through the live graph and through `hexa eval`'s simulate on the same seed, side by side.

    .venv/bin/python scripts/live_vs_eval.py [--cases plate,arm,rod] [--runs 1] [--seed 0] [--realism ideal]
                                             [--rtf 0.5] [--out DIR]

Each live run is `hexa demo --case CASE` (hexa_bringup.demo_run.run_case: the whole sim graph, recorded, in its own
ROS domain) at real-time factor `--rtf`; the offline run is hexa.eval.consistency.offline_case (the same nominal
scenario, trajectory, duration, seed and robot). Prints one markdown row per live run: detection time live and
offline (commands at phase 0), their difference, whether link and chain agree, the force RMSE of both and their
ratio, and the offline detection times over the command phases 0-4 ms (hexa.eval.consistency.detection_span)
(docs/eval_live.md).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", default="plate,arm,rod")
    p.add_argument("--runs", type=int, default=1, help="live runs per case")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--realism", choices=["ideal", "realistic"], default=None,
                   help="the simulated robot (default: hexa demo's); the live nodes run the description that goes with "
                        "it, as in hexa demo")
    p.add_argument("--rtf", type=float, default=0.5)
    p.add_argument("--out", default=None, help="where the live runs' bags go (default: a temporary folder)")
    p.add_argument("--campaign", type=int, default=None, metavar="N",
                   help="instead of the demo's cases, hexa eval's contacts 0..N-1 of `--seed` on the paper's "
                        "trajectories (draw_contact(seed, i, 'paper'), simulator seed seed*100003 + i), each written "
                        "as a scenario YAML for the live simulator")
    a = p.parse_args(argv)
    from hexa_bringup.graphs import DEFAULT_REALISM

    a.realism = a.realism or DEFAULT_REALISM

    from hexa.eval.consistency import TABLE_HEADER, agreement, detection_span, offline_case
    from hexa.report.collision_demo import compute_metrics, plate_equivalent_truth
    from hexa_bringup.demo_run import case_data_from_bag, nodes_description, run_case
    from hexa_bringup.rosenv import ros_env

    out = Path(a.out or tempfile.mkdtemp(prefix="live_vs_eval_"))
    out.mkdir(parents=True, exist_ok=True)
    env = ros_env(int(os.environ.get("ROS_DOMAIN_ID", str(100 + os.getpid() % 100))))
    rows = []
    if a.campaign is not None:
        rows = campaign_rows(a, out, env)
    for case in ([] if a.campaign is not None else a.cases.split(",")):
        offline = offline_case(case, a.seed, a.realism)
        lo, hi = detection_span(case, a.seed, a.realism)
        for k in range(a.runs):
            run = run_case(case, out / f"run{k}", env, seed=a.seed, real_time_factor=a.rtf, status_every=1e9,
                           realism=a.realism, description=nodes_description(a.realism, a.seed))
            data = case_data_from_bag(case, run.bag)
            live = compute_metrics(data, plate_equivalent=plate_equivalent_truth(data)).as_dict()
            rows.append(agreement(case, live, offline).row() + f" {lo:.3f}-{hi:.3f} |")
            print(rows[-1], flush=True)
    names, rule = TABLE_HEADER.split("\n")
    print(f"\n{a.realism} robot, seed {a.seed}, live at {a.rtf:g}x real time\n"
          f"{names} detected offline over the command phases (s) |\n{rule}---|\n" + "\n".join(rows))
    return 0


def campaign_rows(a: argparse.Namespace, out: Path, env: dict[str, str]) -> list[str]:
    """One row per campaign contact: live (the contact as a scenario YAML) against offline on the same seed."""
    import yaml

    from hexa.eval.campaign import TAIL, draw_contact
    from hexa.eval.consistency import agreement, offline_contact
    from hexa.report.collision_demo import compute_metrics, plate_equivalent_truth
    from hexa.sim.scenarios import scenario_data
    from hexa_bringup.demo_run import case_data_from_bag, nodes_description, run_case

    rows = []
    for i in range(a.campaign):
        c = draw_contact(a.seed, i, "paper")
        sim_seed, duration = a.seed * 100003 + i, c.end_time + TAIL
        path = out / f"contact{i}.yaml"
        path.write_text(yaml.safe_dump(scenario_data(c)), encoding="utf-8")
        offline = offline_contact(c, duration, sim_seed, a.realism)
        run = run_case(f"contact{i}", out, env, seed=sim_seed, real_time_factor=a.rtf, status_every=1e9,
                       realism=a.realism, duration=duration, scenario=(str(path), c.trajectory),
                       description=nodes_description(a.realism, sim_seed))
        data = case_data_from_bag(c.name, run.bag)
        live = compute_metrics(data, plate_equivalent=plate_equivalent_truth(data)).as_dict()
        rows.append(agreement(f"{i} {c.link} {c.chain} {c.trajectory} {c.peak_force:.1f} N", live, offline).row()
                    + " |")
        print(rows[-1], flush=True)
    return rows


if __name__ == "__main__":
    sys.exit(main())
