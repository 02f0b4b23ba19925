"""ROS-free logic of the driver node: angle <-> pulse calibration, command checking, currents and torques.

    pulse_us = zero_us + us_per_rad * (zeta - zeta_ref)       per servo (config/driver.yaml `servos`)
    I        = sensor model (counts -> A), I - I_0 after the zero-current calibration
    tau      = K_t * (I - I_0)                                (seed 000 §4: torque from the measured current)
"""
from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
import yaml

from hexa.protocol.frames import MAX_RATE_HZ, MIN_RATE_HZ, PULSE_MAX_US, PULSE_MIN_US
from hexa.protocol.sensor_model import CurrentSensorModel

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

N_JOINTS = 6
#: a command this far (rad) outside the joint range is float noise at a limit: clamped; farther: rejected
RANGE_TOLERANCE = 1e-6
JOINT_NAMES = tuple(f"arm_{i}" for i in range(1, N_JOINTS + 1))


class DriverConfigError(ValueError):
    """Invalid driver configuration (the message names the key and value)."""


class CommandRejected(ValueError):
    """A joint command that cannot be executed (non-finite, outside the joint range, wrong names or size); the
    message says why."""


@dataclass(frozen=True)
class ServoCalibration:
    """Linear angle <-> pulse-width map of one servo and its pulse limits (us)."""

    zero_us: float          # pulse width at zeta = zeta_ref
    us_per_rad: float       # signed slope (negative if the horn turns the other way)
    zeta_ref: float = 0.0   # rad
    min_us: int = 500
    max_us: int = 2500

    def __post_init__(self) -> None:
        if self.us_per_rad == 0 or not math.isfinite(self.us_per_rad):
            raise DriverConfigError(f"us_per_rad {self.us_per_rad} must be finite and non-zero")
        if not PULSE_MIN_US <= self.min_us <= self.max_us <= PULSE_MAX_US:
            raise DriverConfigError(f"pulse limits min_us={self.min_us} max_us={self.max_us} invalid "
                                    f"(need {PULSE_MIN_US} <= min_us <= max_us <= {PULSE_MAX_US})")

    def pulse_from_angle(self, zeta: float) -> int:
        """Pulse width (us, rounded, clamped to the limits) for the arm angle `zeta` (rad)."""
        p = self.zero_us + self.us_per_rad * (zeta - self.zeta_ref)
        return int(min(max(round(p), self.min_us), self.max_us))

    def angle_from_pulse(self, pulse_us: float) -> float:
        """Arm angle (rad) commanded by a pulse width (us)."""
        return self.zeta_ref + (pulse_us - self.zero_us) / self.us_per_rad


def servo_calibrations_from_config(items: Sequence[dict] | None,
                                   desc: HexaDescription | None = None) -> list[ServoCalibration]:
    """Six ServoCalibration from the `servos` list of driver.yaml; None: from the robot description's pulse map.

    Args:
        items: the config's `servos` entries, or None.
        desc: HexaDescription used when `items` is None (default: hexa.robots.hexa_description.load_hexa()).

    Raises:
        DriverConfigError: not six entries, or an entry with unknown/missing keys.
    """
    if items is None:
        if desc is None:
            from hexa.robots.hexa_description import load_hexa

            desc = load_hexa()
        return servo_calibrations_from_description(desc)
    if len(items) != N_JOINTS:
        raise DriverConfigError(f"servos: expected {N_JOINTS} entries, got {len(items)}")
    out = []
    for i, d in enumerate(items):
        try:
            values: dict[str, Any] = {k: (int(v) if k in ("min_us", "max_us") else float(v)) for k, v in d.items()}
            out.append(ServoCalibration(**values))
        except TypeError as exc:
            raise DriverConfigError(f"servos[{i}]: {exc}") from exc
    return out


@dataclass
class CommandCounters:
    accepted: int = 0
    rejected_nan: int = 0        # NaN or ±inf
    rejected_names: int = 0      # unknown or missing joint names
    rejected_size: int = 0       # as many positions as names, six without names
    rejected_range: int = 0      # outside the joint limits by more than RANGE_TOLERANCE
    clamped: int = 0
    slew_limited: int = 0
    coalesced: int = 0


