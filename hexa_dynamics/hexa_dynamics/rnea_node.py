"""RNEA node: the contact force at the located contact point (seed 000 §3.3, eqs 27–36) → `contact_wrench` and
RViz/Foxglove markers, computed by hexa.dynamics.contact_force.ContactForceTracker (ζ̈ filter, τ window, plate pose
by FK seeded by the camera, identification at `rate_hz` while in collision, backfill of late contacts stamped with
the sample times: `backfilled` in diagnostics). ζ̂, ζ̂̇ and τ come from the observer's `zeta_estimates`, every
accepted sample with its time, several per message: the graph runs one ζ estimator. Parameters: `PARAMETERS` below
(start-up only; the same defaults in hexa_bringup/config/hexa_params.yaml, `/**/rnea`).
Topics (relative): sub `zeta_estimates` (hexa_msgs/ZetaEstimates: times, ζ̂ rad, ζ̂̇ rad/s, τ N·m per sample, read
from its bytes; hexa_ros.qos.STREAM), `plate_pose` (geometry_msgs/PoseStamped, camera), `contact` (hexa_msgs/Contact),
`collision` (hexa_msgs/CollisionEvent); pub `contact_wrench` (hexa_msgs/ContactWrench; STREAM: a backfill sends up
to history·rate_hz at once), `contact_markers` (visualization_msgs/MarkerArray while subscribed: contact sphere and
force arrow, DELETEALL on END), `contact_force` (geometry_msgs/WrenchStamped: the same force in frame `contact`,
which /tf places at the contact point with base's axes, one transform per identification), `/diagnostics` (1 Hz,
rejects by reason).
"""
from __future__ import annotations

import sys
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from hexa_msgs.msg import CollisionEvent, Contact, ContactWrench, ZetaEstimates
from rclpy.node import Node
from visualization_msgs.msg import Marker, MarkerArray

import hexa_ros.node
from hexa import frames
from hexa.dynamics.contact_force import ContactForce, ContactForceConfig, ContactForceTracker, LocatedContact
from hexa.pose_check import PoseCheck
from hexa.rotations import pose6_from_transform
from hexa_ros import diagnostics, markers, qos
from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param, declare_parameters
from hexa_ros.cdr import CdrError, zeta_estimates_from_cdr
from hexa_ros.conversions import pose_fields, wrench_stamped
from hexa_ros.stamps import to_sec, to_stamp
from hexa_ros.tf import TfPublisher

LINK_NAMES = {Contact.PLATE: "plate", Contact.ARM: "arm", Contact.ROD: "rod"}
LINK_CODES = {v: k for k, v in LINK_NAMES.items()}
PARAMETERS = {DESCRIPTION: DESCRIPTION_PARAM,
              "rate_hz": Param(100.0, "identifications per second of sample time in a collision; 0 = on contacts only",
                               range=(0.0, 1000.0)),
              "torque_window": Param(0.02, "s over which tau is averaged", range=(0.0, 1.0)),
              "accel_tau": Param(0.02, "s, time constant of the low-pass derivative giving zeta_ddot",
                                 range=(0.0, 1.0)),
              "require_collision": Param(True, "reject contacts outside a collision START..END"),
              "history": Param(3.0, "s of states kept to identify late contacts (backfill); 0 = none",
                               range=(0.0, 60.0)),
              "arm_force_model": Param("friction_cone", "what an arm force's two unobservable directions get"),
              "arm_friction": Param(0.2, "Coulomb coefficient mu of friction_cone (>= 0)"),
              "saturation": Param(ContactForceConfig().saturation, "|tau| > saturation * torque_max is a stalled "
                                  "servo (flags the wrench servo_stalled); set it as the observer's",
                                  range=(0.01, 1.0)),
              "marker_scale": Param(0.02, "force arrow length per newton (m/N)", range=(0.0, 1.0)),
              "frame_id": Param("base", "frame of the contact points and forces")}


