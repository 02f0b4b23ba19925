"""The `hexa eval` report: summary figures beside the targets, the DET curve, per-link detection and delay, force
RMSE — Markdown + PNG, with every number in JSON beside them."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.dynamics.observer import ObserverConfig
from hexa.eval.campaign import (DETECTOR_NAMES, GRID_SCALES, LINKS, THRESHOLD_SCALES, TRAJECTORY_KINDS,
                                trajectory_kind)
from hexa.report.collision_demo import PAPER_RMSE

if TYPE_CHECKING:
    from types import ModuleType

    from matplotlib.figure import Figure

#: a START counts as the contact's detection if it comes no later than this after the contact's end (s)
DETECT_GRACE = 0.1
#: contacts at or above this peak force enter the detection-rate targets (N)
STRONG_N = 3.0
#: threshold scales at which the report counts the strong contacts whose true load reaches them (`within_reach`)
REACH_SCALES = (0.5, 0.75, 1.0)
#: the campaign's targets (docs/eval_results.md), as (key, text, comparison, value)
TARGETS = (
    ("fa_per_10h", "false alarms per 10 h of free motion", "<=", 1.0),
    ("det_plate_3n", "detection, plate, peak >= 3 N", ">=", 0.99),
    ("det_rod_3n", "detection, rod, peak >= 3 N", ">=", 0.99),
    ("det_arm_3n", "detection, arm, peak >= 3 N", ">=", 0.95),
    ("delay_median_ms", "delay after r_low, median, all links (ms)", "<=", 20.0),
    ("delay_p95_ms", "delay after r_low, p95, all links (ms)", "<=", 60.0),
    ("delay_arm_median_ms", "delay after r_low, median, arm (ms)", "<=", 40.0),
    ("isolation_right", "isolation: right link + chain, detected contacts", ">=", 0.98),
    ("point_error_median_mm", "isolation: point error, median (mm)", "<=", 5.0),
    ("rmse_below_paper", "detected cases with force RMSE below the paper's on every axis", ">=", 0.90),
    ("delay_vs_paper", "CUSUM detector's median delay ÷ the paper detector's, at its false alarms", "<=", 0.5),
)


def _finite(values: list[float]) -> np.ndarray:
    a = np.asarray(values, dtype=float)
    return a[np.isfinite(a)]


def _pct(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) if a.size else float("nan")


def detected(case: dict[str, Any], detect_time: float) -> bool:
    """Whether a START at `detect_time` (NaN: none after the onset) detects the case's contact."""
    end = case["onset"] + case["rise_time"] + case["hold_time"] + case["release_time"]
    return bool(np.isfinite(detect_time) and detect_time <= end + DETECT_GRACE)


def within_reach(cases: list[dict[str, Any]], det: list[bool]) -> dict[str, Any]:
    """What the live detector could see of `cases` (detected or not: `det`), and how fast it saw it.

    reach: of the contacts ≥ STRONG_N, those whose true load crosses the detector's thresholds at some instant
    (metrics.plate_exceed_time finite: the plate-equivalent wrench or the servo torques of the true force, without
    noise or model error, over the thresholds), and how many of them were detected. A contact outside it loads the
    servos less than the thresholds allow for the model's errors: a force along an arm's motor axis reaches no servo.
    own delay: from that crossing to the START (metrics.observer_delay_ms), median and p95 of the detected ones —
    the detector's share of the delay after r_low; the rest is the force's own rise to a visible load."""
    reach = [d for c, d in zip(cases, det)
             if c["peak_force"] >= STRONG_N and math.isfinite(c["metrics"].get("plate_exceed_time", math.nan))]
    own = _finite([c["metrics"].get("observer_delay_ms", math.nan) for c, d in zip(cases, det) if d])
    # the true load's peak in threshold units (metrics.load_peak): how far the thresholds would have to come down
    load = _finite([c["metrics"].get("load_peak", math.nan) for c in cases if c["peak_force"] >= STRONG_N])
    return {"strong_reach_cases": len(reach), "strong_reach_detected": int(sum(reach)),
            "own_delay_median_ms": _pct(own, 50), "own_delay_p95_ms": _pct(own, 95),
            "strong_load_cases": int(load.size),
            "strong_load_at": {f"{k:g}": int((load >= k).sum()) for k in REACH_SCALES}}


def _detect_at(case: dict[str, Any], detector: str, scale: float) -> tuple[bool, float]:
    """(detected, delay ms) of `detector` at threshold `scale` in one case (from the replays)."""
    for row in case["detect"][detector]:
        if abs(row["scale"] - scale) < 1e-9:
            return detected(case, row["detect_time"]), row["delay_ms"]
    raise KeyError(f"no replay at scale {scale}")


def case_isolation(case: dict[str, Any]) -> str:
    """"rendered" or "oracle": how a contact case's isolation ran (results without the field: the oracle)."""
    iso = case.get("isolation")
    return iso.get("mode", "oracle") if isinstance(iso, dict) else "oracle"


