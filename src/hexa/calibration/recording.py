"""What `hexa calibrate` works on: the three streams of a run (currents, servo set-points, camera plate poses).

A `Recording` comes from a bag of the live graph (`recording_from_bag`: /hexa/motor_currents, /hexa/joint_states,
/hexa/plate_pose) or from the simulator in-process (`simulate_recording`, the same streams the live graph records:
the Mega's ADC through the driver's sensor model at the driver's 200 Hz, the set-points the servo board reports, the
plate pose at the cameras' 30 Hz with the pose node's error), so tests identify a known robot in seconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np

if TYPE_CHECKING:
    from pathlib import Path

    from numpy.typing import NDArray

    from hexa.robots.hexa_description import HexaDescription
    from hexa.sim.realism import RealismConfig, RobotTruth
    from hexa.sim.simulator import Simulator

COMMAND_RATE_HZ = 100.0
CURRENT_RATE_HZ = 200.0     # Hz: the driver's default stream rate (hexa_driver/config/driver.yaml)
#: Hz: the Mega's stream rate of a calibration run (the driver's `stream_rate_hz`). The servos' torque ripples at
#: their 50 Hz pulse frame (a new set-point every 20 ms, the position loop's step response); 200 Hz is a multiple of
#: 50 Hz, so each sample sits at the same phase of the frame and the ripple's 200, 400 … Hz harmonics alias to
#: a steady error proportional to the arm's speed (±0.06 N·m·s/rad on the realistic robot, as large as the
#: friction). At 143 Hz (a 6993 µs period, 979 µs of frame phase more every three samples) the samples sweep the
#: frame every 140 ms: the aliases land at ≥ 7 Hz, above the analysis low-pass, and average out.
CALIBRATION_RATE_HZ = 143.0
#: s: the servo board's pulse frame (firmware uno_servo)
SERVO_FRAME_PERIOD = 0.02


class RecordingError(ValueError):
    """A recording that cannot be used (a stream missing or too short, bad payload); the message says which."""


@dataclass
class Recording:
    """Three streams of one run, SI: currents (N, 6) A at `t_current` (the driver's amps, its own zero offsets
    removed), servo set-points (M, 6) rad at `t_state` (joint_states position), plate poses (K, 6) [x y z α β γ] at
    `t_pose` (the pose node's); `payload`: a known point mass (kg) carried at `payload_point` ({P}, m) during the
    run (0: none); `source`: where it came from (for reports)."""

    t_current: NDArray
    currents: NDArray
    t_state: NDArray
    setpoints: NDArray
    t_pose: NDArray
    poses: NDArray
    payload: float = 0.0
    payload_point: NDArray = field(default_factory=lambda: np.zeros(3))
    source: str = ""

    def check(self) -> None:
        """Raises RecordingError naming the first stream that is empty, not increasing or not finite."""
        for name, t, x in (("motor_currents", self.t_current, self.currents),
                           ("joint_states", self.t_state, self.setpoints), ("plate_pose", self.t_pose, self.poses)):
            if len(t) < 10:
                raise RecordingError(f"{self.source or 'recording'}: {name} has {len(t)} samples (need ≥ 10)")
            if np.any(np.diff(t) <= 0):
                raise RecordingError(f"{self.source or 'recording'}: {name} times do not increase")
            if x.shape != (len(t), 6) or not np.all(np.isfinite(x)):
                raise RecordingError(f"{self.source or 'recording'}: {name} must hold 6 finite values per sample")
        if not (self.payload >= 0 and math.isfinite(self.payload)):
            raise RecordingError(f"payload must be a mass >= 0 kg, got {self.payload!r}")

    def save(self, path: str | Path) -> None:
        """As .npz (the recording of an in-process run, `hexa calibrate … --save`)."""
        np.savez_compressed(path, t_current=self.t_current, currents=self.currents, t_state=self.t_state,
                            setpoints=self.setpoints, t_pose=self.t_pose, poses=self.poses,
                            payload=self.payload, payload_point=self.payload_point, source=self.source)

    @staticmethod
    def load(path: str | Path) -> "Recording":
        with np.load(path) as z:
            return Recording(**{k: z[k] for k in ("t_current", "currents", "t_state", "setpoints", "t_pose",
                                                   "poses", "payload_point")},
                             payload=float(z["payload"]), source=str(z["source"]))


def add_plate_payload(sim: Simulator, mass: float, point: NDArray) -> None:
    """Fix a point mass (kg) at `point` ({P}, m) to the simulated plate: its body's mass, COM and inertia change."""
    import mujoco

    m, d = sim.model, sim.data
    b = sim._plate_body
    M0, c0 = float(m.body_mass[b]), m.body_ipos[b].copy()
    Rq = np.zeros(9)
    mujoco.mju_quat2Mat(Rq, m.body_iquat[b])
    R = Rq.reshape(3, 3)
    I0 = R @ np.diag(m.body_inertia[b]) @ R.T
    p = np.asarray(point, dtype=float)
    M = M0 + mass
    c = (M0 * c0 + mass * p) / M
    par = lambda mm, r: mm * (float(r @ r) * np.eye(3) - np.outer(r, r))   # noqa: E731
    I = I0 + par(M0, c0 - c) + par(mass, p - c)
    w, V = np.linalg.eigh(0.5 * (I + I.T))
    if np.linalg.det(V) < 0:
        V[:, 0] = -V[:, 0]
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, V.ravel())
    m.body_mass[b], m.body_ipos[b], m.body_inertia[b], m.body_iquat[b] = M, c, w, q
    mujoco.mj_forward(m, d)


