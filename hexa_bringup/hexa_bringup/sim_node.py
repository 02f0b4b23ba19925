"""ROS node `hexa-sim`: steps the simulated Hexa and publishes /clock, the two RGB-D cameras and the ground truth.

Parameters: scenario (none | plate | arm | rod | YAML path), seed, randomize, real_time_factor (1.0; 0 = as fast as
possible), camera_rate_hz (30), cameras (true), clock_rate_hz (250: every 4 ms of sim time; every sim-time node
handles each /clock message, so 1 kHz costs the whole graph CPU), truth_rate_hz (100), boards (true: the virtual
Uno/Mega ptys linked at link_dir, /tmp/hexa_sim/{uno,mega}), duration (0 = run until shut down), start_delay (wall s
with sim time frozen at 0 before stepping, while the rest of the graph starts), lead_in (sim s at rest before the
trajectory and the scenario's clock start; the collision happens at lead_in + the scenario's onset), contact_model
(scripted | physical, see hexa.sim.Simulator), trajectory ("" = home; with scenario none the robot starts at rest at
this trajectory's start pose, as a scenario starts at its own: the trajectory node's first command is its start pose,
and from home that is a 0.36 rad jump the servos make at their torque limit), max_lag (0.005 wall s: when a camera
render or a host stall puts the loop further behind the real-time factor, the lost time is dropped instead of caught
up in a burst — see hexa_bringup.pacing), servo_frame_period (-1 = the description's sim.servo.frame_period; 0.02 =
the servo board's 20 ms pulse frame, with the virtual Uno's latch report).
Topics (relative, under the node namespace, e.g. /hexa): cam_{top,side}/color/image_raw (rgb8),
cam_{top,side}/color/camera_info, cam_{top,side}/aligned_depth_to_color/image_raw (16UC1 mm),
cam_{top,side}/aligned_depth_to_color/camera_info (sensor-data QoS); sim/wrench_truth (WrenchStamped: force at the
contact point), sim/contact_truth (hexa_msgs/Contact), sim/plate_pose_truth (PoseStamped), sim/joint_states_truth
(JointState: ζ, ζ̇, τ); /clock. All stamps are sim time; the output is deterministic for a given seed (the stepping
does not depend on wall time; only the pacing does).
"""
from __future__ import annotations

import sys
import time

import numpy as np


