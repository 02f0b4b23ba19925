#!/usr/bin/env python3
"""How much of the free-motion residual comes from not knowing *when* each servo takes its set-point (ROS-free).

    .venv/bin/python scripts/servo_frame_study.py [--duration 6] [--json]

The MuJoCo Hexa follows the circle (eq 37) from 100 Hz commands (inverse kinematics); current samples with ADC
quantization and noise go to the ζ estimator (hexa.estimation) and its ζ̂, ζ̂̇ to the residual observer
(hexa.dynamics.observer, K = 100 1/s); plate poses with 1 mm / 0.3° noise at 30 Hz correct both. Varied:

- frame: 0 = the simulator applies each set-point at once (the default), 0.02 = the servo board's 20 ms pulse frame
  (`sim.servo.frame_period`: a servo takes the newest target only at the end of its pulse);
- jitter: commands reach the servo board 0-jitter s after the host sent them (uniform);
- sample: current sample period (the driver's `stream_rate_hz` 200 = 5 ms, up to 1 kHz);
- set-point: "command" = the estimator gets the command the host sent (what the live graph has), "oracle" = the
  set-point each servo really acts on (what a board reporting its latch times would give).

With --gaps: no frame, commands on time, but every 0.5 s the host sends nothing for 90 ms (a stalled driver), then
catches up with the trajectory — at once (a jump) or at 1.5 or 1 rad/s (the driver's `max_speed`, 1.5, over one 10 ms
command period); the residual's peak during each gap and in the 0.15 s after it (docs/driver_timing.md).

Printed per row: the estimator's ζ̇ error RMS (rad/s), the residual force RMS and peak per axis (N) after the first
second, samples with a force component over r_low = 2 N, the residual as servo torques (peak, samples over the
servo threshold 0.35 N·m), and the residual from the true ζ, ζ̇ (the observer itself).
docs/history/observer_node.md ("What it takes to run with the pulse frame") has the table and what it means.
"""
from __future__ import annotations

import argparse
import json

import numpy as np


def run(frame: float, jitter: float, sample: float, setpoint: str, duration: float, seed: int = 0,
        torque_sigma: float | None = None, accel_sigma: float | None = None,
        gaps: tuple[tuple[float, float], ...] = (), catch_up: float = 0.0) -> dict:
    from hexa import trajectories
    from hexa.dynamics.lagrange import HexaDynamicParameters
    from hexa.dynamics.observer import ObserverConfig, ResidualObserver
    from hexa.estimation import EstimatorConfig, ZetaEstimator
    from hexa.kinematics import hexa6rus as kin
    from hexa.protocol.sensor_model import DEFAULT_SENSOR
    from hexa.sim import Simulator

    sim = Simulator(cameras=False, trajectory="circle", drive="external", seed=seed)
    sim._frame_period = frame                 # sim.servo.frame_period without writing a description file
    desc = sim.desc
    tau_count = DEFAULT_SENSOR.amps_per_count * float(desc.K_t)   # N·m per ADC count of the Mega's current sensing
    cfg = EstimatorConfig(**{k: v for k, v in (("torque_sigma", torque_sigma), ("accel_sigma", accel_sigma))
                             if v is not None})
    est = ZetaEstimator(desc, config=cfg)
    params = HexaDynamicParameters.from_description(desc)
    obs, obs_true = ResidualObserver(params, ObserverConfig()), ResidualObserver(params, ObserverConfig())
    rng = np.random.default_rng(seed)
    path = trajectories.TRAJECTORIES["circle"]
    n_sample, n_cmd, n_cam = (int(round(p / sim.timestep)) for p in (sample, 0.01, 1 / 30))
    res, res_true, zd_err, times, pending, u, servo = [], [], [], [], [], None, []
    k = 0
    while sim.time < duration:
        if k % n_cmd == 0 and not any(a <= sim.time < b for a, b in gaps):
            target = kin.inverse_kinematics(desc, path(sim.time)[0])
            step = catch_up * 0.01                       # rad per 10 ms command; 0: no limit
            u = target if (u is None or step <= 0) else u + np.clip(target - u, -step, step)
            pending.append((sim.time + rng.uniform(0.0, jitter), u))
        for item in [p for p in pending if p[0] <= sim.time]:
            sim.set_servo_targets(item[1])
            pending.remove(item)
        sim.step()
        k += 1
        if k % n_sample:
            continue
        s = sim.state()
        tau = np.round((s.tau + rng.normal(0.0, 0.008, 6)) / tau_count) * tau_count
        c = (sim._setpoints if frame > 0 else sim._targets).copy() if setpoint == "oracle" else u
        e = est.update(s.time, c, tau)
        if k % n_cam < n_sample:
            pose = s.pose + np.r_[rng.normal(0, 1e-3, 3), rng.normal(0, np.radians(0.3), 3)]
            est.update_camera(s.time, pose)
            obs.update_pose(s.time, pose)
            obs_true.update_pose(s.time, s.pose)
        r = obs.update_arm(s.time, e.zeta, tau, e.zeta_dot) if e is not None and e.settled else None
        rt = obs_true.update_arm(s.time, s.zeta, tau, s.zeta_dot)
        if s.time > 1.0:
            if r is not None:
                res.append(r.wrench[:3])
                servo.append(r.servo_torque)
                times.append(s.time)
                zd_err.append(e.zeta_dot - s.zeta_dot)
            if rt is not None:
                res_true.append(rt.wrench[:3])
    f, ft, zd, t = np.array(res), np.array(res_true), np.array(zd_err), np.array(times)
    tq = np.abs(np.nan_to_num(np.array(servo)))
    peak = np.abs(f).max(1)
    gap_peaks = [(float(peak[(t >= a) & (t < b)].max()), float(peak[(t >= b) & (t < b + 0.15)].max()))
                 for a, b in gaps if b + 0.15 < duration]
    return {"gap_peaks": gap_peaks,"frame_s": frame, "jitter_s": jitter, "sample_s": sample, "setpoint": setpoint,
            "zeta_dot_error_rms": float(np.sqrt((zd ** 2).mean())),
            "force_rms": np.sqrt((f ** 2).mean(0)).round(3).tolist(), "force_peak": np.abs(f).max(0).round(3).tolist(),
            "samples_over_2N": int((np.abs(f) > 2.0).any(1).sum()), "samples": len(f),
            "servo_torque_peak": float(tq.max()), "samples_over_servo": int((tq > 0.35).any(1).sum()),
            "true_state_force_peak": np.abs(ft).max(0).round(3).tolist()}


