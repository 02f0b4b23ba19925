"""Trajectory node: plays the paper's trajectories (or a pose file) through IK to `joint_commands`, and reacts to
collisions (hold | retract along the residual | ignore), resuming on a service call.

Thin adapter over hexa.trajectory_runner.TrajectoryRunner (clock, approach, requests) and its TrajectoryPlayer.
Parameters (the fields of hexa.trajectory_runner.TrajectorySettings): `trajectory` ("circle" | "helix" | "ellipse" |
"file"), `file` (CSV of t x y z alpha beta gamma in SI, for trajectory=file), `rate_hz` (100), `start_delay` (s after
the first clock reading, 1.0), `start_time` (s, clock time of trajectory time 0; −1 = use start_delay; with the
simulator's scenarios use 0.0 so that sim time = trajectory time), `loop` (false), `loop_blend` (s, 2.0: with loop, a
trajectory that does not end where it starts — the helix — cross-fades onto its next cycle over this time instead of
jumping), `collision_policy` ("hold"), `retract_distance` (m, 0.02), `retract_time` (s, 0.5), `max_step` (s, 0.03:
the most trajectory time advances between two commands; when the node is late — a stalled host, sim time in bursts —
the trajectory pauses instead of commanding a jump; 0 = no limit), `start_blend` (s, 1.0: the command blends from
rest onto the trajectory, which starts moving at once as in the paper; 0 = velocity step at the start),
`approach_speed` (rad/s, 0 = off: with > 0 nothing is commanded until a `plate_pose` arrives (used if ≤ 0.5 s old);
from that measured pose the plate moves slowly — no arm faster than this — to the trajectory's start pose, then the
trajectory starts; `hexa bringup robot` sets 0.3), `approach_tolerance` (rad, 0.02: no approach when every arm is
this close), and `description` (robot YAML path, default packaged).
Topics (relative): pub `joint_commands` (sensor_msgs/JointState, arm_1..arm_6, ζ rad and ζ̇ rad/s),
`trajectory_state` (std_msgs/String: waiting | waiting_for_pose | approaching | running | held | retracting |
resuming | finished); sub `collision` (hexa_msgs/CollisionEvent, reliable), `residual`
(hexa_msgs/Residual, only with collision_policy "retract", for its direction), `plate_pose`
(geometry_msgs/PoseStamped, only with approach_speed > 0, until the approach is planned).
Services: `~/resume`, `~/hold` (std_srvs/Trigger). `/diagnostics`.
"""
from __future__ import annotations

import sys
from dataclasses import fields

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from hexa_msgs.msg import CollisionEvent, Residual
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

import hexa_ros.node
from hexa.trajectory_runner import WARN_STATES, TrajectoryRunner, TrajectorySettings
from hexa_ros import diagnostics, qos
from hexa_ros.conversions import JOINT_NAMES, hexa_pose_from_msg
from hexa_ros.stamps import to_sec


class TrajectoryNode(Node):
    """Publishes arm-angle commands at `rate_hz` from the TrajectoryRunner; holds on collision START."""

    def __init__(self, **kwargs) -> None:
        super().__init__("trajectory", **kwargs)
        from hexa.robots.hexa_description import load_hexa

        d = TrajectorySettings()    # one parameter per field, its default the field's
        s = TrajectorySettings(**{f.name: self.declare_parameter(f.name, getattr(d, f.name)).value for f in fields(d)})
        desc_path = str(self.declare_parameter("description", "").value) or None
        self.runner = TrajectoryRunner.from_settings(load_hexa(desc_path), s, self._log)
        self.pub = self.create_publisher(JointState, "joint_commands", qos.RELIABLE)
        self.pub_state = self.create_publisher(String, "trajectory_state", qos.RELIABLE)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.create_subscription(CollisionEvent, "collision", self._on_collision, qos.EVENT)
        if s.collision_policy == "retract":
            self.create_subscription(Residual, "residual", self._on_residual, qos.RELIABLE)
        self._pose_sub = None
        if self.runner.approach_pending:
            self._pose_sub = self.create_subscription(PoseStamped, "plate_pose", self._on_pose, qos.RELIABLE)
        self.create_service(Trigger, "~/resume", self._on_resume)
        self.create_service(Trigger, "~/hold", self._on_hold)
        self._last_force = np.zeros(3)
        self.create_timer(1.0 / s.rate_hz, self._tick)
        self.create_timer(1.0, self._diagnostics)
        self.get_logger().info(f"trajectory {s.trajectory} ({self.runner.player.duration:.1f} s) at {s.rate_hz:g} Hz, "
                               f"collision policy {s.collision_policy}"
                               + (f", approach at {s.approach_speed:g} rad/s from the first plate_pose"
                                  if s.approach_speed > 0 else ""))

    def _log(self, level: str, text: str) -> None:
        if level == "info":
            self.get_logger().info(text)
        elif level == "warn":
            self.get_logger().warn(text, throttle_duration_sec=1.0)
        else:
            self.get_logger().error(text, throttle_duration_sec=1.0)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            pose = hexa_pose_from_msg(msg.pose)
        except ValueError as exc:
            self.runner.reject_pose(str(exc))
            return
        self.runner.on_pose(pose, to_sec(msg.header.stamp), self._now())   # the image's time

    def _tick(self) -> None:
        tick = self.runner.tick(self._now())
        if self._pose_sub is not None and not self.runner.approach_pending:
            self.destroy_subscription(self._pose_sub)
            self._pose_sub = None
        if tick.zeta is not None:
            msg = JointState(name=list(JOINT_NAMES), position=[float(v) for v in tick.zeta],
                             velocity=[float(v) for v in tick.zeta_dot])
            msg.header.stamp = self.get_clock().now().to_msg()
            self.pub.publish(msg)
        if tick.state is not None:
            self.pub_state.publish(String(data=tick.state))

    def _on_residual(self, msg: Residual) -> None:
        f = msg.wrench.force
        self._last_force = np.array([f.x, f.y, f.z])

    def _on_collision(self, msg: CollisionEvent) -> None:
        if msg.event != CollisionEvent.START:
            return
        state = self.runner.collision(self._now(), self._last_force)
        if state is not None:
            self.get_logger().warn(f"collision {msg.id} on axis {msg.axis_name}: {state}")

    def _on_resume(self, _req, resp):
        resp.success = self.runner.resume(self._now())
        resp.message = "resumed" if resp.success else "not held"
        return resp

    def _on_hold(self, _req, resp):
        resp.success = self.runner.hold(self._now())
        resp.message = "held" if resp.success else "policy 'ignore' or not started"
        return resp

    def _diagnostics(self) -> None:
        state = self.runner.state
        st = diagnostics.status(self.get_fully_qualified_name(),
                                diagnostics.WARN if state in WARN_STATES else diagnostics.OK, state,
                                self.runner.diagnostic_values())
        self.pub_diag.publish(diagnostics.array(self, [st]))


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(TrajectoryNode, "trajectory", argv)


if __name__ == "__main__":
    sys.exit(main())
