"""The simulator's two virtual Arduino boards on pseudo-terminals, using the project's protocol emulators.

- Uno (servo board): every SET_TARGETS pulse width is turned into an arm angle with the same per-servo calibration
  the driver uses (hexa_driver/config/driver.yaml `servos`, hexa.protocol.driver_core) and commanded to the servos,
  tagged with the frame's SEQ. With the simulator's pulse frame (`sim.servo.frame_period` > 0) the Uno's latch
  report (LATCH, when the host enables it) carries the simulator's own frames (`Simulator.pop_latch_frames`): when
  each servo's pulse started and which SET_TARGETS it carried — the frames the servos really acted on. (The simulator
  reads a servo's target at the start of the previous servo's slot, as the firmware does.) Without the pulse frame the
  virtual Uno is firmware without the report (UNKNOWN_TYPE): the driver then dates set-points by the commands.
- Mega (current board): each sample at board time t reads the simulated servo torques τ at the sim time of that
  sample and streams I = τ / K_t + I_0 through the ACS712-like sensor and the 10-bit ADC (hexa.protocol.sensor_model),
  with Gaussian ADC noise; I_0 is a per-channel zero offset drawn once from the seed (what the driver's zero-current
  calibration removes). Board time runs on *sim time*, so rates and stamps follow the simulation at any speed.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.protocol import frames as fr
from hexa.protocol.driver_core import load_driver_config, servo_calibrations_from_config
from hexa.protocol.emulator import MegaEmulator, UnoEmulator
from hexa.protocol.sensor_model import CurrentSensorModel

if TYPE_CHECKING:
    from hexa.sim.simulator import Simulator

DEFAULT_LINK_DIR = Path("/tmp/hexa_sim")


def board_offsets(sim: "Simulator") -> np.ndarray:
    """The virtual Mega's per-channel zero offsets I_0 (A) of the simulator's robot (`sim.robot_seed`: the board is
    part of the robot): N(0, `sim.current_offset_sigma`), or none when the simulator has a truth (the realistic
    robot carries its own, `RobotTruth.current_offset`)."""
    if sim.truth is not None:
        return np.zeros(6)
    return np.random.default_rng([int(sim.robot_seed), 2]).normal(0.0, sim.config.current_offset_sigma, 6)


#: a ROS-free run's camera poses: the top camera's frame period (s) and the pose node's error (m, rad per axis)
CAMERA_PERIOD = 1.0 / 30.0
POSE_NOISE = (0.0005, math.radians(0.1))


def camera_pose(pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The plate pose a ROS-free run hands over as the camera's: the true pose plus the pose node's error
    (POSE_NOISE, Gaussian, position then angles)."""
    return pose + np.concatenate([rng.normal(0, POSE_NOISE[0], 3), rng.normal(0, POSE_NOISE[1], 3)])


