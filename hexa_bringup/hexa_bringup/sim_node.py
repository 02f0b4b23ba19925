"""ROS node `hexa-sim`: steps the simulated Hexa (hexa.sim.Simulator, looped by hexa.sim.pacing.SimRunner) and
publishes /clock, the two RGB-D cameras and the ground truth.

Topics (relative, e.g. under /hexa): cam_{top,side}/color/image_raw (rgb8), cam_{top,side}/color/camera_info,
cam_{top,side}/aligned_depth_to_color/image_raw (16UC1 mm) and its camera_info (sensor-data QoS); sim/wrench_truth
(WrenchStamped: force at the contact point), sim/contact_truth (hexa_msgs/Contact), sim/plate_pose_truth
(PoseStamped), sim/joint_states_truth (JointState: ζ, ζ̇, τ); /clock. All stamps are sim time; the output is
deterministic for a given seed. Subscribes to `trajectory_start` (std_msgs/Header, transient local): the scripted
collision is timed from trajectory time 0, recorded on `sim/scenario_start` (std_msgs/Header, transient local;
docs/simulator.md). The virtual Uno/Mega serial ports appear at `link_dir` (boards: true).
Parameters: hexa_bringup.sim_params (start-up only, read-only), hexa_bringup/config/hexa_params.yaml (`/**/sim`)
and docs/simulator.md.
"""
from __future__ import annotations

import sys
from typing import Any, Callable

import numpy as np

from geometry_msgs.msg import PoseStamped, WrenchStamped
from hexa_msgs.msg import Contact
import hexa_ros.node
from hexa_ros import qos
from hexa_ros.cdr import image_to_cdr
from hexa_ros.conversions import sim_truth_messages
from hexa_ros.node import declare_parameters
from hexa_ros.stamps import to_sec, to_stamp
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header

from hexa.sim import Simulator
from hexa.sim.boards import VirtualBoards
from hexa.sim.pacing import Pacer, SimRunner
from hexa.sim.realism import RealismConfig
from hexa.sim.render_thread import RenderThread
from hexa.sim.simulator import LINK_CODES, SimulatorError
from hexa_bringup.sim_params import PARAMETERS


