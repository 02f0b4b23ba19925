"""One simulated run of `hexa eval`: the nodes' core classes on the MuJoCo robot, without ROS, faster than real time.

A run drives the simulator like the live graph does and feeds the same classes the nodes run:
- the trajectory node's `TrajectoryRunner` commands ζ at 100 Hz, starting on the observer's first monitoring OK and
  holding on a LOST (`hexa.dynamics.monitoring.MonitoringWatch`, evaluated before each command); each command
  reaches the servo board after the host jitter of the realism (`JitterConfig`), then the servos take it through the
  pulse frame (if any);
- the current board samples at the driver's `stream_rate_hz` (200 Hz, as in the live graph): the truth's motor
  currents through the ACS712 + 10-bit ADC with the realism's noise (`hexa.sim.realism.adc_counts`), converted back
  by the driver's sensor model; host stamps carry the jitter;
  the joint_states position is each servo's set-point (what the driver gives it with the latch report);
- the observer node's `CollisionMonitor` (ζ estimator → residual observer → detector) takes both streams and the
  plate pose at 30 Hz (the true pose with σ = 0.5 mm / 0.1° of noise, standing in for the pose node — the marker
  fit is not run here);
- in a contact run, the isolation node's `IsolationScheduler` and `ContactLocator` take both cameras' frames,
  rendered from the simulator as the sim node renders them (30 Hz from t = 0; only the frames the scheduler hands
  out are rendered: the backgrounds and the pairs from the START's onset on, every `eval_period`, until END), the
  same plate poses and the START / END (`hexa.eval.rendered_isolation`); isolation "oracle" replaces them with the
  true link, chain, point and force direction at the START;
- the rnea node's `ContactForceTracker` identifies the force from the observer's ζ̂, ζ̂̇ and τ at each contact the
  isolation hands it (as the node takes the isolation node's `contact`).

The recorded arrays become a `hexa.report.collision_demo.CaseData`, and `compute_metrics` — the demo's own — gives
delay, RMSE and false STARTs. The residual is also replayed at scaled thresholds (the DET curve) through the CUSUM
detector (`hexa.dynamics.cusum`), the threshold detector (`CollisionDetector`) and the paper's detector (plate axes
only, r_low = 2 N / 0.2 N·m, no servo criterion).
"""
from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.sim.scenarios import ScriptedCollision

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, DTypeLike, NDArray

    from hexa.dynamics.contact_force import ContactForce
    from hexa.dynamics.cusum import CusumConfig
    from hexa.dynamics.observer import ObserverConfig
    from hexa.eval.rendered_isolation import Evaluation
    from hexa.report.collision_demo import CaseData
    from hexa.robots.hexa_description import HexaDescription
    from hexa.sim.realism import RealismConfig

LINKS = ("plate", "arm", "rod")
TRAJECTORIES = ("circle", "helix", "ellipse")
#: the kinds of trajectory: the paper's three, and random smooth reachable ones (hexa.random_trajectory)
TRAJECTORY_KINDS = ("paper", "random")
#: what `--trajectories` may select: one kind, or "all" (both, alternating)
TRAJECTORY_CHOICES = ("paper", "random", "all")
#: s of rest at the start pose before the trajectory (the estimator and the observer settle), as `hexa demo`
LEAD_IN = 1.0
#: s simulated after a contact's end
TAIL = 0.8
#: threshold scales of the DET curve (× the detector's thresholds, plate axes and servo torques together)
THRESHOLD_SCALES = (0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.15, 1.3, 1.5, 1.75, 2.0, 2.5)
#: the detectors replayed on every run (`detectors`)
DETECTOR_NAMES = ("cusum", "threshold", "paper")
#: the threshold detector is also replayed with these minimum durations (s) at GRID_SCALES × its thresholds
#: (`grid_specs`: each run's `detect_grid` and `starts_grid`), to weigh the START's wait against false alarms
GRID_MIN_DURATIONS = (0.005, 0.01, 0.015)
GRID_SCALES = (0.6, 0.7, 0.8, 0.9, 1.0, 1.15, 1.3)
#: the paper's detector: r_low on the plate axes only (seed 000 §3.1), no servo-torque criterion
PAPER_THRESHOLDS = (2.0, 2.0, 2.0, 0.2, 0.2, 0.2)
R_LOW = 2.0
#: truth samples between two plate-equivalent wrenches of the observer-lag figure (5 ms at the 1 kHz physics)
PLATE_EQUIVALENT_STRIDE = 5
#: the isolation of a contact run: the isolation node's core on rendered frames, or the truth at the START
ISOLATION_MODES = ("rendered", "oracle")


