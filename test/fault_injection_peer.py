"""Fault injector for test_fault_injection.py: a separate ROS process beside a running `hexa bringup sim` that
publishes one bad message at a time into every input topic of the graph, then stops the current board's stream,
kills the observer (SIGKILL), kills the simulator that holds the boards' ports (port loss), and records what the
graph did: the residual's sample stamps, collision events,
motor_currents arrival times and the last /diagnostics of every node. Prints one JSON line.

Usage: fault_injection_peer.py SUPERVISOR_LOG LINK_DIR
"""
from __future__ import annotations

import json
import math
import os
import re
import signal
import sys
import threading
import time

from hexa_bringup.rosenv import apply_defaults
from hexa_ros.diagnostics import values_of

NS = "/hexa"
NAMES = [f"arm_{i}" for i in range(1, 7)]
ZETA = [-2.6] * 6


class Peer:
    def __init__(self, node) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped
        from hexa_msgs.msg import CollisionEvent, Contact, MotorCurrents, Residual, ZetaEstimates
        from hexa_ros import qos
        from sensor_msgs.msg import JointState

        self.node, self.lock = node, threading.Lock()
        self.residual: list[tuple[float, float]] = []      # (sample stamp, wall time)
        self.currents_wall: list[float] = []
        self.events: list[dict] = []
        self.diag: dict[str, dict] = {}
        self.diag_max: dict[str, dict[str, float]] = {}     # largest value of each counter while collecting
        self.collect_max = True
        self.last_mc = None
        self.last_pose = None
        self.fresh_pose = threading.Event()
        self.sent_stamps: set[tuple[int, int]] = set()      # of the injected poses, which come back on plate_pose
        sub = node.create_subscription
        sub(Residual, f"{NS}/residual", self._on_residual, qos.STREAM)
        sub(MotorCurrents, f"{NS}/motor_currents", self._on_currents, qos.STREAM)
        sub(PoseStamped, f"{NS}/plate_pose", self._on_pose, qos.RELIABLE)
        sub(CollisionEvent, f"{NS}/collision", self._on_collision, qos.EVENT)
        sub(DiagnosticArray, "/diagnostics", self._on_diag, qos.RELIABLE)
        pub = node.create_publisher
        self.pub = {"joint_states": pub(JointState, f"{NS}/joint_states", qos.STREAM),
                    "motor_currents": pub(MotorCurrents, f"{NS}/motor_currents", qos.STREAM),
                    "plate_pose": pub(PoseStamped, f"{NS}/plate_pose", qos.RELIABLE),
                    "plate_pose_estimate": pub(PoseStamped, f"{NS}/plate_pose_estimate", qos.RELIABLE),
                    "joint_commands": pub(JointState, f"{NS}/joint_commands", qos.RELIABLE),
                    "zeta_estimates": pub(ZetaEstimates, f"{NS}/zeta_estimates", qos.STREAM),
                    "contact": pub(Contact, f"{NS}/contact", qos.EVENT)}

    @staticmethod
    def sec(stamp) -> float:
        return stamp.sec + stamp.nanosec * 1e-9

    def _on_residual(self, m) -> None:
        with self.lock:
            self.residual.append((self.sec(m.header.stamp), time.monotonic()))

    def _on_currents(self, m) -> None:
        with self.lock:
            self.currents_wall.append(time.monotonic())
            self.last_mc = m

    def _on_pose(self, m) -> None:
        if (m.header.stamp.sec, m.header.stamp.nanosec) in self.sent_stamps:
            return                                   # our own bad pose, never the base of the next one
        self.last_pose = m
        self.fresh_pose.set()

    def _on_collision(self, m) -> None:
        with self.lock:
            self.events.append({"event": int(m.event), "id": int(m.id), "axis_name": m.axis_name,
                                "onset": self.sec(m.onset), "t": self.sec(m.header.stamp),
                                "wall": time.monotonic()})

    def _on_diag(self, m) -> None:
        with self.lock:
            for st in m.status:
                if self.collect_max:
                    seen = self.diag_max.setdefault(st.name, {})
                    for kv in st.values:
                        try:
                            seen[kv.key] = max(seen.get(kv.key, 0.0), float(kv.value))
                        except ValueError:
                            pass
                self.diag[st.name] = {"level": int.from_bytes(st.level, "little") if isinstance(st.level, bytes)
                                      else int(st.level), "message": st.message,
                                      "values": values_of(st)}

    # ------------------------------------------------------------------ messages
    def stamp(self, t: float):
        from builtin_interfaces.msg import Time

        t = max(t, 0.0)
        return Time(sec=int(math.floor(t)), nanosec=int(round((t - math.floor(t)) * 1e9)) % 1_000_000_000)

    def joint_state(self, t: float, position, velocity=(), effort=(), names=NAMES):
        from sensor_msgs.msg import JointState

        m = JointState(name=list(names), position=[float(v) for v in position],
                       velocity=[float(v) for v in velocity], effort=[float(v) for v in effort])
        m.header.stamp = self.stamp(t)
        return m

    def currents(self, t: float, board_us: int, current=(0.0,) * 6, setpoint=None):
        """A motor_currents; its set-points those of the newest one received unless given."""
        from hexa_msgs.msg import MotorCurrents

        m = MotorCurrents()
        m.header.stamp, m.header.frame_id = self.stamp(t), "base"
        m.current = [float(v) for v in current] if len(current) == 6 else [0.0] * 6
        m.board_time_us = int(board_us) & 0xFFFFFFFF
        m.sequence = 0
        m.setpoint = list(self.last_mc.setpoint) if setpoint is None else [float(v) for v in setpoint]
        return m

    def zetas(self, t: float, zeta):
        from hexa_msgs.msg import ZetaEstimates

        m = ZetaEstimates(time=[float(t)], zeta=[float(v) for v in zeta], zeta_dot=[0.0] * 6, tau=[0.0] * 6)
        m.header.stamp = self.stamp(t)
        return m

    def pose(self, t: float, p, q):
        from geometry_msgs.msg import PoseStamped

        m = PoseStamped()
        m.header.stamp, m.header.frame_id = self.stamp(t), "base"
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in p)
        o = m.pose.orientation
        o.x, o.y, o.z, o.w = (float(v) for v in q)
        return m

    def faults(self) -> list[tuple[str, str, object]]:
        """(name, topic, message) of every single bad message, built from the live streams' newest values (call it
        just before sending one)."""
        mc, pose = self.last_mc, self.last_pose
        s, b = self.sec(mc.header.stamp), int(mc.board_time_us)
        sp = self.sec(pose.header.stamp)
        pp = [pose.pose.position.x, pose.pose.position.y, pose.pose.position.z]
        o = pose.pose.orientation
        pq = [o.x, o.y, o.z, o.w]
        nan = float("nan")
        js, cur, ps = self.joint_state, self.currents, self.pose
        from hexa_msgs.msg import Contact

        contact = Contact(collision_id=1, link=Contact.PLATE, camera="cam_top", confidence=1.0)
        contact.header.stamp, contact.header.frame_id = self.stamp(s), "base"
        contact.point.x = nan
        return [
            ("setpoint_nan", "motor_currents", cur(s + 0.0005, b + 1, setpoint=[nan] * 6)),
            ("setpoint_size", "motor_currents", cur(s + 0.0005, b + 1, setpoint=ZETA[:5])),
            ("setpoint_range", "motor_currents", cur(s + 0.0005, b + 1, setpoint=[1e9] * 6)),
            ("currents_board_future", "motor_currents", cur(s, b + 2_000_000_000)),
            ("currents_board_past", "motor_currents", cur(s, b - 1_000_000_000)),
            ("currents_stamp_future", "motor_currents", cur(s + 1e6, b + 1)),
            ("currents_nan", "motor_currents", cur(s + 0.0005, b + 1, [nan] * 6)),
            ("currents_range", "motor_currents", cur(s + 0.0005, b + 1, [1e6] * 6)),
            ("pose_quaternion", "plate_pose", ps(sp + 0.001, pp, [0.0, 0.0, 0.0, 2.0])),
            ("pose_far", "plate_pose", ps(sp + 0.001, [10.0, 0.0, 0.0], pq)),
            ("pose_nan", "plate_pose", ps(sp + 0.001, [nan, 0.0, 0.0], pq)),
            ("pose_future", "plate_pose", ps(sp + 1e6, pp, pq)),
            ("pose_past", "plate_pose", ps(max(sp - 1e3, 0.0), pp, pq)),
            ("pose_jump", "plate_pose", ps(sp + 0.005, [pp[0] + 0.05, pp[1], pp[2]], pq)),   # 10 m/s
            ("estimate_quaternion", "plate_pose_estimate", ps(s, pp, [0.0, 0.0, 0.0, 2.0])),
            ("estimate_far", "plate_pose_estimate", ps(s, [0.0, 0.0, 10.0], pq)),
            ("zeta_nan", "zeta_estimates", self.zetas(s, [nan] * 6)),
            ("zeta_past", "zeta_estimates", self.zetas(s - 1e3, ZETA)),
            ("contact_nan", "contact", contact),
            ("command_huge", "joint_commands", js(s, [1e9] * 6)),
            ("command_nan", "joint_commands", js(s, [nan] * 6)),
            ("command_size", "joint_commands", js(s, ZETA[:5], (), (), NAMES[:5])),
        ]


