"""`hexa demo` machinery: run one collision case of the paper on the simulated robot with the whole node graph,
record a bag, and turn the bag into the arrays of hexa.report.collision_demo."""
from __future__ import annotations

import math
import os
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexa.report.collision_demo import DEMO_CASES
from hexa_bringup.graphs import DEFAULT_PARAMS, DEMO_REAL_TIME_FACTOR, build_graph, with_description
from hexa_bringup.supervisor import NodeSpec, Supervisor

#: case -> (scenario, trajectory, sim seconds to run: nominal onset + rise + release + margin); the demo's
#: cases, which free-motion runs extend in their own process
CASES: dict[str, tuple[str, str, float]] = dict(DEMO_CASES)

RECORDED = ["sim/wrench_truth", "sim/contact_truth", "sim/plate_pose_truth", "sim/joint_states_truth",
            "sim/scenario_start", "trajectory_start", "residual",
            "collision", "contact", "contact_wrench", "joint_states", "joint_commands", "motor_currents",
            "plate_pose", "plate_detections", "trajectory_state", "singularity", "/diagnostics"]
IMAGES = ["cam_top/color/image_raw", "cam_top/aligned_depth_to_color/image_raw", "cam_top/color/camera_info",
          "cam_side/color/image_raw", "cam_side/aligned_depth_to_color/image_raw", "cam_side/color/camera_info"]


@dataclass
class CaseRun:
    case: str
    bag: Path
    log_dir: Path
    returncode: int
    wall_s: float
    #: sim seconds per wall second from the simulator's first /clock after t = 0 to its last (None: no /clock seen)
    reached_rtf: float | None = None
    #: the signal (Ctrl-C: SIGINT) that stopped the graph before the case ended; None when it ran to its end
    stopped_by: int | None = None


class _ClockWatcher:
    """Reads /clock in a background thread for the progress display and the real-time factor the run reached."""

    def __init__(self, env: dict[str, str]) -> None:
        self.t = 0.0
        self._first: tuple[float, float] | None = None     # (wall s, sim s) of the first /clock after t = 0
        self._last: tuple[float, float] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(env,), daemon=True)

    def _run(self, env: dict[str, str]) -> None:
        try:
            import rclpy
            from rosgraph_msgs.msg import Clock

            from hexa_ros.node import executor_kind, make_executor

            ctx = rclpy.context.Context()
            rclpy.init(context=ctx, domain_id=int(env.get("ROS_DOMAIN_ID", "0")))
            node = rclpy.create_node(f"hexa_demo_progress_{os.getpid()}", context=ctx,
                                     start_parameter_services=False)

            def on_clock(m: Clock) -> None:
                self.t = m.clock.sec + m.clock.nanosec * 1e-9
                if self.t > 0.0:
                    self._last = (time.monotonic(), self.t)
                    if self._first is None:
                        self._first = self._last

            node.create_subscription(Clock, "/clock", on_clock, 10)
            ex = make_executor(executor_kind(), context=ctx)   # the nodes' EventsExecutor: /clock at 125-250 Hz
            ex.add_node(node)
            while not self._stop.is_set():
                ex.spin_once(timeout_sec=0.1)
            ex.shutdown()
            node.destroy_node()
            rclpy.shutdown(context=ctx)
        except Exception as exc:  # noqa: BLE001 - progress is cosmetic; say why it is missing
            print(f"hexa demo: no progress display ({exc})", file=sys.stderr)

    @property
    def reached_rtf(self) -> float | None:
        """Sim seconds per wall second between the first and the last /clock after t = 0 (None: under 1 s of wall
        time seen). The simulator's pacing drops the wall time a camera render or a stall costs (hexa.sim.pacing),
        so this is below the factor asked for when the renders do not fit in its sleeps."""
        if self._first is None or self._last is None or self._last[0] - self._first[0] < 1.0:
            return None
        return (self._last[1] - self._first[1]) / (self._last[0] - self._first[0])

    def __enter__(self) -> "_ClockWatcher":
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)


#: most wall seconds the simulator holds sim time at 0 while the graph starts (DDS discovery, serial handshakes); it
#: starts sooner once the graph is up (the sim node's `start_subscribers`)
START_DELAY = 3.0
#: sim seconds at rest before the trajectory and the scenario clock start (the estimator and observer settle, the
#: driver's commands take over from the simulator's own start pose)
LEAD_IN = 1.0


def nodes_description(realism: str, seed: int, log: Callable[[str], None] | None = None) -> Path | None:
    """The description the nodes run on the simulated robot `realism` of `seed`: None (the packaged one) on the ideal
    robot, which is that model; on the realistic robot the calibration overlay identified on it the way an operator
    calibrates a real robot (`hexa calibrate`, hexa.calibration.simulated.simulated_calibration: cached per robot,
    ≈ 25 s on a quiet machine the first time). The nodes never read the simulator's truth.

    Raises:
        hexa.calibration.identify.CalibrationError, hexa.calibration.recording.RecordingError: no calibration.
    """
    from hexa.calibration.simulated import nodes_description_of
    from hexa.sim.realism import RealismConfig

    return nodes_description_of(seed, RealismConfig.named(realism), log=log)