@dataclass(frozen=True)
class DetectorSpec:
    """A detector to replay on recorded residuals: its kind ("threshold": `CollisionDetector`, "cusum":
    `hexa.dynamics.cusum.CusumDetector` with `cusum`), plate-axis thresholds (N, N·m) and servo thresholds (N·m,
    0 = off), with the live detector's release ratio and minimum duration."""

    name: str
    thresholds: tuple[float, ...]
    servo_thresholds: tuple[float, ...]
    kind: str = "threshold"
    cusum: CusumConfig | None = None
    min_duration: float | None = None    # s; None: the live detector's

    def config(self, base: ObserverConfig, scale: float = 1.0) -> ObserverConfig:
        md = base.min_duration if self.min_duration is None else self.min_duration
        return dataclasses.replace(base, thresholds=tuple(scale * v for v in self.thresholds),
                                   servo_thresholds=tuple(scale * v for v in self.servo_thresholds), min_duration=md)


def detectors(observer_config: ObserverConfig, cusum: CusumConfig | None = None) -> tuple[DetectorSpec, ...]:
    """The detectors replayed on every run: the CUSUM detector (`cusum`: CusumConfig, default the node's), the
    threshold detector (both at the configured thresholds) and the paper's baseline."""
    from hexa.dynamics.cusum import CusumConfig

    th, servo = tuple(observer_config.thresholds), tuple(observer_config.servo_thresholds)
    return (DetectorSpec("cusum", th, servo, "cusum", cusum or CusumConfig()),
            DetectorSpec("threshold", th, servo),
            DetectorSpec("paper", PAPER_THRESHOLDS, (0.0,) * 6))


def threshold_spec(observer_config: ObserverConfig) -> DetectorSpec:
    """The node's threshold detector of `detectors`."""
    return next(d for d in detectors(observer_config) if d.name == "threshold")


def grid_specs(observer_config: ObserverConfig) -> dict[str, DetectorSpec]:
    """The threshold detector of `detectors` at each of GRID_MIN_DURATIONS, keyed by that minimum duration
    ("0.01")."""
    spec = threshold_spec(observer_config)
    return {f"{md:g}": dataclasses.replace(spec, min_duration=md) for md in GRID_MIN_DURATIONS}


def kinds_of(trajectories: str) -> tuple[str, ...]:
    """The trajectory kinds a `--trajectories` choice selects ("all": both).

    Raises:
        ValueError: not one of TRAJECTORY_CHOICES.
    """
    if trajectories not in TRAJECTORY_CHOICES:
        raise ValueError(f"trajectories must be one of {TRAJECTORY_CHOICES}, got {trajectories!r}")
    return TRAJECTORY_KINDS if trajectories == "all" else (trajectories,)


def trajectory_kind(name: str) -> str:
    """"random" for a random trajectory's name (random:SEED), "paper" for the paper's three."""
    from hexa.trajectories import RANDOM_PREFIX

    return "random" if name.startswith(RANDOM_PREFIX) else "paper"


#: draws of a case before it gives up on a feasible contact (`draw_contact`)
MAX_DRAWS = 100


def _draw(seed: int, index: int, kinds: tuple[str, ...], attempt: int) -> ScriptedCollision:
    """Draw `attempt` of contact `index` (see draw_contact): the link and chain of the first draw, the rest from
    (seed, index, attempt)."""
    rng = np.random.default_rng([int(seed), 7, int(index)])
    link = LINKS[int(rng.integers(3))]
    chain = 0 if link == "plate" else int(rng.integers(1, 7))
    if attempt:
        rng = np.random.default_rng([int(seed), 7, int(index), int(attempt)])
    position = (float(rng.uniform(-np.pi, np.pi)) if link == "plate"
                else float(rng.uniform(0.3, 0.9) if link == "arm" else rng.uniform(0.2, 0.9)))
    trajectory = TRAJECTORIES[int(rng.integers(3))]
    if kinds[int(index) % len(kinds)] == "random":
        trajectory = f"random:{int(seed) * 100003 + int(index)}"
    return ScriptedCollision(
        name=f"case{index}", trajectory=trajectory, link=link, chain=chain,
        onset=float(rng.uniform(1.5, 8.0)), rise_time=float(rng.uniform(0.1, 0.5)),
        release_time=float(rng.uniform(0.1, 0.4)), peak_force=float(rng.uniform(1.0, 10.0)), position=position,
        elevation=float(np.radians(rng.uniform(-80.0, 30.0))), azimuth=float(np.radians(rng.uniform(-40.0, 40.0))),
        approach_time=0.6, approach_distance=0.25, hold_time=float(rng.uniform(0.0, 0.5)))


