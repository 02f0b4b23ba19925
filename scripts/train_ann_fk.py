#!/usr/bin/env python3
"""Train the Hexa ANN forward kinematics (seed 000 §2.2.2) reproducibly and export numpy weights.

Usage: .venv/bin/python scripts/train_ann_fk.py [--samples 200000] [--epochs 150] [--seed 0] [--out PATH]

Data: random poses around home through IK with out-of-workspace and near-singular samples rejected
(hexa.kinematics.hexa_ann.sample_training_set). Model: tanh MLP 6→H→H→H→6 on standardised data, Adam with a cosine
learning-rate schedule, MSE loss; one CPU thread, fixed seeds. Writes src/hexa/kinematics/hexa_ann_fk.npz and prints
the held-out accuracy against the exact poses (= Newton–Raphson FK to 1e-10).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=200_000)
    ap.add_argument("--test", type=int, default=20_000)
    ap.add_argument("--hidden", type=int, default=128)
    ap.add_argument("--layers", type=int, default=3)
    ap.add_argument("--epochs", type=int, default=150)
    ap.add_argument("--batch", type=int, default=512)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--description", default=None, help="robot description YAML (default: packaged hexa.yaml)")
    ap.add_argument("--out", default=None, help="output .npz (default: src/hexa/kinematics/hexa_ann_fk.npz)")
    args = ap.parse_args(argv)

    import torch

    from hexa.kinematics.hexa_ann import DEFAULT_WEIGHTS, SAMPLE_SPAN, geometry_fingerprint, load_ann_fk, \
        sample_training_set, save_ann_fk
    from hexa.robots.hexa_description import load_hexa

    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    torch.use_deterministic_algorithms(True)
    desc = load_hexa(args.description)
    t0 = time.perf_counter()
    zeta, pose = sample_training_set(desc, args.samples + args.test, seed=args.seed)
    print(f"dataset: {len(zeta)} poses in {time.perf_counter() - t0:.1f} s", flush=True)
    x_tr, y_tr = zeta[:args.samples], pose[:args.samples]
    x_te, y_te = zeta[args.samples:], pose[args.samples:]
    x_mean, x_std = x_tr.mean(0), x_tr.std(0)
    y_mean, y_std = y_tr.mean(0), y_tr.std(0)
    X = torch.tensor((x_tr - x_mean) / x_std, dtype=torch.float32)
    Y = torch.tensor((y_tr - y_mean) / y_std, dtype=torch.float32)

    layers: list[torch.nn.Module] = []
    width = 6
    for _ in range(args.layers):
        layers += [torch.nn.Linear(width, args.hidden), torch.nn.Tanh()]
        width = args.hidden
    layers.append(torch.nn.Linear(width, 6))
    net = torch.nn.Sequential(*layers)
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)
    steps_per_epoch = math.ceil(len(X) / args.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.epochs * steps_per_epoch,
                                                pct_start=0.1)
    gen = torch.Generator().manual_seed(args.seed)
    t0 = time.perf_counter()
    for epoch in range(args.epochs):
        perm = torch.randperm(len(X), generator=gen)
        total = 0.0
        for s in range(0, len(X), args.batch):
            idx = perm[s:s + args.batch]
            opt.zero_grad()
            loss = torch.mean((net(X[idx]) - Y[idx]) ** 2)
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
        if epoch % 10 == 0 or epoch == args.epochs - 1:
            print(f"epoch {epoch:4d}  train mse {total / len(X):.3e}  ({time.perf_counter() - t0:.0f} s)", flush=True)
    train_s = time.perf_counter() - t0

    lin = [m for m in net if isinstance(m, torch.nn.Linear)]
    weights = [m.weight.detach().numpy().T.copy() for m in lin]
    biases = [m.bias.detach().numpy().copy() for m in lin]
    out = args.out or str(DEFAULT_WEIGHTS)
    meta = {"seed": args.seed, "samples": args.samples, "epochs": args.epochs, "hidden": args.hidden,
            "layers": args.layers, "activation": "tanh", "span": list(SAMPLE_SPAN), "train_seconds": train_s,
            "torch": torch.__version__}
    save_ann_fk(out, weights, biases, x_mean, x_std, y_mean, y_std, geometry_fingerprint(desc), meta)
    model = load_ann_fk(out, desc)
    err = model.predict(x_te) - y_te
    pos_mm = np.linalg.norm(err[:, :3], axis=1) * 1000
    ang_deg = np.degrees(np.abs(err[:, 3:])).max(1)
    metrics = {"test_samples": len(x_te), "pos_mean_mm": float(pos_mm.mean()),
               "pos_p99_mm": float(np.percentile(pos_mm, 99)),
               "pos_max_mm": float(pos_mm.max()), "ang_mean_deg": float(ang_deg.mean()),
               "ang_p99_deg": float(np.percentile(ang_deg, 99)), "ang_max_deg": float(ang_deg.max())}
    meta["test"] = metrics
    save_ann_fk(out, weights, biases, x_mean, x_std, y_mean, y_std, geometry_fingerprint(desc), meta)
    print(json.dumps(meta, indent=2))
    print(f"wrote {out} ({model.n_parameters} parameters)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