class RneaNode(Node):
    """zeta_estimates + plate_pose + contact + collision → contact_wrench and contact_markers."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("rnea", **kwargs)
        from hexa.robots.hexa_description import load_hexa

        cfg = declare_parameters(self, PARAMETERS)
        desc = load_hexa(str(cfg.pop(DESCRIPTION)) or None)
        self.marker_scale, self.frame_id = float(cfg.pop("marker_scale")), str(cfg.pop("frame_id"))
        self.tracker = ContactForceTracker(desc, ContactForceConfig(**cfg))
        self.rejects = {"bad_message": 0, "no_velocity": 0}
        self.pose_check = PoseCheck.for_hexa(desc)   # non-unit quaternions, off the workspace, jumps: counted
        self.published = 0
        self.pub_wrench = self.create_publisher(ContactWrench, "contact_wrench", qos.STREAM)
        self.pub_markers = self.create_publisher(MarkerArray, "contact_markers", qos.RELIABLE)
        self.pub_force = self.create_publisher(WrenchStamped, "contact_force", qos.STREAM)
        self.tf = TfPublisher(self)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.create_subscription(ZetaEstimates, "zeta_estimates", self._on_zeta, qos.STREAM, raw=True)
        self.create_subscription(PoseStamped, "plate_pose", self._on_pose, qos.RELIABLE)
        self.create_subscription(Contact, "contact", self._on_contact, qos.EVENT)
        self.create_subscription(CollisionEvent, "collision", self._on_collision, qos.EVENT)
        self.create_timer(1.0, self._diagnostics)

    def _on_zeta(self, data: bytes) -> None:
        try:
            times, zeta, zeta_dot, tau = zeta_estimates_from_cdr(data)
        except CdrError:
            self.rejects["bad_message"] += 1
            return
        skip = np.isnan(zeta_dot).all(axis=1) & np.isfinite(zeta).all(axis=1)   # zeta_source measured: no ζ̇
        self.rejects["no_velocity"] += int(skip.sum())
        for k in np.flatnonzero(~skip).tolist():
            self._publish(self.tracker.step_state(float(times[k]), zeta[k], zeta_dot[k], tau[k]))

    def _on_pose(self, msg: PoseStamped) -> None:
        T = self.pose_check.check(to_sec(msg.header.stamp), *pose_fields(msg.pose))
        if T is not None:
            self.tracker.on_pose(to_sec(msg.header.stamp), pose6_from_transform(T))

    def _on_collision(self, msg: CollisionEvent) -> None:
        was = self.tracker.active
        kind = "START" if msg.event == CollisionEvent.START else "END"
        self._publish(self.tracker.on_collision(kind, int(msg.id), to_sec(msg.header.stamp)))
        if was is not None and self.tracker.active is None and self.pub_markers.get_subscription_count() > 0:
            m = Marker(action=Marker.DELETEALL)
            m.header.frame_id = self.frame_id
            self.pub_markers.publish(MarkerArray(markers=[m]))

    def _on_contact(self, msg: Contact) -> None:
        v = msg.push_direction
        c = LocatedContact(time=to_sec(msg.header.stamp), collision_id=int(msg.collision_id),
                           link=LINK_NAMES.get(msg.link, f"link {msg.link}"), chain=int(msg.chain),
                           point=np.array([msg.point.x, msg.point.y, msg.point.z]),
                           push_direction=np.array([v.x, v.y, v.z]))
        self.tracker.on_contact(c, emit=self._publish_one)   # each force as identified: a backfill takes a while

    def _publish(self, forces: list[ContactForce]) -> None:
        for f in forces:
            self._publish_one(f)

    def _publish_one(self, f: ContactForce) -> None:
        w = ContactWrench(collision_id=f.collision_id, link=LINK_CODES[f.link], chain=f.chain, rank=f.rank,
                          condition=f.condition, observable=f.observable, residual_norm=f.residual_norm,
                          force_model=f.force_model, servo_stalled=f.servo_stalled)
        w.header.stamp, w.header.frame_id = to_stamp(f.time), self.frame_id
        w.point = markers.point(f.point)
        w.force.x, w.force.y, w.force.z = (float(v) for v in f.force)
        self.pub_wrench.publish(w)
        self.tf.send([(self.frame_id, frames.CONTACT, frames.transform(np.eye(3), f.point))], w.header.stamp)
        self.pub_force.publish(wrench_stamped(frames.CONTACT, w.header.stamp, f.force))
        self.published += 1
        if not f.backfilled and self.pub_markers.get_subscription_count() > 0:  # markers show the present
            self.pub_markers.publish(self._markers(f, w.header.stamp))

    def _markers(self, f: ContactForce, stamp: Any) -> MarkerArray:
        rgba = (1.0, 0.2, 0.2, 1.0) if f.observable else (1.0, 0.6, 0.2, 1.0)
        return MarkerArray(markers=[
            markers.sphere("contact_point", self.frame_id, stamp, f.point, 0.015, (1.0, 0.8, 0.0, 1.0)),
            markers.arrow("contact_force", self.frame_id, stamp, f.point, f.point + self.marker_scale * f.force,
                          rgba)])

    def _diagnostics(self) -> None:
        t = self.tracker
        values: dict[str, Any] = {"published": self.published, "backfilled": t.backfilled, "active_collision": t.active,
                                  "stream_restarts": t.restarts, "last_identification_error": t.last_error}
        values.update({f"reject_{k}": v for k, v in {**self.rejects, **t.rejects}.items()})
        values.update(self.pose_check.counters())
        level, message = (diagnostics.OK, "ok") if t.state is not None else (diagnostics.WARN, "no zeta_estimates yet")
        st = diagnostics.status(self.get_fully_qualified_name(), level, message, values)
        self.pub_diag.publish(diagnostics.array(self, [st]))


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(RneaNode, "rnea", argv)


if __name__ == "__main__":
    sys.exit(main())