@dataclass
class DriverCore:
    """Command and telemetry conversions of the driver (one instance per robot).

    Args:
        servos: six calibrations.
        zeta_min, zeta_max: joint limits (rad, scalar or six), from the robot description.
        k_t: torque constant(s) at the horn (N·m/A), from the robot description.
        sensor: current-sensor model.
        max_speed: slew limit (rad/s, robot time) between consecutive commands; 0 = none.
        slew_period: the longest time (s) the slew allowance builds up over between two commands; 0 = no bound.
            After the driver stalled (a starved or paused host) the newest trajectory point can lie far ahead of the
            last one sent, and the time since it would allow the whole jump: the servos jumped there at their full
            speed, a real jerk that the collision observer saw as a collision. With one command period here they
            catch up at max_speed instead (docs/driver_timing.md, "Catching up after a stall").
        joint_names: names expected in joint_commands / used in joint_states.
    """

    servos: list[ServoCalibration]
    zeta_min: np.ndarray
    zeta_max: np.ndarray
    k_t: np.ndarray
    sensor: CurrentSensorModel = field(default_factory=CurrentSensorModel)
    max_speed: float = 0.0
    slew_period: float = 0.0
    joint_names: tuple[str, ...] = JOINT_NAMES
    offsets: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))

    def __post_init__(self) -> None:
        self.zeta_min = np.broadcast_to(np.asarray(self.zeta_min, float), (N_JOINTS,)).copy()
        self.zeta_max = np.broadcast_to(np.asarray(self.zeta_max, float), (N_JOINTS,)).copy()
        self.k_t = np.broadcast_to(np.asarray(self.k_t, float), (N_JOINTS,)).copy()
        self.offsets = np.broadcast_to(np.asarray(self.offsets, float), (N_JOINTS,)).copy()
        if np.any(self.zeta_min > self.zeta_max):
            raise DriverConfigError(f"joint limits zeta_min {self.zeta_min} above zeta_max {self.zeta_max}")
        if not (math.isfinite(self.max_speed) and self.max_speed >= 0):
            raise DriverConfigError(f"max_speed must be >= 0 rad/s (0 = off), got {self.max_speed}")
        if not (math.isfinite(self.slew_period) and self.slew_period >= 0):
            raise DriverConfigError(f"slew_period must be >= 0 s (0 = no bound), got {self.slew_period}")
        self.counters = CommandCounters()
        self.commanded = np.full(N_JOINTS, np.nan)   # last commanded angles (rad), NaN before the first
        self._last_cmd_time: float | None = None     # host monotonic time of the last command (rest detection)
        self._slew_time: float | None = None         # its time on the slew limit's clock (robot time)

    # ------------------------------------------------------------------------------------------ commands
    def order_command(self, names: Sequence[str], positions: Sequence[float]) -> np.ndarray:
        """Positions (6,) in joint order from a JointState's names/positions (empty names: given order).

        A command is executed whole or not at all: one outside the joint limits (as 1e9 rad) is rejected, not
        clamped, and the servos keep the last good command.

        Raises:
            CommandRejected: wrong size, unknown/missing names, a non-finite value or one outside the joint range
                (each counted in `counters` by reason).
        """
        pos = np.asarray(positions, dtype=float)
        if len(names) == 0:
            if pos.shape != (N_JOINTS,):
                self.counters.rejected_size += 1
                raise CommandRejected(f"{pos.size} positions without names; expected {N_JOINTS}")
            ordered = pos
        else:
            if len(names) != len(pos):
                self.counters.rejected_size += 1
                raise CommandRejected(f"{len(names)} names but {len(pos)} positions")
            index = {n: i for i, n in enumerate(names)}
            missing = [n for n in self.joint_names if n not in index]
            if missing:
                self.counters.rejected_names += 1
                raise CommandRejected(f"joint command lacks {missing} (got {list(names)})")
            ordered = np.array([pos[index[n]] for n in self.joint_names])
        if not np.all(np.isfinite(ordered)):
            self.counters.rejected_nan += 1
            raise CommandRejected(f"non-finite joint command {ordered.tolist()}")
        outside = (ordered < self.zeta_min - RANGE_TOLERANCE) | (ordered > self.zeta_max + RANGE_TOLERANCE)
        if np.any(outside):
            self.counters.rejected_range += 1
            i = int(np.argmax(outside))
            raise CommandRejected(f"{self.joint_names[i]} = {ordered[i]:.6g} rad outside its range "
                                  f"[{self.zeta_min[i]:.4f}, {self.zeta_max[i]:.4f}] rad")
        return ordered

    def limit_command(self, zeta: np.ndarray, now: float | None = None) -> np.ndarray:
        """Clamp to the joint limits and (if max_speed > 0) to the slew limit from the last command: at most
        max_speed·min(now − then, slew_period) per angle, `now` on the clock `accept` got as `slew_now` (robot time:
        sim time in simulation; default host monotonic)."""
        now = time.monotonic() if now is None else now
        z = np.clip(zeta, self.zeta_min, self.zeta_max)
        if np.any(z != zeta):
            self.counters.clamped += 1
        if self.max_speed > 0 and self._slew_time is not None and np.all(np.isfinite(self.commanded)):
            dt = max(now - self._slew_time, 1e-3)
            if self.slew_period > 0:
                dt = min(dt, self.slew_period)
            step = self.max_speed * dt
            zs = np.clip(z, self.commanded - step, self.commanded + step)
            if np.any(zs != z):
                self.counters.slew_limited += 1
            z = zs
        return z

    def pulses_from_angles(self, zeta: np.ndarray) -> list[int]:
        """Pulse widths (us) for six arm angles (rad)."""
        return [s.pulse_from_angle(float(a)) for s, a in zip(self.servos, zeta)]

    def accept(self, zeta: np.ndarray, now: float | None = None, slew_now: float | None = None) -> list[int]:
        """Record `zeta` as the commanded position at host time `now` (monotonic) and, for the slew limit, at
        `slew_now` (default `now`); return its pulse widths (us)."""
        self.commanded = np.asarray(zeta, float).copy()
        self._last_cmd_time = time.monotonic() if now is None else now
        self._slew_time = self._last_cmd_time if slew_now is None else float(slew_now)
        self.counters.accepted += 1
        return self.pulses_from_angles(self.commanded)

    @property
    def last_command_time(self) -> float | None:
        return self._last_cmd_time

    # ------------------------------------------------------------------------------------------ telemetry
    def currents_from_counts(self, counts: Sequence[int]) -> np.ndarray:
        """Motor currents I - I_0 (A) from six raw ADC counts."""
        return self.sensor.current_from_counts(counts) - self.offsets

    def torques_from_currents(self, currents: np.ndarray) -> np.ndarray:
        """Actuator torques tau = K_t (I - I_0) (N·m) from offset-corrected currents (A)."""
        return self.k_t * currents

    def calibrate_offsets(self, raw_counts: np.ndarray) -> np.ndarray:
        """Set I_0 to the mean current of `raw_counts` (N, 6) taken at rest; returns the offsets (A)."""
        c = np.asarray(raw_counts, dtype=float)
        if c.ndim != 2 or c.shape[1] != N_JOINTS or c.shape[0] == 0:
            raise CommandRejected(f"calibration needs (N>0, 6) samples, got shape {c.shape}")
        self.offsets = self.sensor.current_from_counts(c).mean(axis=0)
        return self.offsets.copy()