def isolation_right(case: dict[str, Any]) -> bool:
    """Whether the isolation's answer (the most frequent link and chain during the true contact, as `hexa demo`)
    is the true link and, for an arm or rod, the true chain."""
    m = case["metrics"]
    return m["found_link"] == case["link"] and (case["link"] == "plate" or m["found_chain"] == case["chain"])


def summarize_isolation(cases: list[dict[str, Any]]) -> dict[str, Any]:
    """The rendered isolation over the detected contacts (an oracle case measures nothing): right link + chain
    (`isolation_right`), the same for the onset pair alone, point errors (each case's median over its contacts
    during the true contact) of the right cases, per link and in all, and the cost per case (wall s)."""
    rendered = [c for c in cases if case_isolation(c) == "rendered"]
    det = [c for c in rendered if detected(c, c["metrics"]["detect_time"])]
    out: dict[str, Any] = {"rendered_cases": len(rendered), "oracle_cases": len(cases) - len(rendered),
                           "notes": sorted({c["isolation"].get("note", "") for c in cases
                                            if isinstance(c.get("isolation"), dict)} - {""}),
                           "detected": len(det), "links": {}}

    def figures(group: list[dict[str, Any]]) -> dict[str, Any]:
        right = [c for c in group if isolation_right(c)]
        errs = _finite([c["metrics"]["point_error_median_mm"] for c in right])
        onset = [next((e for e in c["isolation"]["evaluations"] if e["onset"]), None) for c in group]
        onset_ok = [e is not None and e["link"] == e["true_link"] and (e["true_link"] == "plate"
                    or e["chain"] == e["true_chain"]) for e in onset]
        found = [c["metrics"]["found_link"] for c in group]
        return {"cases": len(group), "right": len(right), "right_rate": len(right) / len(group) if group
                else float("nan"), "onset_right": int(sum(onset_ok)), "none_found": found.count("none"),
                "point_error_median_mm": _pct(errs, 50), "point_error_p95_mm": _pct(errs, 95),
                "point_errors_mm": errs.tolist()}

    out.update(figures(det))
    for link in LINKS:
        out["links"][link] = figures([c for c in det if c["link"] == link])
    cost = [c["isolation"].get("cost", {}) for c in rendered]
    out["render_s_median"] = _pct(_finite([k.get("render_s", np.nan) for k in cost]), 50)
    out["isolate_s_median"] = _pct(_finite([k.get("isolate_s", np.nan) for k in cost]), 50)
    out["frames_rendered_median"] = _pct(_finite([k.get("frames_rendered", np.nan) for k in cost]), 50)
    out["case_wall_s_median"] = _pct(_finite([c.get("wall_s", np.nan) for c in rendered]), 50)
    return out


def _kind_of(run: dict[str, Any]) -> str:
    return run.get("trajectory_kind") or trajectory_kind(run["trajectory"])


def summarize_kinds(cases: list[dict[str, Any]], free: list[dict[str, Any]]) -> dict[str, Any]:
    """Per trajectory kind ("paper", "random") present in one robot's runs: the live detector's detection (all
    contacts and those ≥ STRONG_N, per link), delays and false STARTs before the contacts; free-motion time and the
    live detector's false STARTs; and, at × 1, every replayed detector's detection ≥ STRONG_N, median delay and false
    alarms (per hour)."""
    out: dict[str, Any] = {}
    for kind in TRAJECTORY_KINDS:
        kc = [c for c in cases if _kind_of(c) == kind]
        kf = [f for f in free if _kind_of(f) == kind]
        if not kc and not kf:
            continue
        hours = sum(f["seconds"] for f in kf) / 3600.0
        det = [detected(c, c["metrics"]["detect_time"]) for c in kc]
        strong = [(c["link"], d) for c, d in zip(kc, det) if c["peak_force"] >= STRONG_N]
        delays = _finite([c["metrics"]["delay_ms"] for c, d in zip(kc, det) if d])
        k: dict[str, Any] = {
            "cases": len(kc), "detected": int(sum(det)), "strong_cases": len(strong),
            "strong_detected": int(sum(d for _, d in strong)),
            "strong_by_link": {link: [int(sum(d for li, d in strong if li == link)),
                                      sum(1 for li, _ in strong if li == link)] for link in LINKS},
            "delay_median_ms": _pct(delays, 50), "delay_p95_ms": _pct(delays, 95),
            "false_starts_before_contact": int(sum(c["metrics"]["false_starts"] for c in kc)),
            "free_hours": hours, "live_false_starts_free": int(sum(f["live_starts"] for f in kf)),
            "trajectories": sorted({c["trajectory"] for c in kc} | {f["trajectory"] for f in kf}),
            "detectors": {}}
        one = THRESHOLD_SCALES.index(1.0)
        for name in DETECTOR_NAMES:
            dd = [_detect_at(c, name, 1.0) for c in kc]
            ok = [d for c, (d, _) in zip(kc, dd) if c["peak_force"] >= STRONG_N]
            fa = int(sum(f["starts"][name][one] for f in kf))
            k["detectors"][name] = {"detection_strong": sum(ok) / len(ok) if ok else float("nan"),
                                    "delay_median_ms": _pct(_finite([dl for d, dl in dd if d]), 50),
                                    "false_alarms": fa, "fa_per_hour": fa / hours if hours > 0 else float("nan")}
        out[kind] = k
    return out