def draw_contact_counted(seed: int, index: int, trajectories: str = "all") -> tuple[ScriptedCollision, int]:
    """(contact `index` of a campaign `seed`, draws rejected before it); see draw_contact.

    Raises:
        RuntimeError: no feasible draw in MAX_DRAWS.
    """
    from hexa.robots.hexa_description import load_hexa
    from hexa.vision.evaluation import MIN_CLEARANCE, contact_clearance

    kinds = kinds_of(trajectories)
    desc = load_hexa()
    for attempt in range(MAX_DRAWS):
        c = _draw(seed, index, kinds, attempt)
        if contact_clearance(desc, c) >= MIN_CLEARANCE:
            return c, attempt
    raise RuntimeError(f"no feasible contact in {MAX_DRAWS} draws of case {index}, seed {seed}")


def draw_contact(seed: int, index: int, trajectories: str = "all") -> ScriptedCollision:
    """Contact `index` of a campaign `seed`: link (plate/arm/rod), chain, point on the link, direction, peak force
    1–10 N, rise 0.1–0.5 s, hold 0–0.5 s, release 0.1–0.4 s, onset 1.5–8 s into a trajectory: one of the paper's
    three, or (`trajectories` "random", or "all" at odd indices) the random trajectory random:N with N the case's
    simulator seed (seed·100003 + index); the first draw of every other field is the same whatever `trajectories`
    selects (a redraw depends on the trajectory). Only feasible contacts: a draw whose pushing object would come
    closer than `hexa.vision.evaluation.MIN_CLEARANCE` to another link (or pass through the plate) on its approach
    or hold (`contact_clearance`, the vision evaluation's rule) is rejected and drawn again (the same link and
    chain, the rest from (seed, index, attempt)), so an index always gives the same contact and the links stay
    equally likely."""
    return draw_contact_counted(seed, index, trajectories)[0]


@dataclass
class RunRecord:
    """Arrays of one run (SI): at the monitor's sample times `t`, residual (N,6) on the plate axes and servo (N,6) as
    servo torques; the live events; the simulator's truth at every physics step (`truth_t`, 1 kHz); the identified
    forces and their points; the isolation that ran ("rendered", "oracle"; "none" in free motion), its isolated pairs
    (`hexa.eval.rendered_isolation.Evaluation`) and their cost."""

    t: np.ndarray
    residual: np.ndarray
    servo: np.ndarray
    events: list[tuple[float, str, int, str]]
    truth_t: np.ndarray
    truth_force: np.ndarray
    truth_point: np.ndarray
    truth_link: np.ndarray
    truth_chain: np.ndarray
    truth_pose: np.ndarray
    truth_zeta: np.ndarray
    wrench_t: np.ndarray
    wrench_force: np.ndarray
    sim_seconds: float
    zeta_dot: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    wrench_point: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))   # where each force was identified
    counters: dict[str, Any] = field(default_factory=dict)
    isolation: str = "oracle"
    evaluations: list[Evaluation] = field(default_factory=list)     # rendered isolation: every isolated pair
    isolation_cost: dict[str, float] = field(default_factory=dict)
    truth_tau: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))   # servo torques (N·m), at truth_t


class CommandLink:
    """The servo board's serial link in an offline run: commands arrive after their host delays, in the order they
    were sent (one byte stream: a late command holds back the ones behind it)."""

    def __init__(self) -> None:
        self._queue: list[tuple[float, NDArray, int]] = []

    def send(self, arrival: float, zeta: NDArray, tag: int) -> None:
        """Queue a command that the host's delay would deliver at `arrival` (s)."""
        if self._queue:
            arrival = max(arrival, self._queue[-1][0])
        self._queue.append((arrival, zeta, tag))

    def arrived(self, now: float) -> tuple[NDArray, int] | None:
        """(set-points, tag) of the last command arrived by `now` since the previous call, None if none has."""
        n = 0
        while n < len(self._queue) and self._queue[n][0] <= now + 1e-12:
            n += 1
        if not n:
            return None
        last = self._queue[n - 1]
        del self._queue[:n]
        return last[1], last[2]


