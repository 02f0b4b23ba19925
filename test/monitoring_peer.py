"""Peer for the monitoring graph test. It stands in for the driver and the camera: the simulated robot at rest at the
circle's start pose (MuJoCo), published as the driver does (motor_currents with the board's µs clock + joint_states
with the same stamp, 200 Hz, wall clock) and plate_pose at 30 Hz. It waits for `monitoring` OK and the trajectory
running, then goes silent (a board that stops streaming) and times, from the last sample sent: `monitoring` LOST,
`trajectory_state` held and the observer's /diagnostics ERROR; calls trajectory/resume while LOST (refused); streams
again and times OK; calls resume (accepted). Prints a JSON summary on the last line."""
from __future__ import annotations

import json
import os
import signal
import sys
import time

import numpy as np

from hexa_bringup.rosenv import apply_defaults

DT = 0.005
POSE_EVERY = 7          # samples between plate poses (≈ 30 Hz)


def rest_samples(n: int = 400):
    """n samples of the robot at rest at the circle's start pose: (currents A, commanded ζ, plate pose, K_t)."""
    from hexa.sim import Simulator

    sim = Simulator(cameras=False, trajectory="circle", drive="external")
    s0 = sim.state()
    cur = []
    for _ in range(n):
        sim.step(5)
        cur.append(sim.state().tau / sim.desc.K_t)
    return np.array(cur), s0.zeta.copy(), s0.pose.copy(), float(sim.desc.K_t)


def _level(v) -> int:
    """A DiagnosticStatus level (a byte in rclpy) as an int."""
    return v[0] if isinstance(v, (bytes, bytearray)) else int(v)