def summarize_robots(cases: list[dict[str, Any]], free: list[dict[str, Any]]) -> dict[int, dict[str, Any]]:
    """Per simulated robot (`robot_seed` of a campaign on a few robots): free-motion hours, the live detector's false
    STARTs and every replayed detector's false alarms at × 1 in free motion, and the contacts ≥ STRONG_N it
    detected live — whether the false alarms come from one robot (its model, its calibration) or from all."""
    one = THRESHOLD_SCALES.index(1.0)
    out: dict[int, dict[str, Any]] = {}
    for seed in sorted({r["robot_seed"] for r in [*cases, *free] if "robot_seed" in r}):
        rf = [f for f in free if f.get("robot_seed") == seed]
        strong = [detected(c, c["metrics"]["detect_time"]) for c in cases
                  if c.get("robot_seed") == seed and c["peak_force"] >= STRONG_N]
        out[int(seed)] = {"free_hours": sum(f["seconds"] for f in rf) / 3600.0,
                          "live_false_starts_free": int(sum(f["live_starts"] for f in rf)),
                          "false_alarms": {n: int(sum(f["starts"][n][one] for f in rf)) for n in DETECTOR_NAMES},
                          "strong_detected": int(sum(strong)), "strong_cases": len(strong)}
    return out


def matched_delay(rows: list[dict[str, Any]], paper1: dict[str, Any], hours: float) -> dict[str, Any]:
    """A detector's DET row at the paper detector's false-alarm count (its fixed thresholds, × 1): of the scales
    that raise no more false alarms in free motion than the paper's, the one with the shortest median delay, and
    that delay ÷ the paper's. Without free motion (`hours` 0) the false-alarm rates are unknown: NaN, scale None."""
    none = {"scale": None, "delay_ms": float("nan"), "ratio": float("nan"), "false_alarms": None,
            "detection_arm_strong": float("nan")}
    if hours <= 0 or not paper1["delay_median_ms"] > 0:
        return none
    fit = [r for r in rows if r["false_alarms"] <= paper1["false_alarms"] and math.isfinite(r["delay_median_ms"])]
    if not fit:
        return none
    best = min(fit, key=lambda r: r["delay_median_ms"])
    return {"scale": best["scale"], "delay_ms": best["delay_median_ms"], "false_alarms": best["false_alarms"],
            "ratio": best["delay_median_ms"] / paper1["delay_median_ms"],
            "detection_arm_strong": best["detection_arm_strong"]}


def summarize_grid(cases: list[dict[str, Any]], free: list[dict[str, Any]], hours: float,
                   node_min_duration: float) -> list[dict[str, Any]]:
    """The threshold detector over minimum duration × threshold scale (the runs' `detect_grid` and `starts_grid`,
    and its DET rows at the node's own minimum duration): per row the false alarms in free motion (and per hour),
    the median and p95 delay after r_low of the detected contacts, the arms' median, and detection ≥ STRONG_N per
    link. Empty when some run has no grid (results written before it existed)."""
    if not cases or not all("detect_grid" in c for c in cases) or not all("starts_grid" in f for f in free):
        return []
    keys = sorted(cases[0]["detect_grid"], key=float) + [f"{node_min_duration:g}"]
    rows = []
    for key in keys:
        for k, scale in enumerate(GRID_SCALES):
            if key in cases[0]["detect_grid"]:
                dd = [(detected(c, c["detect_grid"][key][k]["detect_time"]), c["detect_grid"][key][k]["delay_ms"])
                      for c in cases]
                fa = int(sum(f["starts_grid"][key][k] for f in free))
            else:
                dd = [_detect_at(c, "threshold", scale) for c in cases]
                fa = int(sum(f["starts"]["threshold"][THRESHOLD_SCALES.index(scale)] for f in free))
            delays = _finite([d for ok, d in dd if ok])
            arm = _finite([d for c, (ok, d) in zip(cases, dd) if ok and c["link"] == "arm"])
            strong = {link: [ok for c, (ok, _) in zip(cases, dd) if c["peak_force"] >= STRONG_N and c["link"] == link]
                      for link in LINKS}
            rows.append({"min_duration": float(key), "scale": scale, "false_alarms": fa,
                         "fa_per_hour": fa / hours if hours > 0 else float("nan"),
                         "delay_median_ms": _pct(delays, 50), "delay_p95_ms": _pct(delays, 95),
                         "delay_arm_median_ms": _pct(arm, 50),
                         "detection_strong": {link: sum(v) / len(v) if v else float("nan")
                                              for link, v in strong.items()}})
    return rows


