"""Peer for the observer/rnea node tests: replays a short MuJoCo run (circle, 3 N on the plate from 2.0 to 3.0 s) as
driver-like joint_states (position = commanded angle, effort = ADC-quantized τ) at 500 Hz and noisy 30 Hz plate
poses; in rnea mode it also sends the true contact point as `contact` at the camera rate during the collision.
Phase 2 (observer mode): raises the thresholds at runtime, replays the run again, then sends bad input.
Prints a JSON summary on the last line."""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from hexa_bringup.rosenv import apply_defaults

DT = 0.005          # the driver's default Mega stream rate (200 Hz)
FORCE = np.array([0.0, 0.0, 3.0])
F_ON, F_OFF, T_END = 2.0, 3.0, 4.0
TAU_COUNT = 0.0119


def simulate(seed: int = 0) -> dict:
    from hexa import trajectories
    from hexa.kinematics import hexa6rus as kin
    from hexa.sim import Simulator

    sim = Simulator(cameras=False, trajectory="circle", drive="external", servo_frame_period=0.0)  # set-points = u
    desc = sim.desc
    rng = np.random.default_rng(seed)
    fn = trajectories.TRAJECTORIES["circle"]
    out = {"t": [], "u": [], "tau": [], "pose_t": [], "pose": [], "point": None}
    u = None
    n = int(round(T_END / sim.timestep))
    for k in range(n):
        t = sim.time
        if k % 10 == 0:
            u = kin.inverse_kinematics(desc, fn(t)[0])
            sim.set_servo_targets(u)
        if k == int(round(F_ON / sim.timestep)):
            s = sim.state()
            point = s.pose[:3] + np.array([0.02, 0.01, 0.0])
            sim.apply_external_force("plate", 0, point, FORCE)
            out["point"] = point.tolist()
        if k == int(round(F_OFF / sim.timestep)):
            sim.clear_external_force()
        sim.step()
        s = sim.state()
        if k % 5 == 4:
            tau = np.round((s.tau + rng.normal(0.0, 0.008, 6)) / TAU_COUNT) * TAU_COUNT
            out["t"].append(s.time)
            out["u"].append(u.tolist())
            out["tau"].append(tau.tolist())
        if k % 33 == 0:
            out["pose_t"].append(s.time)
            out["pose"].append((s.pose + np.r_[rng.normal(0, 1e-3, 3), rng.normal(0, np.radians(0.3), 3)]).tolist())
    return out


