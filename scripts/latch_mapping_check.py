"""How well the driver's `joint_states.position` matches the set-points the simulated servos really acted on, with the
servo board's 20 ms pulse frame simulated: with the Uno's latch report (default) and without (commands as sent).

    python scripts/latch_mapping_check.py [--seconds 6] [--rtf 0.3] [--frame 0.02] [--cameras] [--no-sync]

Runs the MuJoCo Hexa (no cameras) with the virtual boards and the real driver node (its own process, a private ROS
domain on loopback), streams the circle trajectory's IK to `joint_commands` at 100 Hz of sim time, and compares each
published sample's set-points with the simulator's own at the sample's board time (the Mega's board clock is sim
time). Prints, per mode, the share of samples with some servo one command off, the servo-sample mismatches, and those
of them more than 1 ms from a change of that servo's set-point (not a switch placed slightly early or late);
LATCH_CHECK_DEBUG=1 lists those on stderr.
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


def run(latch: bool, seconds: float, rtf: float, frame: float, domain: int, cameras: bool = False,
        sync: bool = True) -> dict:
    import rclpy
    from hexa_msgs.msg import MotorCurrents
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from hexa.kinematics import hexa6rus as kin
    from hexa.sim import Simulator
    from hexa.sim.boards import VirtualBoards
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
    stop = threading.Event()
    driver = subprocess.Popen([str(Path(sys.executable).with_name("hexa-driver")), "--ros-args", "-r", "__ns:=/hexa",
                               "-p", f"uno_port:={link / 'uno'}", "-p", f"mega_port:={link / 'mega'}",
                               "-p", f"latch_report:={'true' if latch else 'false'}",
                               "-p", f"command_sync:={'true' if sync else 'false'}"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    rclpy.init()
    node = rclpy.create_node("latch_check")
    qos = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
    states, currents = [], []
    node.create_subscription(JointState, "/hexa/joint_states", states.append, qos)
    node.create_subscription(MotorCurrents, "/hexa/motor_currents", currents.append, qos)
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
        wall0 = time.monotonic()
        while sim.time - t0 < seconds:
            k = int((sim.time - t0) * 100.0) % len(zetas)
            if k != k_last:
                command(zetas[k])
                k_last = k
            if cameras and sim.time >= next_render:    # both cameras at 30 Hz: the sim clock stops meanwhile
                for cam in ("cam_top", "cam_side"):
                    sim.render(cam)
                next_render += 1.0 / 30.0
            sim.step(1)
            sp = sim._setpoints.copy() if sim._latch_at is not None else sim._targets.copy()
            if not log or np.any(sp != log[-1][1]):
                log.append((sim.time, sp))
            ahead = (sim.time - t0) / rtf - (time.monotonic() - wall0)
            if ahead > 0:
                time.sleep(ahead)
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
    wrong_samples = wrong_servos = wrong_far = n = 0
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
        sent = boards.angles_from_pulses(tuple(c.pulse_from_angle(z) for c, z in zip(boards.servos, js.position)))
        err = np.abs(sent - sp_log[i]) > 1e-6
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
    return {"latch_report": latch, "command_sync": sync and latch, "frame_s": frame, "cameras": cameras, "samples": n,
            "samples_with_a_servo_off": round(wrong_samples / max(n, 1), 3),
            "servo_samples_off": round(wrong_servos / max(6 * n, 1), 3),
            # off where the servo's set-point had not changed within 1 ms: a command the servo never had then
            "servo_samples_off_far_from_a_change": round(wrong_far / max(6 * n, 1), 4)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--rtf", type=float, default=0.3)
    ap.add_argument("--frame", type=float, default=0.02)
    ap.add_argument("--domain", type=int, default=77)
    ap.add_argument("--mode", choices=["latch", "commands", "both"], default="both")
    ap.add_argument("--cameras", action="store_true", help="render both cameras at 30 Hz (the sim clock stops)")
    ap.add_argument("--no-sync", action="store_true", help="driver command_sync:=false (commands sent as they come)")
    args = ap.parse_args(argv)
    modes = {"latch": [True], "commands": [False], "both": [True, False]}[args.mode]
    for latch in modes:   # one process per mode: rclpy is initialised once per process
        if len(modes) > 1:
            out = subprocess.run([sys.executable, __file__, "--mode", "latch" if latch else "commands",
                                  "--seconds", str(args.seconds), "--rtf", str(args.rtf), "--frame", str(args.frame),
                                  "--domain", str(args.domain)] + (["--cameras"] if args.cameras else [])
                                 + (["--no-sync"] if args.no_sync else []),
                                 capture_output=True, text=True)
            sys.stdout.write(out.stdout or out.stderr[-3000:])
        else:
            print(json.dumps(run(latch, args.seconds, args.rtf, args.frame, args.domain, args.cameras,
                                 sync=not args.no_sync)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