def summarize(result: dict[str, Any]) -> dict[str, Any]:
    """Per robot (realism): per-link detection and delays, free-motion false alarms, the DET curves of every replayed
    detector (the CUSUM, the threshold detector, the paper's), force RMSE against the paper's, the live detector
    against the paper's at equal false-alarm rate, and the figures beside the targets."""
    live = result["config"].get("detector", "threshold")
    out: dict[str, Any] = {}
    realisms = sorted({c["realism"] for c in result["contacts"]} | {f["realism"] for f in result["free"]})
    for realism in realisms:
        cases = [c for c in result["contacts"] if c["realism"] == realism and "metrics" in c]
        free = [f for f in result["free"] if f["realism"] == realism]
        hours = sum(f["seconds"] for f in free) / 3600.0
        s: dict[str, Any] = {"cases": len(cases), "free_hours": hours,
                             "errors": sum(1 for c in result["contacts"] if c["realism"] == realism
                                           and "metrics" not in c)}
        per_link: dict[str, Any] = {}
        all_delays: list[float] = []
        rmse_ok, rmse_n = 0, 0
        # the same split by whether some servo reached its stall torque during the contact (servo_saturated_s)
        # and, of the stalled ones, those the push drove through a type II singularity (type2_crossings)
        rmse_split = {"held": [0, 0], "stalled": [0, 0], "stalled_type2": [0, 0]}
        for link in LINKS:
            lc = [c for c in cases if c["link"] == link]
            det = [detected(c, c["metrics"]["detect_time"]) for c in lc]
            strong = [d for c, d in zip(lc, det) if c["peak_force"] >= STRONG_N]
            delays = _finite([c["metrics"]["delay_ms"] for c, d in zip(lc, det) if d])
            all_delays += delays.tolist()
            for c, d in zip(lc, det):
                # every detected case whose force was identified: one without a force (no contact isolated, or
                # the identification failed) is not below the paper's
                r = np.asarray(c["metrics"]["force_rmse"], dtype=float)
                if d and c.get("identify", True):
                    rmse_n += 1
                    below = int(np.all(np.isfinite(r)) and np.all(r < np.asarray(PAPER_RMSE[link])))
                    rmse_ok += below
                    stalled = c.get("servo_saturated_s", float("nan"))
                    if math.isfinite(stalled):
                        part = rmse_split["stalled" if stalled > 0 else "held"]
                        part[0] += below
                        part[1] += 1
                        if stalled > 0 and c.get("type2_crossings", 0) > 0:
                            rmse_split["stalled_type2"][0] += below
                            rmse_split["stalled_type2"][1] += 1
            per_link[link] = {"cases": len(lc), "detected": int(sum(det)), "strong_cases": len(strong),
                              "strong_detected": int(sum(strong)),
                              "strong_rate": sum(strong) / len(strong) if strong else float("nan"),
                              "delay_median_ms": _pct(delays, 50), "delay_p95_ms": _pct(delays, 95),
                              "delays_ms": delays.tolist(),
                              "false_starts": int(sum(c["metrics"]["false_starts"] for c in lc)),
                              **within_reach(lc, det)}
        s["links"] = per_link
        ad = np.asarray(all_delays)
        fa = {name: [sum(f["starts"][name][k] for f in free) for k in range(len(THRESHOLD_SCALES))]
              for name in DETECTOR_NAMES}
        det_curve: dict[str, list[dict[str, float]]] = {}
        for name in DETECTOR_NAMES:
            rows = []
            for k, scale in enumerate(THRESHOLD_SCALES):
                dd = [_detect_at(c, name, scale) for c in cases]
                delays = _finite([d for (ok, d) in dd if ok])
                strong = [ok for c, (ok, _) in zip(cases, dd) if c["peak_force"] >= STRONG_N]
                arm = [ok for c, (ok, _) in zip(cases, dd) if c["peak_force"] >= STRONG_N and c["link"] == "arm"]
                rows.append({"scale": scale, "false_alarms": fa[name][k],
                             "fa_per_hour": fa[name][k] / hours if hours > 0 else float("nan"),
                             "delay_median_ms": _pct(delays, 50),
                             "detection_strong": sum(strong) / len(strong) if strong else float("nan"),
                             "detection_arm_strong": sum(arm) / len(arm) if arm else float("nan")})
            det_curve[name] = rows
        s["det"] = det_curve
        node1 = next(r for r in det_curve[live] if abs(r["scale"] - 1.0) < 1e-9)
        paper1 = next(r for r in det_curve["paper"] if abs(r["scale"] - 1.0) < 1e-9)
        matched = {name: matched_delay(det_curve[name], paper1, hours) for name in DETECTOR_NAMES if name != "paper"}
        m = matched["cusum"]
        s["vs_paper"] = {"detector": "cusum", "scale": m["scale"], "delay_ms": m["delay_ms"],
                         "paper_delay_ms": paper1["delay_median_ms"], "false_alarms": m["false_alarms"],
                         "paper_false_alarms": paper1["false_alarms"], "ratio": m["ratio"],
                         "arm_detection": m["detection_arm_strong"],
                         "paper_arm_detection": paper1["detection_arm_strong"], "matched": matched}
        iso = summarize_isolation(cases)
        s["isolation"] = iso
        s["targets"] = {
            "fa_per_10h": node1["fa_per_hour"] * 10 if hours > 0 else float("nan"),
            "isolation_right": iso["right_rate"], "point_error_median_mm": iso["point_error_median_mm"],
            "det_plate_3n": per_link["plate"]["strong_rate"], "det_rod_3n": per_link["rod"]["strong_rate"],
            "det_arm_3n": per_link["arm"]["strong_rate"],
            "delay_median_ms": _pct(ad, 50), "delay_p95_ms": _pct(ad, 95),
            "delay_arm_median_ms": per_link["arm"]["delay_median_ms"],
            "rmse_below_paper": rmse_ok / rmse_n if rmse_n else float("nan"),
            "delay_vs_paper": m["ratio"],
        }
        s["rmse_cases"] = rmse_n
        s["rmse_by_servos"] = {k: {"below": v[0], "cases": v[1]} for k, v in rmse_split.items()}
        s["live_false_starts_free"] = sum(f["live_starts"] for f in free)
        node_md = result["config"].get("observer", {}).get("min_duration", ObserverConfig().min_duration)
        s["min_duration_grid"] = summarize_grid(cases, free, hours, float(node_md))
        s["kinds"] = summarize_kinds(cases, free)
        if int(result["config"].get("robots") or 0) > 0:
            s["robots"] = summarize_robots(cases, free)
        out[realism] = s
    return out