class CurrentReadout:
    """The currents a ROS-free run reads as the driver does, without the virtual Mega: the servo torques as currents
    plus the Mega's zero offsets (`board_offsets`), through the ADC with the simulator's noise
    (`hexa.sim.realism.adc_counts`), back to amps by the driver's sensor model minus its configured offsets."""

    def __init__(self, sim: "Simulator") -> None:
        self.sim = sim
        self.driver_config = load_driver_config()
        self.sensor = CurrentSensorModel.from_dict(self.driver_config.get("sensor", {}))
        self.driver_offsets = np.asarray(self.driver_config.get("current_offsets") or np.zeros(6), dtype=float)
        self.offsets = board_offsets(sim)

    def amps(self, tau: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The driver's currents (A) for servo torques `tau` (N·m); ADC noise drawn from `rng`."""
        from hexa.sim.realism import adc_counts

        sim = self.sim
        counts = adc_counts(self.sensor, sim.motor_currents(tau) + self.offsets, sim.config.current_noise_counts, rng)
        return self.sensor.current_from_counts(counts) - self.driver_offsets


class VirtualBoards:
    """Uno + Mega emulators wired to a Simulator (context manager; `uno.port` / `mega.port` are the tty paths).

    Args:
        sim: the simulator (its servos receive the Uno's targets; its torques feed the Mega).
        link_dir: directory for stable symlinks `uno` and `mega` to the ptys (the driver's default ports); None: none.
        driver_config: driver configuration mapping (default: hexa_driver/config/driver.yaml) for the servo
            calibration and the sensor model.
        seed: draws the ADC noise (default the simulator's seed; the zero offsets are the robot's, `board_offsets`).
    """

    def __init__(self, sim: "Simulator", link_dir: str | os.PathLike | None = DEFAULT_LINK_DIR,
                 driver_config: dict[str, Any] | None = None, seed: int | None = None) -> None:
        self.sim = sim
        cfg = driver_config if driver_config is not None else load_driver_config()
        self.servos = servo_calibrations_from_config(cfg["servos"])
        self.sensor = CurrentSensorModel.from_dict(cfg.get("sensor", {}))
        seed = sim.seed if seed is None else int(seed)
        self.offsets = board_offsets(sim)
        self.k_t = float(sim.desc.K_t)
        uno_link = mega_link = None
        if link_dir is not None:
            Path(link_dir).mkdir(parents=True, exist_ok=True)
            uno_link, mega_link = Path(link_dir) / "uno", Path(link_dir) / "mega"
        clock = self._clock
        framed = sim.config.servo.frame_period > 0   # without the pulse frame there is nothing to report
        self.uno = UnoEmulator(on_command=self._on_command, link=uno_link, clock=clock,
                               latch_source=self._latches if framed else None, latch_capable=framed)
        self.mega = MegaEmulator(current_source=self._currents, units="amps", sensor=self.sensor,
                                 noise_counts=sim.config.current_noise_counts, seed=seed, link=mega_link, clock=clock)
        self._t0 = self._clock()

    def _clock(self) -> float:
        return self.sim.time

    def angles_from_pulses(self, pulses_us: tuple[int, ...]) -> np.ndarray:
        """Arm angles (rad) commanded by six pulse widths (us)."""
        return np.array([s.angle_from_pulse(p) for s, p in zip(self.servos, pulses_us)])

    def _on_command(self, pulses_us: tuple[int, ...], seq: int) -> None:
        self.sim.set_servo_targets(self.angles_from_pulses(pulses_us), tag=seq)

    def _latches(self) -> list[fr.Latch]:
        """The simulator's completed pulse frames as LATCH reports on the Uno's board clock."""
        out = []
        for f in self.sim.pop_latch_frames():
            mask = sum(1 << i for i in range(6) if f.tags[i] >= 0)
            if not mask or f.start < self.uno.clock_zero:   # no command yet, or before the board's clock began
                continue
            out.append(fr.Latch(self.uno.board_time_us_at(f.start),
                                tuple(int(round(o * 1e6)) for o in f.pulse_offsets),
                                tuple(int(t) & 0xFF if t >= 0 else 0 for t in f.tags), mask))
        return out

    def currents_at(self, t_sim: float) -> np.ndarray:
        """The six true motor currents (A) the Mega measures at sim time `t_sim`: τ/K_t + I_0 (with the realistic
        robot's truth: its K_t, sensor gain and offsets, `Simulator.motor_currents`)."""
        return self.sim.motor_currents(self.sim.tau_at(t_sim)) + self.offsets

    def sim_time_of(self, t_board: float) -> float:
        """Sim time (s) of a Mega board time (s since the boards were created)."""
        return self._t0 + t_board

    def _currents(self, t_board: float) -> np.ndarray:
        return self.currents_at(self.sim_time_of(t_board))

    def start(self) -> "VirtualBoards":
        self.uno.start()
        self.mega.start()
        return self

    def stop(self) -> None:
        self.uno.stop()
        self.mega.stop()

    def __enter__(self) -> "VirtualBoards":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
