"""`hexa srm --all`: run the five Table 3 trajectories (and TR15) with SRM-V1 and SRM-V2, write a Markdown
report with a Table-4-style table beside the paper's, and plots like seed 003 Figures 10, 12 and 13."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.srm.experiment import PAPER_TABLE4, PAPER_TABLE5, ReleaseResult, run_release_experiment

if TYPE_CHECKING:
    from hexa.robots.upsrpu_description import UpsrpuDescription

__all__ = ["run_all", "write_report", "plot_indices", "plot_xm", "plot_limb"]


def _mm(v: float) -> str:
    return f"{v * 1e3:.2f}"


def plot_indices(res: list[ReleaseResult], path: Path, desc: UpsrpuDescription) -> None:
    """Figure 10 style: |det J_D| and min Omega over time, one line per variant, limits dashed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    for r in res:
        ax[0].plot(r.t, np.abs(r.det_jd), label=f"SRM-V{r.variant}")
        ax[1].plot(r.t, np.degrees(r.min_omega), label=f"SRM-V{r.variant}")
    t_on = res[0].t[res[0].k]
    for a in ax:
        a.axvline(t_on, color="k", lw=0.8, ls=":", label="e_pin on")
        a.grid(alpha=0.3)
    ax[0].axhline(desc.det_jd_limit, color="r", ls="--", lw=0.8, label="|J_D| limit")
    ax[1].axhline(math.degrees(desc.omega_limit), color="r", ls="--", lw=0.8, label="Omega limit")
    ax[0].set_ylabel("|det J_D|")
    ax[1].set_ylabel("min Omega (deg)")
    ax[1].set_xlabel("t (s)")
    ax[0].legend(fontsize=8)
    ax[0].set_title(f"Trajectory {res[0].trajectory}: type II singularity indices (cf. seed 003 Fig. 10)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_xm(r: ReleaseResult, path: Path) -> None:
    """Figure 12 style: x_m reference, measured (tracking system) and FK estimate."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(r.t, r.X_r[:, 0] * 1e3, label="reference r")
    ax.plot(r.t, r.X_kin[:, 0] * 1e3, "--", label="FK estimate c^")
    ax.plot(r.t, r.X_c[:, 0] * 1e3, label="measured c (3D tracking)")
    ax.axvline(r.t[r.k], color="k", lw=0.8, ls=":")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("x_m (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"Trajectory {r.trajectory}, SRM-V{r.variant}: x_m (cf. seed 003 Fig. 12)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_limb(r: ReleaseResult, limb: int, path: Path) -> None:
    """Figure 13 style: limb `limb` (from 1) reference / desired / measured length and its force tau."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    i = limb - 1
    fig, ax = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    ax[0].plot(r.t, r.q_r[:, i] * 1e3, label="reference r")
    ax[0].plot(r.t, r.q_d[:, i] * 1e3, "--", label="desired d")
    ax[0].plot(r.t, r.q_c[:, i] * 1e3, ":", label="measured c")
    ax[1].plot(r.t, r.tau[:, i])
    for a in ax:
        a.axvline(r.t[r.k], color="k", lw=0.8, ls=":")
        a.grid(alpha=0.3)
    ax[0].set_ylabel(f"q_ind limb {limb} (mm)")
    ax[1].set_ylabel("tau (N)")
    ax[1].set_xlabel("t (s)")
    ax[0].legend(fontsize=8)
    ax[0].set_title(f"Trajectory {r.trajectory}, SRM-V{r.variant}: limb {limb} (cf. seed 003 Fig. 13)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_all(desc: UpsrpuDescription, include_reference: bool = True, push: bool = False
            ) -> dict[str, dict[int, ReleaseResult]]:
    """Run trajectories 1..5 (and TR15 when its data is present) with both variants."""
    from hexa.kinematics.upsrpu import reference_data_dir

    names: list[str] = [str(n) for n in range(1, len(desc.singular_poses) + 1)]
    if include_reference and reference_data_dir() is not None:
        names.append("TR15")
    return {name: {v: run_release_experiment(desc, name, v, push=push) for v in (1, 2)} for name in names}


def write_report(desc: UpsrpuDescription, results: dict[str, dict[int, ReleaseResult]], out_dir: Path,
                 plots: bool = True, push_demo: ReleaseResult | None = None) -> Path:
    """Write report.md, results.json and the PNG figures into `out_dir`; return the Markdown path.

    `push_demo` (a run with the push by hand during the wait) adds a row and the Figure 12-style plot of
    x_m measured by the tracking system against the FK estimate of the encoder lengths.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = ["# SRM-V1 / SRM-V2 release of the 3UPS+RPU in simulation (seed 003 Table 4 style)", "",
             "Ours: simulated robot of hexa.srm.plant (PD inner loop, FK pose, no push, no tracking noise); "
             "MDSR = mean actuator path length after activation (see docs/srm.md for why the printed formula "
             "cannot be the one behind Table 4). Paper: seed 003 Table 4 (simulation).", "",
             "| Traj | MAE V1 (mm) | MAE V2 (mm) | MAPE V1 (%) | MAPE V2 (%) | MDSR V1 (mm) | MDSR V2 (mm) | "
             "AVR V1 (N) | AVR V2 (N) | released V1 / V2 | min pair | paper MAE V1/V2 | paper MAPE V1/V2 | "
             "paper MDSR V1/V2 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    table_rows = [n for n in results if n.isdigit()]
    sums = np.zeros((2, 4))
    for name in list(results):
        r1, r2 = results[name][1], results[name][2]
        m1, m2 = r1.metrics, r2.metrics
        paper = PAPER_TABLE4.get(int(name)) if name.isdigit() else None
        pp = (f"{paper[1][0]:.2f} / {paper[2][0]:.2f} | {paper[1][1]:.2f} / {paper[2][1]:.2f} | "
              f"{paper[1][2]:.2f} / {paper[2][2]:.2f}") if paper else "- | - | -"
        lines.append(
            f"| {name} | {_mm(m1['mae_m'])} | {_mm(m2['mae_m'])} | {m1['mape_pct']:.2f} | {m2['mape_pct']:.2f} | "
            f"{_mm(m1['mdsr_m'])} | {_mm(m2['mdsr_m'])} | {m1['avr_n']:.2f} | {m2['avr_n']:.2f} | "
            f"{'yes' if r1.released else 'NO'} ({r1.release_time if r1.release_time is not None else '-'} s) / "
            f"{'yes' if r2.released else 'NO'} ({r2.release_time if r2.release_time is not None else '-'} s) | "
            f"{r1.min_pair[r1.k]} | {pp} |")
        if name in table_rows:
            for vi, m in enumerate((m1, m2)):
                sums[vi] += [m["mae_m"] * 1e3, m["mape_pct"], m["mdsr_m"] * 1e3, m["avr_n"]]
    if table_rows:
        mean = sums / len(table_rows)
        lines.append(f"| MEAN 1-5 | {mean[0, 0]:.2f} | {mean[1, 0]:.2f} | {mean[0, 1]:.2f} | {mean[1, 1]:.2f} | "
                     f"{mean[0, 2]:.2f} | {mean[1, 2]:.2f} | {mean[0, 3]:.2f} | {mean[1, 3]:.2f} | | | "
                     "4.09 / 7.92 | 0.54 / 1.02 | 7.95 / 14.77 |")
    lines += ["", "Indices at activation and at the end of the 15 s window (|det J_D| limit "
              f"{desc.det_jd_limit}, Omega limit {math.degrees(desc.omega_limit):.1f} deg):", "",
              "| Traj | variant | det J_D at e_pin | min Omega at e_pin (deg) | det J_D end | min Omega end (deg) | "
              "implicated limbs | moved limbs | final Delta |", "|---|---|---|---|---|---|---|---|---|"]
    for name, by_v in results.items():
        for v, r in by_v.items():
            lines.append(f"| {name} | V{v} | {r.det_jd[r.k]:.4f} | {math.degrees(r.min_omega[r.k]):.2f} | "
                         f"{r.det_jd[-1]:.4f} | {math.degrees(r.min_omega[-1]):.2f} | {list(r.implicated)} | "
                         f"{list(r.moved_limbs)} | {list(r.final_delta)} |")
    if push_demo is not None:
        r, m = push_demo, push_demo.metrics
        dev = np.max(np.abs(r.X_c - r.X_kin), axis=0)
        lines += ["", f"Push by hand during the wait (trajectory {r.trajectory}, SRM-V{r.variant}): the tracking "
                  f"system sees x_m move by up to {dev[0] * 1e3:.2f} mm, theta {math.degrees(dev[2]):.2f} deg, "
                  f"psi {math.degrees(dev[3]):.2f} deg while the encoders (FK estimate) see nothing; released "
                  f"{'yes' if r.released else 'NO'}, MAE {_mm(m['mae_m'])} mm, MDSR {_mm(m['mdsr_m'])} mm, "
                  f"AVR {m['avr_n']:.2f} N."]
    lines += ["", "Paper Table 5 (experiment, SRM-V1; MAE mm, MAPE %, MDSR mm, AVR N): " +
              "; ".join(f"{k}: {v}" for k, v in PAPER_TABLE5.items()), ""]
    if plots:
        lines.append("## Figures")
        for name, by_v in results.items():
            r1 = by_v[1]
            f_idx = out_dir / f"indices_traj{name}.png"
            plot_indices([by_v[1], by_v[2]], f_idx, desc)
            f_xm = out_dir / f"xm_traj{name}_v1.png"
            plot_xm(r1, f_xm)
            limb = r1.implicated[0] if r1.implicated else 3
            limb = 3 if 3 in r1.implicated else limb
            f_limb = out_dir / f"limb{limb}_traj{name}_v1.png"
            plot_limb(r1, limb, f_limb)
            lines += [f"### Trajectory {name}", f"![indices]({f_idx.name})", f"![x_m]({f_xm.name})",
                      f"![limb {limb}]({f_limb.name})", ""]
        if push_demo is not None:
            f_push = out_dir / f"xm_traj{push_demo.trajectory}_v{push_demo.variant}_push.png"
            plot_xm(push_demo, f_push)
            lines += ["### Push by hand during the wait", f"![x_m with push]({f_push.name})", ""]
    md = out_dir / "report.md"
    md.write_text("\n".join(lines) + "\n", encoding="utf-8")
    summary: dict[str, Any] = {name: {f"v{v}": r.summary() for v, r in by_v.items()} for name, by_v in results.items()}
    (out_dir / "results.json").write_text(json.dumps(summary, indent=2), encoding="utf-8")
    return md
