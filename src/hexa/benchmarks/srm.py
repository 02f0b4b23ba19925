"""Benchmark of one SRM step (Algorithm 1 with every M_inc candidate: FK + spherical joints + Omega), <= 2 ms."""
from __future__ import annotations

import numpy as np

from hexa.benchmarks import BenchRow, register, time_per_call
from hexa.benchmarks.singularity import cpu_time_per_call


@register("srm")
def bench(quick: bool) -> list[BenchRow]:
    """Time one active SRM-V1 / V2 step at Table 3 pose 1, plus the forward kinematics alone."""
    from hexa.kinematics import upsrpu as kin
    from hexa.robots.upsrpu_description import load_upsrpu
    from hexa.singularity import upsrpu_indices
    from hexa.srm import SingularityReleaseModule

    min_time = 0.1 if quick else 0.3
    d = load_upsrpu()
    X = np.array(d.singular_poses[0])
    q_r = kin.inverse_kinematics(d, X)
    rep = upsrpu_indices(d, X)
    rows = []
    for variant in (1, 2):
        srm = SingularityReleaseModule(d, variant)

        def one_step() -> None:
            srm.delta[:] = 0
            srm.step(q_r, X, True, rep)

        one_step()
        n_cand = int(srm.last.feasible.sum())
        t = time_per_call(one_step, min_time=min_time)
        rows.append(BenchRow(f"SRM-V{variant} step ({n_cand} candidates: FK + Omega)", t * 1e3, "ms", "<= 2 ms",
                             t <= 2e-3, note="8 M_inc columns per step"))
        t = cpu_time_per_call(one_step, 50 if quick else 200)
        rows.append(BenchRow(f"SRM-V{variant} step (CPU time)", t * 1e3, "ms", "<= 2 ms", t <= 2e-3,
                             note="process CPU time: unaffected by other load"))
    q1 = kin.inverse_kinematics(d, X + np.array([0.0005, 0.0, 0.002, -0.002]))
    t = time_per_call(lambda: kin.forward_kinematics(d, q1, X), min_time=min_time)
    rows.append(BenchRow("upsrpu NR forward kinematics (from X_c)", t * 1e6, "us", "", None))
    t = time_per_call(lambda: kin.inverse_kinematics(d, X), min_time=min_time)
    rows.append(BenchRow("upsrpu inverse kinematics", t * 1e6, "us", "", None))
    return rows
