"""How well the driver's `joint_states.position` matches the set-points the simulated servos really acted on, with the
servo board's 20 ms pulse frame simulated: with the Uno's latch report (default) and without (commands as sent).

    python scripts/latch_mapping_check.py [--seconds 6] [--rtf 0.3] [--frame 0.02] [--cameras] [--load N]

Runs the MuJoCo Hexa, paced as the sim node paces it (`hexa.sim.pacing.Pacer`: a stall, such as the renders of
`--cameras`, is dropped instead of caught up), with the virtual boards and the real driver node (its own process, a
private ROS domain on loopback), streams the circle trajectory's IK to `joint_commands` at 100 Hz of sim time, and
compares each published sample's set-points with the simulator's own at the sample's board time (the Mega's board
clock is sim time). Prints, per mode, the share of samples with some servo one command off, the servo-sample
mismatches, and those of them more than 1 ms from a change of that servo's set-point (not a switch placed slightly
early or late); the servo-samples whose published set-point went back to an older command than the servo's previous
sample had (a pulse frame predicted with a command the board did not have yet, which its LATCH report corrected); and
the driver's `latch_predicted_wrong` (servos whose reported command differed from the one predicted). `--load N` runs
N busy processes beside it. LATCH_CHECK_DEBUG=1 lists the far mismatches and the reversals on stderr;
LATCH_CHECK_DUMP=FILE writes, per sample and servo, the commands the published and the simulated set-points can be
(JSON).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np


def run(latch: bool, seconds: float, rtf: float, frame: float, domain: int, cameras: bool = False) -> dict:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from hexa_msgs.msg import MotorCurrents
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from hexa.kinematics import hexa6rus as kin
    from hexa.sim import Simulator
    from hexa.sim.boards import VirtualBoards
    from hexa.sim.pacing import Pacer
    from hexa.trajectories import sample
    from hexa_bringup.rosenv import ros_env

    env = ros_env(domain)
    os.environ.update(env)
    t_traj, poses, _, _ = sample("circle", 100.0)
    sim = Simulator(cameras=cameras, servo_frame_period=frame, pose=poses[0])
    desc = sim.desc
    zetas = np.array([kin.inverse_kinematics(desc, p) for p in poses])
    link = Path(tempfile.mkdtemp())
    boards = VirtualBoards(sim, link_dir=link).start()
    log: list[tuple[float, np.ndarray]] = []          # (sim time, set-points) after every change
    sent_log: list[tuple[float, int]] = []             # (sim time, trajectory index) of every command
    stop = threading.Event()
    driver = subprocess.Popen([str(Path(sys.executable).with_name("hexa-driver")), "--ros-args", "-r", "__ns:=/hexa",
                               "-p", f"uno_port:={link / 'uno'}", "-p", f"mega_port:={link / 'mega'}",
                               "-p", f"latch_report:={'true' if latch else 'false'}"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    rclpy.init()
    node = rclpy.create_node("latch_check")
    qos = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
    states, currents = [], []
    node.create_subscription(JointState, "/hexa/joint_states", states.append, qos)
    node.create_subscription(MotorCurrents, "/hexa/motor_currents", currents.append, qos)
    latch_diag: dict[str, str] = {}

    def on_diag(msg: DiagnosticArray) -> None:
        for st in msg.status:
            latch_diag.update({kv.key: kv.value for kv in st.values if kv.key.startswith("latch_")})

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    pub = node.create_publisher(JointState, "/hexa/joint_commands", 10)
    spin = threading.Thread(target=lambda: [rclpy.spin_once(node, timeout_sec=0.05) for _ in iter(stop.is_set, True)],
                            daemon=True)
    spin.start()

    def command(z: np.ndarray) -> None:
        m = JointState()
        m.name = [f"arm_{i}" for i in range(1, 7)]
        m.position = [float(v) for v in z]
        pub.publish(m)

    try:
        t_wait = time.monotonic() + 20.0
        while not currents and time.monotonic() < t_wait:
            sim.step(4)
            time.sleep(0.004 / rtf)
        for _ in range(100):                              # at the start pose, the clock maps settle
            command(zetas[0])
            sim.step(10)
            time.sleep(0.01 / rtf)
        t0 = sim.time
        k_last = -1
        next_render = t0
        pacer = Pacer(rtf)   # as the sim node paces: stalls over max_lag are dropped, not caught up in a burst
        pacer.start(t0)
        while sim.time - t0 < seconds:
            k = int((sim.time - t0) * 100.0) % len(zetas)
            if k != k_last:
                command(zetas[k])
                sent_log.append((sim.time, k))
                k_last = k
            if cameras and sim.time >= next_render:    # both cameras at 30 Hz: the sim clock stops meanwhile
                for cam in ("cam_top", "cam_side"):
                    sim.render(cam)
                next_render += 1.0 / 30.0
            sim.step(1)
            sp = sim._setpoints.copy() if sim._latch_at is not None else sim._targets.copy()
            if not log or np.any(sp != log[-1][1]):
                log.append((sim.time, sp))
            pacer.pace(sim.time)
        time.sleep(0.5)
    finally:
        stop.set()
        driver.terminate()
        driver.wait(timeout=10)
        boards.stop()
        node.destroy_node()
        rclpy.shutdown()
    by_stamp = {(m.header.stamp.sec, m.header.stamp.nanosec): m.board_time_us for m in currents}
    t_log = np.array([t for t, _ in log])
    sp_log = np.array([s for _, s in log])
    wrong_samples = wrong_servos = wrong_far = n = reversals = 0
    t_sent = np.array([t for t, _ in sent_log])
    k_sent = np.array([k for _, k in sent_log])
    # per servo, the command indices (into sent_log) whose whole-µs pulse equals each published set-point
    pulses = np.array([[c.pulse_from_angle(z[j]) for j, c in enumerate(boards.servos)] for z in zetas[k_sent]]) \
        if len(k_sent) else np.zeros((0, 6))
    prev: list[np.ndarray | None] = [None] * 6
    dump: list | None = [] if os.environ.get("LATCH_CHECK_DUMP") else None
    # per servo, the sim times its set-point changed
    changes = [t_log[1:][np.abs(np.diff(sp_log[:, j])) > 1e-9] for j in range(6)]
    for js in states:
        b = by_stamp.get((js.header.stamp.sec, js.header.stamp.nanosec))
        if b is None:
            continue
        t_sim = boards.sim_time_of(b * 1e-6)
        if t_sim < t0 + 0.2 or t_sim > t0 + seconds:
            continue
        i = np.searchsorted(t_log, t_sim, side="right") - 1
        if i < 0:
            continue
        # the driver publishes angles; the servos got them as whole-µs pulses (the virtual Uno's calibration)
        published = tuple(c.pulse_from_angle(z) for c, z in zip(boards.servos, js.position))
        sent = boards.angles_from_pulses(published)
        err = np.abs(sent - sp_log[i]) > 1e-6
        # a set-point that steps back: every command it can be is older than every one the servo's previous
        # published set-point could be (the commands sent in the 0.3 s before the sample)
        lo, hi = np.searchsorted(t_sent, t_sim - 0.3), np.searchsorted(t_sent, t_sim + 0.02)
        for j in range(6):
            idx = lo + np.flatnonzero(pulses[lo:hi, j] == published[j])
            if idx.size and prev[j] is not None and prev[j].size and idx.max() < prev[j].min():
                reversals += 1
                if os.environ.get("LATCH_CHECK_DEBUG"):
                    print("back", round(t_sim, 4), j, "commands", idx.tolist(), "after", prev[j].tolist(),
                          file=sys.stderr)
            if idx.size:
                prev[j] = idx
            if dump is not None:
                true_idx = lo + np.flatnonzero(pulses[lo:hi, j] == boards.servos[j].pulse_from_angle(sp_log[i][j]))
                dump.append((float(t_sim), j, idx.tolist(), true_idx.tolist(), int(b)))
        wrong_samples += int(err.any())
        wrong_servos += int(err.sum())
        for j in np.nonzero(err)[0]:      # a set-point change placed a little early or late, or a wrong command?
            near = changes[j][np.searchsorted(changes[j], t_sim - 0.001):np.searchsorted(changes[j], t_sim + 0.001)]
            wrong_far += int(len(near) == 0)
            if len(near) == 0 and os.environ.get("LATCH_CHECK_DEBUG"):
                k_true = np.searchsorted(changes[j], t_sim)
                print("far", round(t_sim, 4), j, round(float(sent[j]), 4), round(float(sp_log[i][j]), 4),
                      "prev change", round(float(changes[j][k_true - 1]), 4) if k_true else None,
                      "next change", round(float(changes[j][k_true]), 4) if k_true < len(changes[j]) else None,
                      "values", [round(float(v), 4) for v in sp_log[max(i - 3, 0):i + 3, j]], file=sys.stderr)
        n += 1
    if dump is not None:
        Path(os.environ["LATCH_CHECK_DUMP"]).write_text(json.dumps(dump))
    return {"latch_report": latch, "frame_s": frame, "cameras": cameras, "samples": n,
            "samples_with_a_servo_off": round(wrong_samples / max(n, 1), 3),
            "servo_samples_off": round(wrong_servos / max(6 * n, 1), 3),
            # off where the servo's set-point had not changed within 1 ms: a command the servo never had then
            "servo_samples_off_far_from_a_change": round(wrong_far / max(6 * n, 1), 4),
            # a servo's published set-point went back to an older command (a prediction the report corrected)
            "set_point_reversals": reversals,
            "latch_predicted_wrong": latch_diag.get("latch_predicted_wrong")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--rtf", type=float, default=0.3)
    ap.add_argument("--frame", type=float, default=0.02)
    ap.add_argument("--domain", type=int, default=77)
    ap.add_argument("--mode", choices=["latch", "commands", "both"], default="both")
    ap.add_argument("--cameras", action="store_true", help="render both cameras at 30 Hz (the sim clock stops)")
    ap.add_argument("--load", type=int, default=0, help="busy processes beside the run (a loaded host)")
    args = ap.parse_args(argv)
    modes = {"latch": [True], "commands": [False], "both": [True, False]}[args.mode]
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    try:
        _modes(args, modes)
    finally:
        for h in hogs:
            h.kill()
    return 0


def _modes(args: argparse.Namespace, modes: list[bool]) -> None:
    for latch in modes:   # one process per mode: rclpy is initialised once per process
        if len(modes) > 1:
            out = subprocess.run([sys.executable, __file__, "--mode", "latch" if latch else "commands",
                                  "--seconds", str(args.seconds), "--rtf", str(args.rtf), "--frame", str(args.frame),
                                  "--domain", str(args.domain)] + (["--cameras"] if args.cameras else []),
                                 capture_output=True, text=True)
            sys.stdout.write(out.stdout or out.stderr[-3000:])
        else:
            print(json.dumps(run(latch, args.seconds, args.rtf, args.frame, args.domain, args.cameras)), flush=True)


if __name__ == "__main__":
    sys.exit(main())