# ---------------------------------------------------------------------------------------------- configuration
SCALAR_KEYS = ("uno_port", "mega_port", "baud", "stream_rate_hz", "stale_timeout", "drop_after", "reconnect_period",
               "hello_timeout", "boot_delay", "stream_rerequest_period", "stream_reconnect_after", "command_rate_hz",
               "max_speed",
               "board_clock_max_extrapolation", "watchdog_ms", "diagnostics_period", "calibration_duration",
               "rest_quiet_time", "frame_id", "latch_report")
REQUIRED_KEYS = SCALAR_KEYS + ("joint_names", "sensor", "current_offsets", "servos")


def default_driver_config_path() -> Path:
    """hexa_driver/config/driver.yaml of this source tree (editable install) or of the ament share directory."""
    here = Path(__file__).resolve()
    candidates = [here.parents[3] / "hexa_driver" / "config" / "driver.yaml"]
    prefix = os.environ.get("AMENT_PREFIX_PATH", "")
    candidates += [Path(p) / "share" / "hexa_driver" / "config" / "driver.yaml" for p in prefix.split(":") if p]
    candidates.append(Path(sys.prefix) / "share" / "hexa_driver" / "config" / "driver.yaml")
    for c in candidates:
        if c.is_file():
            return c
    raise DriverConfigError(f"driver.yaml not found in {[str(c) for c in candidates]}")


def load_driver_config(path: str | os.PathLike | None = None) -> dict:
    """The driver configuration mapping (driver.yaml), checked for the required keys.

    Raises:
        DriverConfigError: the file is missing, not a mapping, or lacks a key (named).
    """
    p = Path(path) if path else default_driver_config_path()
    try:
        cfg = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise DriverConfigError(f"cannot read driver config {p}: {exc}") from exc
    if not isinstance(cfg, dict):
        raise DriverConfigError(f"driver config {p} is not a mapping")
    missing = [k for k in REQUIRED_KEYS if k not in cfg]
    if missing:
        raise DriverConfigError(f"driver config {p} lacks {missing}")
    if cfg["servos"] is not None:
        servo_calibrations_from_config(cfg["servos"])  # validate now
    CurrentSensorModel.from_dict(cfg["sensor"])
    return cfg