def simulate(collision: ScriptedCollision | None, trajectory: str, duration: float, realism: RealismConfig,
             seed: int, observer_config: ObserverConfig | None = None, identify: bool = True,
             desc: HexaDescription | None = None, detector: str = "threshold",
             cusum: CusumConfig | None = None, isolation: str = "rendered", nodes_desc: HexaDescription | None = None,
             stream_rate_hz: float | None = None, command_phase: float = 0.0,
             robot_seed: int | None = None) -> RunRecord:
    """Run the robot `duration` s of trajectory time (after LEAD_IN) with an optional scripted contact (its onset in
    trajectory time); see the module docstring for what runs. Free motion (no contact) loops the trajectory and
    ignores STARTs (it keeps moving, to count false alarms) and runs no isolation; with a contact a START holds the
    trajectory, as the trajectory node's default policy does. `detector` and `cusum`: the monitor's detector (the
    node's default: "threshold"; "cusum" with CusumConfig()). `isolation`: "rendered" (the isolation node's core on
    rendered frames; needs EGL) or "oracle" (ISOLATION_MODES). `nodes_desc`: the description the observer and the
    rnea tracker use (a calibration overlay of this robot; default `desc`, which builds the simulated robot);
    `stream_rate_hz`: the currents' rate (default the driver's `stream_rate_hz`); `command_phase` (s, in [0, 1/rate)):
    the commands go out this long after a current sample (0: each reaches the servos just after a sample, and the
    next sample is the first to carry it — in the live graph the phase is wherever the host's scheduling puts it);
    `robot_seed`: the simulated robot's seed (default `seed`, which also seeds the noise and the phases).

    Raises:
        ValueError: an unknown isolation; hexa.sim.camera.RenderError: "rendered" without a GL context.
    """
    from hexa.dynamics.contact_force import ContactForceConfig, ContactForceTracker, LocatedContact
    from hexa.dynamics.monitor import CollisionMonitor, MonitorConfig
    from hexa.dynamics.observer import ObserverConfig
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim import Simulator
    from hexa.sim.boards import CAMERA_PERIOD, CurrentReadout, camera_pose
    from hexa.dynamics.monitoring import MonitoringWatch
    from hexa.trajectory_runner import TrajectoryRunner, TrajectorySettings

    if isolation not in ISOLATION_MODES:
        raise ValueError(f"isolation must be one of {ISOLATION_MODES}, got {isolation!r}")
    desc = desc or load_hexa()
    ocfg = observer_config or ObserverConfig()
    render = collision is not None and isolation == "rendered"
    sim = Simulator(desc, seed=seed, scenario=collision, cameras=render, drive="external", lead_in=LEAD_IN,
                    trajectory=None if collision is not None else trajectory, realism=realism, robot_seed=robot_seed)
    vision = None
    if render:
        from hexa.eval.rendered_isolation import RenderedIsolation

        vision = RenderedIsolation(sim, desc)
    rng = np.random.default_rng([int(seed), 11])
    jitter = realism.jitter
    readout = CurrentReadout(sim)
    driver_cfg = readout.driver_config
    punctual = jitter.sample_sigma <= 0 and jitter.spike_rate <= 0
    nodes_desc = nodes_desc or desc
    mon = CollisionMonitor(nodes_desc, MonitorConfig(sim_clock=punctual), ocfg, detector=detector, cusum=cusum)
    # the observer node's monitoring contract: the runner starts on its first OK and holds on LOST, as live
    watch = MonitoringWatch(mon, now=0.0)
    tracker = ContactForceTracker(nodes_desc, ContactForceConfig()) if identify else None
    runner = TrajectoryRunner.from_settings(desc, TrajectorySettings(
        trajectory=trajectory, start_time=LEAD_IN, loop=collision is None,
        collision_policy="ignore" if collision is None else "hold"))
    command_period = 1.0 / TrajectorySettings().rate_hz
    link = CommandLink()
    next_cmd, next_cam, seq = float(command_phase), 0.0, 0
    rec: dict[str, list] = {k: [] for k in ("t", "res", "servo", "zd", "wt", "wf", "wp")}
    events: list[tuple[float, str, int, str]] = []

    t_end = LEAD_IN + duration
    rate = float(stream_rate_hz or driver_cfg["stream_rate_hz"])
    steps_per_sample = max(1, int(round(1.0 / (rate * sim.timestep))))
    if not 0.0 <= command_phase < 1.0 / rate:
        raise ValueError(f"command_phase must be in [0, {1.0 / rate:g}) s, got {command_phase!r}")
    k, lost_until = 0, -math.inf

    def keep(forces: list[ContactForce]) -> None:
        for f in forces:
            rec["wt"].append(f.time)
            rec["wf"].append(f.force)
            rec["wp"].append(f.point)

    def located(contacts: list[LocatedContact]) -> None:
        """The isolation's contacts to the rnea node's tracker, as the node takes `contact`."""
        for c in contacts:
            if tracker is not None:
                keep(tracker.on_contact(c))

    try:
        if vision is not None:
            located(vision.step(sim.time))           # the sim node's first frame, at t = 0
        while sim.time < t_end - 1e-9:
            now = sim.time
            if now >= next_cmd - 1e-12:
                # sim time stands for wall time too: the campaign's clock never stalls. The runner gets the current
                # state at every tick, as the observer node re-publishes it every 50 ms: it takes silence as LOST
                watch.evaluate(now, now)
                runner.on_monitoring(watch.status.level, watch.status.reason, now)
                tick = runner.tick(now)
                if tick.zeta is not None:
                    seq = (seq + 1) & 0xFF
                    link.send(now + jitter.command_delay(rng), tick.zeta, seq)
                next_cmd += command_period
            latest = link.arrived(now)
            if latest is not None:
                sim.set_servo_targets(latest[0], tag=latest[1])
            sim.step(1)
            k += 1
            if vision is not None:
                located(vision.step(sim.time))
            if k % steps_per_sample:
                continue
            s = sim.state()
            t = s.time
            amps = readout.amps(s.tau, rng)
            stamp = t + jitter.sample_delay(rng)
            lost_until = max(lost_until, t + jitter.loss(rng))
            out = []
            if t >= lost_until:
                out += watch.push_currents(stamp, int(round(t * 1e6)), amps)
                out += watch.push_states(stamp, sim.servo_setpoints(), None, None)
            if t >= next_cam - 1e-12:
                pose = camera_pose(s.pose, rng)
                out += watch.push_pose(t, pose)
                if tracker is not None:
                    tracker.on_pose(t, pose)
                if vision is not None:
                    located(vision.add_pose(t, pose, t))
                next_cam += CAMERA_PERIOD
            for m in out:
                r = m.residual
                rec["t"].append(m.time)
                rec["res"].append(r.wrench)
                rec["servo"].append(r.servo_torque)
                rec["zd"].append(m.zeta_dot if m.zeta_dot is not None else np.full(6, np.nan))
                if tracker is not None and m.zeta_dot is not None:
                    keep(tracker.step_state(m.time, m.zeta, m.zeta_dot, m.tau))
                for e in r.events:
                    events.append((e.time, e.kind, e.id, e.axis_name))
                    if e.kind == "START":
                        runner.collision(now, r.wrench[:3])
                    if tracker is not None:
                        keep(tracker.on_collision(e.kind, e.id, e.time))
                    if vision is not None:
                        located(vision.collision(e.kind, e.id, e.onset, e.time, t))
                    elif e.kind == "START" and collision is not None:
                        g = sim.ground_truth()
                        if g.in_contact:   # the oracle isolation's contact
                            located([LocatedContact(e.time, e.id, g.link, g.chain or 1, g.point.copy(),
                                                    g.force / np.linalg.norm(g.force))])
        log = sim.truth_log()
    finally:
        sim.close()

    def arr(key: str, width: int | None = None, dtype: DTypeLike = float) -> np.ndarray:
        a = np.asarray(rec[key], dtype=dtype)
        return a.reshape(len(rec[key]), width) if width else a

    order = np.argsort(arr("wt"), kind="stable")
    return RunRecord(t=arr("t"), residual=arr("res", 6), servo=arr("servo", 6), events=sorted(events),
                     truth_t=log["time"], truth_force=log["force"], truth_point=log["point"],
                     truth_link=log["link"].astype(int), truth_chain=log["chain"].astype(int),
                     truth_pose=log["plate_pose"], truth_zeta=log["zeta"], wrench_t=arr("wt")[order],
                     wrench_force=arr("wf", 3)[order], wrench_point=arr("wp", 3)[order], sim_seconds=t_end,
                     zeta_dot=arr("zd", 6), truth_tau=log["tau"],
                     counters={**mon.counters(), "monitoring_lost": watch.lost_count},
                     isolation=isolation if collision is not None else "none",
                     evaluations=vision.evaluations if vision is not None else [],
                     isolation_cost=vision.cost.as_dict() if vision is not None else {})


