"""`hexa calibrate excite | identify BAG | validate BAG`: the robot's model from its own motion
(docs/calibration.md)."""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from hexa.calibration.simulated import SIM_PAYLOAD   # kg: the simulated payload run's known mass (`--simulate`)
#: s of held-out motion `validate --simulate` records (two turns of the paper's circle)
SIM_VALIDATE_SECONDS = 20.0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="identify the model, friction, current sensors and servo horns from "
                                         "the robot's motion (excite | identify BAG | validate BAG)")
    csub = p.add_subparsers(dest="calibrate_command", metavar="STEP")
    csub.required = True

    e = csub.add_parser("excite", help="design a periodic excitation and write it as a trajectory file",
                        description="Fourier series per plate DOF, inside the workspace and the servos' speed and "
                                    "torque limits, optimized for the identification regressor's condition number. "
                                    "Play it with `hexa bringup sim|robot --trajectory FILE` and record a bag.")
    e.add_argument("--out", default="excitation.csv", help="trajectory file to write (default excitation.csv)")
    e.add_argument("--period", type=float, default=None, help="seconds per cycle (default 4)")
    e.add_argument("--harmonics", type=int, default=None, help="harmonics per DOF (default 5)")
    e.add_argument("--cycles", type=int, default=None, help="cycles in the file (default 7: 28 s)")
    e.add_argument("--iterations", type=int, default=None, help="optimizer iterations (default 100)")
    e.add_argument("--speed-fraction", type=float, default=None, help="|ζ̇| ≤ this × speed_max (default 0.5)")
    e.add_argument("--torque-fraction", type=float, default=None, help="|τ| ≤ this × torque_max (default 0.6)")
    e.add_argument("--seed", type=int, default=0, help="seed of the random search")
    e.add_argument("--description", default=None, help="robot description YAML (default: the packaged one)")
    e.add_argument("--json", action="store_true", help="print the design as JSON")
    e.set_defaults(func=run_excite)

    i = csub.add_parser("identify", help="identify the model from recorded runs of the excitation → overlay YAML",
                        description="Reads motor_currents, joint_states and plate_pose of BAG (and of --payload-bag, "
                                    "a run carrying a known mass, which fixes the torque scale), identifies per-servo "
                                    "K_t, current offset, Coulomb + viscous friction, inertia and horn offset and the "
                                    "plate's inertial parameters, and writes a calibration overlay for the nodes.")
    i.add_argument("bag", nargs="?", help="bag of a run of the excitation (omit with --simulate)")
    i.add_argument("--payload-bag", default=None, help="bag of the same run carrying a known mass on the plate")
    i.add_argument("--payload", type=float, default=None, metavar="KG",
                   help=f"the known mass of --payload-bag (with --simulate default {SIM_PAYLOAD})")
    i.add_argument("--payload-point", type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                   help="where the mass sits, in the plate frame {P} (m; default its origin)")
    i.add_argument("--trajectory", default="excitation.csv",
                   help="the excitation file the runs played (its period; default excitation.csv)")
    i.add_argument("--simulate", type=int, default=None, metavar="SEED",
                   help="record the runs on the realistic simulated robot of SEED in-process instead of bags "
                        "(no ROS) and compare with its truth")
    i.add_argument("--horn-tolerance", type=float, default=0.03, metavar="RAD",
                   help="--simulate: the simulated horns sit up to ± this off their nominal angle (default 0.03)")
    _common(i)
    i.add_argument("--out", default="calibration.yaml", help="overlay to write (default calibration.yaml)")
    i.set_defaults(func=run_identify)

    v = csub.add_parser("validate", help="free-motion residual before/after on a held-out run: table + plot",
                        description="The residual of free motion (the observer's model error) on BAG with the "
                                    "description alone and with the calibration overlay, per plate axis and "
                                    "servo; BAG must be other motion than the excitation.")
    v.add_argument("bag", nargs="?", help="bag of held-out free motion (omit with --simulate)")
    v.add_argument("--calibration", default="calibration.yaml", help="the overlay (default calibration.yaml)")
    v.add_argument("--simulate", type=int, default=None, metavar="SEED",
                   help="record the paper's circle on the realistic simulated robot of SEED in-process instead")
    v.add_argument("--trajectory", default="circle", help="--simulate: circle | helix | ellipse (default circle)")
    v.add_argument("--horn-tolerance", type=float, default=0.03, metavar="RAD",
                   help="--simulate: as for identify (the same robot needs the same value)")
    _common(v)
    v.add_argument("--out", default="out/calibration", help="folder for the plot and JSON (default out/calibration)")
    v.set_defaults(func=run_validate)


