"""Trajectory node: plays the paper's trajectories (or a pose file) through IK to `joint_commands`, and reacts to
collisions (hold | retract along the residual | ignore), resuming on a service call.

Parameters: `trajectory` ("circle" | "helix" | "ellipse" | "file"), `file` (CSV of t x y z alpha beta gamma in SI,
for trajectory=file), `rate_hz` (100), `start_delay` (s after the first clock reading, 1.0), `start_time`
(s, clock time of trajectory time 0; −1 = use start_delay; with the simulator's scenarios use 0.0 so that sim time =
trajectory time), `loop` (false), `loop_blend` (s, 2.0: with loop, a trajectory that does not end where it starts —
the helix — cross-fades onto its next cycle over this time instead of jumping), `collision_policy` ("hold"),
`retract_distance` (m, 0.02), `retract_time` (s, 0.5), `max_step` (s, 0.03: the most trajectory time advances
between two commands; when the node is late — a stalled host, sim time in bursts — the trajectory pauses instead of
commanding a jump; 0 = no limit), `start_blend` (s, 1.0: the command blends from rest onto the trajectory, which
starts moving at once as in the paper; 0 = velocity step at the start), `approach_speed` (rad/s, 0 = off: with
> 0 nothing is commanded until a `plate_pose` arrives (used if ≤ 0.5 s old); from that measured pose the plate
moves slowly — no arm faster than this — to the trajectory's start pose, then the trajectory starts; `hexa bringup
robot` sets 0.3),
`approach_tolerance` (rad, 0.02: no approach when every arm is this close), `description` (robot YAML path,
default packaged).
Topics (relative): pub `joint_commands` (sensor_msgs/JointState, arm_1..arm_6, ζ rad and ζ̇ rad/s),
`trajectory_state` (std_msgs/String: waiting | waiting_for_pose | approaching | running | held | retracting |
resuming | finished); sub `collision` (hexa_msgs/CollisionEvent, reliable), `residual`
(hexa_msgs/Residual, only with collision_policy "retract", for its direction), `plate_pose`
(geometry_msgs/PoseStamped, only with approach_speed > 0, until the approach is planned).
Services: `~/resume`, `~/hold` (std_srvs/Trigger). `/diagnostics`.
"""
from __future__ import annotations

import math
import sys

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from hexa_msgs.msg import CollisionEvent, Residual
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

JOINT_NAMES = [f"arm_{i}" for i in range(1, 7)]
#: s: the approach starts only from a plate_pose whose stamp is this recent (limp servos let the plate sag; a stalled
#: camera lies)
APPROACH_POSE_MAX_AGE = 0.5


def load_pose_file(path: str):
    """A trajectory callable from a CSV file of rows t x y z alpha beta gamma (SI), linearly interpolated.

    Raises:
        ValueError: the file has the wrong number of columns, non-finite values or non-increasing time.
    """
    data = np.loadtxt(path, delimiter=",", ndmin=2, comments="#")
    if data.shape[1] != 7:
        raise ValueError(f"{path}: expected 7 columns (t x y z alpha beta gamma), got {data.shape[1]}")
    if not np.all(np.isfinite(data)):
        raise ValueError(f"{path}: non-finite values")
    t = data[:, 0]
    if np.any(np.diff(t) <= 0):
        raise ValueError(f"{path}: time must increase strictly")
    poses = data[:, 1:]
    rates = np.gradient(poses, t, axis=0) if len(t) > 1 else np.zeros_like(poses)

    def traj(tt: float):
        pose = np.array([np.interp(tt, t, poses[:, k]) for k in range(6)])
        rate = np.array([np.interp(tt, t, rates[:, k]) for k in range(6)])
        return pose, rate, np.zeros(6)

    return traj, float(t[-1] - t[0]) if len(t) > 1 else 0.0