def _fmt(v: object, fmt: str = ".3g") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    return format(v, fmt) if isinstance(v, (int, float)) else str(v)


def _meets(value: float, op: str, target: float) -> str:
    if not (isinstance(value, (int, float)) and math.isfinite(value)):
        return "not measured"
    ok = value <= target if op == "<=" else value >= target
    return "met" if ok else "NOT met"


def _isolation_sentence(cfg: dict[str, Any], summary: dict[str, Any], note: str) -> str:
    """How the contacts were isolated, naming the oracle and why it ran."""
    rendered = sum(s["isolation"]["rendered_cases"] for s in summary.values())
    oracle = sum(s["isolation"]["oracle_cases"] for s in summary.values())
    notes = sorted({n for s in summary.values() for n in s["isolation"]["notes"]} | ({note} if note else set()))
    if not oracle:
        return ("Isolation: the isolation node's scheduler and locator on both cameras' rendered frames (the frames "
                "the node would use); the rnea tracker identifies the force at the contacts it finds.")
    text = (f"Isolation: rendered frames in {rendered} cases, an **oracle** (the true link, chain, point and force "
            f"direction at the START: isolation not measured) in {oracle}"
            + (" (`--isolation oracle`)." if cfg.get("isolation") == "oracle" and not note else "."))
    return text + "".join(f" {n}." for n in notes)


def _isolation_lines(iso: dict[str, Any]) -> list[str]:
    """The rendered isolation per link (Markdown), or nothing when no case rendered its frames."""
    if not iso["rendered_cases"]:
        return []
    lines = [f"Isolation on rendered frames, {iso['detected']} detected contacts (answer: the most frequent link "
             "and chain during the true contact; point error: each case's median, over the right cases); per case "
             f"a median {_fmt(iso['frames_rendered_median'])} frames rendered in {_fmt(iso['render_s_median'])} s, "
             f"{_fmt(iso['isolate_s_median'])} s isolating, {_fmt(iso['case_wall_s_median'])} s for the whole case:",
             "", "| link | detected | right link + chain | onset pair right | none found | point error median / "
             "p95 (mm) |", "|---|---|---|---|---|---|"]
    for link, g in [*iso["links"].items(), ("all", iso)]:
        lines.append(f"| {link} | {g['cases']} | {g['right']} ({_fmt(g['right_rate'])}) | {g['onset_right']} | "
                     f"{g['none_found']} | {_fmt(g['point_error_median_mm'])} / {_fmt(g['point_error_p95_mm'])} |")
    return lines + [""]


def _panels(plt: ModuleType, n: int) -> tuple[Figure, np.ndarray]:
    return plt.subplots(1, n, figsize=(5.5 * n, 3.8), squeeze=False)