def _pid(log: str, name: str) -> int | None:
    """The newest pid the supervisor printed for node `name`."""
    found = None
    try:
        with open(log, encoding="utf-8", errors="replace") as f:
            for line in f:
                m = re.match(rf"^.*\b{name}: started pid (\d+)", line)
                if m:
                    found = int(m.group(1))
    except OSError:
        return None
    return found


def _duplicates(node) -> list[str]:
    """Nodes that run twice on this ROS domain: another graph shares it, and its messages mix with this run's."""
    seen = [f"{ns.rstrip('/')}/{name}" for name, ns in node.get_node_names_and_namespaces()]
    return sorted({n for n in seen if seen.count(n) > 1})


#: where each node counts a pose jump in /diagnostics
JUMP_COUNTERS = {"/hexa/observer": "reject_pose_jump", "/hexa/rnea": "reject_pose_jump",
                 "/hexa/singularity": "reject_pose_jump", "hexa_vision: isolation": "reject: plate_pose jump"}


def _send_jump_until_counted(peer: Peer, first, tries: int = 3) -> int:
    """Sends of the pose jump until every node counted one (at most `tries`). A jump is 5 ms after the newest camera
    pose the injector heard; a node that already took the next camera pose (the injector ran late on a loaded host)
    sees it as a pose from the past, counts that, and needs another jump. Each send is one bad message."""
    def counted() -> bool:
        with peer.lock:
            return all(peer.diag_max.get(st, {}).get(k, 0.0) >= 1 for st, k in JUMP_COUNTERS.items())

    msg, sends = first, 1
    while not _wait(counted, 3.0) and sends < tries:
        peer.fresh_pose.clear()
        peer.fresh_pose.wait(2.0)
        msg = next(m for name, _t, m in peer.faults() if name == "pose_jump")
        peer.sent_stamps.add((msg.header.stamp.sec, msg.header.stamp.nanosec))
        peer.pub["plate_pose"].publish(msg)
        sends += 1
    return sends