def replay(rec: RunRecord, spec: DetectorSpec, base_config: ObserverConfig, scale: float = 1.0
           ) -> list[tuple[float, str, int, str]]:
    """The events `spec` at `scale` raises on the recorded residuals (the live detector, replayed; the CUSUM fed the
    recorded ζ̂̇ as in the monitor)."""
    from hexa.dynamics.cusum import make_detector

    det = make_detector(spec.kind, spec.config(base_config, scale), spec.cusum)
    motion = getattr(det, "motion", None)
    zd = rec.zeta_dot if len(rec.zeta_dot) == len(rec.t) else None
    out = []
    for k, (t, r, s) in enumerate(zip(rec.t.tolist(), rec.residual, rec.servo)):
        if motion is not None and zd is not None:
            motion(t, zd[k])
        for e in det.update(t, r, s)[1]:
            out.append((e.time, e.kind, e.id, e.axis_name))
    return out


def case_data(name: str, rec: RunRecord, events: list, thresholds: ArrayLike, servo_thresholds: ArrayLike,
              with_outputs: bool = True) -> CaseData:
    """The demo's CaseData of a run (`with_outputs` False: truth and events only, for the replays)."""
    from hexa.report.collision_demo import CaseData
    from hexa.vision.isolation import LINK_UNKNOWN

    d = CaseData(case=name, truth_t=rec.truth_t, truth_force=rec.truth_force, truth_point=rec.truth_point,
                 truth_link=rec.truth_link, truth_chain=rec.truth_chain, events=events,
                 threshold=np.asarray(thresholds, float), servo_threshold=np.asarray(servo_thresholds, float))
    if with_outputs:
        d.truth_tau = rec.truth_tau if len(rec.truth_tau) == len(rec.truth_t) else None
        d.truth_pose, d.truth_zeta = rec.truth_pose, rec.truth_zeta
        d.residual_t, d.residual, d.residual_servo = rec.t, rec.residual, rec.servo
        d.wrench_t, d.wrench_force = rec.wrench_t, rec.wrench_force
        found = [e for e in rec.evaluations if e.link != LINK_UNKNOWN]   # what the node publishes on `contact`
        d.contact_t = np.array([e.stamp for e in found], float)
        d.contact_link = np.array([e.link for e in found], int)
        d.contact_chain = np.array([e.chain for e in found], int)
        d.contact_point = np.array([e.point for e in found], float).reshape(len(found), 3)
    return d


