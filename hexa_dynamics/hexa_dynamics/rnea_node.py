"""RNEA node: contact force at the located contact point by Newton–Euler (seed 000 §3.3, eqs 27-36) → `contact_wrench`
and RViz/Foxglove markers (contact sphere + force arrow).

It runs its own ζ estimator on `joint_states` (hexa.estimation, as the observer node), tracks the plate pose with
forward kinematics from ζ̂ seeded by `plate_pose`, low-pass differentiates ζ̂̇ for ζ̈, averages τ over
`torque_window`, and calls H5's hexa.dynamics.identification.identify_contact_force on each `contact` of the active
collision, and again at `rate_hz` (message time) with the latest contact of that collision until its END.

Isolation takes time (two camera frames, the detector, on a loaded host up to ~1 s): the first contact of a collision
often arrives well after its START, or after its END. The node keeps the last `history` seconds of its states, so
such a contact is also identified retroactively, at `rate_hz`, from the contact's image time (or the START) up to the
present or to the END: the contact_wrench series covers the whole contact, stamped with the sample times
(`backfilled` in diagnostics; a contact of a collision that ended more than `history` ago is rejected as
`not_in_collision`).

Parameters: description (""), zeta_source ("estimator" | "measured"), accel_sigma, torque_sigma, camera_sigma,
bias_walk, saturation, stall_sigma, command_delay (ZetaEstimator, as the observer), rate_hz (100; 0 = only on contact
messages), torque_window (0.02 s), accel_tau (0.02 s: time constant of the ζ̈ low-pass derivative),
require_collision (true: ignore contacts outside a START..END), marker_scale (0.02 m/N), frame_id ("base"), history
(3.0 s of states kept for late contacts; 0 = no backfill), arm_force_model ("friction_cone" | "object_axis" |
"surface_normal" | "min_norm": what an arm force's two unobservable directions get — the pushing object's axis as the
vision measured it (`Contact.push_direction`; the collision's last measured direction when a contact carries none)
clamped into the friction cone about the inward surface normal at the contact point; that axis unclamped; a
frictionless push along the normal; or nothing; without a measured direction the first two act as
"surface_normal"; hexa.dynamics.identification), arm_friction (0.2: μ of "friction_cone").
Topics (relative): sub `joint_states`, `motor_currents` (reliable; time_source as the observer), `plate_pose`,
`contact` (hexa_msgs/Contact), `collision`
(reliable); pub `contact_wrench` (hexa_msgs/ContactWrench), `contact_markers` (visualization_msgs/MarkerArray),
`/diagnostics` (rejects by reason).
"""
from __future__ import annotations

import math
import sys
from collections import deque
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Point
from hexa_msgs.msg import CollisionEvent, Contact, ContactWrench
from rclpy.node import Node
from visualization_msgs.msg import Marker, MarkerArray

from hexa_dynamics.observer_node import (EVENT_QOS, ArmSampleInput, declare_estimator, diagnostic, make_estimator,
                                         run_node, stamp_from_seconds)

LINK_NAMES = {Contact.PLATE: "plate", Contact.ARM: "arm", Contact.ROD: "rod"}
REJECT_REASONS = ("non_finite", "unknown_link", "bad_chain", "no_state", "not_in_collision", "identification",
                  "bad_joint_names", "bad_pose", "estimator", "pose_tracking")


