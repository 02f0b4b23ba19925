"""The observer node's per-sample outputs: what one hexa.dynamics.monitor.MonitorSample becomes on the graph.

`residual` (hexa_msgs/Residual, every sample) and `zeta_estimates` (hexa_msgs/ZetaEstimates, the samples of
`zeta_batch_period` s of sample time per message, sent at once when a collision event comes) are written as bytes
(hexa_ros.cdr): at 1 kHz the message objects cost more to build and convert than the observer's update, and every
message on a 1 kHz topic costs its subscriber ≈ 0.1 ms in the transport. Standard types beside them go out only while
someone subscribes: `zeta_estimate` (sensor_msgs/JointState per sample), `external_wrench` (WrenchStamped in
`plate`), `external_joint_torques` (JointState effort), `markers`, and /tf at its rate in sample time (who
subscribes is looked up every 0.1 s of sample time, not per sample; thirteen transforms cost ≈ 0.3 ms). At its rate
in sample time: `plate_pose_estimate`. Collision events on `collision` and the latched `collision_state`.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from geometry_msgs.msg import PoseStamped, WrenchStamped
from hexa_msgs.msg import CollisionEvent, Residual, ZetaEstimates
from hexa_ros import cdr, markers, qos
from hexa_ros.conversions import JOINT_NAMES, fill_pose_msg, wrench_stamped
from hexa_ros.stamps import stamp_parts, to_stamp
from hexa_ros.tf import TfPublisher
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from hexa import frames
from hexa.kinematics.hexa6rus import rotation_zyx

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

NAN6 = [math.nan] * 6
#: s of sample time between looks at who subscribes to the outputs sent only while subscribed
SUBSCRIBERS_EVERY = 0.1


class ObserverOutputs:
    """Publishers of the observer's outputs on `node`; `settings` (the node's runtime values, read at each sample):
    marker_rate_hz, marker_scale, pose_estimate_rate_hz, tf_rate_hz, zeta_batch_period."""

    def __init__(self, node: Any, desc: HexaDescription, frame_id: str, settings: dict[str, Any]) -> None:
        self.node, self.desc, self.frame_id, self.set = node, desc, frame_id, settings
        pub = node.create_publisher
        self.residual = pub(Residual, "residual", qos.STREAM)
        self.collision = pub(CollisionEvent, "collision", qos.EVENT)
        self.state = pub(CollisionEvent, "collision_state", qos.LATCHED)
        self.state.publish(CollisionEvent(event=CollisionEvent.END, id=0))
        self.wrench = pub(WrenchStamped, "external_wrench", qos.STREAM)
        self.torques = pub(JointState, "external_joint_torques", qos.STREAM)
        self.zeta = pub(JointState, "zeta_estimate", qos.STREAM)
        self.zetas = pub(ZetaEstimates, "zeta_estimates", qos.STREAM)
        self.pose = pub(PoseStamped, "plate_pose_estimate", qos.RELIABLE)
        self.markers = pub(MarkerArray, "markers", qos.RELIABLE)
        self.tf = TfPublisher(node)
        self.tf.send_static(frames.static_transforms(desc))
        self.last = {"marker": -math.inf, "pose": -math.inf, "tf": -math.inf}
        self.batch: tuple[list[float], list[float], list[float], list[float]] = ([], [], [], [])
        self.events_sent = 0
        self.subscribed: dict[str, bool] = {}
        self._looked = -math.inf

    def _due(self, key: str, t: float, rate: str) -> bool:
        if t - self.last[key] >= 1.0 / max(float(self.set[rate]), 1e-3):
            self.last[key] = t
            return True
        return False

    def publish(self, samples: list, detector: Any) -> None:
        """Every output of `samples` (MonitorSample); `detector` gives the thresholds the residual is shown with."""
        for s in samples:
            out, (sec, nsec) = s.residual, stamp_parts(s.time)
            if s.time - self._looked >= SUBSCRIBERS_EVERY or s.time < self._looked:
                self._looked = s.time
                self.subscribed = {k: getattr(self, k).get_subscription_count() > 0
                                   for k in ("zeta", "wrench", "torques", "markers")}
                self.subscribed["tf"] = self.tf.pub.get_subscription_count() > 0
            w = out.wrench.tolist()
            self.residual.publish(cdr.residual_to_cdr(
                sec, nsec, self.frame_id, out.r_zyz.tolist(), w[:3], w[3:], detector.thresholds.tolist(),
                out.over.tolist(), out.servo_torque.tolist(), detector.servo_thresholds.tolist(),
                out.servo_over.tolist(), bool(out.in_collision)))
            zeta, tau = s.zeta.tolist(), s.tau.tolist()
            zeta_dot = NAN6 if s.zeta_dot is None else s.zeta_dot.tolist()
            self._batch(s.time, zeta, zeta_dot, tau, bool(out.events))
            if self.subscribed["zeta"]:
                self.zeta.publish(cdr.joint_state_to_cdr(sec, nsec, "", JOINT_NAMES, zeta,
                                                         [] if s.zeta_dot is None else zeta_dot, tau))
            if self.subscribed["wrench"] or self.subscribed["torques"]:
                self._standard(out, to_stamp(s.time))
            for ev in out.events:
                self._event(ev)
            if self._due("pose", s.time, "pose_estimate_rate_hz"):
                ps = PoseStamped()
                ps.header.stamp, ps.header.frame_id = to_stamp(s.time), self.frame_id
                fill_pose_msg(ps.pose, rotation_zyx(*out.pose[3:6]), out.pose[:3])
                self.pose.publish(ps)
            if self.subscribed["tf"] and self._due("tf", s.time, "tf_rate_hz"):
                self.tf.send(frames.robot_transforms(self.desc, out.pose, s.zeta), to_stamp(s.time))
            if self.subscribed["markers"] and (self._due("marker", s.time, "marker_rate_hz") or out.events):
                self.markers.publish(self._markers(out, to_stamp(s.time)))

    def _batch(self, t: float, zeta: list, zeta_dot: list, tau: list, flush: bool) -> None:
        times, z, zd, ta = self.batch
        times.append(t)
        z += zeta
        zd += zeta_dot
        ta += tau
        if flush or t - times[0] >= float(self.set["zeta_batch_period"]) - 1e-9:
            self.zetas.publish(cdr.zeta_estimates_to_cdr(*stamp_parts(t), times, z, zd, ta))
            self.batch = ([], [], [], [])

    def _event(self, ev: Any) -> None:
        c = CollisionEvent(event=CollisionEvent.START if ev.kind == "START" else CollisionEvent.END, id=int(ev.id),
                           onset=to_stamp(ev.onset), axis=int(ev.axis), axis_name=ev.axis_name, value=float(ev.value),
                           peak=float(ev.peak), duration=float(ev.duration))
        c.header.stamp, c.header.frame_id = to_stamp(ev.time), self.frame_id
        self.collision.publish(c)
        self.state.publish(c)
        self.events_sent += 1
        self.node.get_logger().warn(f"collision {ev.id} {ev.kind} on {ev.axis_name}: {ev.value:.3f} (peak "
                                    f"{ev.peak:.3f}, onset {ev.onset:.3f} s)")

    def _standard(self, out: Any, stamp: Any) -> None:
        """The residual as a WrenchStamped in `plate` (moment about the plate centre) and as servo-space efforts."""
        if self.subscribed["wrench"]:
            R = rotation_zyx(*out.pose[3:6])
            self.wrench.publish(wrench_stamped(frames.PLATE, stamp, R.T @ out.wrench[:3], R.T @ out.wrench[3:]))
        if self.subscribed["torques"]:
            js = JointState(name=list(JOINT_NAMES), effort=out.servo_torque.tolist())
            js.header.stamp = stamp
            self.torques.publish(js)

    def _markers(self, out: Any, stamp: Any) -> MarkerArray:
        """The residual force as an arrow at the plate (green; red in collision)."""
        P, F = out.pose[:3], out.wrench[:3]
        rgba = (1.0, 0.1, 0.1, 1.0) if out.in_collision else (0.1, 0.8, 0.2, 0.8)
        return MarkerArray(markers=[markers.arrow("residual_force", self.frame_id, stamp, P,
                                                  P + float(self.set["marker_scale"]) * F, rgba)])