def isolation_evaluations(rec: RunRecord) -> list[dict[str, Any]]:
    """Every isolated pair of a rendered-isolation run with the truth at the truth sample nearest its stamp: the
    true link and chain ("none" when nothing touches) and the point error (mm; NaN when either side has none)."""
    from hexa.report.collision_demo import LINK_NAMES
    from hexa.vision.isolation import LINK_UNKNOWN

    out = []
    for e in rec.evaluations:
        k = int(np.argmin(np.abs(rec.truth_t - e.stamp)))
        touching = bool(np.linalg.norm(rec.truth_force[k]) > 0)
        err = (float(np.linalg.norm(e.point - rec.truth_point[k]) * 1e3) if touching and e.link != LINK_UNKNOWN
               else float("nan"))
        out.append({**e.as_dict(), "true_link": LINK_NAMES.get(int(rec.truth_link[k]), "none") if touching
                    else "none", "true_chain": int(rec.truth_chain[k]) if touching else 0, "error_mm": err})
    return out


# d: a CaseData with its truth_pose (Any, as CaseData.truth_pose is Optional)
def plate_equivalent_every(d: Any, stride: int) -> np.ndarray:
    """The true force's plate-equivalent wrench (hexa.report.collision_demo.plate_equivalent_truth) computed on every
    `stride`-th truth sample and interpolated between them (it costs ~5 ms a sample)."""
    from hexa.report.collision_demo import plate_equivalent_truth

    idx = np.unique(np.r_[np.arange(0, len(d.truth_t), stride), len(d.truth_t) - 1])
    sub = dataclasses.replace(d, truth_t=d.truth_t[idx], truth_force=d.truth_force[idx],
                              truth_point=d.truth_point[idx], truth_link=d.truth_link[idx],
                              truth_chain=d.truth_chain[idx], truth_pose=d.truth_pose[idx])
    W = plate_equivalent_truth(sub)
    return np.stack([np.interp(d.truth_t, sub.truth_t, W[:, k]) for k in range(6)], axis=1)


def _nodes_description(job: dict[str, Any]) -> HexaDescription | None:
    """The description the job's nodes use: its robot's calibration overlay (`nodes_overlay`, the YAML text of a
    `run_calibration_job`), else with `calibrate` (an excitation file of `hexa calibrate excite`) the overlay
    `run_calibration_job` identifies now on the job's own simulated robot; else None (the description itself)."""
    import tempfile

    from hexa.robots.hexa_description import load_hexa

    text = job.get("nodes_overlay")
    if not text and job.get("calibrate"):
        text = run_calibration_job({"calibrate": job["calibrate"], "realism": job["realism"],
                                    "robot_seed": job.get("robot_seed", job["sim_seed"])})["overlay"]
    if not text:
        return None
    with tempfile.TemporaryDirectory() as tmp:   # load_hexa reads files: the overlay lays itself over its base
        path = f"{tmp}/calibration.yaml"
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        return load_hexa(path)