def _wait(cond, timeout: float, step: float = 0.05) -> bool:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(step)
    return False


def main() -> int:
    apply_defaults()
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from hexa.protocol import frames as fr

    log, link_dir = sys.argv[1], sys.argv[2]
    rclpy.init()
    node = rclpy.create_node("fault_injector")
    peer = Peer(node)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    spinner = threading.Thread(target=ex.spin, daemon=True)
    spinner.start()
    out: dict = {"faults": [], "ok": False}
    t0 = time.monotonic()
    try:
        # the graph is up: the residual flows, the camera gives poses (cameras, detector and marker fit are slow)
        up = _wait(lambda: len(peer.residual) > 400 and peer.last_pose is not None and peer.last_mc is not None
                   and peer.residual[-1][1] > time.monotonic() - 0.5, 150.0)
        out["startup_wall_s"] = time.monotonic() - t0
        if not up:
            out["error"] = f"graph not up: {len(peer.residual)} residuals, pose {peer.last_pose is not None}"
            return 0
        time.sleep(1.0)
        out["duplicate_nodes"] = _duplicates(node)
        # 1. one bad message at a time into every input topic
        for k in range(len(peer.faults())):
            if peer.faults()[k][1] == "plate_pose":
                # right after a camera pose: its stamp is then the newest the nodes accepted, and a pose 5 ms
                # after it is a jump, not a pose older than one that overtook it
                peer.fresh_pose.clear()
                peer.fresh_pose.wait(2.0)
            with peer.lock:
                t_sample = peer.residual[-1][0]
            name, topic, msg = peer.faults()[k]      # stamped from the newest stream values
            if topic == "plate_pose":
                peer.sent_stamps.add((msg.header.stamp.sec, msg.header.stamp.nanosec))
            peer.pub[topic].publish(msg)
            out["faults"].append({"name": name, "topic": topic, "t_sample": t_sample, "wall": time.monotonic()})
            if name == "pose_jump":
                out["pose_jump_sends"] = _send_jump_until_counted(peer, msg)
            time.sleep(0.4)
        time.sleep(1.5)          # poses are applied pose_delay (0.5 s) of sample time later
        out["faults_end_wall"] = time.monotonic()
        time.sleep(1.5)          # two more /diagnostics rounds from every node (1 Hz, late on a loaded host)
        with peer.lock:
            out["diag_after_faults"] = json.loads(json.dumps(peer.diag))
            out["diag_max"] = json.loads(json.dumps(peer.diag_max))
            peer.collect_max = False             # the killed nodes start their counters again
        out["duplicate_nodes"] += _duplicates(node)   # before the kills: a killed node's entry lingers a while
        # 2. the current board stops streaming (one STOP_STREAM on its port, as after a reset)
        fd = os.open(os.path.join(link_dir, "mega"), os.O_WRONLY | os.O_NOCTTY)
        try:
            t_stop = time.monotonic()
            os.write(fd, fr.encode_frame(fr.STOP_STREAM, 0))
        finally:
            os.close(fd)
        _wait(lambda: peer.currents_wall and peer.currents_wall[-1] > t_stop + 1.5, 10.0)
        with peer.lock:
            after = [w for w in peer.currents_wall if w >= t_stop - 0.5]
        out["silence_gap_wall_s"] = max((b - a for a, b in zip(after, after[1:])), default=None)
        out["silence_wall"] = t_stop
        # 3. the observer killed (SIGKILL): the supervisor respawns it, the residual comes back
        pid = _pid(log, "observer")
        out["observer_pid"] = pid
        if pid is not None:
            t_kill = time.monotonic()
            os.kill(pid, signal.SIGKILL)
            out["kill_wall"] = t_kill
            back = _wait(lambda: peer.residual[-1][1] > t_kill + 0.5 and _pid(log, "observer") != pid, 60.0)
            with peer.lock:
                first = next((w for _s, w in peer.residual if w > t_kill + 0.05), None)
            out["observer_back"] = back
            out["residual_back_after_kill_s"] = None if first is None else first - t_kill
            out["observer_respawned"] = _pid(log, "observer") not in (None, pid)
            time.sleep(2.0)
        # 4. port loss: the simulator (which holds the boards' ptys) killed with SIGKILL: the ports vanish, the
        # supervisor respawns it with new ptys and sim time from 0 — the driver reconnects, and every clock of the
        # graph jumped back: the residual resumes once the stream's new times are adopted
        pid = _pid(log, "sim")
        out["sim_pid"] = pid
        if pid is not None:
            t_kill = time.monotonic()
            os.kill(pid, signal.SIGKILL)
            out["sim_kill_wall"] = t_kill
            back = _wait(lambda: peer.currents_wall[-1] > t_kill + 0.5 and peer.residual[-1][1] > t_kill + 0.5
                         and _pid(log, "sim") != pid, 90.0)
            with peer.lock:
                first_mc = next((w for w in peer.currents_wall if w > t_kill + 0.05), None)
                first_res = next((w for _s, w in peer.residual if w > t_kill + 0.05), None)
            out["sim_back"] = back
            out["currents_back_after_port_loss_s"] = None if first_mc is None else first_mc - t_kill
            out["residual_back_after_port_loss_s"] = None if first_res is None else first_res - t_kill
            time.sleep(2.0)
        time.sleep(1.5)                        # one more /diagnostics round from every node
        out["ok"] = True
    finally:
        with peer.lock:
            out["residual"] = peer.residual
            out["events"] = peer.events
            out["diag"] = peer.diag
        out["total_wall_s"] = time.monotonic() - t0
        print(json.dumps(out), flush=True)
        ex.shutdown(timeout_sec=2.0)
        spinner.join(timeout=2.0)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