def _quat_from_zyx(a: float, b: float, g: float) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of Rz(a)·Ry(b)·Rx(g)."""
    ca, sa, cb, sb, cg, sg = (np.cos(a / 2), np.sin(a / 2), np.cos(b / 2), np.sin(b / 2), np.cos(g / 2),
                              np.sin(g / 2))
    w = ca * cb * cg + sa * sb * sg
    x = ca * cb * sg - sa * sb * cg
    y = ca * sb * cg + sa * cb * sg
    z = sa * cb * cg - ca * sb * sg
    return float(x), float(y), float(z), float(w)


def main(argv: list[str] | None = None) -> int:
    from hexa_bringup.pacing import MAX_LAG, Pacer

    from hexa_bringup.rosenv import apply_defaults

    apply_defaults()
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from rosgraph_msgs.msg import Clock
    from geometry_msgs.msg import PoseStamped, WrenchStamped
    from sensor_msgs.msg import CameraInfo, Image, JointState
    from hexa_msgs.msg import Contact
    from builtin_interfaces.msg import Time

    from hexa.sim import Simulator
    from hexa.sim.boards import VirtualBoards
    from hexa.sim.simulator import LINK_CODES
    from hexa.vision.images import fill_message

    def stamp(t: float) -> Time:
        ns = int(round(t * 1e9))
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    class SimNode(Node):
        """Publishers and parameters; the stepping loop lives in `run`."""

        def __init__(self) -> None:
            super().__init__("sim")
            p = self.declare_parameter
            self.scenario = p("scenario", "plate").value
            self.seed = int(p("seed", 0).value)
            self.randomize = bool(p("randomize", False).value)
            self.rtf = float(p("real_time_factor", 1.0).value)
            self.pacer = Pacer(self.rtf, float(p("max_lag", MAX_LAG).value))  # ValueError names a bad value
            self.cam_rate = float(p("camera_rate_hz", 30.0).value)
            self.use_cams = bool(p("cameras", True).value)
            self.clock_rate = float(p("clock_rate_hz", 250.0).value)
            self.truth_rate = float(p("truth_rate_hz", 100.0).value)
            self.use_boards = bool(p("boards", True).value)
            self.link_dir = str(p("link_dir", "/tmp/hexa_sim").value)
            self.duration = float(p("duration", 0.0).value)
            self.lead_in = float(p("lead_in", 0.0).value)
            self.start_delay = float(p("start_delay", 0.0).value)
            self.contact_model = str(p("contact_model", "scripted").value)
            frame = float(p("servo_frame_period", -1.0).value)
            trajectory = str(p("trajectory", "").value) or None
            scenario = None if self.scenario in ("", "none") else self.scenario
            self.sim = Simulator(seed=self.seed, scenario=scenario, cameras=self.use_cams,
                                 randomize=self.randomize, lead_in=self.lead_in,
                                 contact_model=self.contact_model, trajectory=trajectory,
                                 servo_frame_period=None if frame < 0 else frame)
            self.boards = VirtualBoards(self.sim, link_dir=self.link_dir).start() if self.use_boards else None
            self.clock_pub = self.create_publisher(Clock, "/clock", 10)
            self.cam_pubs = {}
            for name in ("cam_top", "cam_side"):
                model = self.sim.camera_model(name)
                info = CameraInfo()
                for k, v in model.camera_info_fields().items():
                    setattr(info, k, v)
                info.header.frame_id = model.frame_id
                self.cam_pubs[name] = (
                    self.create_publisher(Image, f"{name}/color/image_raw", qos_profile_sensor_data),
                    self.create_publisher(CameraInfo, f"{name}/color/camera_info", qos_profile_sensor_data),
                    self.create_publisher(Image, f"{name}/aligned_depth_to_color/image_raw", qos_profile_sensor_data),
                    self.create_publisher(CameraInfo, f"{name}/aligned_depth_to_color/camera_info",
                                          qos_profile_sensor_data),
                    info, model.frame_id)
            self.wrench_pub = self.create_publisher(WrenchStamped, "sim/wrench_truth", 10)
            self.contact_pub = self.create_publisher(Contact, "sim/contact_truth", 10)
            self.pose_pub = self.create_publisher(PoseStamped, "sim/plate_pose_truth", 10)
            self.joint_pub = self.create_publisher(JointState, "sim/joint_states_truth", 10)
            ports = f"uno {self.boards.uno.port}, mega {self.boards.mega.port}" if self.boards else "no boards"
            self.get_logger().info(f"sim ready: scenario={self.scenario!r} seed={self.seed} rtf={self.rtf} ({ports})")

        def publish_cameras(self) -> None:
            st = stamp(self.sim.time)
            for name, (pi, pinfo, pd, pdinfo, info, frame) in self.cam_pubs.items():
                rgb, depth = self.sim.render(name)
                img = fill_message(Image(), rgb, "rgb8")
                img.header.stamp, img.header.frame_id = st, frame
                dimg = fill_message(Image(), depth, "16UC1")
                dimg.header.stamp, dimg.header.frame_id = st, frame
                info.header.stamp = st
                pi.publish(img)
                pinfo.publish(info)
                pd.publish(dimg)
                pdinfo.publish(info)

        def publish_truth(self) -> None:
            s, g = self.sim.state(), self.sim.ground_truth()
            st = stamp(g.time)
            w = WrenchStamped()
            w.header.stamp, w.header.frame_id = st, "base"
            w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = (float(v) for v in g.force)
            w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = (float(v) for v in g.torque)
            self.wrench_pub.publish(w)
            c = Contact()
            c.header.stamp, c.header.frame_id = st, "base"
            c.link = LINK_CODES[g.link]
            c.chain = int(g.chain)
            c.point.x, c.point.y, c.point.z = (float(v) for v in g.point)
            c.pixel_u = c.pixel_v = -1.0
            c.camera = ""
            c.confidence = 1.0 if g.in_contact else 0.0
            self.contact_pub.publish(c)
            ps = PoseStamped()
            ps.header.stamp, ps.header.frame_id = st, "base"
            ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = (float(v) for v in s.pose[:3])
            q = _quat_from_zyx(*s.pose[3:])
            ps.pose.orientation.x, ps.pose.orientation.y, ps.pose.orientation.z, ps.pose.orientation.w = q
            self.pose_pub.publish(ps)
            js = JointState()
            js.header.stamp, js.header.frame_id = st, "base"
            js.name = [f"arm_{i}" for i in range(1, 7)]
            js.position = [float(v) for v in s.zeta]
            js.velocity = [float(v) for v in s.zeta_dot]
            js.effort = [float(v) for v in s.tau]
            self.joint_pub.publish(js)

        def run(self) -> None:
            sim = self.sim
            dt = sim.timestep
            clock_every = max(1, int(round(1.0 / (self.clock_rate * dt)))) if self.clock_rate > 0 else 0
            truth_every = max(1, int(round(1.0 / (self.truth_rate * dt)))) if self.truth_rate > 0 else 0
            cam_period = 1.0 / self.cam_rate if (self.use_cams and self.cam_rate > 0) else None
            next_cam = 0.0
            k = 0
            if cam_period is not None:
                self.publish_cameras()
                next_cam = cam_period
            hold_until = time.monotonic() + self.start_delay
            while rclpy.ok() and time.monotonic() < hold_until:   # sim time frozen at 0 while the graph starts
                self.clock_pub.publish(Clock(clock=stamp(sim.time)))
                self.publish_truth()
                if cam_period is not None:
                    self.publish_cameras()
                rclpy.spin_once(self, timeout_sec=0.0)
                time.sleep(min(0.5, max(0.0, hold_until - time.monotonic())))
            self.pacer.start(sim.time)
            while rclpy.ok():
                sim.step(1)
                k += 1
                if clock_every and k % clock_every == 0:
                    self.clock_pub.publish(Clock(clock=stamp(sim.time)))
                if truth_every and k % truth_every == 0:
                    self.publish_truth()
                if cam_period is not None and sim.time + 1e-9 >= next_cam:
                    self.publish_cameras()
                    next_cam += cam_period
                if self.duration > 0 and sim.time >= self.duration:
                    break
                # every step: the virtual boards' threads run while the loop sleeps, so the servos take each command
                # within 1 ms of sim time (every 5 steps made 8/12 ms commands 5/10/15 ms steps); after a render the
                # loop does not catch up in a burst (hexa_bringup.pacing)
                self.pacer.pace(sim.time)
                if k % 50 == 0:
                    rclpy.spin_once(self, timeout_sec=0.0)

        def close(self) -> None:
            if self.pacer.stalls:
                self.get_logger().info(f"pacing: {self.pacer.stalls} stalls over max_lag, "
                                       f"{self.pacer.dropped:.1f} s of wall time dropped (not caught up)")
            if self.boards is not None:
                self.boards.stop()
            self.sim.close()

    rclpy.init(args=argv if argv is not None else sys.argv)
    from hexa.sim.simulator import SimulatorError

    try:
        node = SimNode()
    except (ValueError, SimulatorError) as exc:  # a bad parameter (scenario, trajectory, max_lag, ...): named, exit 2
        print(f"hexa sim: {exc}", file=sys.stderr)
        rclpy.shutdown()
        return 2
    try:
        node.run()
    except KeyboardInterrupt:
        pass
    finally:
        node.close()
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
