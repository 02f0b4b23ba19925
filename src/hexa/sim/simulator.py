"""The simulated Hexa: MuJoCo physics of the closed-loop model, hobby servos, scripted collisions, RGB-D cameras.

    sim = Simulator(scenario="plate", seed=3)          # builds at the circle's start pose, follows it by IK
    while sim.time < 5.0:
        sim.step(10)
        s = sim.state()                                # ζ, ζ̇, ζ̈, plate pose/twist, servo torques τ (one instant)
        truth = sim.ground_truth()                     # contact wrench/point/link/chain at that same instant
    rgb, depth_mm = sim.render("cam_top")

Exactness (for validating the dynamic model): every `step` runs mj_step1 (positions, velocities at t), sets the
servo commands and the external wrench for time t, then mj_step2 (accelerations at t, integration to t + dt).
`state()` and `ground_truth()` return that consistent sample at time t = `time - timestep`, with q, q̇ copied before
the integration and q̈ (`qacc`), τ (`actuator_force`) computed in the same call. External forces enter as
`xfrc_applied = [f, (p − com) × f]` on the touched body, i.e. exactly mj_applyFT at the point p.
"""
from __future__ import annotations

import dataclasses
import math
import threading
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.sim.camera import NoiseBank, RGBDRenderer, RenderError, camera_model_of, depth_image_mm, noisy_rgb
from hexa.sim.config import CAMERA_NAMES, SimConfig, sim_config_of
from hexa.sim.mjcf import HOME_POSE, PARK_POS, build_mjcf
from hexa.sim.realism import RealismConfig, RobotTruth, ServoMechanics, draw_truth, nominal_truth
from hexa.robots.plate import hexagon_border_point, plate_outline
from hexa.vision.camera import CameraModel
from hexa.sim.scenarios import ScenarioSpec, ScriptedCollision, draw_collision, load_scenario, push_direction

import mujoco  # noqa: E402  (after hexa.sim.camera set MUJOCO_GL)

if TYPE_CHECKING:
    from pathlib import Path

    from hexa.robots.hexa_description import HexaDescription

LINK_CODES = {"plate": 0, "arm": 1, "rod": 2, "none": 255}   # as hexa_msgs/Contact (UNKNOWN = 255: no contact)


class SimulatorError(RuntimeError):
    """Bad use of the simulator (unknown link/chain/camera, non-finite command); the message names the value."""


@dataclass(frozen=True)
class SimState:
    """One instant of the simulated robot (SI units, base frame).

    zeta, zeta_dot, zeta_ddot: arm angles ζ_i (rad) and their rates (6,); pose: plate [x y z α β γ] (Z-Y-X, eq 38);
    twist: plate [v (m/s) of P, ω (rad/s)] in base; accel: [a of P, ω̇] in base; tau: servo torques at the horns
    (N·m, what the current sensors measure as K_t·I); u: universal-joint angles (6,2) (rad); time (s).
    """

    time: float
    zeta: np.ndarray
    zeta_dot: np.ndarray
    zeta_ddot: np.ndarray
    pose: np.ndarray
    twist: np.ndarray
    accel: np.ndarray
    tau: np.ndarray
    targets: np.ndarray
    u: np.ndarray


@dataclass(frozen=True)
class GroundTruth:
    """The "force sensor": the external wrench at its point of application, at the same instant as `state()`.

    link: "plate", "arm", "rod" or "none"; chain: 1..6 (0 for the plate or none); point: base (m); force (N);
    torque: moment about `point` (N·m, zero for a point contact); plate_pose as SimState.pose.
    """

    time: float
    link: str
    chain: int
    point: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    plate_pose: np.ndarray

    @property
    def in_contact(self) -> bool:
        return self.link != "none" and float(np.linalg.norm(self.force)) > 0.0


@dataclass(frozen=True)
class FrameState:
    """What the cameras see at one instant, kept to render later (`Simulator.render_frame`): sim time (s), the joint
    positions and every mocap body's placement (the pushing object placed as `render` places it)."""

    time: float
    qpos: np.ndarray
    mocap_pos: np.ndarray
    mocap_quat: np.ndarray


@dataclass
class _Contact:
    link: str
    chain: int
    body: int
    local_point: np.ndarray      # in the body frame
    force: np.ndarray            # base frame


@dataclass
class _Log:
    time: list = field(default_factory=list)
    force: list = field(default_factory=list)
    point: list = field(default_factory=list)
    link: list = field(default_factory=list)
    chain: list = field(default_factory=list)
    pose: list = field(default_factory=list)
    zeta: list = field(default_factory=list)
    tau: list = field(default_factory=list)


def zyx_from_matrix(R: np.ndarray) -> np.ndarray:
    """Z-Y-X angles (α, β, γ) of a rotation matrix, R = Rz(α)·Ry(β)·Rx(γ) (seed 000 eq 38)."""
    beta = -np.arcsin(np.clip(R[2, 0], -1.0, 1.0))
    return np.array([np.arctan2(R[1, 0], R[0, 0]), beta, np.arctan2(R[2, 1], R[2, 2])])


_ZERO3 = np.zeros(3)


def _poses_from_qpos(pq: np.ndarray) -> np.ndarray:
    """Plate poses [x y z α β γ] (N,6) from free-joint qpos rows [x y z qw qx qy qz] (N,7)."""
    w, x, y, z = pq[:, 3], pq[:, 4], pq[:, 5], pq[:, 6]
    r00 = 1 - 2 * (y * y + z * z)
    r10 = 2 * (x * y + w * z)
    r20 = 2 * (x * z - w * y)
    r21 = 2 * (y * z + w * x)
    r22 = 1 - 2 * (x * x + y * y)
    return np.column_stack([pq[:, :3], np.arctan2(r10, r00), -np.arcsin(np.clip(r20, -1, 1)), np.arctan2(r21, r22)])


def _desc_default(desc: HexaDescription | None) -> HexaDescription:
    if desc is not None:
        return desc
    from hexa.robots.hexa_description import load_hexa

    return load_hexa()