class TrajectoryNode(Node):
    """Publishes arm-angle commands at `rate_hz` from the TrajectoryPlayer; holds on collision START."""

    def __init__(self) -> None:
        super().__init__("trajectory")
        from hexa.robots.hexa_description import load_hexa
        from hexa.trajectories import DURATIONS, TRAJECTORIES
        from hexa.trajectory_player import TrajectoryPlayer

        name = str(self.declare_parameter("trajectory", "circle").value)
        path = str(self.declare_parameter("file", "").value)
        rate = float(self.declare_parameter("rate_hz", 100.0).value)
        self.start_delay = float(self.declare_parameter("start_delay", 1.0).value)
        self.start_time = float(self.declare_parameter("start_time", -1.0).value)
        loop = bool(self.declare_parameter("loop", False).value)
        loop_blend = float(self.declare_parameter("loop_blend", 2.0).value)
        policy = str(self.declare_parameter("collision_policy", "hold").value)
        dist = float(self.declare_parameter("retract_distance", 0.02).value)
        rtime = float(self.declare_parameter("retract_time", 0.5).value)
        max_step = float(self.declare_parameter("max_step", 0.03).value)
        start_blend = float(self.declare_parameter("start_blend", 1.0).value)
        self.approach_speed = float(self.declare_parameter("approach_speed", 0.0).value)
        self.approach_tolerance = float(self.declare_parameter("approach_tolerance", 0.02).value)
        desc_path = str(self.declare_parameter("description", "").value) or None
        if not (math.isfinite(self.approach_speed) and self.approach_speed >= 0):
            raise ValueError(f"parameter approach_speed must be >= 0 rad/s (0 = off), got {self.approach_speed}")
        if not (math.isfinite(self.approach_tolerance) and self.approach_tolerance >= 0):
            raise ValueError(f"parameter approach_tolerance must be >= 0 rad, got {self.approach_tolerance}")
        if not rate > 0:
            raise ValueError(f"parameter rate_hz must be > 0, got {rate}")
        if not start_blend >= 0:
            raise ValueError(f"parameter start_blend must be >= 0 s, got {start_blend}")
        if not math.isfinite(max_step) or max_step < 0 or (0 < max_step < 1.0 / rate):
            raise ValueError(f"parameter max_step must be 0 (no limit) or >= 1/rate_hz = {1.0 / rate:g} s, "
                             f"got {max_step}")
        self.desc = load_hexa(desc_path)
        if name == "file":
            traj, duration = load_pose_file(path)
        elif name in TRAJECTORIES:
            traj, duration = TRAJECTORIES[name], DURATIONS[name]
        else:
            raise ValueError(f"parameter trajectory must be one of {sorted(TRAJECTORIES)} or 'file', got {name!r}")
        self.player = TrajectoryPlayer(self.desc, traj, duration, policy=policy, retract_distance=dist,
                                       retract_time=rtime, loop=loop, max_step=max_step or None,
                                       start_blend=start_blend, loop_blend=loop_blend)
        self.pub = self.create_publisher(JointState, "joint_commands", 10)
        self.pub_state = self.create_publisher(String, "trajectory_state", 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(CollisionEvent, "collision", self._on_collision, reliable)
        if policy == "retract":
            self.create_subscription(Residual, "residual", self._on_residual, 10)
        self._pose_now: np.ndarray | None = None
        self._pose_time = -math.inf
        self._pose_sub = None
        self.bad_poses = 0
        if self.approach_speed > 0:
            self._pose_sub = self.create_subscription(PoseStamped, "plate_pose", self._on_pose, 10)
        self.create_service(Trigger, "~/resume", self._on_resume)
        self.create_service(Trigger, "~/hold", self._on_hold)
        self._t0: float | None = None
        self._last_force = np.zeros(3)
        self._last_cmd = None
        self._state = "waiting"
        self.collisions = 0
        self.create_timer(1.0 / rate, self._tick)
        self.create_timer(1.0, self._diagnostics)
        self.get_logger().info(f"trajectory {name} ({duration:.1f} s) at {rate:g} Hz, collision policy {policy}"
                               + (f", approach at {self.approach_speed:g} rad/s from the first plate_pose"
                                  if self.approach_speed > 0 else ""))

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _t(self) -> float | None:
        now = self._now()
        if now <= 0.0:  # sim time not started yet
            return None
        if self._t0 is None:
            self._t0 = self.start_time if self.start_time >= 0 else now + self.start_delay
        if self._pose_sub is not None:  # approach: the trajectory clock starts at the first measured pose
            if self._pose_now is None or now < self._t0 or now - self._pose_time > APPROACH_POSE_MAX_AGE:
                return None
            self._plan_approach(now)
        return now - self._t0

    def _on_pose(self, msg: PoseStamped) -> None:
        from hexa_dynamics.conversions import hexa_pose_from_msg

        try:
            pose = hexa_pose_from_msg(msg.pose)
            if not np.all(np.isfinite(pose)):
                raise ValueError(f"non-finite pose {pose.tolist()}")
        except ValueError as exc:
            self.bad_poses += 1
            self.get_logger().warn(f"plate_pose rejected: {exc}", throttle_duration_sec=1.0)
            return
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self._pose_now, self._pose_time = pose, (stamp if stamp > 0 else self._now())   # the image's time

    def _plan_approach(self, now: float) -> None:
        """Once: the approach from the latest measured pose; the trajectory clock starts now."""
        try:
            T = self.player.approach_from(self._pose_now, self.approach_speed, self.approach_tolerance)
        except ValueError as exc:  # unreachable measured pose: wait for the next one
            self.bad_poses += 1
            self._pose_now = None
            self.get_logger().error(f"cannot approach from the measured plate pose: {exc}",
                                    throttle_duration_sec=1.0)
            return
        self.destroy_subscription(self._pose_sub)
        self._pose_sub = None
        self._t0 = now
        p = self._pose_now
        self.get_logger().info(f"approach from plate pose ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m: {T:.2f} s"
                               if T > 0 else "at the start pose: no approach needed")

    def _tick(self) -> None:
        t = self._t()
        if t is None:
            if self._pose_sub is not None:
                fresh = self._pose_now is not None and self._now() - self._pose_time <= APPROACH_POSE_MAX_AGE
                self._state = "waiting" if fresh else "waiting_for_pose"
                self.pub_state.publish(String(data=self._state))
            return
        try:
            cmd = self.player.command(max(0.0, t))
        except ValueError as exc:
            self.get_logger().error(f"IK failed, holding the last command: {exc}", throttle_duration_sec=1.0)
            cmd = self._last_cmd
            if cmd is None:
                return
        self._last_cmd = cmd
        self._state = "waiting" if t < 0 else cmd.state
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.name = JOINT_NAMES
        msg.position = [float(v) for v in cmd.zeta]
        msg.velocity = [0.0] * 6 if t < 0 else [float(v) for v in cmd.zeta_dot]
        self.pub.publish(msg)
        self.pub_state.publish(String(data=self._state))

    def _on_residual(self, msg: Residual) -> None:
        f = msg.wrench.force
        self._last_force = np.array([f.x, f.y, f.z])

    def _on_collision(self, msg: CollisionEvent) -> None:
        if msg.event != CollisionEvent.START:
            return
        self.collisions += 1
        t = self._t()
        if t is None:
            return
        state = self.player.on_collision(max(0.0, t), self._last_force)
        self.get_logger().warn(f"collision {msg.id} on axis {msg.axis_name}: {state}")

    def _on_resume(self, _req, resp):
        t = self._t()
        resp.success = t is not None and self.player.resume(max(0.0, t))
        resp.message = "resumed" if resp.success else "not held"
        return resp

    def _on_hold(self, _req, resp):
        t = self._t()
        resp.success = t is not None and self.player.on_collision(max(0.0, t)) in ("held", "retracting")
        resp.message = "held" if resp.success else "policy 'ignore' or not started"
        return resp

    def _diagnostics(self) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        level = (DiagnosticStatus.WARN if self._state in ("held", "retracting", "waiting_for_pose")
                 else DiagnosticStatus.OK)
        st = DiagnosticStatus(level=level, name=self.get_fully_qualified_name(), message=self._state)
        st.values = [KeyValue(key="state", value=self._state),
                     KeyValue(key="collisions", value=str(self.collisions)),
                     KeyValue(key="ik_failures", value=str(self.player.ik_failures)),
                     KeyValue(key="lag_events", value=str(self.player.lag_events)),
                     KeyValue(key="lag_time_s", value=f"{self.player.lag_time:.3f}"),
                     KeyValue(key="approach_time_s", value=f"{self.player.approach_time:.3f}"),
                     KeyValue(key="rejected_poses", value=str(self.bad_poses))]
        arr.status = [st]
        self.pub_diag.publish(arr)


def main(argv: list[str] | None = None) -> int:
    from hexa_bringup.rosenv import apply_defaults

    apply_defaults()
    rclpy.init(args=argv if argv is not None else sys.argv)
    try:
        node = TrajectoryNode()
    except (ValueError, OSError) as exc:
        print(f"hexa trajectory: {exc}", file=sys.stderr)
        rclpy.shutdown()
        return 2
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