def main() -> int:
    mode = sys.argv[1] if len(sys.argv) > 1 else "observer"
    data = simulate()
    apply_defaults()
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from hexa_ros.diagnostics import values_of
    from geometry_msgs.msg import PoseStamped
    from hexa_msgs.msg import CollisionEvent, Contact, ContactWrench, Residual
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from hexa.rotations import quaternion_from_matrix
    from hexa_ros.stamps import to_sec as stamp_seconds, to_stamp as stamp_from_seconds
    from hexa.kinematics.hexa6rus import rotation_zyx

    rclpy.init()
    node = rclpy.create_node("observer_peer", namespace="/hexa")
    rel = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
    pub_js = node.create_publisher(JointState, "joint_states", rel)
    pub_pose = node.create_publisher(PoseStamped, "plate_pose", 10)
    ev_qos = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE)
    pub_contact = node.create_publisher(Contact, "contact", ev_qos)
    events: list[dict] = []
    residuals: list[tuple[float, list[float], bool]] = []
    wrenches: list[dict] = []
    diags: dict[str, dict[str, str]] = {}
    active = {"id": None}
    thresholds: list[list[float]] = []

    def on_collision(m: CollisionEvent) -> None:
        events.append({"event": int(m.event), "id": int(m.id), "t": stamp_seconds(m.header.stamp),
                       "onset": stamp_seconds(m.onset), "axis": int(m.axis), "axis_name": m.axis_name,
                       "value": m.value, "peak": m.peak})
        active["id"] = int(m.id) if m.event == CollisionEvent.START else None

    def on_diag(m: DiagnosticArray) -> None:
        for st in m.status:
            diags[st.name] = values_of(st)

    node.create_subscription(CollisionEvent, "collision", on_collision, ev_qos)
    node.create_subscription(Residual, "residual",
                             lambda m: (residuals.append((stamp_seconds(m.header.stamp),
                                                          [m.wrench.force.x, m.wrench.force.y, m.wrench.force.z],
                                                          m.in_collision)),
                                            thresholds.append(list(m.threshold) + list(m.servo_threshold))),
                             100)
    node.create_subscription(ContactWrench, "contact_wrench",
                             lambda m: wrenches.append({"t": stamp_seconds(m.header.stamp), "id": int(m.collision_id),
                                                        "force": [m.force.x, m.force.y, m.force.z], "rank": int(m.rank),
                                                        "observable": bool(m.observable), "link": int(m.link),
                                                        "stalled": bool(m.servo_stalled)}), 100)
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)

    def spin(sec: float) -> None:
        end = time.monotonic() + sec
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.01)

    deadline = time.monotonic() + 20     # the observer on joint_states; rnea on contact (it reads zeta_estimate)
    while time.monotonic() < deadline and (pub_js.get_subscription_count() < 1 or (
            mode.startswith("rnea") and pub_contact.get_subscription_count() < 1)):
        spin(0.1)
    spin(1.0)

    def js_msg(t: float, u, tau, names=None) -> JointState:
        m = JointState()
        m.header.stamp = stamp_from_seconds(t)
        m.name = names if names is not None else [f"arm_{i}" for i in range(1, 7)]
        m.position = [float(v) for v in u]
        m.effort = [float(v) for v in tau]
        return m

    def replay(t0: float) -> None:
        start = time.monotonic()
        j = 0
        pt, poses = data["pose_t"], data["pose"]
        for k, t in enumerate(data["t"]):
            while j < len(pt) and pt[j] <= t:
                q = poses[j]
                ps = PoseStamped()
                ps.header.stamp = stamp_from_seconds(t0 + pt[j])
                ps.header.frame_id = "base"
                ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = q[0], q[1], q[2]
                x, y, z, w = quaternion_from_matrix(np.asarray(rotation_zyx(q[3], q[4], q[5])))
                ps.pose.orientation.x, ps.pose.orientation.y, ps.pose.orientation.z, ps.pose.orientation.w = x, y, z, w
                pub_pose.publish(ps)
                if mode == "rnea" and F_ON < pt[j] < F_OFF and active["id"] is not None:
                    c = Contact(collision_id=active["id"], link=Contact.PLATE, chain=0, camera="cam_top",
                                confidence=0.9)
                    c.header.stamp = ps.header.stamp
                    c.header.frame_id = "base"
                    c.point.x, c.point.y, c.point.z = data["point"]
                    pub_contact.publish(c)
                j += 1
            pub_js.publish(js_msg(t0 + t, data["u"][k], data["tau"][k]))
            rclpy.spin_once(node, timeout_sec=0.0)
            lag = start + (k + 1) * DT - time.monotonic()
            if lag > 0:
                time.sleep(lag)
        spin(1.0)

    out: dict = {"mode": mode, "force": FORCE.tolist(), "f_on": F_ON, "f_off": F_OFF}
    T0 = 100.0
    replay(T0)
    if mode == "rnea_late" and events:  # isolation slower than the collision: its contact arrives after the END
        end_by = time.monotonic() + 10
        while not any(e["event"] == CollisionEvent.END for e in events) and time.monotonic() < end_by:
            spin(0.1)
        c = Contact(collision_id=events[0]["id"], link=Contact.PLATE, chain=0, camera="cam_top", confidence=0.9)
        c.header.stamp = stamp_from_seconds(T0 + F_ON + 0.1)
        c.header.frame_id = "base"
        c.point.x, c.point.y, c.point.z = data["point"]
        pub_contact.publish(c)
        spin(2.0)
    out["events"] = [dict(e, t=e["t"] - T0, onset=e["onset"] - T0) for e in events]
    out["residuals"] = len(residuals)
    res = np.array([[r[0] - T0] + r[1] for r in residuals]) if residuals else np.zeros((0, 4))
    free = res[(res[:, 0] > 0.3) & (res[:, 0] < F_ON)] if len(res) else res
    out["free_peak"] = np.abs(free[:, 1:]).max(axis=0).tolist() if len(free) else None
    late = res[(res[:, 0] > F_ON + 0.3) & (res[:, 0] < F_OFF)] if len(res) else res
    out["forced_mean"] = late[:, 1:].mean(axis=0).tolist() if len(late) else None
    if mode.startswith("rnea"):
        w = [x for x in wrenches if F_ON + 0.3 < x["t"] - T0 < F_OFF]
        out["wrenches"] = len(wrenches)
        out["wrench_mean"] = np.mean([x["force"] for x in w], axis=0).tolist() if w else None
        out["wrench_rms_err"] = (np.sqrt(np.mean((np.array([x["force"] for x in w]) - FORCE) ** 2, axis=0)).tolist()
                                 if w else None)
        out["wrench_rank"] = sorted({x["rank"] for x in wrenches})
        out["wrench_stalled"] = sum(x["stalled"] for x in wrenches)
        out["wrench_ids"] = sorted({x["id"] for x in wrenches})
        out["wrench_t"] = [min(x["t"] for x in wrenches) - T0, max(x["t"] for x in wrenches) - T0] if wrenches else None
        # a bad contact: NaN point, unknown link, chain out of range
        for c in (Contact(link=Contact.PLATE, collision_id=1), Contact(link=7, collision_id=1),
                  Contact(link=Contact.ROD, chain=9, collision_id=1)):
            if c.link == Contact.PLATE:
                c.point.x = float("nan")
            pub_contact.publish(c)
        spin(2.5)
        out["diag"] = diags.get("/hexa/rnea", {})
    else:
        cli = node.create_client(SetParameters, "/hexa/observer/set_parameters")
        cli.wait_for_service(timeout_sec=10)
        req = SetParameters.Request()
        req.parameters = [Parameter(name="thresholds", value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE_ARRAY, double_array_value=[20.0, 20.0, 20.0, 2.0, 2.0, 2.0])),
            Parameter(name="servo_thresholds", value=ParameterValue(
                type=ParameterType.PARAMETER_DOUBLE_ARRAY, double_array_value=[3.0] * 6))]
        fut = cli.call_async(req)
        while not fut.done():
            spin(0.05)
        out["set_thresholds_ok"] = all(res.successful for res in fut.result().results)
        bad = SetParameters.Request()
        bad.parameters = [Parameter(name="thresholds", value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE_ARRAY, double_array_value=[-1.0, 2.0, 2.0, 0.2, 0.2, 0.2]))]
        fut = cli.call_async(bad)
        while not fut.done():
            spin(0.05)
        out["set_negative_rejected"] = not fut.result().results[0].successful
        n_events = len(events)
        n_res = len(residuals)
        T1 = 200.0
        replay(T1)
        out["events_phase2"] = len(events) - n_events
        out["threshold_seen"] = thresholds[-1] if thresholds else None
        # bad input: NaN angles, wrong names, then good samples again
        t = T1 + T_END + 0.001
        for k in range(5):
            pub_js.publish(js_msg(t + k * DT, [float("nan")] * 6, data["tau"][-1]))
        for k in range(3):
            pub_js.publish(js_msg(t + (5 + k) * DT, data["u"][-1], data["tau"][-1], names=list("abcdef")))
        spin(0.2)
        n_res2 = len(residuals)
        for k in range(40):
            pub_js.publish(js_msg(t + (10 + k) * DT, data["u"][-1], data["tau"][-1]))
            spin(DT)
        spin(2.5)
        out["residuals_phase2"] = n_res2 - n_res
        out["alive_after_bad_input"] = len(residuals) - n_res2
        out["diag"] = diags.get("/hexa/observer", {})
    print(json.dumps(out), flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