def _common(p: argparse.ArgumentParser) -> None:
    from hexa.calibration.recording import CALIBRATION_RATE_HZ

    p.add_argument("--stream-rate", type=float, default=CALIBRATION_RATE_HZ, metavar="HZ",
                   help="--simulate: the currents' sample rate of the simulated runs (the driver's stream_rate_hz; "
                        f"default {CALIBRATION_RATE_HZ:g}, off the servos' 50 Hz pulse frame; 200 is the graph's)")
    p.add_argument("--description", default=None, help="robot description YAML (default: the packaged one)")
    p.add_argument("--ns", default="/hexa", help="namespace of the recorded graph (default /hexa)")
    p.add_argument("--json", action="store_true", help="print the result as JSON (SI units)")


def _progress(prefix: str):
    def show(frac: float) -> None:
        sys.stderr.write(f"\rhexa calibrate: {prefix} {100 * frac:3.0f} %")
        if frac >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()
    return show


def _desc(path: str | None) -> Any:
    from hexa.robots.hexa_description import load_hexa
    from hexa.robots.schema import RobotDescriptionError

    try:
        return load_hexa(path)
    except RobotDescriptionError as exc:
        raise SystemExit(str(exc)) from None


# ------------------------------------------------------------------------------------------------ excite
def run_excite(args: argparse.Namespace) -> int:
    from hexa.calibration.excitation import SLOW_SPEED, ExcitationError, ExcitationSettings, design_excitation

    desc = _desc(args.description)
    given = {k: getattr(args, k) for k in ("period", "harmonics", "cycles", "iterations", "speed_fraction",
                                            "torque_fraction") if getattr(args, k) is not None}
    try:
        settings = ExcitationSettings(seed=args.seed, **given)
        total = settings.iterations

        def show(it: int, cond: float) -> None:
            sys.stderr.write(f"\rhexa calibrate excite: iteration {it}/{total}, condition number {cond:.1f}")
            if it == total:
                sys.stderr.write("\n")
            sys.stderr.flush()

        exc = design_excitation(desc, settings, progress=show)
    except ExcitationError as err:
        raise SystemExit(str(err)) from None
    path = exc.write(args.out, settings.rate_hz)
    out = {"file": str(path), "period": exc.period, "cycles": exc.cycles, "duration": exc.duration,
           "harmonics": int(exc.a.shape[1]), "condition_number": exc.condition, "peak_zeta_dot": exc.peak_speed,
           "peak_torque": exc.peak_torque, "slow_fraction": exc.slow}
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"excitation: {path} ({exc.cycles} × {exc.period:g} s = {exc.duration:g} s, {out['harmonics']} "
              f"harmonics per DOF)\n  condition number {exc.condition:.1f}; peak |ζ̇| {exc.peak_speed:.2f} rad/s, "
              f"peak |τ| {exc.peak_torque:.2f} N·m (nominal model); the slowest servo spends "
              f"{100 * exc.slow:.1f} % of a period below {SLOW_SPEED:g} rad/s\n"
              f"next: hexa bringup sim --realism realistic --trajectory {path} (with the bag recorder), then "
              f"hexa calibrate identify BAG --trajectory {path}")
    return 0