def _save(plt: ModuleType, fig: Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _plots(result: dict[str, Any], summary: dict[str, Any], out: Path) -> dict[str, Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths: dict[str, Path] = {}
    colours = {"plate": "tab:blue", "arm": "tab:orange", "rod": "tab:green"}
    realisms = list(summary)
    # detection rate against peak force, per link
    fig, axes = _panels(plt, len(realisms))
    bins = np.arange(1.0, 11.0, 1.5)
    for ax, realism in zip(axes[0], realisms):
        cases = [c for c in result["contacts"] if c["realism"] == realism and "metrics" in c]
        for link in LINKS:
            lc = [c for c in cases if c["link"] == link]
            if not lc:
                continue
            f = np.array([c["peak_force"] for c in lc])
            d = np.array([detected(c, c["metrics"]["detect_time"]) for c in lc], dtype=float)
            idx = np.digitize(f, bins)
            xs, ys = [], []
            for b in range(1, len(bins) + 1):
                sel = idx == b
                if sel.any():
                    xs.append(f[sel].mean())
                    ys.append(d[sel].mean())
            ax.plot(xs, ys, "o-", color=colours[link], label=f"{link} ({len(lc)})")
        ax.set_xlabel("peak force (N)")
        ax.set_ylabel("detection rate")
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(f"{realism}: detection vs peak force")
        ax.legend(fontsize=8)
    paths["detection"] = _save(plt, fig, out / "detection_vs_force.png")
    # delay distribution per link
    fig, axes = _panels(plt, len(realisms))
    for ax, realism in zip(axes[0], realisms):
        data = [summary[realism]["links"][link]["delays_ms"] for link in LINKS]
        ax.boxplot([d if d else [np.nan] for d in data], positions=[1, 2, 3])
        ax.set_xticks([1, 2, 3], list(LINKS))
        ax.set_ylabel("delay after |F| component > r_low (ms)")
        ax.set_title(f"{realism}: detection delay per link")
    paths["delay"] = _save(plt, fig, out / "delay_per_link.png")
    # DET curve: false alarms per hour against median delay across threshold scales
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for realism, ls in zip(realisms, ("-", "--", ":")):
        for name, colour in (("cusum", "tab:red"), ("threshold", "tab:blue"), ("paper", "tab:gray")):
            rows = summary[realism]["det"][name]
            x = [r["delay_median_ms"] for r in rows]
            fa = [r["fa_per_hour"] for r in rows]
            y = [max(v, 0.0) for v in fa]
            ax.plot(x, y, ls, marker="o", ms=3, color=colour, label=f"{name} detector, {realism}")
            for r in rows:
                if abs(r["scale"] - 1.0) < 1e-9 and np.isfinite(r["delay_median_ms"]):
                    ax.plot([r["delay_median_ms"]], [max(r["fa_per_hour"], 0.0)], "s", color=colour, ms=7,
                            mfc="none")
    ax.set_yscale("symlog", linthresh=0.1)
    ax.set_xlabel("median detection delay (ms)")
    ax.set_ylabel("false alarms per hour of free motion")
    ax.set_title("DET: thresholds × 0.5 … 2.5 (square: × 1)")
    ax.legend(fontsize=7)
    paths["det"] = _save(plt, fig, out / "det_curve.png")
    # force RMSE per axis, relative to the paper's
    fig, axes = _panels(plt, len(realisms))
    for ax, realism in zip(axes[0], realisms):
        cases = [c for c in result["contacts"] if c["realism"] == realism and "metrics" in c
                 and detected(c, c["metrics"]["detect_time"])]
        for j, link in enumerate(LINKS):
            r = np.array([c["metrics"]["force_rmse"] for c in cases if c["link"] == link], dtype=float)
            r = r[np.all(np.isfinite(r), axis=1)] if r.size else r.reshape(0, 3)
            if len(r):
                ratio = r / np.asarray(PAPER_RMSE[link])
                ax.boxplot(list(ratio.T), positions=[4 * j + k for k in range(3)], widths=0.7)
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_xticks([4 * j + 1 for j in range(3)], list(LINKS))
        ax.set_ylabel("force RMSE / paper's RMSE (x, y, z)")
        ax.set_title(f"{realism}: force identification")
    paths["rmse"] = _save(plt, fig, out / "rmse.png")
    return paths


def _robots_sentence(result: dict[str, Any]) -> str:
    """Which simulated robots the jobs ran on, and what calibrating them cost."""
    n = int(result["config"].get("robots") or 0)
    if n <= 0:
        return "Simulated robots: one drawn per job."
    walls = [r["wall_s"] for r in result.get("robots", [])]
    cost = (f", each calibrated once before the jobs ({len(walls)} identifications, median "
            f"{float(np.median(walls)):.0f} s wall)" if walls else "")
    return f"Simulated robots: {n}, the jobs on each in turn{cost}."


def write_report(result: dict[str, Any], out_dir: str | Path, plots: bool = True) -> Path:
    """Write report.md, report.json and the PNGs into `out_dir`; returns the Markdown's path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize(result)
    (out / "report.json").write_text(json.dumps({"summary": summary, **result}, indent=1, default=float),
                                     encoding="utf-8")
    cfg = result["config"]
    lines = ["# hexa eval — randomized contacts and free motion on the simulated Hexa", "",
             f"{cfg['cases']} contacts and {cfg['free_seconds']:.0f} s of free motion per robot "
             f"({', '.join(cfg['realisms'])}) over the trajectories: {cfg.get('trajectories', 'paper')}, seed "
             f"{cfg['seed']}; {result['sim_s']:.0f} s simulated in "
             f"{result['wall_s']:.0f} s wall on {result['workers']} workers ({result.get('engine', 'process pool')}) "
             f"({result['sim_s'] / max(result['wall_s'], 1e-9):.1f}× real time).", "",
             "Nodes' model: " + (f"a calibration overlay identified on each robot from {cfg['calibrate']}"
                                 if cfg.get("calibrate") else "the description's (nominal)")
             + f"; currents at {cfg.get('stream_rate_hz') or 200:g} Hz. " + _robots_sentence(result), "",
             "Detection: a START from the observer's live detector no later than "
             f"{DETECT_GRACE * 1e3:.0f} ms after the contact's end. Delay: from the first instant a true force "
             "component exceeds r_low = 2 N (hexa.report.collision_demo.compute_metrics, as `hexa demo`). "
             + _isolation_sentence(cfg, summary, result.get("isolation_note", "")) +
             f" The live detector: {cfg.get('detector', 'threshold')} (the observer node's `detector`). "
             "The paper's detector: plate axes only, 2 N / 0.2 N·m, no servo-torque criterion.", ""]
    for realism, s in summary.items():
        lines += [f"## {realism} robot", "",
                  f"{s['cases']} contacts, {s['free_hours'] * 60:.1f} min of free motion; "
                  f"{s['live_false_starts_free']} false STARTs of the live detector in free motion.", "",
                  "| target | measured | target value | |", "|---|---|---|---|"]
        iso = s["isolation"]
        for key, text, op, value in TARGETS:
            v = s["targets"][key]
            measured = _fmt(v)
            if key in ("isolation_right", "point_error_median_mm") and not iso["rendered_cases"]:
                measured = "— (oracle isolation)"
            elif key == "point_error_median_mm":
                measured += f" (p95 {_fmt(iso['point_error_p95_mm'])})"
            lines.append(f"| {text} | {measured} | {op} {value:g} | {_meets(v, op, value)} |")
        split = s.get("rmse_by_servos", {})
        if any(v["cases"] for v in split.values()):
            held, stalled = split["held"], split["stalled"]
            t2 = split.get("stalled_type2", {"below": 0, "cases": 0})
            lines += ["", f"Force RMSE below the paper's on every axis: {held['below']} / {held['cases']} detected "
                      f"cases whose servos held, {stalled['below']} / {stalled['cases']} where some servo reached "
                      f"its stall torque during the contact; of these, {t2['below']} / {t2['cases']} where the push "
                      "also drove the robot through a type II singularity (docs/eval_findings.md)."]
        lines += [""] + _isolation_lines(iso) + [
                  "| link | cases | detected | peak ≥ 3 N: detected / cases | of these, true load over the "
                  "thresholds: detected / cases | delay median / p95 (ms) | the detector's own delay median / p95 "
                  "(ms) | false STARTs before the contact |", "|---|---|---|---|---|---|---|---|"]
        for link, pl in s["links"].items():
            lines.append(f"| {link} | {pl['cases']} | {pl['detected']} | {pl['strong_detected']} / "
                         f"{pl['strong_cases']} | {pl['strong_reach_detected']} / {pl['strong_reach_cases']} | "
                         f"{_fmt(pl['delay_median_ms'])} / {_fmt(pl['delay_p95_ms'])} | "
                         f"{_fmt(pl['own_delay_median_ms'])} / {_fmt(pl['own_delay_p95_ms'])} | "
                         f"{pl['false_starts']} |")
        lines += ["", "True load over the thresholds: the true force's plate-equivalent wrench or servo torques, "
                  "without noise or model error, cross the detector's thresholds at some instant. The detector's "
                  "own delay runs from that instant to the START; the delay after r_low adds the force's rise "
                  "to it."]
        reach_at = [f"{link} " + " / ".join(str(pl["strong_load_at"].get(f"{k:g}", 0)) for k in REACH_SCALES)
                    + f" of {pl['strong_load_cases']}" for link, pl in s["links"].items()
                    if pl.get("strong_load_cases")]
        if reach_at:
            lines += ["", "Contacts ≥ 3 N whose true load reaches " + ", ".join(f"{k:g}" for k in REACH_SCALES)
                      + " × the thresholds: " + "; ".join(reach_at) + "."]
        lines += ["", "Per trajectory kind (the paper's three; random smooth reachable ones, hexa.random_trajectory) "
                  "— the live detector, and every detector at × 1 (detection ≥ 3 N / median delay ms / false "
                  "alarms in free motion):", "",
                  "| trajectories | contacts | detected | ≥ 3 N detected (plate, arm, rod) | delay median / p95 (ms) "
                  "| false STARTs before the contact | free motion (min) | live false STARTs in free motion | "
                  + " | ".join(DETECTOR_NAMES) + " |",
                  "|---|---|---|---|---|---|---|---|" + "---|" * len(DETECTOR_NAMES)]
        for kind, k in s["kinds"].items():
            by_link = ", ".join(f"{d}/{n}" for d, n in k["strong_by_link"].values())
            cells = [f"{_fmt(r['detection_strong'])} / {_fmt(r['delay_median_ms'])} / {r['false_alarms']}"
                     for r in k["detectors"].values()]
            lines.append(f"| {kind} | {k['cases']} | {k['detected']} | {k['strong_detected']}/{k['strong_cases']} "
                         f"({by_link}) | {_fmt(k['delay_median_ms'])} / {_fmt(k['delay_p95_ms'])} | "
                         f"{k['false_starts_before_contact']} | {k['free_hours'] * 60:.1f} | "
                         f"{k['live_false_starts_free']} | " + " | ".join(cells) + " |")
        if s.get("robots"):
            lines += ["", "Per simulated robot — free motion and the false alarms there (the live detector; every "
                      "detector at × 1), contacts ≥ 3 N detected live:", "",
                      "| robot seed | free motion (h) | live false STARTs | " + " | ".join(DETECTOR_NAMES)
                      + " | contacts ≥ 3 N detected |", "|---|---|---|" + "---|" * len(DETECTOR_NAMES) + "---|"]
            for seed, r in s["robots"].items():
                lines.append(f"| {seed} | {r['free_hours']:.2f} | {r['live_false_starts_free']} | "
                             + " | ".join(str(r["false_alarms"][n]) for n in DETECTOR_NAMES)
                             + f" | {r['strong_detected']} / {r['strong_cases']} |")
        v = s["vs_paper"]
        if v["scale"] is not None:
            at = f"at × {v['scale']:g}"
        elif s["free_hours"] <= 0:
            at = "(no free motion: no false-alarm rate to match)"
        else:
            at = "(at no scale as few false alarms)"
        lines += ["", f"At the paper detector's false alarms (its fixed thresholds, × 1: {v['paper_false_alarms']} "
                  f"in {s['free_hours'] * 60:.1f} min of free motion), the CUSUM detector {at}: median delay "
                  f"{_fmt(v['delay_ms'])} ms vs {_fmt(v['paper_delay_ms'])} ms (ratio {_fmt(v['ratio'])}), arm "
                  f"contacts ≥ 3 N detected {_fmt(v['arm_detection'])} vs {_fmt(v['paper_arm_detection'])}; the "
                  "node's threshold detector " + ("—" if v["matched"]["threshold"]["scale"] is None else
                                                   f"at × {v['matched']['threshold']['scale']:g}: ratio "
                                                   f"{_fmt(v['matched']['threshold']['ratio'])}") + ".", "",
                  "DET (thresholds × scale; every detector on the same runs — FA/h, median delay (ms), detection "
                  "≥ 3 N):", "",
                  "| scale | " + " | ".join(f"{n}: FA/h | {n}: delay | {n}: det ≥ 3 N" for n in DETECTOR_NAMES)
                  + " |", "|---|" + "---|---|---|" * len(DETECTOR_NAMES)]
        for k, scale in enumerate(THRESHOLD_SCALES):
            cells = []
            for n in DETECTOR_NAMES:
                r = s["det"][n][k]
                cells += [_fmt(r["fa_per_hour"]), _fmt(r["delay_median_ms"]), _fmt(r["detection_strong"])]
            lines.append(f"| {scale:g} | " + " | ".join(cells) + " |")
        if s.get("min_duration_grid"):
            lines += ["", "The threshold detector over its minimum duration and threshold scale (the same runs; "
                      "delay after r_low of the detected contacts; detection ≥ 3 N per link):", "",
                      "| min_duration (ms) | scale | false alarms (per h) | delay median / p95 (ms) | arm median "
                      "(ms) | det ≥ 3 N plate / rod / arm |", "|---|---|---|---|---|---|"]
            for r in s["min_duration_grid"]:
                ds = r["detection_strong"]
                lines.append(f"| {r['min_duration'] * 1e3:g} | {r['scale']:g} | {r['false_alarms']} "
                             f"({_fmt(r['fa_per_hour'])}) | {_fmt(r['delay_median_ms'])} / "
                             f"{_fmt(r['delay_p95_ms'])} | {_fmt(r['delay_arm_median_ms'])} | "
                             f"{_fmt(ds['plate'])} / {_fmt(ds['rod'])} / {_fmt(ds['arm'])} |")
        lines.append("")
    if plots and summary:
        paths = _plots(result, summary, out)
        lines += ["## Figures", ""] + [f"![{k}]({p.name})" for k, p in paths.items()] + [""]
    path = out / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path