def run_calibration_job(job: dict[str, Any]) -> dict[str, Any]:
    """Worker: the calibration overlay of one simulated robot (`robot_seed`, `realism`) identified from the
    excitation file `calibrate` as `hexa calibrate identify --simulate` does (optional `seconds`: what that
    simulates) → {"robot_seed", "realism", "overlay" (its YAML text, laid over the packaged description),
    "sim_seconds", "wall_s"}."""
    import tempfile
    from pathlib import Path

    from hexa.calibration.simulated import calibrate_simulated_robot
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim.realism import RealismConfig
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "calibration.yaml"
        calibrate_simulated_robot(job["calibrate"], job["robot_seed"], RealismConfig.named(job["realism"]),
                                  load_hexa(), out)
        text = out.read_text(encoding="utf-8")
    return {"robot_seed": job["robot_seed"], "realism": job["realism"], "overlay": text,
            "sim_seconds": float(job.get("seconds", 0.0)), "wall_s": time.perf_counter() - t0}


def _detector_settings(job: dict[str, Any]) -> tuple[ObserverConfig, str, CusumConfig]:
    """(ObserverConfig, detector kind, CusumConfig) of a job's optional observer, detector and cusum fields."""
    from hexa.dynamics.cusum import CusumConfig
    from hexa.dynamics.observer import ObserverConfig

    return (ObserverConfig(**job.get("observer", {})), job.get("detector", "threshold"),
            CusumConfig(**job.get("cusum", {})))


#: s between the truth samples checked for a type II singularity (type2_crossings)
TYPE2_STEP = 0.005


def type2_crossings(rec: RunRecord, during: np.ndarray) -> int:
    """How many times det J_D of the true plate pose and arm angles changes sign over the truth samples selected by
    `during`, every TYPE2_STEP s: the push drove the robot through a type II singularity (J_D t = J_I ζ̇,
    hexa.kinematics.hexa6rus.constraint_jacobians). There the arm rates do not determine the plate's motion, so the
    force identification, which takes the plate's twist and acceleration from ζ, ζ̇, ζ̈ through J_ζ⁻¹
    (hexa.dynamics.lagrange.motion_from_joint_rates), is singular."""
    from hexa.kinematics.hexa6rus import constraint_jacobians
    from hexa.robots.hexa_description import load_hexa

    idx = np.nonzero(during)[0]
    if len(idx) < 2 or len(rec.truth_pose) != len(rec.truth_t) or len(rec.truth_zeta) != len(rec.truth_t):
        return 0
    stride = max(1, int(round(TYPE2_STEP / float(np.median(np.diff(rec.truth_t[idx])) or TYPE2_STEP))))
    desc = load_hexa()
    signs = [np.sign(np.linalg.det(constraint_jacobians(desc, rec.truth_pose[k], rec.truth_zeta[k])[0]))
             for k in idx[::stride]]
    signs = [v for v in signs if v != 0]
    return int(sum(a != b for a, b in zip(signs, signs[1:])))