def servo_calibrations_from_description(desc: HexaDescription) -> list[ServoCalibration]:
    """Six ServoCalibration from a HexaDescription's actuator pulse map (centre of the joint range at the centre
    pulse, us_per_rad * direction_i, pulse limits).

    Raises:
        DriverConfigError: the description has no pulse map (naming the missing attribute).
    """
    names = ("pulse_center_us", "us_per_rad", "servo_direction", "pulse_min_us", "pulse_max_us")
    values = {}
    for name in names:
        if not hasattr(desc, name):
            raise DriverConfigError(f"robot description has no `{name}`: set `servos` in driver.yaml")
        values[name] = getattr(desc, name)
    zeta_ref = 0.5 * (np.asarray(desc.zeta_min, float) + np.asarray(desc.zeta_max, float))
    zeta_ref = np.broadcast_to(zeta_ref, (N_JOINTS,))
    # a calibration overlay's horn offsets: the horn sits at the nominal angle of its pulse plus the offset
    horn = (desc.section("calibration").get("horn_offset") if hasattr(desc, "sections")
            and "calibration" in desc.sections() else None)
    if horn is not None:
        zeta_ref = zeta_ref + np.asarray(horn, dtype=float).reshape(N_JOINTS)
    direction = np.broadcast_to(np.asarray(values["servo_direction"], float), (N_JOINTS,))
    return [ServoCalibration(zero_us=float(values["pulse_center_us"]),
                             us_per_rad=float(values["us_per_rad"]) * float(direction[i]),
                             zeta_ref=float(zeta_ref[i]), min_us=int(round(float(values["pulse_min_us"]))),
                             max_us=int(round(float(values["pulse_max_us"]))))
            for i in range(N_JOINTS)]


def driver_core_from_config(cfg: dict, zeta_min, zeta_max, k_t,
                            servos: list[ServoCalibration] | None = None) -> DriverCore:
    """DriverCore from a driver config plus the robot description's joint limits and K_t.

    `servos` (e.g. from servo_calibrations_from_description) is used when the config's `servos` is null.
    """
    if cfg["servos"] is not None or servos is None:
        servos = servo_calibrations_from_config(cfg["servos"])
    if servos is None:
        raise DriverConfigError("driver config `servos` is null and no calibration from the description was given")
    rate = float(cfg["command_rate_hz"])
    if not (math.isfinite(rate) and rate > 0):
        raise DriverConfigError(f"command_rate_hz must be > 0, got {cfg['command_rate_hz']}")
    if not MIN_RATE_HZ <= int(cfg["stream_rate_hz"]) <= MAX_RATE_HZ:
        raise DriverConfigError(f"stream_rate_hz must be in {MIN_RATE_HZ}..{MAX_RATE_HZ}, got {cfg['stream_rate_hz']}")
    return DriverCore(servos=servos, zeta_min=zeta_min, zeta_max=zeta_max,
                      k_t=k_t, sensor=CurrentSensorModel.from_dict(cfg["sensor"]),
                      max_speed=float(cfg["max_speed"]), slew_period=1.0 / rate,
                      joint_names=tuple(cfg["joint_names"]),
                      offsets=np.asarray(cfg["current_offsets"], dtype=float))


def driver_links_from_config(cfg: dict, core: DriverCore, on_samples, on_latch=None, on_state=None):
    """The (ServoLink, CurrentLink) of a driver config, not started (hexa.protocol.link).

    Args:
        cfg: the driver configuration (ports, baud, link supervision, watchdog, stream rate).
        core: its servos' pulse limits go to the Uno (SET_LIMITS).
        on_samples: `CurrentLink.on_samples`, called with each read's samples.
        on_latch: `ServoLink.on_latch`, used with `latch_report` (else, or None, the Uno's latch report stays off).
        on_state: called as `on_state(board, state)` with board "uno" or "mega".
    """
    from hexa.protocol.link import CurrentLink, ServoLink

    common: dict[str, Any] = dict(baud=int(cfg["baud"]), stale_timeout=float(cfg["stale_timeout"]),
                  drop_after=float(cfg["drop_after"]), reconnect_period=float(cfg["reconnect_period"]),
                  hello_timeout=float(cfg["hello_timeout"]), boot_delay=float(cfg["boot_delay"]),
                  stream_rerequest_period=float(cfg["stream_rerequest_period"]),
                  stream_reconnect_after=float(cfg["stream_reconnect_after"]))
    state = (lambda board: None) if on_state is None else (lambda board: lambda s: on_state(board, s))
    uno = ServoLink(str(cfg["uno_port"]), min_us=[s.min_us for s in core.servos],
                    max_us=[s.max_us for s in core.servos], watchdog_ms=int(cfg["watchdog_ms"]),
                    on_latch=on_latch if cfg["latch_report"] else None, on_state=state("uno"), **common)
    mega = CurrentLink(str(cfg["mega_port"]), rate_hz=int(cfg["stream_rate_hz"]), on_samples=on_samples,
                       on_state=state("mega"), **common)
    return uno, mega
