"""Arm force models compared on recorded demo bags (the arm case): force RMSE per axis for each model of the two
directions the dynamics cannot see (hexa.dynamics.identification, `arm_force_model`).

    python scripts/arm_force_model_study.py out/demo/arm/bag /tmp/demo_phys/arm/bag [--mu 0 0.2 0.5 1]

Only the component of an arm force along the arm's direction of motion m = e_k × (D − A_k) is observed. Whatever
model the rnea node ran, that component is F·m̂ of each recorded `contact_wrench`; any other model's answer at the
same sample is that component carried along the model's direction g, F_g = (F·m̂ / g·m̂) g (min-norm when
|g·m̂| < ARM_NORMAL_MIN_GAIN). So every model is evaluated on the same samples without re-running the graph. The
arm's axis for the surface normal comes from the simulator's true ζ (`sim/joint_states_truth`), the push direction
from the `contact` messages (the collision's last measured one, as the node does). RMSE as the demo report computes
it (hexa.report.collision_demo.compute_metrics).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bags", nargs="+", type=Path, help="arm-case bags of `hexa demo`")
    ap.add_argument("--mu", type=float, nargs="*", default=[0.2, 0.5],
                    help="friction coefficients for the friction-cone model")
    ap.add_argument("--ns", default="/hexa")
    args = ap.parse_args(argv)

    from hexa.dynamics.identification import arm_surface_normal, carry_observed_component
    from hexa.kinematics import hexa6rus as kin
    from hexa.report.collision_demo import compute_metrics
    from hexa.robots.hexa_description import load_hexa
    from hexa_bringup.bag import read_bag, typestore
    from hexa_bringup.demo_run import case_data_from_bag

    desc = load_hexa()
    store = typestore()
    models = ["min_norm", "surface_normal", "object_axis"] + [f"friction_cone mu={m:g}" for m in args.mu]
    print(f"| bag | {' | '.join(models)} |")
    print("|---" * (len(models) + 1) + "|")
    for bag in args.bags:
        data = case_data_from_bag("arm", bag, args.ns)
        wrenches, contacts, zeta = [], [], []
        for topic, msgtype, _t, raw in read_bag(bag):
            name = topic[len(args.ns) + 1:] if topic.startswith(args.ns + "/") else topic
            if name not in ("contact_wrench", "contact", "sim/joint_states_truth"):
                continue
            m = store.deserialize_cdr(raw, msgtype)
            t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            if name == "contact_wrench":
                wrenches.append((t, int(m.chain), np.array([m.point.x, m.point.y, m.point.z]),
                                 np.array([m.force.x, m.force.y, m.force.z])))
            elif name == "contact":
                d = np.array([m.push_direction.x, m.push_direction.y, m.push_direction.z])
                contacts.append((t, d / np.linalg.norm(d) if np.linalg.norm(d) > 0 else None))
            else:
                zeta.append((t, np.array(m.position[:6], float)))
        if not wrenches:
            print(f"| {bag} | no contact_wrench |")
            continue
        zt = np.array([z[0] for z in zeta])
        pushes = [d for _, d in contacts if d is not None]
        row = []
        for model in models:
            forces = []
            for t, chain, D, F in wrenches:
                k = chain - 1
                e = np.array([-np.sin(desc.alpha[k]), np.cos(desc.alpha[k]), 0.0])
                A = np.asarray(desc.A[k], float)
                mdir = np.cross(e, D - A)
                mdir /= np.linalg.norm(mdir)
                obs = float(F @ mdir)
                earlier = [d for tc, d in contacts if d is not None and tc <= t + 1e-9]
                push = earlier[-1] if earlier else (pushes[0] if pushes else None)
                z = zeta[int(np.argmin(np.abs(zt - t)))][1]
                B = np.asarray(kin.elbows(desc, z), float)[k]
                normal = arm_surface_normal(D, A, (B - A) / np.linalg.norm(B - A))
                name, mu = (model.split(" mu=")[0], float(model.split("=")[1])) if "=" in model else (model, 0.2)
                force, _ = carry_observed_component(mdir, obs, name, normal, push, mu)
                forces.append(obs * mdir if force is None else force)
            d2 = dataclasses.replace(data, wrench_force=np.array(forces))
            rmse = compute_metrics(d2).force_rmse
            row.append(" ".join(f"{v:.2f}" for v in rmse))
        print(f"| {bag} | {' | '.join(row)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