# ------------------------------------------------------------------------------------------------ bags
def recording_from_bag(path: str, ns: str, payload: float = 0.0, point: Any = (0.0, 0.0, 0.0)) -> Any:
    """The Recording of a bag: ns/motor_currents, ns/joint_states (set-points) and ns/plate_pose.

    Raises:
        hexa.bags.BagError: unreadable bag; SystemExit: a topic missing.
    """
    import numpy as np

    from hexa.calibration.recording import Recording
    from hexa.dynamics.lagrange import rotation_to_zyx
    from hexa.rotations import matrix_from_quaternion
    from hexa_bringup.bag import read_bag, typestore

    ns = "/" + ns.strip("/") if ns.strip("/") else ""
    topics = {f"{ns}/motor_currents": "c", f"{ns}/joint_states": "s", f"{ns}/plate_pose": "p"}
    store = typestore()
    got: dict[str, list] = {"c": [], "s": [], "p": []}
    for topic, msgtype, _, data in read_bag(path, list(topics)):
        m = store.deserialize_cdr(data, msgtype)
        t = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
        key = topics[topic]
        if key == "c":
            got["c"].append((t, np.asarray(m.current, dtype=float)))
        elif key == "s":
            pos = dict(zip(m.name, m.position))
            if all(f"arm_{i}" in pos for i in range(1, 7)):
                got["s"].append((t, np.array([pos[f"arm_{i}"] for i in range(1, 7)])))
        else:
            q, o = m.pose.orientation, m.pose.position
            R = matrix_from_quaternion(q.x, q.y, q.z, q.w)
            got["p"].append((t, np.concatenate([[o.x, o.y, o.z], rotation_to_zyx(R[None])[0]])))
    for key, topic in (("c", "motor_currents"), ("s", "joint_states"), ("p", "plate_pose")):
        if not got[key]:
            raise SystemExit(f"bag {path} has no {ns}/{topic} messages (record the graph with the bag recorder; "
                             f"--ns if it ran in another namespace)")

    def arrays(key: str) -> tuple:
        rows = sorted(got[key], key=lambda r: r[0])
        t = np.array([r[0] for r in rows])
        x = np.array([r[1] for r in rows])
        keep = np.r_[True, np.diff(t) > 0] & np.all(np.isfinite(x), axis=1)   # no value yet: NaN (driver)
        return t[keep], x[keep]

    tc, ic = arrays("c")
    ts, ss = arrays("s")
    tp, pp = arrays("p")
    return Recording(tc, ic, ts, ss, tp, pp, payload=float(payload), payload_point=np.asarray(point, dtype=float),
                     source=str(path))


def _sim_realism(horn: float) -> Any:
    from hexa.sim.realism import RealismConfig, Tolerances

    base = RealismConfig.realistic()
    return base.replace(tolerances=Tolerances(horn_offset=float(horn)))