@dataclass(frozen=True)
class LatchFrame:
    """One pulse frame of the simulated servo board: start (sim time, s), each servo's pulse start (s after it) and
    the tag of the targets each pulse carried (-1: none given)."""

    start: float
    pulse_offsets: np.ndarray
    tags: np.ndarray


class Simulator:
    """The Hexa in MuJoCo (see module docstring).

    Args:
        desc: HexaDescription (default: load_hexa()).
        seed: seeds the scenario draw (when `randomize`), sensor offsets and image/current noise.
        scenario: None, a bundled name ("plate", "arm", "rod"), a YAML path, a ScenarioSpec or a ScriptedCollision.
        cameras: create the offscreen renderer (needs EGL); False for physics-only runs.
        pose: assembly/start pose when there is no scenario (default HOME_POSE).
        drive: "trajectory" (servo targets = IK of the scenario's trajectory at sim time t; default with a
            scenario or a trajectory) or "external" (targets only from `set_servo_targets`, e.g. the virtual Uno;
            default without).
        randomize: draw the scenario's collision from its ranges with `seed` (False: nominal values).
        settle: seconds simulated before t = 0 holding the start targets, so the robot starts at rest under gravity.
        trajectory: without a scenario, follow this trajectory ("circle", "helix", "ellipse", "random:SEED") in free
            motion for its duration (hexa.trajectories.trajectory_named), then hold its last pose.
        lead_in: seconds of sim time at rest at the start pose before the trajectory (and the scenario's clock)
            starts, e.g. to let a ROS graph come up and calibrate; collision times are shifted by it.
        contact_model: "scripted" (the scenario's force is applied exactly at the point, mj_applyFT; the object is
            visual) or "physical" (a capsule on a force-driven slide pushes the link through MuJoCo contacts; the
            ground truth is then MuJoCo's contact force and contact point, the force profile only approximately
            the scenario's).
        servo_frame_period: overrides the description's `sim.servo.frame_period` (s; 0 = set-points at once) and the
            realism's.
        realism: hexa.sim.realism.RealismConfig (default: ideal — the robot is the description). With `truth` the
            robot is built from `draw_truth(desc, robot_seed)` (`self.truth`); with `servo_mechanics` the servos run the
            dead band and gear play of hexa.sim.realism.ServoMechanics; its frame period and ADC noise replace the
            description's.
        robot_seed: the seed of the drawn robot (default `seed`): runs with different seeds (noise, phases) on one
            robot, as a campaign that calibrates a few robots and runs many contacts on each does.
    """

    def __init__(self, desc: HexaDescription | None = None, seed: int = 0,
                 scenario: str | Path | ScenarioSpec | ScriptedCollision | None = None, cameras: bool = True,
                 pose: np.ndarray | None = None, drive: str | None = None, randomize: bool = False,
                 settle: float = 0.5, trajectory: str | None = None, lead_in: float = 0.0,
                 contact_model: str = "scripted", servo_frame_period: float | None = None,
                 realism: RealismConfig | None = None, robot_seed: int | None = None) -> None:
        self.desc = _desc_default(desc)
        self.config: SimConfig = sim_config_of(self.desc)
        self.realism = realism or RealismConfig.ideal()
        if servo_frame_period is None:
            servo_frame_period = self.realism.frame_period
        if self.realism.current_noise_counts is not None:
            self.config = dataclasses.replace(self.config, current_noise_counts=self.realism.current_noise_counts)
        if servo_frame_period is not None:
            if not (0.0 <= float(servo_frame_period) <= 0.1):
                raise SimulatorError(f"servo_frame_period must be 0..0.1 s, got {servo_frame_period!r}")
            self.config = dataclasses.replace(
                self.config, servo=dataclasses.replace(self.config.servo, frame_period=float(servo_frame_period)))
        self.seed = int(seed)
        self._rng = np.random.default_rng(self.seed)
        # the robot the world is built from (never read by a node); None: the description itself
        self.robot_seed = self.seed if robot_seed is None else int(robot_seed)
        self.truth: RobotTruth | None = (draw_truth(self.desc, self.robot_seed, self.realism.tolerances)
                                         if self.realism.truth else None)
        self._mech: ServoMechanics | None = None
        if self.realism.servo_mechanics:
            self._mech = ServoMechanics(self.truth or nominal_truth(self.desc), self.config.servo.kp,
                                        self.config.servo.kv, float(self.desc.torque_max))
        self.collision: ScriptedCollision | None = None
        if scenario is not None:
            if isinstance(scenario, ScriptedCollision):
                self.collision = scenario
            else:
                spec = scenario if isinstance(scenario, ScenarioSpec) else load_scenario(scenario)
                self.collision = draw_collision(spec, np.random.default_rng([self.seed, 1]) if randomize else None)
        if lead_in < 0:
            raise SimulatorError(f"lead_in must be >= 0 s, got {lead_in}")
        self.lead_in = float(lead_in)
        #: the move of the scripted collision's times by `start_scenario_at` (s); None: none made
        self.scenario_shift: float | None = None
        if self.collision is not None and self.lead_in > 0:
            self.collision = dataclasses.replace(self.collision, onset=self.collision.onset + self.lead_in)
        self.trajectory = self.collision.trajectory if self.collision is not None else trajectory
        self.drive = drive or ("trajectory" if self.trajectory is not None else "external")
        if self.drive not in ("trajectory", "external"):
            raise SimulatorError(f"drive must be 'trajectory' or 'external', got {self.drive!r}")
        if self.drive == "trajectory" and self.trajectory is None:
            raise SimulatorError("drive='trajectory' needs a scenario or a trajectory name")

        self._traj_targets: np.ndarray | None = None
        if self.trajectory is not None:
            from hexa import trajectories
            from hexa.kinematics import hexa6rus as kin

            if self.trajectory == "file":
                raise SimulatorError("the simulator follows a named trajectory, not 'file'")
            try:
                fn, run_length = trajectories.trajectory_named(self.trajectory)
            except ValueError as exc:
                raise SimulatorError(f"unknown trajectory {self.trajectory!r}: {exc}") from None
            start_pose = np.asarray(fn(0.0)[0], dtype=float)
            if self.drive == "trajectory":
                dt = self.config.timestep
                duration = float(run_length) + self.lead_in
                if self.collision is not None:
                    duration = max(duration, self.collision.end_time + 3.0)
                t = np.arange(int(np.ceil(duration / dt)) + 1) * dt
                poses = np.asarray(fn(np.maximum(t - self.lead_in, 0.0))[0], dtype=float)
                self._traj_targets = kin.inverse_kinematics_batch(self.desc, poses)
        else:
            start_pose = HOME_POSE if pose is None else np.asarray(pose, dtype=float)
        self.start_pose = start_pose

        if contact_model not in ("scripted", "physical"):
            raise SimulatorError(f"contact_model must be 'scripted' or 'physical', got {contact_model!r}")
        self.contact_model = contact_model
        physical = contact_model == "physical"
        self.xml = build_mjcf(self.desc, start_pose, self.config, physical_contact=physical, truth=self.truth,
                              motor_servos=self._mech is not None)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._arm_qpos = np.array([m.jnt_qposadr[m.joint(f"arm_{i}").id] for i in range(1, 7)])
        self._arm_dof = np.array([m.jnt_dofadr[m.joint(f"arm_{i}").id] for i in range(1, 7)])
        self._u_qpos = np.array([[m.jnt_qposadr[m.joint(f"u{k}_{i}").id] for k in (1, 2)] for i in range(1, 7)])
        pj = m.joint("plate").id
        self._plate_qpos = int(m.jnt_qposadr[pj])
        self._plate_dof = int(m.jnt_dofadr[pj])
        self._plate_body = m.body("plate").id
        self._arm_body = [m.body(f"arm_{i}").id for i in range(1, 7)]
        self._rod_body = [m.body(f"rod_{i}").id for i in range(1, 7)]
        self._object_mocap = int(m.body_mocapid[m.body("object").id])
        self._pusher: dict[str, Any] | None = None
        if physical:
            links = {m.geom("plate").id: ("plate", 0)}
            for i in range(1, 7):
                links[m.geom(f"arm_{i}").id] = ("arm", i)
                links[m.geom(f"rod_{i}").id] = ("rod", i)
            jp = m.joint("pusher_slide").id
            self._pusher = {"mocap": int(m.body_mocapid[m.body("pusher_carrier").id]), "geom": m.geom("pusher").id,
                            "qpos": int(m.jnt_qposadr[jp]), "dof": int(m.jnt_dofadr[jp]),
                            "act": m.actuator("pusher").id, "links": links}
        self._cam_ids = {name: m.camera(name).id for name in CAMERA_NAMES}
        self._omega_max = float(self.desc.speed_max)
        self._dt = float(m.opt.timestep)
        self._lock = threading.RLock()

        zeta0 = self.data.qpos[self._arm_qpos].copy()
        self._targets = zeta0.copy()          # commanded (before the slew limit)
        # the servo board's pulse frame (external drive, firmware uno_servo; sim.servo.frame_period, 0 = off): servo
        # i takes a new set-point only at the end of its pulse, once per frame, the six pulses one after the other
        # from the frame's start, so a command reaches it 0-20 ms after the board got it; the phase is drawn from the
        # seed
        self._frame_period = float(self.config.servo.frame_period)
        self._pulse_slot = float(self.config.servo.pulse_slot)
        self._setpoints = zeta0.copy()        # what each servo last received (with frames)
        self._frame_phase = float(np.random.default_rng([self.seed, 3]).uniform(0.0, 1.0)) * self._frame_period
        self._latch_at: np.ndarray | None = None   # sim time of each servo's next pulse end; None: frames not running
        self._target_tag = -1                 # tag of the newest targets (the servo board's SET_TARGETS seq)
        self._setpoint_tags = np.full(6, -1)  # tag of the targets each servo last latched
        self._target_hist: deque[tuple[float, np.ndarray, int]] = deque(maxlen=64)   # (sim time set, targets, tag)
        self._latch_frames: deque[LatchFrame] = deque(maxlen=500)   # frames completed, for the virtual Uno's report
        self._cmd = zeta0.copy()              # the servos' set-points after the slew limit
        self.data.ctrl[:6] = zeta0 if self._mech is None else 0.0
        self._manual: _Contact | None = None
        self._scripted: _Contact | None = None
        self._scripted_dir: np.ndarray | None = None
        self._log = _Log()
        self._log_enabled = True
        self._step_count = 0
        self._tau_hist_t = np.full(4096, -np.inf)
        self._tau_hist = np.zeros((4096, 6))
        #: the last consistent sample: t, qpos, qvel, qacc, tau, targets, contact (set by every step)
        self._sample: tuple[Any, ...] = ()

        # settle under gravity at the start targets, then restart the clock at t = 0
        mujoco.mj_forward(m, self.data)
        n_settle = int(round(settle / self._dt))
        log_was = self._log_enabled
        self._log_enabled = False
        for _ in range(n_settle):
            self._step_once(use_schedule=False)
        self._log_enabled = log_was
        self.data.time = 0.0
        self._step_count = 0
        self._latch_at = None                 # the pulse frames start with the clock
        self._tau_hist_t[:] = -np.inf
        self._step_once(use_schedule=True, advance=False)

        self._renderer: RGBDRenderer | None = None
        self._scratch: mujoco.MjData | None = None   # for frame_state / render_frame (made on first use)
        self._noise: dict[str, NoiseBank] = {}
        self.rgb_noise_sigma = self.config.rgb_noise_sigma      # image noise (hexa.sim.randomize changes them)
        self.depth_noise_rel = self.config.depth_noise_rel
        if cameras:
            self._renderer = self.new_renderer()
            for k, name in enumerate(CAMERA_NAMES):
                c = self.config.cameras[name]
                self._noise[name] = NoiseBank(c.width * c.height * 3, seed=self.seed * 7919 + 17 * (k + 1))

    # ------------------------------------------------------------------ time and stepping
    @property
    def time(self) -> float:
        """Simulation time (s); 0 at the start of the trajectory."""
        return float(self.data.time)

    @property
    def timestep(self) -> float:
        return self._dt

    def set_servo_targets(self, zeta: np.ndarray, tag: int = -1) -> None:
        """Command the six servo angles ζ (rad); the servos move there at most at their speed limit.

        Switches `drive` to "external" (a trajectory drive stops following its table). `tag` names the targets
        (the virtual Uno passes its SET_TARGETS seq); with a pulse frame, `pop_latch_frames` says which tag each
        servo's pulse carried.

        Raises:
            SimulatorError: not six finite values.
        """
        z = np.asarray(zeta, dtype=float).reshape(-1)
        if z.shape != (6,) or not np.all(np.isfinite(z)):
            raise SimulatorError(f"servo targets must be six finite angles (rad), got {zeta!r}")
        with self._lock:
            self._targets = z.copy()
            self._target_tag = int(tag)
            self._target_hist.append((float(self.data.time), self._targets, self._target_tag))
            self.drive = "external"

    def pop_latch_frames(self) -> list[LatchFrame]:
        """The pulse frames completed since the last call (with `sim.servo.frame_period` > 0 and the external drive):
        each frame's start (sim time), the start of each servo's pulse in it (s after the frame's start; a servo
        takes the set-point at its pulse's end, `pulse_slot` later) and the tag of the targets each pulse carried."""
        with self._lock:
            out = list(self._latch_frames)
            self._latch_frames.clear()
        return out

    def servo_setpoints(self) -> np.ndarray:
        """The set-point each servo acts on now (rad): with a pulse frame, the target its last pulse carried (what
        the driver reconstructs from the latch report), else the newest target."""
        with self._lock:
            framed = self._frame_period > 0 and self.drive == "external" and self._latch_at is not None
            return (self._setpoints if framed else self._targets).copy()

    def motor_currents(self, tau: np.ndarray) -> np.ndarray:
        """The currents (A) the Mega's sensors read for servo torques `tau` (N·m): the truth's K_t, sensor gain and
        zero offset when there is a truth, else τ / K_t of the description (the virtual Mega adds its own offset)."""
        if self.truth is not None:
            return self.truth.currents(tau)
        return np.asarray(tau, dtype=float) / float(self.desc.K_t)

    def step(self, n: int = 1) -> None:
        """Advance the physics by `n` timesteps."""
        with self._lock:
            for _ in range(int(n)):
                self._step_once(use_schedule=True)

    def start_scenario_at(self, t0: float) -> float | None:
        """Time the scripted collision from trajectory time 0 at sim time `t0` (s) instead of from `lead_in`.

        A graph whose trajectory starts late (its collision monitoring came up late) would otherwise meet the push at
        another point of the trajectory: the onset moves by t0 − lead_in, so the push meets the trajectory where the
        scenario puts it. Once only. Returns the shift (s), or None when nothing moves: no scripted collision, the
        simulator drives the trajectory itself (from `lead_in`), a shift was made already, or the object's approach
        has begun at the old or the new time (it cannot move without a jump).

        Raises:
            SimulatorError: `t0` is not finite.
        """
        if not math.isfinite(t0):
            raise SimulatorError(f"trajectory start must be a finite sim time (s), got {t0!r}")
        with self._lock:
            c = self.collision
            if c is None or self.drive == "trajectory" or self.scenario_shift is not None:
                return None
            shift = float(t0) - self.lead_in
            if self.time >= min(c.onset, c.onset + shift) - c.approach_time:
                return None
            self.collision = dataclasses.replace(c, onset=c.onset + shift)
            self.scenario_shift = shift
            return shift

    def run_until(self, t_end: float) -> None:
        """Step until `time >= t_end`."""
        n = int(np.ceil((t_end - self.time) / self._dt - 1e-9))
        if n > 0:
            self.step(n)

    def _servo_setpoints(self, t: float) -> np.ndarray:
        """The set-points the servos act on at sim time t: driven through the servo board with a pulse frame
        (`sim.servo.frame_period` > 0), the targets as each servo's last pulse carried them; else the targets."""
        if self._frame_period <= 0 or self.drive != "external":
            self._latch_at = None
            return self._targets
        if self._latch_at is None:         # the board's frames run since before t, at the seed's phase; until its
            self._setpoints = self._cmd.copy()   # pulse a servo keeps the set-point it has
            self._latch_at = t - self._frame_phase + self._pulse_slot * np.arange(1, 7)
        due = self._latch_at <= t
        if due.any():
            frames = np.floor((t - self._latch_at[due]) / self._frame_period) + 1.0
            for i, n in zip(np.flatnonzero(due), frames):
                end = float(self._latch_at[i] + (n - 1.0) * self._frame_period)   # the pulse's end (latch)
                start = end - (i + 1) * self._pulse_slot                           # the frame's start
                # the board read this channel's width at the start of the previous channel's slot (channel 1: just
                # before the frame), as the firmware's compare ISR does
                read = start + (i - 1) * self._pulse_slot if i > 0 else start - 50e-6
                found = self._target_at(read)
                if found is not None:        # else no target yet then: the servo keeps its set-point
                    self._setpoints[i] = found[0][i]
                    self._setpoint_tags[i] = found[1]
                if i == 5:   # the frame's last pulse: the frame is complete
                    self._latch_frames.append(LatchFrame(start, self._pulse_slot * np.arange(6),
                                                         self._setpoint_tags.copy()))
            self._latch_at[due] += frames * self._frame_period
        return self._setpoints

    def _target_at(self, t: float) -> tuple[np.ndarray, int] | None:
        """The newest targets (and tag) set at or before sim time t; None when none was (or it is no longer kept:
        then the oldest kept)."""
        for t_set, target, tag in reversed(self._target_hist):
            if t_set <= t:
                return target, tag
        if len(self._target_hist) == self._target_hist.maxlen:
            return self._target_hist[0][1], self._target_hist[0][2]
        return None

    def _step_once(self, use_schedule: bool, advance: bool = True) -> None:
        m, d = self.model, self.data
        mujoco.mj_step1(m, d)
        t = float(d.time)
        if use_schedule and self.drive == "trajectory" and self._traj_targets is not None:
            k = min(self._step_count, len(self._traj_targets) - 1)
            self._targets = self._traj_targets[k]
        step = self._omega_max * self._dt
        self._cmd = self._cmd + np.minimum(np.maximum(self._servo_setpoints(t) - self._cmd, -step), step)
        tau_motor = None
        aim = self._cmd if self.truth is None else self._cmd + self.truth.horn_offset   # the horn on its spline
        if self._mech is None:
            d.ctrl[:6] = aim
        else:   # the servo law outside MuJoCo: dead band, stall clamp, gear play (ζ̈ of the previous step)
            tau_motor = self._mech.motor_torque(aim, d.qpos[self._arm_qpos], d.qvel[self._arm_dof])
            d.ctrl[:6] = self._mech.step(tau_motor, d.qacc[self._arm_dof], self._dt)
        if use_schedule and self.collision is not None:
            self._update_scripted(t)
            if self._pusher is not None:
                self._drive_pusher(t)
        d.xfrc_applied[:] = 0.0
        contact = None
        for c in ((self._manual,) if self._pusher is not None else (self._scripted, self._manual)):
            if c is not None:
                R = d.xmat[c.body].reshape(3, 3)
                p = d.xpos[c.body] + R @ c.local_point
                d.xfrc_applied[c.body, :3] += c.force
                d.xfrc_applied[c.body, 3:] += np.cross(p - d.xipos[c.body], c.force)
                if contact is None and (c.force[0] != 0.0 or c.force[1] != 0.0 or c.force[2] != 0.0):
                    contact = (c.link, c.chain, p, c.force.copy())
        qpos = d.qpos.copy()
        qvel = d.qvel.copy()
        if advance:
            mujoco.mj_step2(m, d)
        else:
            mujoco.mj_forward(m, d)
        tau = d.actuator_force[:6].copy() if tau_motor is None else tau_motor   # what the current sensors see
        if self._pusher is not None and contact is None:
            contact = self._physical_contact()
        self._sample = (t, qpos, qvel, d.qacc.copy(), tau, self._cmd.copy(), contact)
        k = self._step_count % len(self._tau_hist_t)
        self._tau_hist_t[k] = t
        self._tau_hist[k] = tau
        if self._log_enabled:
            lg = self._log
            lg.time.append(t)
            if contact is None:
                lg.force.append(_ZERO3)
                lg.point.append(_ZERO3)
                lg.link.append(255)
                lg.chain.append(0)
            else:
                lg.force.append(contact[3])
                lg.point.append(contact[2])
                lg.link.append(LINK_CODES[contact[0]])
                lg.chain.append(contact[1])
            lg.pose.append(qpos[self._plate_qpos:self._plate_qpos + 7])
            lg.zeta.append(qpos[self._arm_qpos])
            lg.tau.append(tau)
        if advance:
            self._step_count += 1

    # ------------------------------------------------------------------ external forces
    def _body_of(self, link: str, chain: int) -> int:
        if link == "plate":
            return self._plate_body
        if link not in ("arm", "rod"):
            raise SimulatorError(f"link must be 'plate', 'arm' or 'rod', got {link!r}")
        if not 1 <= int(chain) <= 6:
            raise SimulatorError(f"chain must be 1..6 for link {link!r}, got {chain!r}")
        return (self._arm_body if link == "arm" else self._rod_body)[int(chain) - 1]

    def apply_external_force(self, link: str, chain: int, point_base: np.ndarray, force_base: np.ndarray) -> None:
        """Apply `force_base` (N, base frame) at `point_base` (m, base) on a link, from the next step on.

        The point is attached to the link (it moves with it); the force keeps its direction in base. It acts until
        `clear_external_force()` or the next call. Equivalent to mj_applyFT at the point.

        Raises:
            SimulatorError: unknown link or chain, non-finite vectors.
        """
        body = self._body_of(link, chain)
        p = np.asarray(point_base, dtype=float).reshape(3)
        f = np.asarray(force_base, dtype=float).reshape(3)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(f))):
            raise SimulatorError(f"point {point_base!r} and force {force_base!r} must be finite")
        with self._lock:
            mujoco.mj_kinematics(self.model, self.data)
            R = self.data.xmat[body].reshape(3, 3)
            local = R.T @ (p - self.data.xpos[body])
            self._manual = _Contact(link, 0 if link == "plate" else int(chain), body, local, f.copy())

    def clear_external_force(self) -> None:
        """Remove the force set by `apply_external_force`."""
        with self._lock:
            self._manual = None

    def _update_scripted(self, t: float) -> None:
        c = self.collision
        assert c is not None
        if t < c.onset - c.approach_time or t >= c.end_time + c.approach_time:
            self._scripted = None if t >= c.end_time else self._scripted
            return
        if self._scripted_dir is None:
            self._init_scripted_contact()
        assert self._scripted is not None and self._scripted_dir is not None
        self._scripted.force = self._scripted_dir * c.force_magnitude(t)

    def _drive_pusher(self, t: float) -> None:
        """Physical contact: place the carrier behind the contact point and command the slide force for time t."""
        from hexa.sim.mjcf import PUSHER_MASS

        c, pu, d = self.collision, self._pusher, self.data
        assert c is not None and pu is not None
        s, sd = float(d.qpos[pu["qpos"]]), float(d.qvel[pu["dof"]])
        dist = c.object_distance(t)
        if dist is None or self._scripted is None or self._scripted_dir is None:
            d.mocap_pos[pu["mocap"]] = PARK_POS
            d.qpos[pu["qpos"]] = 0.0
            d.qvel[pu["dof"]] = 0.0
            d.ctrl[pu["act"]] = 0.0
            return
        sc, direction = self._scripted, self._scripted_dir
        R = d.xmat[sc.body].reshape(3, 3)
        p = d.xpos[sc.body] + R @ sc.local_point
        gap = 0.0                                     # the tip rests on the surface at s = 0
        d.mocap_pos[pu["mocap"]] = p - direction * (gap + dist)
        z = direction
        x = np.cross(z, [0.0, 0.0, 1.0]) if abs(z[2]) < 0.95 else np.cross(z, [1.0, 0.0, 0.0])
        x /= np.linalg.norm(x)
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, np.column_stack([x, np.cross(z, x), z]).ravel())
        d.mocap_quat[pu["mocap"]] = q
        kp = 400.0
        kd = 2.0 * np.sqrt(kp * PUSHER_MASS)
        if c.onset <= t < c.end_time:
            d.ctrl[pu["act"]] = c.force_magnitude(t) - kd * sd          # push with the scripted force (damped)
        else:
            d.ctrl[pu["act"]] = -kp * s - kd * sd                     # hold retracted

    def _physical_contact(self) -> tuple | None:
        """MuJoCo's contact force of the pusher on a robot link (sum), at the force-weighted contact position."""
        m, d, pu = self.model, self.data, self._pusher
        assert pu is not None
        f6 = np.zeros(6)
        total, moment_pts, hit = np.zeros(3), [], None
        for i in range(d.ncon):
            con = d.contact[i]
            g1, g2 = int(con.geom1), int(con.geom2)
            if pu["geom"] not in (g1, g2):
                continue
            other = g2 if g1 == pu["geom"] else g1
            if other not in pu["links"]:
                continue
            mujoco.mj_contactForce(m, d, i, f6)
            frame = con.frame.reshape(3, 3)
            f = frame.T @ f6[:3]                       # force on geom2 (the normal points from geom1 to geom2)
            if other == g1:
                f = -f
            total += f
            moment_pts.append((con.pos.copy(), f, max(f6[0], 0.0)))
            hit = pu["links"][other]
        if hit is None or not np.any(total):
            return None
        w = np.array([x[2] for x in moment_pts])
        pts = np.array([x[0] for x in moment_pts])
        point = (w[:, None] * pts).sum(0) / w.sum() if w.sum() > 0 else pts.mean(0)
        return (hit[0], hit[1], point, total)

    def _init_scripted_contact(self) -> None:
        """Fix the contact point on the link and the force direction (base) when the object starts its approach."""
        c = self.collision
        assert c is not None
        d = self.data
        body = self._body_of(c.link, c.chain)
        if self._pusher is not None:
            # the pusher only touches the scripted link (its path in may cross others, which it would hit first)
            target = self.model.geom("plate" if c.link == "plate" else f"{c.link}_{c.chain}").id
            for g in self._pusher["links"]:
                self.model.geom_conaffinity[g] = 2 if g == target else 0
        R = d.xmat[body].reshape(3, 3)
        o = d.xpos[body]
        ap = self.config.appearance
        if c.link == "plate":
            border = hexagon_border_point(plate_outline(self.desc), [np.cos(c.position), np.sin(c.position)])
            local_axis = np.array([border[0], border[1], 0.0])
            radius = 0.0
            axis = None
        else:
            length = float(self.desc.l_a if c.link == "arm" else self.desc.l_d)
            local_axis = np.array([c.position * length, 0.0, 0.0])
            radius = ap["arm_radius" if c.link == "arm" else "rod_radius"]
            axis = R[:, 0]
        direction = push_direction(c, o + R @ local_axis, axis)
        surface_local = local_axis - radius * (R.T @ direction)
        self._scripted_dir = direction
        self._scripted = _Contact(c.link, c.chain, body, surface_local, np.zeros(3))

    # ------------------------------------------------------------------ reading
    def _plate_pose_of(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a = self._plate_qpos
        r9 = np.zeros(9)
        mujoco.mju_quat2Mat(r9, qpos[a + 3:a + 7])
        R = r9.reshape(3, 3)
        return np.concatenate([qpos[a:a + 3], zyx_from_matrix(R)]), R

    def _truth_of(self, sample: tuple) -> GroundTruth:
        t, qpos, contact = sample[0], sample[1], sample[6]
        pose, _ = self._plate_pose_of(qpos)
        if contact is None:
            return GroundTruth(t, "none", 0, np.zeros(3), np.zeros(3), np.zeros(3), pose)
        link, chain, p, f = contact
        return GroundTruth(t, link, chain, p.copy(), f.copy(), np.zeros(3), pose)

    def state(self) -> SimState:
        """The last consistent sample of the robot (time = `time - timestep`; see module docstring)."""
        with self._lock:
            t, qpos, qvel, qacc, tau, ctrl, _ = self._sample
        pose, R = self._plate_pose_of(qpos)
        b = self._plate_dof
        twist = np.concatenate([qvel[b:b + 3], R @ qvel[b + 3:b + 6]])
        accel = np.concatenate([qacc[b:b + 3], R @ qacc[b + 3:b + 6]])
        return SimState(time=t, zeta=qpos[self._arm_qpos].copy(), zeta_dot=qvel[self._arm_dof].copy(),
                        zeta_ddot=qacc[self._arm_dof].copy(), pose=pose, twist=twist, accel=accel,
                        tau=tau.copy(), targets=ctrl.copy(), u=qpos[self._u_qpos].copy())

    def ground_truth(self) -> GroundTruth:
        """Contact wrench, point, link and chain, and plate pose at the instant of `state()`."""
        with self._lock:
            sample = self._sample
        return self._truth_of(sample)

    def truth_log(self) -> dict[str, np.ndarray]:
        """Every step's ground truth since t = 0 as arrays: time (N,), force (N,3), point (N,3), link (N,) codes
        (0 plate, 1 arm, 2 rod, 255 none), chain (N,), plate_pose (N,6), zeta (N,6), tau (N,6)."""
        with self._lock:
            lg = self._log
            n = len(lg.time)
            pq = np.asarray(lg.pose, float).reshape(n, 7)
            return {"time": np.asarray(lg.time, float), "force": np.asarray(lg.force, float).reshape(n, 3),
                    "point": np.asarray(lg.point, float).reshape(n, 3), "link": np.asarray(lg.link, np.uint8),
                    "chain": np.asarray(lg.chain, np.uint8), "plate_pose": _poses_from_qpos(pq),
                    "zeta": np.asarray(lg.zeta, float).reshape(n, 6), "tau": np.asarray(lg.tau, float).reshape(n, 6)}

    def tau_at(self, t: float) -> np.ndarray:
        """Servo torques (N·m) of the last step at or before sim time `t` (recent history; used by the Mega)."""
        ts = self._tau_hist_t
        ok = ts <= t + 1e-12
        if not np.any(ok):
            return self._tau_hist[int(np.argmax(ts))].copy() if np.isfinite(ts.max()) else np.zeros(6)
        k = int(np.argmax(np.where(ok, ts, -np.inf)))
        return self._tau_hist[k].copy()

    # ------------------------------------------------------------------ cameras
    def camera_model(self, camera: str) -> CameraModel:
        """Intrinsics K, width, height and T_base_camera (optical frame → base) of `camera`."""
        if camera not in self.config.cameras:
            raise SimulatorError(f"unknown camera {camera!r}; cameras: {list(self.config.cameras)}")
        return camera_model_of(self.config.cameras[camera])

    def _object_placement(self, d: mujoco.MjData, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and quaternion of the scripted contact's object at time `t`, from the link poses in `d` (its
        kinematics current): the capsule's tip `object_distance(t)` from the contact point along the push direction;
        parked out of view when no object is near or the contact model is the physical pusher."""
        c = self.collision
        pos, quat = np.array(PARK_POS, float), np.array([1.0, 0, 0, 0])
        if (c is not None and self._pusher is None and self._scripted is not None
                and self._scripted_dir is not None):
            dist = c.object_distance(t)
            if dist is not None:
                sc = self._scripted
                R = d.xmat[sc.body].reshape(3, 3)
                p = d.xpos[sc.body] + R @ sc.local_point
                tip = p - self._scripted_dir * (dist + 0.015)
                # capsule along +z of the object body, from its origin (the tip) away from the link
                z = -self._scripted_dir
                x = np.cross(z, [0.0, 0.0, 1.0]) if abs(z[2]) < 0.95 else np.cross(z, [1.0, 0.0, 0.0])
                x /= np.linalg.norm(x)
                Rm = np.column_stack([x, np.cross(z, x), z])
                mujoco.mju_mat2Quat(quat, Rm.ravel())
                pos = tip
        return pos, quat

    def _place_object(self) -> None:
        d = self.data
        mujoco.mj_kinematics(self.model, d)
        d.mocap_pos[self._object_mocap], d.mocap_quat[self._object_mocap] = self._object_placement(d, self.time)
        mujoco.mj_kinematics(self.model, d)

    def _scratch_data(self) -> mujoco.MjData:
        """A second MjData of the model for kinematics and rendering off the physics' own (made once)."""
        if self._scratch is None:
            self._scratch = mujoco.MjData(self.model)
        return self._scratch

    def frame_state(self) -> FrameState:
        """What the cameras would see now (`render` of this instant), kept for `render_frame`: the physics' data is
        not touched, so a run that keeps frame states steps exactly as one that does not."""
        with self._lock:
            s = self._scratch_data()
            s.qpos[:] = self.data.qpos
            s.mocap_pos[:] = self.data.mocap_pos
            s.mocap_quat[:] = self.data.mocap_quat
            mujoco.mj_kinematics(self.model, s)
            pos, quat = self._object_placement(s, self.time)
            s.mocap_pos[self._object_mocap], s.mocap_quat[self._object_mocap] = pos, quat
            return FrameState(self.time, s.qpos.copy(), s.mocap_pos.copy(), s.mocap_quat.copy())

    def render(self, camera: str, noise: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Colour (H,W,3 uint8) and aligned depth (H,W uint16 mm, 0 = invalid) of `camera` at the current time.

        Raises:
            SimulatorError: unknown camera; RenderError: the simulator was built with cameras=False.
        """
        renderer, cam_id = self._renderer_of(camera)
        with self._lock:
            self._place_object()
            rgb, depth = renderer.render(self.data, cam_id)
        return self._camera_images(camera, rgb, depth, noise)

    def render_frame(self, camera: str, frame: FrameState, noise: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """`render` of an earlier instant kept by `frame_state`: the same colour and depth images (the noise is the
        camera's next draw), rendered off the physics' data.

        Raises:
            SimulatorError: unknown camera; RenderError: the simulator was built with cameras=False.
        """
        renderer, _cam_id = self._renderer_of(camera)
        with self._lock:
            return self.render_frame_on(renderer, self._scratch_data(), camera, frame, noise)

    def render_frame_on(self, renderer: RGBDRenderer, data: mujoco.MjData, camera: str, frame: FrameState,
                        noise: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """`render_frame` with the caller's renderer and MjData of this model, without the physics' lock: a render
        thread's own GL context (one thread each) renders while the physics steps. The camera's noise is drawn
        here, so one thread at a time renders or skips a given camera, in frame order.

        Raises:
            SimulatorError: unknown camera.
        """
        if camera not in self._cam_ids:
            raise SimulatorError(f"unknown camera {camera!r}; cameras: {list(self._cam_ids)}")
        data.time = frame.time
        data.qpos[:] = frame.qpos
        data.mocap_pos[:] = frame.mocap_pos
        data.mocap_quat[:] = frame.mocap_quat
        mujoco.mj_kinematics(self.model, data)
        mujoco.mj_camlight(self.model, data)          # the cameras' and lights' poses (a fresh MjData has none)
        rgb, depth = renderer.render(data, self._cam_ids[camera])
        return self._camera_images(camera, rgb, depth, noise)

    def new_renderer(self) -> RGBDRenderer:
        """An offscreen renderer of this model, as large as the largest camera, with a GL context of its own,
        current in the calling thread (one per rendering thread: `render_frame_on`).

        Raises:
            RenderError: no headless GL here.
        """
        cams = self.config.cameras.values()
        return RGBDRenderer(self.model, max(c.width for c in cams), max(c.height for c in cams))

    def _renderer_of(self, camera: str) -> tuple[RGBDRenderer, int]:
        """The renderer and the MuJoCo id of `camera`.

        Raises:
            SimulatorError: unknown camera; RenderError: the simulator was built with cameras=False.
        """
        if camera not in self._cam_ids:
            raise SimulatorError(f"unknown camera {camera!r}; cameras: {list(self._cam_ids)}")
        if self._renderer is None:
            raise RenderError("this Simulator was built with cameras=False")
        return self._renderer, self._cam_ids[camera]

    def _camera_images(self, camera: str, rgb: np.ndarray, depth: np.ndarray, noise: bool
                       ) -> tuple[np.ndarray, np.ndarray]:
        """The rendered buffers cut to the camera's size, with its image noise: uint8 colour, uint16 depth (mm)."""
        cfg = self.config.cameras[camera]
        rgb = rgb[:cfg.height, :cfg.width]
        depth = depth[:cfg.height, :cfg.width]
        bank = self._noise.get(camera) if noise else None
        return (noisy_rgb(rgb, self.rgb_noise_sigma, bank),
                depth_image_mm(depth, cfg, self.depth_noise_rel, bank))

    def skip_render(self, camera: str) -> None:
        """Advance `camera`'s image noise as `render` would, without rendering (a frame nobody wants): the frames
        rendered after it are those of a run that rendered every frame.

        Raises:
            SimulatorError: unknown camera.
        """
        if camera not in self._cam_ids:
            raise SimulatorError(f"unknown camera {camera!r}; cameras: {list(self._cam_ids)}")
        bank = self._noise.get(camera)
        if bank is None:
            return
        cfg = self.config.cameras[camera]
        if self.rgb_noise_sigma > 0:                      # the draws of noisy_rgb and depth_image_mm, in order
            bank.draw(cfg.width * cfg.height * 3)
        if self.depth_noise_rel > 0:
            bank.draw(cfg.width * cfg.height)

    def render_raw(self, camera: str) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free colour and metric depth (float32 m, inf = nothing hit) of `camera`."""
        if self._renderer is None:
            raise RenderError("this Simulator was built with cameras=False")
        with self._lock:
            self._place_object()
            return self._renderer.render(self.data, self._cam_ids[camera])

    def set_pose(self, pose: np.ndarray, settle: float = 0.0) -> None:
        """Re-assemble the robot at plate `pose` [x y z α β γ] at rest, without rebuilding the model or the renderer
        (fast for rendering many poses). Servo targets become the pose's ζ; external forces are cleared; with a
        trajectory drive, the drive switches to "external". `settle` seconds are then simulated (time advances).

        Raises:
            UnreachablePoseError (hexa.kinematics.hexa6rus): the pose is outside the workspace.
        """
        from hexa.kinematics import hexa6rus as kin

        pose = np.asarray(pose, dtype=float).reshape(6)
        zeta = kin.inverse_kinematics(self.desc, pose)
        m, d = self.model, self.data
        with self._lock:
            d.qpos[self._arm_qpos] = zeta
            d.qpos[self._u_qpos] = 0.0
            a = self._plate_qpos
            d.qpos[a:a + 3] = pose[:3]
            q = np.zeros(4)
            mujoco.mju_mat2Quat(q, kin.rotation_zyx(*pose[3:]).ravel())
            d.qpos[a + 3:a + 7] = q
            mujoco.mj_kinematics(m, d)
            C = kin.plate_joints(self.desc, pose)
            for i in range(6):
                self._aim_rod(i, C[i])
            d.qvel[:] = 0.0
            d.qacc_warmstart[:] = 0.0
            self._cmd = zeta.copy()
            d.ctrl[:6] = zeta if self._mech is None else 0.0
            if self._mech is not None:
                self._mech.reset()
            self._targets = zeta.copy()
            self._setpoints = zeta.copy()
            if self.drive == "trajectory":
                self.drive = "external"
            self._manual = None
            self._scripted = None
            self._scripted_dir = None
            mujoco.mj_forward(m, d)
            self._step_once(use_schedule=False, advance=False)
        if settle > 0:
            for _ in range(int(round(settle / self._dt))):
                with self._lock:
                    self._step_once(use_schedule=False)

    def _aim_rod(self, i: int, target: np.ndarray) -> None:
        """Set the universal-joint angles of chain i+1 so that its rod points at `target` (kinematics current)."""
        m, d = self.model, self.data
        body = self._rod_body[i]
        j1 = m.joint(f"u1_{i + 1}").id
        a1 = m.jnt_axis[j1] / np.linalg.norm(m.jnt_axis[j1])          # in the rod frame at u = 0 (y-component 0)
        R_ref = d.xmat[body].reshape(3, 3)                             # u = 0 here (set by the caller)
        w = R_ref.T @ (target - d.xpos[body])
        w /= np.linalg.norm(w)
        phi = np.arctan2(a1[2], a1[0])
        c = np.clip(a1 @ w, -1.0, 1.0)
        # R(a1,u1)·R(y,u2)·e_x = w  →  a1·(cos u2, 0, −sin u2) = a1·w  →  cos(u2 + φ) = a1·w
        cands = [np.arccos(c) - phi, -np.arccos(c) - phi]
        u2 = min(((u + np.pi) % (2 * np.pi) - np.pi for u in cands), key=abs)
        v = np.array([np.cos(u2), 0.0, -np.sin(u2)])
        vp, wp = v - (a1 @ v) * a1, w - (a1 @ w) * a1
        u1 = np.arctan2(a1 @ np.cross(vp, wp), vp @ wp)
        d.qpos[self._u_qpos[i]] = [u1, u2]

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> "Simulator":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
