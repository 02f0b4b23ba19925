"""Trajectory node: plays the paper's trajectories (or a pose file) through IK to `joint_commands`, and reacts to
collisions (hold | retract along the residual | ignore), resuming on a service call.

Thin adapter over hexa.trajectory_runner.TrajectoryRunner (clock, approach, requests) and its TrajectoryPlayer.
Parameters: hexa_dynamics.trajectory_params (the fields of hexa.trajectory_runner.TrajectorySettings and
`description`), all read at start-up (read-only: a set on the running node is refused). With the simulator's
scenarios use start_time 0.0 so that sim time = trajectory time; `hexa bringup robot` sets approach_speed 0.3.
Topics (relative): pub `joint_commands` (sensor_msgs/JointState, arm_1..arm_6, ζ rad and ζ̇ rad/s),
`trajectory_state` (std_msgs/String, transient local: a late subscriber gets the current state; waiting |
waiting_for_monitoring | waiting_for_pose | approaching | running | held | retracting | resuming | finished),
`trajectory_start` (std_msgs/Header, transient local, once: its stamp is the clock time of trajectory time 0, known
after the monitoring's first OK; the simulator times its scripted collision from it); sub
`collision` (hexa_msgs/CollisionEvent, reliable), `monitoring` (hexa_msgs/MonitoringState, transient local: nothing
moves before its first OK, LOST holds like a START; docs/monitoring.md), `residual`
(hexa_msgs/Residual, only with collision_policy "retract", for its direction), `plate_pose`
(geometry_msgs/PoseStamped, only with approach_speed > 0, until the approach is planned).
Services: `~/resume` (refused with the reason while monitoring is not OK), `~/hold` (std_srvs/Trigger).
`/diagnostics`.
"""
from __future__ import annotations

import sys

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from hexa_msgs.msg import CollisionEvent, MonitoringState, Residual
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String
from std_srvs.srv import Trigger

import hexa_ros.node
from hexa.trajectory_runner import WARN_STATES, TrajectoryRunner, TrajectorySettings
from hexa_ros import diagnostics, qos
from hexa_ros.node import DESCRIPTION, declare_parameters
from hexa_ros.conversions import JOINT_NAMES, hexa_pose_from_msg
from hexa_ros.stamps import to_sec, to_stamp
from hexa_dynamics.trajectory_params import PARAMETERS


class TrajectoryNode(Node):
    """Publishes arm-angle commands at `rate_hz` from the TrajectoryRunner; holds on collision START."""

    def __init__(self, **kwargs) -> None:
        super().__init__("trajectory", **kwargs)
        from hexa.robots.hexa_description import load_hexa

        v = declare_parameters(self, PARAMETERS)
        desc_path = str(v.pop(DESCRIPTION)) or None
        s = TrajectorySettings(**v)
        self.runner = TrajectoryRunner.from_settings(load_hexa(desc_path), s, self._log)
        self.pub = self.create_publisher(JointState, "joint_commands", qos.RELIABLE)
        self.pub_state = self.create_publisher(String, "trajectory_state", qos.LATCHED)
        self.pub_start = self.create_publisher(Header, "trajectory_start", qos.LATCHED)
        self._start_sent = False
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.create_subscription(CollisionEvent, "collision", self._on_collision, qos.EVENT)
        self.create_subscription(MonitoringState, "monitoring", self._on_monitoring, qos.LATCHED)
        if s.collision_policy == "retract":
            self.create_subscription(Residual, "residual", self._on_residual, qos.RELIABLE)
        self._pose_sub = None
        if self.runner.approach_pending:
            self._pose_sub = self.create_subscription(PoseStamped, "plate_pose", self._on_pose, qos.RELIABLE)
        self.create_service(Trigger, "~/resume", self._on_resume)
        self.create_service(Trigger, "~/hold", self._on_hold)
        self._last_force = np.zeros(3)
        self._state = ""
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
        now = self._now()
        tick = self.runner.tick(now)
        if self._pose_sub is not None and not self.runner.approach_pending:
            self.destroy_subscription(self._pose_sub)
            self._pose_sub = None
        if tick.zeta is not None:
            msg = JointState(name=list(JOINT_NAMES), position=[float(v) for v in tick.zeta],
                             velocity=[float(v) for v in tick.zeta_dot])
            msg.header.stamp = to_stamp(now)   # the time the command was computed for, not when it went out
            self.pub.publish(msg)
        if not self._start_sent and self.runner.start is not None:
            self._start_sent = True
            self.pub_start.publish(Header(stamp=to_stamp(self.runner.start)))
            self.get_logger().info(f"trajectory time 0 at {self.runner.start:.3f} s")
        if tick.state is not None:
            self.pub_state.publish(String(data=tick.state))
            if tick.state != self._state:
                self._state = tick.state
                self.get_logger().info(f"trajectory state {tick.state} at {now:.3f} s")

    def _on_residual(self, msg: Residual) -> None:
        f = msg.wrench.force
        self._last_force = np.array([f.x, f.y, f.z])

    def _on_collision(self, msg: CollisionEvent) -> None:
        if msg.event != CollisionEvent.START:
            return
        state = self.runner.collision(self._now(), self._last_force)
        if state is not None:
            self.get_logger().warn(f"collision {msg.id} on axis {msg.axis_name}: {state}")

    def _on_monitoring(self, msg: MonitoringState) -> None:
        text = self.runner.on_monitoring(msg.level_name, msg.reason, self._now())
        if text is None:
            return
        if msg.level == MonitoringState.LOST:   # (rclpy fixes one severity per call site)
            self.get_logger().error(text)
        else:
            self.get_logger().info(text)
        self._tick()   # a hold takes effect at once, not at the next tick

    def _on_resume(self, _req, resp):
        resp.success = self.runner.resume(self._now())
        resp.message = "resumed" if resp.success else self.runner.refusal
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
