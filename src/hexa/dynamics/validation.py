"""Validation of the dynamics against MuJoCo (hexa.sim, built from the same YAML): runs and figures.

    python -m hexa.dynamics.validation [--json]      # the table of docs/dynamics.md

Free motion: the robot follows a trajectory (servo targets = IK of the path), nothing touches it, and the residual
(momentum form, from the simulator's ζ, ζ̇, τ and plate pose) should stay below r_low. Known forces: a constant force
at a point of the plate, an arm or a rod from `t_on` on; the steady residual and the Newton–Euler force are compared
with the simulator's ground truth.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from hexa.dynamics.identification import ContactForceEstimate, identify_contact_force
from hexa.dynamics.lagrange import HexaDynamicParameters, motion_from_joint_rates
from hexa.dynamics.observer import direct_residual_batch, momentum_residual_batch

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from hexa.dynamics.observer import CollisionEvent
    from hexa.robots.hexa_description import HexaDescription

R_LOW = 2.0


@dataclass
class SimRun:
    """Arrays (N, ·) sampled at every simulator step, plus the ground truth."""

    t: np.ndarray
    zeta: np.ndarray
    zeta_dot: np.ndarray
    zeta_ddot: np.ndarray
    tau: np.ndarray
    pose: np.ndarray
    force: np.ndarray
    point: np.ndarray
    desc: HexaDescription


def _trajectory(name: str) -> Callable[[np.ndarray], np.ndarray]:
    from hexa import trajectories

    fn = trajectories.TRAJECTORIES[name]
    return lambda t: np.asarray(fn(t)[0], dtype=float)


def simulate(path: Callable[[np.ndarray], np.ndarray], duration: float, contact: dict | None = None,
             desc: HexaDescription | None = None) -> SimRun:
    """Drive the simulated Hexa along `path(t) -> poses (N, 6)` for `duration` s; optional contact dict
    {link, chain, fraction (along the arm/rod, or an offset (3,) in {P} for the plate), force (3,), t_on}."""
    from hexa.kinematics import hexa6rus as kin
    from hexa.sim import Simulator

    if desc is None:
        from hexa.robots.hexa_description import load_hexa

        desc = load_hexa()
    start = path(np.array([0.0]))[0]
    # set-points at once: the model is validated against the physics, not the servo board's pulse frame
    sim = Simulator(desc=desc, cameras=False, pose=start, drive="external", servo_frame_period=0.0)
    dt = sim.timestep
    n = int(round(duration / dt))
    targets = kin.inverse_kinematics_batch(desc, path((np.arange(n) + 1) * dt))
    rows: list[tuple] = []
    applied = False
    for k in range(n):
        sim.set_servo_targets(targets[k])
        if contact is not None and not applied and sim.time >= contact["t_on"] - 1e-12:
            st = sim.state()
            point = contact_point(desc, st.zeta, st.pose, contact["link"], contact.get("chain", 0),
                                  contact["fraction"])
            sim.apply_external_force(contact["link"], contact.get("chain", 0), point, contact["force"])
            applied = True
        sim.step(1)
        s, g = sim.state(), sim.ground_truth()
        rows.append((s.time, s.zeta, s.zeta_dot, s.zeta_ddot, s.tau, s.pose, g.force, g.point))
    sim.close()
    cols = list(zip(*rows))
    a = [np.asarray(c, dtype=float) for c in cols]
    return SimRun(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], desc=desc)


def contact_point(desc: HexaDescription, zeta: np.ndarray, pose: np.ndarray, link: str, chain: int,
                  fraction: ArrayLike) -> np.ndarray:
    """A point on the link: the plate at offset `fraction` (3,) in {P}; an arm/rod at `fraction` of its length."""
    from hexa.kinematics import hexa6rus as kin

    if link == "plate":
        return np.asarray(pose[:3], float) + kin.rotation_zyx(*pose[3:]) @ np.asarray(fraction, float)
    A = np.asarray(desc.A, float)[chain - 1]
    B = kin.elbows(desc, zeta)[chain - 1]
    C = kin.plate_joints(desc, pose)[chain - 1]
    return A + fraction * (B - A) if link == "arm" else B + fraction * (C - B)


def free_motion_figures(run: SimRun, params: HexaDynamicParameters, skip: float = 0.3,
                        gains: float = 25.0) -> dict:
    """Residual peak and RMS per axis (N, N·m) of the momentum form after `skip` s, and direct-vs-momentum gap."""
    mom = momentum_residual_batch(params, run.t, run.zeta, run.zeta_dot, run.tau, run.pose, gains)
    direct = direct_residual_batch(params, run.t, run.zeta, run.zeta_dot, run.zeta_ddot, run.tau, run.pose, gains)
    sel = run.t >= run.t[0] + skip
    r = mom.wrench[sel]
    return {"peak": np.abs(r).max(axis=0).tolist(), "rms": np.sqrt((r**2).mean(axis=0)).tolist(),
            "direct_minus_momentum_peak": np.abs(direct.wrench[sel] - r).max(axis=0).tolist(),
            "direct_peak": np.abs(direct.wrench[sel]).max(axis=0).tolist()}


def adc_quantized_torques(tau: np.ndarray, K_t: float) -> np.ndarray:
    """τ as the driver sees it: I = τ/K_t through the ACS712 + 10-bit ADC model and back (11.9 mN·m per count)."""
    from hexa.protocol.sensor_model import CurrentSensorModel

    m = CurrentSensorModel()
    return K_t * m.current_from_counts(m.counts_from_current(tau / K_t))


def free_motion_figures_adc(run: SimRun, params: HexaDynamicParameters, skip: float = 0.3,
                            gains: float = 25.0) -> dict:
    """As free_motion_figures with the servo torques quantized by the current sensor's ADC."""
    tau = adc_quantized_torques(run.tau, params.K_t)
    mom = momentum_residual_batch(params, run.t, run.zeta, run.zeta_dot, tau, run.pose, gains)
    r = mom.wrench[run.t >= run.t[0] + skip]
    return {"peak": np.abs(r).max(axis=0).tolist(), "rms": np.sqrt((r**2).mean(axis=0)).tolist()}