def simulate_recording(pose_of: Callable[[float], NDArray], duration: float, seed: int = 0,
                       realism: RealismConfig | None = None, desc: HexaDescription | None = None,
                       payload: float = 0.0, payload_point: NDArray | None = None, lead_in: float = 1.0,
                       progress: Callable[[float], None] | None = None,
                       current_rate_hz: float = CALIBRATION_RATE_HZ) -> tuple[Recording, RobotTruth | None]:
    """Run the simulated robot of `seed` along `pose_of(t)` (trajectory time t in [0, duration]) and record it as
    the live graph would (module docstring). Returns (recording, the simulator's truth or None).

    pose_of: trajectory time → plate pose (6,); realism: hexa.sim.realism.RealismConfig (default realistic);
    payload: a point mass (kg) fixed at `payload_point` on the plate for the run; progress: called with the fraction
    done about once a simulated second; current_rate_hz: the currents' sample rate (the simulator's step divided by
    a whole number: 1 kHz / 7 for the default `CALIBRATION_RATE_HZ`, the driver's 200 Hz with CURRENT_RATE_HZ).
    """
    from hexa.kinematics import hexa6rus as kin
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim import Simulator
    from hexa.sim.boards import CAMERA_PERIOD, CurrentReadout, camera_pose
    from hexa.sim.realism import RealismConfig

    desc = desc or load_hexa()
    realism = realism or RealismConfig.realistic()
    point = np.zeros(3) if payload_point is None else np.asarray(payload_point, dtype=float)
    start = np.asarray(pose_of(0.0), dtype=float)
    sim = Simulator(desc, seed=seed, cameras=False, drive="external", pose=start, realism=realism)
    try:
        if payload > 0:
            add_plate_payload(sim, payload, point)
        rng = np.random.default_rng([int(seed), 23])
        readout = CurrentReadout(sim)
        jitter = realism.jitter
        z0 = kin.inverse_kinematics(desc, start)
        sim.set_servo_targets(z0)
        pending: list[tuple[float, NDArray]] = []
        rec: dict[str, list] = {k: [] for k in ("tc", "i", "ts", "s", "tp", "p")}
        steps = max(1, int(round(1.0 / (current_rate_hz * sim.timestep))))
        next_cmd, next_cam, next_report, k = 0.0, 0.0, 0.0, 0
        t_end = lead_in + duration
        while sim.time < t_end - 1e-9:
            now = sim.time
            if now >= next_cmd - 1e-12:
                pose = np.asarray(pose_of(min(max(now - lead_in, 0.0), duration)), dtype=float)
                pending.append((now + jitter.command_delay(rng), kin.inverse_kinematics(desc, pose, check=False)))
                next_cmd += 1.0 / COMMAND_RATE_HZ
            due = [c for c in pending if c[0] <= now + 1e-12]
            if due:
                pending = [c for c in pending if c[0] > now + 1e-12]
                sim.set_servo_targets(due[-1][1])
            sim.step(1)
            k += 1
            if k % steps:
                continue
            s = sim.state()
            t = s.time
            rec["tc"].append(t)     # the board's clock: the driver stamps currents with it
            rec["i"].append(readout.amps(s.tau, rng))
            rec["ts"].append(t)
            rec["s"].append(sim.servo_setpoints())
            if t >= next_cam - 1e-12:
                rec["tp"].append(t)
                rec["p"].append(camera_pose(s.pose, rng))
                next_cam += CAMERA_PERIOD
            if progress is not None and t >= next_report:
                progress(min(1.0, t / t_end))
                next_report += 1.0
        truth = sim.truth
        if progress is not None:
            progress(1.0)
    finally:
        sim.close()
    r = Recording(t_current=np.asarray(rec["tc"]), currents=np.asarray(rec["i"]),
                  t_state=np.asarray(rec["ts"]), setpoints=np.asarray(rec["s"]), t_pose=np.asarray(rec["tp"]),
                  poses=np.asarray(rec["p"]), payload=float(payload), payload_point=point,
                  source=f"simulated robot seed {seed} ({realism.name})")
    return r, truth