class RneaNode(Node):
    """contact + states → identified contact force (ContactWrench) and markers."""

    def __init__(self) -> None:
        super().__init__("rnea")
        from hexa.dynamics.identification import ARM_FORCE_MODELS
        from hexa.dynamics.lagrange import HexaDynamicParameters
        from hexa.robots.hexa_description import load_hexa

        p = self.declare_parameter
        desc_path = str(p("description", "").value) or None
        self.zeta_source = str(p("zeta_source", "estimator").value)
        if self.zeta_source not in ("estimator", "measured"):
            raise ValueError(f"parameter zeta_source must be 'estimator' or 'measured', got {self.zeta_source!r}")
        est_cfg, delay = declare_estimator(self)
        rate = float(p("rate_hz", 100.0).value)
        self.period = 1.0 / rate if rate > 0 else math.inf
        self.torque_window = float(p("torque_window", 0.02).value)
        self.accel_tau = float(p("accel_tau", 0.02).value)
        self.require_collision = bool(p("require_collision", True).value)
        self.marker_scale = float(p("marker_scale", 0.02).value)
        self.frame_id = str(p("frame_id", "base").value)
        self.history = float(p("history", 3.0).value)
        self.arm_force_model = str(p("arm_force_model", "friction_cone").value)
        self.arm_friction = float(p("arm_friction", 0.2).value)
        if not (math.isfinite(self.arm_friction) and self.arm_friction >= 0):
            raise ValueError(f"parameter arm_friction must be a finite coefficient >= 0, got {self.arm_friction!r}")
        if self.arm_force_model not in ARM_FORCE_MODELS:
            raise ValueError(f"parameter arm_force_model must be one of {ARM_FORCE_MODELS}, "
                             f"got {self.arm_force_model!r}")
        if not (math.isfinite(self.history) and self.history >= 0):
            raise ValueError(f"parameter history must be >= 0 s, got {self.history!r}")
        if not (self.torque_window >= 0 and self.accel_tau > 0):
            raise ValueError(f"torque_window {self.torque_window!r} must be >= 0 and accel_tau {self.accel_tau!r} > 0")
        self.desc = load_hexa(desc_path)
        self.params = HexaDynamicParameters.from_description(self.desc)
        self.estimator = make_estimator(self.desc, est_cfg, delay)
        self.settling = 0
        self.rejects = {k: 0 for k in REJECT_REASONS}
        self.published = 0
        self._tau: deque[tuple[float, np.ndarray]] = deque()
        self._state: tuple | None = None        # (t, ζ, ζ̇, ζ̈, τ averaged over torque_window)
        self._zd_prev: tuple[float, np.ndarray] | None = None
        self._zdd = np.zeros(6)
        self._pose: np.ndarray | None = None     # plate pose tracked from ζ̂
        self._cam_pose: np.ndarray | None = None
        self._active: int | None = None          # id of the collision in progress
        self._contacts: dict[int, Contact] = {}  # latest contact per collision id
        self._last_ident_t = -math.inf
        self._started = 0                      # newest collision id seen STARTing
        self._early_contacts: dict[int, Contact] = {}
        self._hist: deque[tuple] = deque()      # the states of the last `history` seconds
        self._spans: dict[int, list[float]] = {}  # collision id -> [START t, END t or inf], recent collisions
        self._identified: set[int] = set()       # collisions with at least one contact identified
        self._push_dirs: dict[int, np.ndarray] = {}  # last measured push direction per collision id
        self.backfilled = 0

        self.pub_wrench = self.create_publisher(ContactWrench, "contact_wrench", EVENT_QOS)
        self.pub_markers = self.create_publisher(MarkerArray, "contact_markers", 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.input = ArmSampleInput(self, self.desc.K_t, self._on_sample, self.rejects, on_pose=self._on_pose)
        self.create_subscription(Contact, "contact", self._on_contact, EVENT_QOS)
        self.create_subscription(CollisionEvent, "collision", self._on_collision, EVENT_QOS)
        self.create_timer(1.0, self._diagnostics)
        self.get_logger().info(f"rnea: ζ from {self.zeta_source}, identification at {rate:g} Hz while in collision")

    # ------------------------------------------------------------------ state
    def _on_pose(self, t: float, pose: np.ndarray) -> None:
        """A camera pose (image time t), released by the sequencer at sample time t + pose_delay."""
        self._cam_pose = pose
        if self.zeta_source == "estimator":
            self.estimator.update_camera(t, pose)
            z_then = self.estimator.zeta_at(t)
            if self._pose is not None and z_then is not None:  # tracking on the camera's assembly branch at time t?
                from hexa.kinematics.hexa6rus import forward_kinematics

                try:
                    then = np.asarray(forward_kinematics(self.desc, z_then, guess=self._pose), dtype=float)
                    lost = bool(np.max(np.abs(then[:3] - pose[:3])) > 0.02)
                except (ValueError, ArithmeticError):
                    lost = True
                if lost:
                    self._pose = None  # the next identification starts again from the camera

    def _on_sample(self, t: float, pos: np.ndarray, tau: np.ndarray, vel: np.ndarray | None) -> None:
        if self.zeta_source == "estimator":
            e = self.estimator.update(t, pos, tau)
            if e is None:
                self.rejects["estimator"] += 1
                return
            if not e.settled:  # ζ̇ still converging after a (re)start: the observer restarts after it
                self.settling += 1
                return
            zeta, zd = e.zeta, e.zeta_dot
        else:
            zeta, zd = pos, vel
            if zd is None or not (np.all(np.isfinite(zeta)) and np.all(np.isfinite(zd)) and np.all(np.isfinite(tau))):
                self.rejects["non_finite"] += 1
                return
        if self._zd_prev is not None and t > self._zd_prev[0]:
            h = t - self._zd_prev[0]
            a = math.exp(-h / self.accel_tau)
            self._zdd = a * self._zdd + (1 - a) * (zd - self._zd_prev[1]) / h
        self._zd_prev = (t, zd.copy())
        self._tau.append((t, tau))
        while self._tau and self._tau[0][0] < t - self.torque_window:
            self._tau.popleft()
        self._state = (t, zeta, zd, self._zdd.copy(), np.mean([v for _, v in self._tau], axis=0))
        if self.history > 0:
            self._hist.append(self._state)
            while self._hist and self._hist[0][0] < t - self.history:
                self._hist.popleft()
        if self._active is not None and t - self._last_ident_t >= self.period:
            c = self._contacts.get(self._active)
            if c is not None:
                self._identify(c)

    def _plate_pose(self, zeta: np.ndarray) -> np.ndarray | None:
        from hexa.kinematics.hexa6rus import forward_kinematics

        guess = self._cam_pose if self._pose is None else self._pose
        if guess is None:
            return None
        try:
            pose = np.asarray(forward_kinematics(self.desc, zeta, guess=guess), dtype=float)
        except (ValueError, ArithmeticError):
            return None
        return pose if np.all(np.isfinite(pose)) else None

    # ------------------------------------------------------------------ contacts and collisions
    def _on_collision(self, msg: CollisionEvent) -> None:
        t_ev = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if msg.event == CollisionEvent.START:
            self._spans[int(msg.id)] = [t_ev, math.inf]
            for old in sorted(self._spans)[:-10]:  # only recent collisions can still get a late contact
                self._spans.pop(old)
                self._identified.discard(old)
                self._push_dirs.pop(old, None)
            self._active = int(msg.id)
            self._started = max(self._started, int(msg.id))
            early = self._early_contacts.pop(int(msg.id), None)
            self._early_contacts.clear()
            if early is not None:  # the contact of this collision arrived before its START (separate topics)
                self._contacts[int(msg.id)] = early
                self._identify(early)
        elif int(msg.id) in self._spans:
            self._spans[int(msg.id)][1] = t_ev
        if msg.event != CollisionEvent.START and self._active == int(msg.id):
            self._active = None
            self._contacts.pop(int(msg.id), None)
            m = Marker(action=Marker.DELETEALL)
            m.header.frame_id = self.frame_id
            self.pub_markers.publish(MarkerArray(markers=[m]))

    def _on_contact(self, msg: Contact) -> None:
        pt = np.array([msg.point.x, msg.point.y, msg.point.z])
        if not np.all(np.isfinite(pt)):
            self.rejects["non_finite"] += 1
            return
        if msg.link not in LINK_NAMES:
            self.rejects["unknown_link"] += 1
            return
        if msg.link != Contact.PLATE and not 1 <= msg.chain <= 6:
            self.rejects["bad_chain"] += 1
            return
        cid = int(msg.collision_id)
        if self.require_collision and (self._active is None or cid != self._active):
            if cid in self._spans and cid not in self._identified and self._backfill(msg):
                return  # a collision that ended before its contact arrived: identified retroactively
            if int(msg.collision_id) > self._started:  # its START is still on its way: kept until it arrives
                if len(self._early_contacts) < 20:
                    self._early_contacts[int(msg.collision_id)] = msg
                return
            self.rejects["not_in_collision"] += 1
            return
        self._contacts[int(msg.collision_id)] = msg
        if cid not in self._identified and cid in self._spans:
            self._backfill(msg)  # the states between the contact's image time and now
        self._identify(msg)

    def _backfill(self, c: Contact) -> bool:
        """Identify `c` on the kept states from its image time (not before its collision's START) to the END or the
        newest state, every 1/rate_hz; True if any state was in that span."""
        start, end = self._spans[int(c.collision_id)]
        t_img = c.header.stamp.sec + c.header.stamp.nanosec * 1e-9
        t0 = max(start, t_img)
        span = [h for h in self._hist if t0 <= h[0] <= end and (self._state is None or h[0] < self._state[0])]
        if not span:
            return False
        last = -math.inf
        for h in span:
            if h[0] - last >= min(self.period, 0.05):
                if self._identify(c, h):
                    self.backfilled += 1
                last = h[0]
        return True

    def _identify(self, c: Contact, state: tuple | None = None) -> bool:
        from hexa.dynamics.identification import identify_contact_force
        from hexa.dynamics.lagrange import DynamicsError, motion_from_joint_rates

        backfill = state is not None
        state = state if backfill else self._state
        if state is None:
            self.rejects["no_state"] += 1
            return False
        t, zeta, zd, zdd, tau = state
        stamp = stamp_from_seconds(t)
        pose = self._plate_pose(zeta)
        if pose is None:
            self.rejects["pose_tracking"] += 1
            return False
        self._pose = pose
        link = LINK_NAMES[c.link]
        chain = 0 if link == "plate" else int(c.chain)
        point = np.array([c.point.x, c.point.y, c.point.z])
        push = np.array([c.push_direction.x, c.push_direction.y, c.push_direction.z])
        cid = int(c.collision_id)
        if np.all(np.isfinite(push)) and np.any(push != 0.0):
            self._push_dirs[cid] = push
        push = self._push_dirs.get(cid)   # a later frame may not see the object's axis: keep the last measured
        try:
            st = motion_from_joint_rates(self.params, zeta[None], zd[None], pose[None], zdd[None])
            est = identify_contact_force(self.params, st, tau, link, chain, point,
                                         arm_force_model=self.arm_force_model, push_direction=push,
                                         friction=self.arm_friction)
        except (ValueError, DynamicsError, np.linalg.LinAlgError) as exc:
            self.rejects["identification"] += 1
            self.get_logger().warn(f"identification failed: {exc}", throttle_duration_sec=1.0)
            return False
        self._identified.add(int(c.collision_id))
        if not backfill:
            self._last_ident_t = t
        w = ContactWrench()
        w.header.stamp = stamp
        w.header.frame_id = self.frame_id
        w.collision_id = c.collision_id
        w.link, w.chain = c.link, chain
        w.point = Point(x=float(point[0]), y=float(point[1]), z=float(point[2]))
        w.force.x, w.force.y, w.force.z = (float(v) for v in est.force)
        w.rank = int(est.rank)
        w.condition = float(est.condition)
        w.observable = bool(est.observable)
        w.residual_norm = float(est.residual_norm)
        w.force_model = est.force_model
        self.pub_wrench.publish(w)
        self.published += 1
        if not backfill:  # markers show the present only (a backfilled state is history)
            self.pub_markers.publish(self._markers(point, est.force, stamp, est.observable))
        return True

    def _markers(self, point: np.ndarray, force: np.ndarray, stamp: Any, observable: bool) -> MarkerArray:
        s = Marker()
        s.header.stamp = stamp
        s.header.frame_id = self.frame_id
        s.ns, s.id, s.type, s.action = "contact_point", 0, Marker.SPHERE, Marker.ADD
        s.pose.position = Point(x=float(point[0]), y=float(point[1]), z=float(point[2]))
        s.pose.orientation.w = 1.0
        s.scale.x = s.scale.y = s.scale.z = 0.015
        s.color.r, s.color.g, s.color.b, s.color.a = 1.0, 0.8, 0.0, 1.0
        a = Marker()
        a.header = s.header
        a.ns, a.id, a.type, a.action = "contact_force", 0, Marker.ARROW, Marker.ADD
        end = point + self.marker_scale * np.asarray(force)
        a.points = [s.pose.position, Point(x=float(end[0]), y=float(end[1]), z=float(end[2]))]
        a.pose.orientation.w = 1.0
        a.scale.x, a.scale.y, a.scale.z = 0.006, 0.012, 0.015
        a.color.r, a.color.g, a.color.b, a.color.a = (1.0, 0.2, 0.2, 1.0) if observable else (1.0, 0.6, 0.2, 1.0)
        return MarkerArray(markers=[s, a])

    def _diagnostics(self) -> None:
        values: dict[str, Any] = {"published": self.published, "backfilled": self.backfilled,
                                  "active_collision": self._active,
                                  "servo_saturated_samples": self.estimator.saturated}
        values.update({f"reject_{k}": v for k, v in self.rejects.items()})
        values.update({f"reject_estimator_{k}": v for k, v in self.estimator.rejected.items()})
        level = DiagnosticStatus.OK if self._state is not None else DiagnosticStatus.WARN
        msg = "ok" if self._state is not None else "no joint_states yet"
        self.pub_diag.publish(diagnostic(self, level, msg, values))


def main(argv: list[str] | None = None) -> int:
    return run_node(RneaNode, "rnea", argv)


if __name__ == "__main__":
    sys.exit(main())