def run_contact_job(job: dict[str, Any]) -> dict[str, Any]:
    """Worker: one contact case → its metrics (the demo's) with the live detector, and the detection of every
    replayed detector (`detectors`) at every scale.

    job: campaign_seed and index (the drawn contact) or collision (ScriptedCollision fields), sim_seed, optional
    robot_seed (the simulated robot; default sim_seed) and nodes_overlay (its calibration, `_nodes_description`),
    realism ("ideal" | "realistic"), optional identify (bool), observer (ObserverConfig fields), detector ("cusum" |
    "threshold": the live one), cusum (CusumConfig fields) and isolation ("rendered", the default, or "oracle";
    rendered falls back to the oracle, saying why in `isolation.note`, when this process cannot render)."""
    from hexa.report.collision_demo import compute_metrics
    from hexa.sim.camera import RenderError
    from hexa.sim.realism import RealismConfig

    t0 = time.perf_counter()
    realism = RealismConfig.named(job["realism"])
    ocfg, kind, ccfg = _detector_settings(job)
    c, rejected = ((ScriptedCollision(**job["collision"]), 0) if "collision" in job
                   else draw_contact_counted(job["campaign_seed"], job["index"], job.get("trajectories", "paper")))
    duration = c.end_time + TAIL
    run = functools.partial(simulate, c, c.trajectory, duration, realism, seed=job["sim_seed"],
                            observer_config=ocfg, identify=job.get("identify", True), detector=kind, cusum=ccfg,
                            nodes_desc=_nodes_description(job), stream_rate_hz=job.get("stream_rate_hz"),
                            robot_seed=job.get("robot_seed"))
    note = ""
    try:
        rec = run(isolation=job.get("isolation", "rendered"))
    except RenderError as exc:
        note = f"rendering unavailable ({exc}): oracle isolation"
        rec = run(isolation="oracle")
    out: dict[str, Any] = {"index": job["index"], "realism": job["realism"], "link": c.link, "chain": c.chain,
                           "robot_seed": job.get("robot_seed", job["sim_seed"]),
                           "trajectory": c.trajectory, "trajectory_kind": trajectory_kind(c.trajectory),
                           "peak_force": c.peak_force, "onset": c.onset + LEAD_IN,
                           "rise_time": c.rise_time, "hold_time": c.hold_time, "release_time": c.release_time,
                           "rejected_draws": rejected, "sim_seconds": rec.sim_seconds, "detector": kind,
                           "identify": job.get("identify", True),
                           "isolation": {"mode": rec.isolation, "note": note, "cost": rec.isolation_cost,
                                         "evaluations": isolation_evaluations(rec)}}
    touching = np.linalg.norm(rec.truth_force, axis=1) > 0
    if not touching.any():   # cannot happen with a scripted contact unless the run ended before it
        out["error"] = "no contact in the ground truth"
        return out
    out["type2_crossings"] = type2_crossings(rec, touching)
    d = case_data(c.name, rec, rec.events, ocfg.thresholds, ocfg.servo_thresholds)
    m = compute_metrics(d, r_low=R_LOW, plate_equivalent=plate_equivalent_every(d, PLATE_EQUIVALENT_STRIDE))
    out["servo_saturated_s"] = m.stall_s
    out["metrics"] = m.as_dict()

    def detection(spec: DetectorSpec, scales: tuple[float, ...]) -> list[dict[str, float]]:
        """Per scale: the START time, delay and false STARTs of `spec` replayed on this run."""
        rows = []
        for scale in scales:
            mm = compute_metrics(case_data(c.name, rec, replay(rec, spec, ocfg, scale), ocfg.thresholds,
                                           ocfg.servo_thresholds, False), r_low=R_LOW)
            rows.append({"scale": scale, "detect_time": mm.detect_time, "delay_ms": mm.delay_ms,
                         "false_starts": mm.false_starts})
        return rows

    out["detect"] = {spec.name: detection(spec, THRESHOLD_SCALES) for spec in detectors(ocfg, ccfg)}
    out["detect_grid"] = {key: detection(spec, GRID_SCALES) for key, spec in grid_specs(ocfg).items()}
    out["wall_s"] = time.perf_counter() - t0
    return out


def run_free_job(job: dict[str, Any]) -> dict[str, Any]:
    """Worker: `seconds` of free motion on one trajectory (looped) → STARTs of every replayed detector at every
    scale (the live detector's too)."""
    from hexa.sim.realism import RealismConfig

    realism = RealismConfig.named(job["realism"])
    ocfg, kind, ccfg = _detector_settings(job)
    rec = simulate(None, job["trajectory"], job["seconds"], realism, seed=job["sim_seed"], observer_config=ocfg,
                   identify=False, detector=kind, cusum=ccfg, nodes_desc=_nodes_description(job),
                   stream_rate_hz=job.get("stream_rate_hz"), robot_seed=job.get("robot_seed"))
    moving = rec.t >= LEAD_IN
    out: dict[str, Any] = {"trajectory": job["trajectory"], "trajectory_kind": trajectory_kind(job["trajectory"]),
                           "robot_seed": job.get("robot_seed", job["sim_seed"]),
                           "realism": job["realism"], "seconds": job["seconds"],
                           "sim_seconds": rec.sim_seconds, "live_starts": sum(1 for e in rec.events if e[1] == "START"),
                           "detector": kind}
    rec_moving = dataclasses.replace(rec, t=rec.t[moving], residual=rec.residual[moving], servo=rec.servo[moving],
                                     zeta_dot=rec.zeta_dot[moving])

    def starts(spec: DetectorSpec, scales: tuple[float, ...]) -> list[int]:
        return [sum(1 for e in replay(rec_moving, spec, ocfg, s) if e[1] == "START") for s in scales]

    out["starts"] = {spec.name: starts(spec, THRESHOLD_SCALES) for spec in detectors(ocfg, ccfg)}
    out["starts_grid"] = {key: starts(spec, GRID_SCALES) for key, spec in grid_specs(ocfg).items()}
    return out