def run_case(case: str, out_dir: Path, env: dict[str, str], ns: str = "/hexa", seed: int = 0,
             real_time_factor: float = DEMO_REAL_TIME_FACTOR, record_images: bool = False,
             duration: float | None = None,
             params: Path = DEFAULT_PARAMS, status_every: float = 5.0, loop: bool = False,
             contact_model: str = "scripted", servo_frame_period: float | None = None,
             stream_rate_hz: int | None = None, realism: str = "ideal",
             scenario: tuple[str, str] | None = None, description: str | Path | None = None) -> CaseRun:
    """Bring up the sim graph for `case`, record a bag until the scenario is over, stop everything.

    loop: the trajectory node restarts the trajectory at its end (free-motion runs longer than its 10 s);
    contact_model: the simulator's ("scripted" | "physical", hexa.sim.Simulator); servo_frame_period: the simulated
    servo board's pulse frame (s; None = the description's); stream_rate_hz: the Mega's sample rate (None = the
    driver's configured one); realism: the simulated robot ("ideal" | "realistic", hexa.sim.realism); scenario:
    (scenario name or YAML path, trajectory) instead of the case's (`case` then only names the output folder; give
    `duration`); description: the robot description or calibration overlay of every node but the simulator (None:
    the packaged description; `nodes_description` gives the one that goes with `realism`)."""
    if scenario is None:
        scenario_name, trajectory, default_duration = CASES[case]
    else:
        (scenario_name, trajectory), default_duration = scenario, 0.0
    sim_s = LEAD_IN + (default_duration if duration is None else duration)
    case_dir = out_dir / case
    case_dir.mkdir(parents=True, exist_ok=True)
    bag = case_dir / "bag"
    if bag.exists():
        import shutil

        shutil.rmtree(bag)
    node_args = {
        "sim": ["-p", f"scenario:={scenario_name}", "-p", f"seed:={seed}",
                "-p", f"real_time_factor:={real_time_factor}",
                "-p", f"duration:={sim_s}", "-p", "use_sim_time:=false", "-p", f"link_dir:=/tmp/hexa_sim_{os.getpid()}",
                "-p", f"start_delay:={START_DELAY}", "-p", f"lead_in:={LEAD_IN}", "-p", f"trajectory:={trajectory}",
                "-p", f"contact_model:={contact_model}", "-p", f"realism:={realism}",
                "-p", f"servo_frame_period:={-1.0 if servo_frame_period is None else float(servo_frame_period)}"],
        "driver": ["-p", f"uno_port:=/tmp/hexa_sim_{os.getpid()}/uno",
                   "-p", f"mega_port:=/tmp/hexa_sim_{os.getpid()}/mega"]
                  + ([] if stream_rate_hz is None else ["-p", f"stream_rate_hz:={int(stream_rate_hz)}"]),
        "trajectory": ["-p", f"trajectory:={trajectory}", "-p", f"start_time:={LEAD_IN}",
                       "-p", f"loop:={'true' if loop else 'false'}"],
        "singularity": ["-p", "robot:=hexa"],
    }
    if description is not None:
        node_args = with_description(description, build_graph("sim", ns, params, node_args), node_args)
    specs = build_graph("sim", ns, params, node_args)
    for s in specs:
        if s.name == "sim":
            s.ends_graph = True
    topics = [t if t.startswith("/") else f"{ns}/{t}" for t in RECORDED + (IMAGES if record_images else [])]
    specs.append(NodeSpec("record", [sys.executable, "-m", "hexa_bringup.cli", "record", *topics, "-o", str(bag),
                                     "--use-sim-time"], required=True, respawn=False))
    # sim time starts once every other node (the recorder too) and the progress display below read /clock, or after
    # START_DELAY at the latest
    for s in specs:
        if s.name == "sim":
            s.cmd += ["-p", f"start_subscribers:={len(specs)}"]
    t0 = time.monotonic()
    with _ClockWatcher(env) as clock:
        sup = Supervisor(specs, env, log_dir=str(case_dir / "logs"), status_every=status_every,
                         progress=lambda: f"case {case}: sim t = {clock.t:5.2f} / {sim_s:.2f} s "
                                          f"({100 * min(1.0, clock.t / sim_s):3.0f} %)")
        rc = sup.run()
    return CaseRun(case, bag, case_dir / "logs", rc, time.monotonic() - t0, clock.reached_rtf, sup.stopped_by)


def _stamp(h) -> float:
    return h.stamp.sec + h.stamp.nanosec * 1e-9