def main() -> int:
    currents, zeta, pose, k_t = rest_samples()
    apply_defaults()
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import PoseStamped
    from hexa_msgs.msg import MonitoringState, MotorCurrents
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    from hexa.kinematics.hexa6rus import rotation_zyx
    from hexa.rotations import quaternion_from_matrix
    from hexa_ros import qos
    from hexa_ros.stamps import to_stamp

    rclpy.init()
    node = rclpy.create_node("monitoring_peer", namespace="/hexa")
    pub_cur = node.create_publisher(MotorCurrents, "motor_currents", qos.STREAM)
    pub_js = node.create_publisher(JointState, "joint_states", qos.STREAM)
    pub_pose = node.create_publisher(PoseStamped, "plate_pose", 10)
    seen: dict[str, list] = {"monitoring": [], "trajectory": [], "diag": []}   # (wall, value...)
    node.create_subscription(MonitoringState, "monitoring", lambda m: seen["monitoring"].append(
        (time.monotonic(), m.level_name, m.reason, m.residual_age)), qos.LATCHED)
    node.create_subscription(String, "trajectory_state", lambda m: seen["trajectory"].append(
        (time.monotonic(), m.data)), qos.LATCHED)

    def on_diag(m: DiagnosticArray) -> None:
        for st in m.status:
            if st.name == "/hexa/observer":
                seen["diag"].append((time.monotonic(), _level(st.level), st.message))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 50)
    resume = node.create_client(Trigger, "/hexa/trajectory/resume")
    q = quaternion_from_matrix(np.asarray(rotation_zyx(*pose[3:])))
    k = [0]
    T0 = time.monotonic()
    feed = {"on": False, "base": 0.0}     # sample n is due at wall time base + n·DT while on

    def start_stream() -> None:
        feed["on"], feed["base"] = True, time.monotonic() - k[0] * DT

    def send_due() -> None:
        """Publish every sample due by now (a late loop catches up); the board's µs clock follows wall time."""
        while feed["on"] and feed["base"] + k[0] * DT <= time.monotonic():
            n = k[0]
            stamp = to_stamp(time.time())
            due = feed["base"] + n * DT - T0
            c = MotorCurrents(current=[float(v) for v in currents[n % len(currents)]], sequence=n,
                              board_time_us=(1_000_000 + int(due * 1e6)) & 0xFFFFFFFF)
            c.header.stamp, c.header.frame_id = stamp, "base"
            js = JointState(name=[f"arm_{i}" for i in range(1, 7)], position=[float(v) for v in zeta],
                            effort=[float(v) for v in k_t * currents[n % len(currents)]])
            js.header.stamp = stamp
            pub_cur.publish(c)
            pub_js.publish(js)
            if n % POSE_EVERY == 0:
                ps = PoseStamped()
                ps.header.stamp, ps.header.frame_id = stamp, "base"
                ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = (float(v) for v in pose[:3])
                (ps.pose.orientation.x, ps.pose.orientation.y, ps.pose.orientation.z,
                 ps.pose.orientation.w) = (float(v) for v in q)
                pub_pose.publish(ps)
            k[0] += 1

    def stream(seconds: float, until=lambda: False) -> bool:
        """Stream for up to `seconds` of wall time or until `until()`; True if it came."""
        if not feed["on"]:
            start_stream()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            send_due()
            rclpy.spin_once(node, timeout_sec=0.002)
            if until():
                return True
        return False

    def silent(seconds: float, until=lambda: False) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.01)
            if until():
                return True
        return False

    def last(key: str, idx: int = 1):
        return seen[key][-1][idx] if seen[key] else None

    def call_resume() -> tuple[bool, str]:
        fut = resume.call_async(Trigger.Request())
        t_end = time.monotonic() + 10
        while not fut.done() and time.monotonic() < t_end:
            send_due()
            rclpy.spin_once(node, timeout_sec=0.005)
        r = fut.result()
        return (bool(r.success), r.message) if r is not None else (False, "no answer")

    out: dict = {}
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and (pub_js.get_subscription_count() < 1 or not resume.service_is_ready()):
        rclpy.spin_once(node, timeout_sec=0.1)
    out["ok"] = stream(60.0, lambda: last("monitoring") == "OK" and last("trajectory") == "running")
    out["startup"] = [(lv, r) for _t, lv, r, _a in seen["monitoring"]]
    out["states_before"] = sorted({s for _t, s in seen["trajectory"]})
    stream(1.0)                                           # running, watched
    n_mon, n_traj, n_diag = len(seen["monitoring"]), len(seen["trajectory"]), len(seen["diag"])
    feed["on"] = False
    t_silent = time.monotonic()                           # the board stops streaming: no sample after this
    silent(10.0, lambda: (any(lv == "LOST" for _t, lv, *_ in seen["monitoring"][n_mon:])
                          and any(s == "held" for _t, s in seen["trajectory"][n_traj:])
                          and any(lv == _level(DiagnosticStatus.ERROR) for _t, lv, _m in seen["diag"][n_diag:])))
    lost = next(((t, r, a) for t, lv, r, a in seen["monitoring"][n_mon:] if lv == "LOST"), None)
    held = next((t for t, s in seen["trajectory"][n_traj:] if s == "held"), None)
    err = next(((t, m) for t, lv, m in seen["diag"][n_diag:] if lv == _level(DiagnosticStatus.ERROR)), None)
    out["lost_reason"] = lost[1] if lost else None
    out["lost_residual_age"] = lost[2] if lost else None
    out["lost_after"] = lost[0] - t_silent if lost else None
    out["held_after"] = held - t_silent if held else None
    out["diag_error_after"] = err[0] - t_silent if err else None
    out["diag_error_message"] = err[1] if err else None
    out["resume_while_lost"] = call_resume()
    n_mon = len(seen["monitoring"])
    t_back = time.monotonic()
    out["ok_again"] = stream(30.0, lambda: last("monitoring") == "OK")
    out["recovery"] = [(lv, r) for _t, lv, r, _a in seen["monitoring"][n_mon:]]
    out["ok_after"] = time.monotonic() - t_back
    out["state_before_resume"] = last("trajectory")
    out["resume_when_ok"] = call_resume()
    stream(0.5)
    out["state_after_resume"] = last("trajectory")
    if len(sys.argv) > 1:                                 # the observer's pid: kill it (-9), as a crash would
        n_traj = len(seen["trajectory"])
        t_kill = time.monotonic()
        os.kill(int(sys.argv[1]), signal.SIGKILL)
        stream(10.0, lambda: any(st == "held" for _t, st in seen["trajectory"][n_traj:]))
        held = next((t for t, st in seen["trajectory"][n_traj:] if st == "held"), None)
        out["held_after_observer_kill"] = None if held is None else held - t_kill
    print(json.dumps(out), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