class SimNode(Node):
    """Publishers and parameters; SimRunner asks for the clock, the truth and the cameras (SimOutputs)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("sim", **kwargs)
        v = declare_parameters(self, PARAMETERS)
        self.scenario, self.seed = str(v["scenario"]), int(v["seed"])
        rtf, cameras = float(v["real_time_factor"]), bool(v["cameras"])
        pacer = Pacer(rtf, float(v["max_lag"]))  # ValueError names a bad value
        cam_rate, clock_rate, truth_rate = (float(v[k]) for k in ("camera_rate_hz", "clock_rate_hz", "truth_rate_hz"))
        duration, start_delay, frame = float(v["duration"]), float(v["start_delay"]), float(v["servo_frame_period"])
        try:
            self.sim = Simulator(seed=self.seed, scenario=None if self.scenario in ("", "none") else self.scenario,
                                 cameras=cameras, randomize=bool(v["randomize"]), lead_in=float(v["lead_in"]),
                                 contact_model=str(v["contact_model"]), trajectory=str(v["trajectory"]) or None,
                                 servo_frame_period=None if frame < 0 else frame,
                                 # with the boards the servos take only the driver's commands, and hold the start pose
                                 # until the first one (a trajectory drive would move them on its own until then)
                                 drive="external" if v["boards"] else None,
                                 realism=RealismConfig.named(str(v["realism"])))
        except SimulatorError as exc:   # a bad scenario, trajectory or value: named, exit 2 (hexa_ros.node.run)
            raise ValueError(str(exc)) from None
        self.start_subscribers = int(v["start_subscribers"])
        self.runner = SimRunner(self.sim, pacer, clock_rate, truth_rate, cam_rate if cameras else None, duration,
                                start_delay, ready=self.graph_ready if self.start_subscribers > 0 else None)
        self.boards = VirtualBoards(self.sim, link_dir=str(v["link_dir"])).start() if v["boards"] else None
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.cam_pubs = {}
        for name in ("cam_top", "cam_side"):
            model = self.sim.camera_model(name)
            info = CameraInfo(**model.camera_info_fields())
            info.header.frame_id = model.frame_id
            pub = {k: self.create_publisher(t, f"{name}/{k}", qos.SENSOR) for k, t in (
                ("color/image_raw", Image), ("color/camera_info", CameraInfo),
                ("aligned_depth_to_color/image_raw", Image), ("aligned_depth_to_color/camera_info", CameraInfo))}
            self.cam_pubs[name] = (pub, info, model.frame_id)
        # camera frames are rendered off the stepping loop (hexa.sim.render_thread), published from that thread
        self.render = RenderThread(self.sim, self._publish_frame) if cameras else None
        self.truth_pubs = {k: self.create_publisher(t, f"sim/{k}", qos.RELIABLE) for k, t in (
            ("wrench_truth", WrenchStamped), ("contact_truth", Contact), ("plate_pose_truth", PoseStamped),
            ("joint_states_truth", JointState))}
        self.create_subscription(Header, "trajectory_start", self._on_trajectory_start, qos.LATCHED)
        self.scenario_start_pub = self.create_publisher(Header, "sim/scenario_start", qos.LATCHED)
        if self.sim.collision is not None:
            self.scenario_start_pub.publish(Header(stamp=to_stamp(self.sim.lead_in), frame_id="base"))
        ports = f"uno {self.boards.uno.port}, mega {self.boards.mega.port}" if self.boards else "no boards"
        self.get_logger().info(f"sim ready: scenario={self.scenario!r} seed={self.seed} rtf={rtf} "
                               f"robot={self.sim.realism.name} ({ports})")

    def graph_ready(self) -> bool:
        """The graph is up: `start_subscribers` on /clock, an image subscriber per camera (with cameras), the
        driver streaming from the Mega and talking to the Uno (with boards)."""
        boards_up = self.boards is None or (self.boards.mega.streaming and self.boards.uno.rx_frames > 0)
        return (self.clock_pub.get_subscription_count() >= self.start_subscribers and boards_up
                and (self.runner.camera_period is None or all(self._wanted().values())))

    def _wanted(self) -> dict[str, bool]:
        """Per camera: does anyone subscribe to its images."""
        return {name: pub["color/image_raw"].get_subscription_count()
                + pub["aligned_depth_to_color/image_raw"].get_subscription_count() > 0
                for name, (pub, _info, _frame) in self.cam_pubs.items()}

    def _on_trajectory_start(self, msg: Header) -> None:
        t0 = to_sec(msg.stamp)
        shift = self.runner.start_scenario_at(t0)
        if shift is not None:
            self.scenario_start_pub.publish(Header(stamp=to_stamp(self.sim.lead_in + shift), frame_id="base"))
            self.get_logger().info(f"trajectory time 0 at {t0:.3f} s: the scripted collision moves {shift:+.3f} s")
        elif self.sim.collision is not None and self.sim.scenario_shift is None:
            self.get_logger().warn(f"trajectory time 0 at {t0:.3f} s comes after the scripted object's approach "
                                   f"began: the collision keeps its time")

    # ------------------------------------------------------------------ SimOutputs
    def clock(self) -> None:
        self.clock_pub.publish(Clock(clock=to_stamp(self.sim.time)))

    def cameras(self) -> None:
        """Hand this instant to the render thread: each camera with a subscriber to its images is rendered there
        (colour and depth) and published serialized; a camera nobody listens to is not rendered (its noise advances
        as if it were: the frames stay those of the seed)."""
        assert self.render is not None
        self.render.submit(self.sim.frame_state(), self._wanted())

    def _publish_frame(self, t: float, name: str, rgb: np.ndarray | None, depth: np.ndarray | None) -> None:
        """One camera's frame at sim time `t` (None images: not rendered, only its camera_info), on the render
        thread."""
        pub, info, frame = self.cam_pubs[name]
        st = to_stamp(t)
        if rgb is not None and depth is not None:
            pub["color/image_raw"].publish(image_to_cdr(st.sec, st.nanosec, frame, rgb, "rgb8"))
            pub["aligned_depth_to_color/image_raw"].publish(image_to_cdr(st.sec, st.nanosec, frame, depth, "16UC1"))
        info.header.stamp = st
        pub["color/camera_info"].publish(info)
        pub["aligned_depth_to_color/camera_info"].publish(info)

    def truth(self) -> None:
        for key, msg in sim_truth_messages(self.sim.state(), self.sim.ground_truth(), LINK_CODES).items():
            self.truth_pubs[key].publish(msg)

    def spin(self) -> None:
        import rclpy

        rclpy.spin_once(self, timeout_sec=0.0)

    def run_loop(self, ok: Callable[[], bool]) -> None:
        """Step until the run's duration or until `ok()` turns false (hexa_ros.node.run calls it instead of an
        executor; `spin` serves this node's callbacks between steps)."""
        # the render thread's numpy work holds the GIL in pieces: hand it back to the 1 ms stepping loop sooner than
        # Python's default 5 ms, which the pacing would see as stalls
        sys.setswitchinterval(0.001)
        self.runner.run(self, ok)

    def close(self) -> None:
        for line in self.runner.summary():
            self.get_logger().info(line)
        if self.render is not None:
            self.render.close()
        if self.boards is not None:
            self.boards.stop()
        self.sim.close()


def main(argv: list[str] | None = None) -> int:
    return hexa_ros.node.main(SimNode, "sim", argv)


if __name__ == "__main__":
    sys.exit(main())