def case_data_from_bag(case: str, bag: Path, ns: str = "/hexa"):
    """The CaseData of hexa.report.collision_demo from a recorded bag, its times on the scenario's clock.

    The simulator times its scripted collision from the trajectory's start (`sim/scenario_start`); a trajectory that
    started after LEAD_IN (collision monitoring OK late) moves the whole case by that much in sim time. The times
    here are sim time minus that move, so that a case compares with an offline run (trajectory at LEAD_IN) however
    late the live graph started; a bag without `sim/scenario_start` is taken as not moved.

    Raises:
        hexa_bringup.bag.BagError: the bag is unreadable; ValueError: it lacks the simulator's ground truth.
    """
    from hexa.report.collision_demo import CaseData
    from hexa_bringup.bag import read_bag, typestore
    from hexa_ros.conversions import hexa_pose_from_msg

    store = typestore()
    rows: dict[str, list] = {k: [] for k in ("truth", "wrench_truth", "pose_truth", "zeta_truth", "res", "ev",
                                             "contact", "wrench")}
    scenario_start = LEAD_IN
    for topic, msgtype, _t, data in read_bag(bag):
        name = topic[len(ns) + 1:] if topic.startswith(ns + "/") else topic
        if name not in ("sim/contact_truth", "sim/wrench_truth", "sim/plate_pose_truth", "sim/joint_states_truth",
                        "sim/scenario_start", "residual", "collision", "contact", "contact_wrench"):
            continue
        m = store.deserialize_cdr(data, msgtype)
        if name == "sim/scenario_start":
            scenario_start = _stamp(m)     # the newest: the bag is read in log-time order
        elif name == "sim/contact_truth":
            rows["truth"].append((_stamp(m.header), m.link, m.chain, m.point.x, m.point.y, m.point.z))
        elif name == "sim/wrench_truth":
            f = m.wrench.force
            rows["wrench_truth"].append((_stamp(m.header), f.x, f.y, f.z))
        elif name == "sim/plate_pose_truth":
            rows["pose_truth"].append((_stamp(m.header), *hexa_pose_from_msg(m.pose)))
        elif name == "sim/joint_states_truth":
            effort = [float(v) for v in m.effort[:6]] if len(m.effort) >= 6 else [math.nan] * 6
            rows["zeta_truth"].append((_stamp(m.header), *[float(v) for v in m.position[:6]], *effort))
        elif name == "residual":
            w = m.wrench
            rows["res"].append((_stamp(m.header), w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y,
                                w.torque.z, *[float(v) for v in m.threshold], *[float(v) for v in m.servo_torque],
                                *[float(v) for v in m.servo_threshold]))
        elif name == "collision":
            rows["ev"].append((_stamp(m.header), "START" if m.event == 0 else "END", int(m.id), str(m.axis_name)))
        elif name == "contact":
            rows["contact"].append((_stamp(m.header), m.link, m.chain, m.point.x, m.point.y, m.point.z))
        elif name == "contact_wrench":
            rows["wrench"].append((_stamp(m.header), m.force.x, m.force.y, m.force.z))
    if not rows["truth"] or not rows["wrench_truth"]:
        raise ValueError(f"bag {bag} has no simulator ground truth (sim/contact_truth, sim/wrench_truth)")
    moved = scenario_start - LEAD_IN
    if moved:
        rows = {k: [(r[0] - moved, *r[1:]) for r in v] for k, v in rows.items()}
    truth = np.array(sorted(rows["truth"]), dtype=float)
    wt = np.array(sorted(rows["wrench_truth"]), dtype=float)
    force = np.stack([np.interp(truth[:, 0], wt[:, 0], wt[:, k]) for k in (1, 2, 3)], axis=1)
    pose = None
    if rows["pose_truth"]:
        pt = np.array(sorted(rows["pose_truth"]), dtype=float)
        pose = np.stack([np.interp(truth[:, 0], pt[:, 0], np.unwrap(pt[:, k]) if k > 3 else pt[:, k])
                         for k in range(1, 7)], axis=1)
    zeta, tau = None, None
    if len(rows["zeta_truth"]) > 1:
        zt = np.array(sorted(rows["zeta_truth"]), dtype=float)
        zeta = np.stack([np.interp(truth[:, 0], zt[:, 0], zt[:, k]) for k in range(1, 7)], axis=1)
        if np.isfinite(zt[:, 7:13]).all():   # the servos' true torques (effort), as ζ
            tau = np.stack([np.interp(truth[:, 0], zt[:, 0], zt[:, k]) for k in range(7, 13)], axis=1)
    res = np.array(sorted(rows["res"]), dtype=float) if rows["res"] else np.zeros((0, 25))
    con = np.array(sorted(rows["contact"]), dtype=float) if rows["contact"] else np.zeros((0, 6))
    wr = np.array(sorted(rows["wrench"]), dtype=float) if rows["wrench"] else np.zeros((0, 4))
    return CaseData(
        case=case, truth_t=truth[:, 0], truth_force=force, truth_point=truth[:, 3:6],
        truth_link=truth[:, 1].astype(int), truth_chain=truth[:, 2].astype(int), truth_pose=pose,
        residual_t=res[:, 0], residual=res[:, 1:7], threshold=res[0, 7:13] if len(res) else np.full(6, 2.0),
        truth_zeta=zeta, truth_tau=tau, residual_servo=res[:, 13:19],
        servo_threshold=res[0, 19:25] if len(res) else np.zeros(6),
        events=sorted(rows["ev"]), contact_t=con[:, 0], contact_link=con[:, 1].astype(int),
        contact_chain=con[:, 2].astype(int), contact_point=con[:, 3:6], wrench_t=wr[:, 0], wrench_force=wr[:, 1:4])