def pose_driven_residual(run: SimRun, params: HexaDynamicParameters, pose_noise: tuple[float, float] = (1e-3, 5e-3),
                         camera_every: int = 33, seed: int = 0, commanded_offset: float = 0.01):
    """Stream the run through a pose-driven observer (kinematics="pose"): τ every step, the plate pose every
    `camera_every` steps with Gaussian noise (m, rad), ζ only as a seed (the true angle + `commanded_offset`).
    Returns (residual wrench (N, 6), events, observer)."""
    from hexa.dynamics.observer import ObserverConfig, ResidualObserver

    # K = 25 1/s and min_duration 0.01 s: the settings of docs/dynamics.md's validation figures (the live graph's
    # defaults differ: docs/observer_parameters.md)
    obs = ResidualObserver(params, ObserverConfig(kinematics="pose", gains=(25.0,) * 6, min_duration=0.01))
    rng = np.random.default_rng(seed)
    out = np.full((run.t.size, 6), np.nan)
    events: list[CollisionEvent] = []
    for k, t in enumerate(run.t):
        if k % camera_every == 0:
            noise = np.concatenate([rng.normal(scale=pose_noise[0], size=3), rng.normal(scale=pose_noise[1], size=3)])
            obs.update_pose(t, run.pose[k] + noise)
        res = obs.update_arm(t, run.zeta[k] + commanded_offset, run.tau[k])
        if res is not None:
            out[k] = res.wrench
            events += res.events
    return out, events, obs


def contact_figures(run: SimRun, params: HexaDynamicParameters, link: str, chain: int, settle: float = 0.3,
                    gains: float = 25.0) -> dict:
    """Steady residual vs the applied wrench (plate) and the identified force vs the truth (all links)."""
    mom = momentum_residual_batch(params, run.t, run.zeta, run.zeta_dot, run.tau, run.pose, gains)
    on = np.linalg.norm(run.force, axis=1) > 0
    t_on = run.t[on][0]
    steady = on & (run.t >= t_on + settle)
    k = int(np.flatnonzero(steady)[-1])
    ms = motion_from_joint_rates(params, run.zeta[k], run.zeta_dot[k], run.pose[k], run.zeta_ddot[k])
    est: ContactForceEstimate = identify_contact_force(params, ms, run.tau[k], link, chain, run.point[k])
    truth = run.force[k]
    seen = truth - est.unobservable_directions.T @ (est.unobservable_directions @ truth)
    out = {"link": link, "chain": chain, "truth": truth.tolist(), "identified": est.force.tolist(),
           "identified_error": (est.force - seen).tolist(), "rank": est.rank, "condition": est.condition,
           "observable": est.observable, "truth_observable_part": seen.tolist()}
    if link == "plate":
        P = run.pose[:, :3]
        W = np.concatenate([run.force, np.cross(run.point - P, run.force)], axis=1)
        err = mom.wrench[steady] - W[steady]
        out["residual_error_peak"] = np.abs(err).max(axis=0).tolist()
    else:
        out["residual_steady"] = mom.wrench[k].tolist()
    return out