ROWS = [(0.0, 0.0, 0.005, "command"), (0.0, 0.01, 0.005, "command"),
        (0.02, 0.01, 0.005, "command"), (0.02, 0.01, 0.005, "oracle"),
        (0.02, 0.01, 0.001, "command"), (0.02, 0.01, 0.001, "oracle")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=6.0, help="sim seconds per row (default 6)")
    ap.add_argument("--json", action="store_true", help="print one JSON list instead of the table")
    ap.add_argument("--gaps", action="store_true", help="90 ms command gaps instead of the frame rows")
    args = ap.parse_args()
    if args.gaps:
        gaps = tuple((a, a + 0.09) for a in np.arange(1.5, args.duration - 0.3, 0.5))
        runs = {speed: run(0.0, 0.0, 0.005, "command", args.duration, gaps=gaps, catch_up=speed)
                for speed in (0.0, 1.5, 1.0)}
        if args.json:
            print(json.dumps({f"catch_up_{k}": v for k, v in runs.items()}, indent=1))
            return
        print("| catch-up | peak \\|F\\| during each gap (N) | peak in the 0.15 s after each gap (N) "
              "| peak x y z (N) |")
        print("|---|---|---|---|")
        for speed, r in runs.items():
            name = f"{speed} rad/s" if speed else "a jump"
            during = ', '.join(f'{d:.2f}' for d, _ in r['gap_peaks'])
            after = ', '.join(f'{a:.2f}' for _, a in r['gap_peaks'])
            print(f"| {name} | {during} | {after} | {' '.join(f'{v:.2f}' for v in r['force_peak'])} |")
        return
    rows = []
    for frame, jitter, sample, setpoint in ROWS:
        rows.append(run(frame, jitter, sample, setpoint, args.duration))
        # with the true set-point and 1 kHz samples the filter can follow the ripple: trust the torque more
        if setpoint == "oracle" and sample < 0.005:
            rows.append(dict(run(frame, jitter, sample, setpoint, args.duration, torque_sigma=0.05),
                             setpoint="oracle, torque_sigma 0.05"))
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print("| frame (s) | command jitter (s) | sample (ms) | estimator set-point | ζ̇ error RMS (rad/s) | "
          "force RMS x y z (N) | force peak x y z (N) | samples > 2 N | servo torque peak (N·m) | samples > 0.35 N·m | "
          "true-state peak (N) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['frame_s']} | {r['jitter_s']} | {1e3 * r['sample_s']:.0f} | {r['setpoint']} | "
              f"{r['zeta_dot_error_rms']:.3f} | {' '.join(f'{v:.2f}' for v in r['force_rms'])} | "
              f"{' '.join(f'{v:.2f}' for v in r['force_peak'])} | {r['samples_over_2N']} of {r['samples']} | "
              f"{r['servo_torque_peak']:.2f} | {r['samples_over_servo']} | "
              f"{' '.join(f'{v:.2f}' for v in r['true_state_force_peak'])} |")


if __name__ == "__main__":
    main()
