#!/usr/bin/env python3
"""How the servo-torque criterion's threshold was chosen (docs/detectors.md, "Detection in servo coordinates").

    .venv/bin/python scripts/servo_threshold_study.py bags out/demo/*/bag [--thresholds 0.3 0.35 0.4]
    .venv/bin/python scripts/servo_threshold_study.py arm-draws [--draws 16]

bags: for each recorded demo bag, the observer's residual r (`residual`) mapped to servo torques τ_r = J_ζ⁻ᵀ r with
J_ζ at the simulator's true pose and arm angles (`sim/plate_pose_truth`, `sim/joint_states_truth`; bags recorded
before the observer published `servo_torque` work too). Printed per bag: the free motion before the contact (peak
|τ_r| and the longest run of samples over each threshold) and, from the first instant the true force exceeds
r_low = 2 N (a component, as the demo measures), when a run of `--run` samples over each threshold is complete — the
START (ms; negative = before the force reached 2 N), beside the plate-axis criterion (2 N / 0.2 N·m).

arm-draws: the arm scenario drawn `--draws` times from its random ranges (physics only, no cameras): the peak of the
true push as servo torques J_ζ⁻ᵀ J_Dᵀ F and as plate-axis wrench J_Dᵀ F — how many draws each criterion can see at
all (a perfect observer).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

PLATE_THRESHOLDS = np.array([2.0, 2.0, 2.0, 0.2, 0.2, 0.2])


def _stamp(h) -> float:
    return h.stamp.sec + 1e-9 * h.stamp.nanosec


def bag_series(bag: Path, ns: str = "/hexa") -> dict:
    """Residual times, plate-axis residual (N, N·m), τ_r (N·m) and the true force's largest component (N) of one demo
    bag."""
    from rosbags.highlevel import AnyReader

    from hexa.dynamics.lagrange import HexaDynamicParameters, chain_jacobian, pose_to_position_rotation
    from hexa.robots.hexa_description import load_hexa
    from hexa_bringup.bag import typestore
    from hexa_ros.conversions import hexa_pose_from_msg

    prm = HexaDynamicParameters.from_description(load_hexa())
    res, zeta, pose, force = [], [], [], []
    wanted = ("residual", "sim/joint_states_truth", "sim/plate_pose_truth", "sim/wrench_truth")
    # the bag's own message definitions: bags whose Residual has no servo_torque field still read
    with AnyReader([Path(bag)], default_typestore=typestore()) as reader:
        cons = [c for c in reader.connections if c.topic.removeprefix(ns + "/") in wanted]
        messages = [(c.topic.removeprefix(ns + "/"), reader.deserialize(raw, c.msgtype))
                    for c, _t, raw in reader.messages(connections=cons)]
    for name, m in messages:
        if name == "residual":
            w = m.wrench
            res.append((_stamp(m.header), w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z))
        elif name == "sim/joint_states_truth":
            zeta.append((_stamp(m.header), *list(m.position)[:6]))
        elif name == "sim/plate_pose_truth":
            pose.append((_stamp(m.header), *hexa_pose_from_msg(m.pose)))
        else:
            f = m.wrench.force
            force.append((_stamp(m.header), float(max(abs(f.x), abs(f.y), abs(f.z)))))
    res, zeta, pose, force = (np.array(sorted(x)) for x in (res, zeta, pose, force))
    t = res[:, 0]
    iz = np.clip(np.searchsorted(zeta[:, 0], t), 0, len(zeta) - 1)
    ip = np.clip(np.searchsorted(pose[:, 0], t), 0, len(pose) - 1)
    p, R = pose_to_position_rotation(pose[ip, 1:])
    J = chain_jacobian(prm, zeta[iz, 1:], p, R)
    tau = np.linalg.solve(np.transpose(J, (0, 2, 1)), res[:, 1:, None])[..., 0]
    return {"t": t, "r": res[:, 1:], "tau": tau, "force_t": force[:, 0], "force": force[:, 1]}


def _longest_run(mask: np.ndarray) -> int:
    best = cur = 0
    for m in mask:
        cur = cur + 1 if m else 0
        best = max(best, cur)
    return best


def _first_run_start(t: np.ndarray, mask: np.ndarray, n: int) -> float | None:
    cur = 0
    for k, m in enumerate(mask):
        cur = cur + 1 if m else 0
        if cur >= n:
            return float(t[k])
    return None


def study_bags(bags: list[Path], thresholds: list[float], run: int) -> None:
    print("| bag | free samples | free peak \\|τ_r\\| (N·m) | free longest run (" + ", ".join(map(str, thresholds))
          + ") | contact peak \\|τ_r\\| (N·m) | detection after F > 2 N (" + ", ".join(map(str, thresholds))
          + " N·m; plate axes) (ms) |")
    print("|---|---|---|---|---|---|")
    for bag in bags:
        s = bag_series(bag)
        t, r, tau = s["t"], s["r"], s["tau"]
        touching = s["force"] > 0
        onset = s["force_t"][np.argmax(touching)] if touching.any() else np.inf
        over2 = s["force"] > 2.0
        f2 = s["force_t"][np.argmax(over2)] if over2.any() else np.nan
        free = (t > t[0] + 1.0) & (t < onset - 0.05)
        after = t >= onset
        runs = [_longest_run((np.abs(tau[free]) > th).any(axis=1)) for th in thresholds]
        det = []
        for th in thresholds:
            d = _first_run_start(t[after], (np.abs(tau[after]) > th).any(axis=1), run)
            det.append("—" if d is None else f"{1e3 * (d - f2):.0f}")
        d = _first_run_start(t[after], (np.abs(r[after]) > PLATE_THRESHOLDS).any(axis=1), run)
        det.append("—" if d is None else f"{1e3 * (d - f2):.0f}")
        peak = np.abs(tau[after]).max() if after.any() else float("nan")
        print(f"| {bag} | {int(free.sum())} | {np.abs(tau[free]).max():.3f} | {', '.join(map(str, runs))} | "
              f"{peak:.3f} | {'; '.join(det)} |")


def study_arm_draws(draws: int) -> None:
    from hexa.dynamics.contact_map import plate_equivalent_wrench
    from hexa.dynamics.lagrange import HexaDynamicParameters, chain_jacobian, pose_to_position_rotation
    from hexa.sim import Simulator

    print("| draw | chain | peak \\|F\\| (N) | peak plate-axis W (N; N·m) | peak servo torque (N·m) |")
    print("|---|---|---|---|---|")
    for seed in range(draws):
        sim = Simulator(scenario="arm", cameras=False, seed=seed, randomize=True)
        prm = HexaDynamicParameters.from_description(sim.desc)
        c = sim.collision
        sim.run_until(c.onset + 0.05)
        best = (0.0, 0.0, 0.0, 0.0, 0)
        while sim.time < c.onset + c.rise_time + 0.05:
            sim.step(10)
            g, s = sim.ground_truth(), sim.state()
            if g.link == "none":
                continue
            W = plate_equivalent_wrench(sim.desc, s.pose, g.link, g.chain, np.asarray(g.point), np.asarray(g.force))
            p, R = pose_to_position_rotation(s.pose[None])
            tau = np.linalg.solve(chain_jacobian(prm, s.zeta[None], p, R)[0].T, W)
            if np.abs(tau).max() > best[0]:
                best = (float(np.abs(tau).max()), float(np.linalg.norm(g.force)), float(np.abs(W[:3]).max()),
                        float(np.abs(W[3:]).max()), int(g.chain))
        print(f"| {seed} | {best[4]} | {best[1]:.2f} | {best[2]:.2f}; {best[3]:.3f} | {best[0]:.3f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="mode", required=True)
    b = sub.add_parser("bags", help="demo bags: free-motion and contact τ_r")
    b.add_argument("bags", nargs="+", type=Path)
    b.add_argument("--thresholds", nargs="+", type=float, default=[0.3, 0.35, 0.4])
    b.add_argument("--run", type=int, default=5, help="samples in a row for a START (min_duration 0.02 s: 5)")
    a = sub.add_parser("arm-draws", help="the arm scenario's random draws, physics only")
    a.add_argument("--draws", type=int, default=16)
    args = ap.parse_args()
    if args.mode == "bags":
        study_bags(args.bags, args.thresholds, args.run)
    else:
        study_arm_draws(args.draws)


if __name__ == "__main__":
    main()