# ------------------------------------------------------------------------------------------------ identify
def run_identify(args: argparse.Namespace) -> int:
    from hexa.calibration.excitation import Excitation
    from hexa.calibration.identify import CalibrationError, identify, prepare
    from hexa.calibration.overlay import write_overlay
    from hexa.calibration.recording import RecordingError

    desc = _desc(args.description)
    traj = Path(args.trajectory)
    if not traj.is_file():
        raise SystemExit(f"no excitation file {traj} (write one with `hexa calibrate excite --out {traj}`)")
    exc = Excitation.read_design(traj)
    if exc is None:
        raise SystemExit(f"{traj} holds no excitation design (not written by `hexa calibrate excite`)")
    truth = None
    if args.simulate is not None:
        if args.bag or args.payload_bag:
            raise SystemExit("give either bags or --simulate SEED, not both")
        from hexa.calibration.simulated import simulate_excitation_runs

        mass = SIM_PAYLOAD if args.payload is None else args.payload
        recs, truth = simulate_excitation_runs(traj, args.simulate, _sim_realism(args.horn_tolerance), desc,
                                               payload=mass, payload_point=args.payload_point,
                                               current_rate_hz=args.stream_rate, progress=_progress)
    else:
        if not args.bag:
            raise SystemExit("give the BAG of a run of the excitation (or --simulate SEED)")
        recs = [recording_from_bag(args.bag, args.ns)]
        if args.payload_bag:
            if not args.payload or args.payload <= 0:
                raise SystemExit("--payload-bag needs --payload KG (the known mass, > 0)")
            recs.append(recording_from_bag(args.payload_bag, args.ns, args.payload, args.payload_point))
    try:
        motions = [prepare(r, desc, period=exc.period) for r in recs]
        cal = identify(motions, desc)
    except (RecordingError, CalibrationError) as err:
        raise SystemExit(str(err)) from None
    path = write_overlay(args.out, cal, desc)
    out = {"overlay": str(path), "calibration": cal.as_dict(),
           "periodic": {mo.source: mo.periodic for mo in motions}}
    if truth is not None:
        out["truth_errors"] = truth_errors(cal, truth)
    if args.json:
        print(json.dumps(out, indent=1, default=float))
        return 0
    print(_identify_table(cal, out.get("truth_errors")))
    for mo in motions:
        if not mo.periodic:
            print(f"note: {mo.source} is not the periodic excitation (its poses miss the period's Fourier series: "
                  "paused or late); its motion is low-passed camera poses instead, less accurate")
    for note in dict.fromkeys(cal.notes):
        print(f"note: {note}")
    if cal.scale != "payload":
        print("note: no run with a known payload — the torque scale (every K_t and mass) rests on the "
              "description's K_t; record a second run with a known mass (--payload-bag, --payload)")
    print(f"overlay: {path}  (nodes: description:={path}; check with hexa calibrate validate BAG "
          f"--calibration {path})")
    return 0


def truth_errors(cal: Any, truth: Any) -> dict[str, Any]:
    """Identified minus true values of the simulated robot (relative where the targets are relative)."""
    import numpy as np

    K = truth.k_t / truth.sensor_gain
    fc_ref = truth.coulomb
    return {"k_t_rel": (cal.k_t / K - 1.0).tolist(),
            "coulomb_rel": (cal.coulomb / fc_ref - 1.0).tolist(),
            "viscous_abs": (cal.viscous - truth.viscous).tolist(),
            "current_offset_abs": (cal.current_offset - truth.current_offset).tolist(),
            "rotor_inertia_abs": (cal.rotor_inertia - truth.rotor_inertia).tolist(),
            "plate_mass_rel": float(cal.plate_mass / truth.plate.mass - 1.0),
            "horn_offset_abs": (cal.horn_offset - np.asarray(truth.horn_offset)).tolist()}


def _identify_table(cal: Any, err: dict | None) -> str:
    rows = [("K_t (N·m/A)", cal.k_t, cal.ci95["k_t"], "k_t_rel", 100, "%"),
            ("current offset (A)", cal.current_offset, cal.ci95["current_offset"], "current_offset_abs", 1, "A"),
            ("Coulomb (N·m)", cal.coulomb, cal.ci95["coulomb"], "coulomb_rel", 100, "%"),
            ("viscous (N·m·s/rad)", cal.viscous, cal.ci95["viscous"], "viscous_abs", 1, ""),
            ("J about axis (kg·m²)", cal.inertia, cal.ci95["inertia"], None, 1, ""),
            ("rotor inertia (kg·m²)", cal.rotor_inertia, cal.ci95["inertia"], "rotor_inertia_abs", 1, ""),
            ("horn offset (mrad)", 1e3 * cal.horn_offset, 1e3 * cal.ci95["horn_offset"], "horn_offset_abs", 1e3, "")]
    lines = [f"{'per servo':<22}" + "".join(f"{'arm_' + str(i + 1):>19}" for i in range(6))]
    for name, val, ci, key, scale, unit in rows:
        lines.append(f"{name:<22}" + "".join(f"{v:>11.4g} ±{c:<6.2g}" for v, c in zip(val, ci)))
        if err is not None and key is not None:
            lines.append(f"{'  − truth' + (' (' + unit + ')' if unit else ''):<22}"
                         + "".join(f"{scale * e:>19.3g}" for e in err[key]))
    lines.append(f"plate mass {cal.plate_mass:.4f} ± {cal.ci95['plate_mass']:.4f} kg"
                 + (f" ({100 * err['plate_mass_rel']:+.1f} % of the truth)" if err else "")
                 + f"; COM {[round(float(v), 4) for v in cal.plate_com]} m")
    lines.append(f"scale from: {cal.scale}; physical consistency: {cal.consistency}; {cal.samples} samples; "
                 f"fit RMS {[round(float(v), 4) for v in cal.rms]} N·m")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------ validate