FREE_TRAJECTORIES = ("circle", "helix", "ellipse")
CONTACT_CASES: tuple[dict[str, Any], ...] = (
    {"link": "plate", "chain": 0, "fraction": (0.06, 0.03, 0.0), "force": (1.5, -2.0, 3.0)},
    {"link": "plate", "chain": 0, "fraction": (-0.05, 0.05, 0.0), "force": (-3.0, 1.0, -2.0)},
    {"link": "rod", "chain": 1, "fraction": 0.5, "force": (2.0, 1.0, -1.5)},
    {"link": "rod", "chain": 4, "fraction": 0.3, "force": (-2.0, 1.0, 0.5)},
    {"link": "arm", "chain": 3, "fraction": 0.6, "force": (1.0, -2.0, 1.0)},
    {"link": "arm", "chain": 6, "fraction": 0.8, "force": (-1.0, 1.0, 2.0)},
)


def run_all(duration: float = 3.0, contact_duration: float = 2.0) -> dict:
    """Every figure of the validation table (free motion on the three trajectories, the contact cases)."""
    from hexa.robots.hexa_description import load_hexa

    desc = load_hexa()
    prm = HexaDynamicParameters.from_description(desc)
    out: dict = {"free": {}, "free_adc": {}, "free_pose_driven": {}, "contact": []}
    for name in FREE_TRAJECTORIES:
        run = simulate(_trajectory(name), duration, desc=desc)
        out["free"][name] = free_motion_figures(run, prm)
        out["free_adc"][name] = free_motion_figures_adc(run, prm)
        r, _, _ = pose_driven_residual(run, prm)
        sel = run.t >= 0.3
        out["free_pose_driven"][name] = {"peak": np.nanmax(np.abs(r[sel]), axis=0).tolist(),
                                         "rms": np.sqrt(np.nanmean(r[sel] ** 2, axis=0)).tolist()}
    for case in CONTACT_CASES:
        c = dict(case, t_on=1.0)
        run = simulate(_trajectory("circle"), contact_duration, contact=c, desc=desc)
        out["contact"].append(contact_figures(run, prm, c["link"], c["chain"]))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--duration", type=float, default=3.0)
    args = ap.parse_args(argv)
    res = run_all(args.duration)
    if args.json:
        print(json.dumps(res, indent=1))
        return 0
    axes = ("Fx", "Fy", "Fz", "Nx", "Ny", "Nz")
    print("| trajectory | " + " | ".join(f"{a} peak / RMS" for a in axes) + " |")
    print("|---|" + "---|" * 6)
    for name, f in res["free"].items():
        print(f"| {name} | " + " | ".join(f"{p:.4f} / {r:.4f}" for p, r in zip(f["peak"], f["rms"])) + " |")
    print()
    print("With τ quantized by the current sensor's 10-bit ADC (ACS712 model of hexa.protocol.sensor_model):")
    print("| trajectory | " + " | ".join(f"{a} peak / RMS" for a in axes) + " |")
    print("|---|" + "---|" * 6)
    for name, f in res["free_adc"].items():
        print(f"| {name} | " + " | ".join(f"{p:.4f} / {r:.4f}" for p, r in zip(f["peak"], f["rms"])) + " |")
    print()
    print("Pose-driven (τ at 1 kHz, plate pose at 30 Hz with 1 mm / 5 mrad noise, ζ only as a seed):")
    print("| trajectory | " + " | ".join(f"{a} peak / RMS" for a in axes) + " |")
    print("|---|" + "---|" * 6)
    for name, f in res["free_pose_driven"].items():
        print(f"| {name} | " + " | ".join(f"{p:.4f} / {r:.4f}" for p, r in zip(f["peak"], f["rms"])) + " |")
    print()
    print("| link | chain | truth (N) | identified (N) | error (N) | rank | residual error peak |")
    print("|---|---|---|---|---|---|---|")
    for c in res["contact"]:
        fmt = lambda v: "(" + ", ".join(f"{x:.3f}" for x in v) + ")"  # noqa: E731
        extra = fmt(c["residual_error_peak"]) if "residual_error_peak" in c else "—"
        print(f"| {c['link']} | {c['chain']} | {fmt(c['truth'])} | {fmt(c['identified'])} | "
              f"{fmt(c['identified_error'])} | {c['rank']} | {extra} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