def run_validate(args: argparse.Namespace) -> int:
    from hexa.calibration.identify import CalibrationError
    from hexa.calibration.recording import RecordingError, simulate_recording
    from hexa.calibration.validate import AXES, compare, plot

    desc = _desc(args.description)
    cal_path = Path(args.calibration)
    if not cal_path.is_file():
        raise SystemExit(f"no calibration overlay {cal_path} (write one with `hexa calibrate identify`)")
    cal_desc = _desc(str(cal_path))
    if "calibration" not in cal_desc.sections():
        raise SystemExit(f"{cal_path} is not a calibration overlay (no `calibration` section)")
    if args.simulate is not None:
        if args.bag:
            raise SystemExit("give either a BAG or --simulate SEED, not both")
        from hexa import trajectories

        if args.trajectory not in trajectories.TRAJECTORIES:
            raise SystemExit(f"--trajectory must be one of {sorted(trajectories.TRAJECTORIES)}")
        fn = trajectories.TRAJECTORIES[args.trajectory]
        rec, _ = simulate_recording(lambda t: fn(t)[0], SIM_VALIDATE_SECONDS, seed=args.simulate,
                                    realism=_sim_realism(args.horn_tolerance), desc=desc,
                                    progress=_progress(f"simulating the {args.trajectory}"),
                                    current_rate_hz=args.stream_rate)
    elif args.bag:
        rec = recording_from_bag(args.bag, args.ns)
    else:
        raise SystemExit("give the BAG of held-out free motion (or --simulate SEED)")
    try:
        cmp = compare(rec, desc, cal_desc)
    except (RecordingError, CalibrationError) as err:
        raise SystemExit(str(err)) from None
    res = cmp.rms()
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    png = plot(cmp, out_dir / "residual_before_after.png", f"free-motion residual: {rec.source}")
    (out_dir / "validate.json").write_text(json.dumps(res, indent=1), encoding="utf-8")
    if args.json:
        print(json.dumps({**res, "plot": str(png)}, indent=1))
        return 0
    print(f"free-motion residual RMS on {rec.source} ({res['samples']} samples)")
    print(f"{'axis':<8}{'before':>10}{'after':>10}{'after/before':>14}")
    for a in AXES:
        r = res["axes"][a]
        unit = "N" if a.startswith("F") else "N·m"
        print(f"{a + ' (' + unit + ')':<8}{r['before']:>10.3f}{r['after']:>10.3f}{r['ratio']:>14.2f}")
    for k, r in res["servos"].items():
        print(f"{k:<8}{r['before']:>10.4f}{r['after']:>10.4f}{r['ratio']:>14.2f}   (servo torque, N·m)")
    worst = max(r["ratio"] for r in res["axes"].values())
    print(f"worst axis after/before {worst:.2f} ({'meets' if worst <= 1 / 3 else 'misses'} the 1/3 target); "
          f"plot: {png}")
    return 0 if math.isfinite(worst) else 1
