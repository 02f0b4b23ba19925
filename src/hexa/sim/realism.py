"""The realistic simulated robot: a *truth* that is not the nodes' model, hobby-servo mechanics, a real current
sensor's noise and host timing jitter. See docs/realism.md.

    from hexa.sim.realism import RealismConfig, draw_truth
    truth = draw_truth(load_hexa(), seed=3)             # masses, COMs, inertias, K_t, friction, offsets... per seed
    sim = Simulator(scenario="plate", seed=3, realism=RealismConfig.realistic())   # draws the same truth itself

`RealismConfig.ideal()` is the simulator without realism: the robot *is* the model, servos are MuJoCo
position actuators that take set-points at once, the sensor noise is the ADC's only, the host is punctual.
The truth (`RobotTruth`) only builds the simulated world and the virtual Mega's currents; no node reads it.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from hexa.protocol.sensor_model import CurrentSensorModel
    from hexa.robots.hexa_description import HexaDescription

#: The current sensor of the realistic robot: Allegro ACS712ELCTR-05B-T datasheet figures (Vcc = 5 V, 25 °C,
#: C_F = 47 nF on the filter pin, 2 kHz bandwidth) read by the Mega's 10-bit ADC (V_ref = 5 V, 4.88 mV/count).
ACS712_05B: dict[str, Any] = {
    "name": "ACS712ELCTR-05B-T",
    "sensitivity_typ": 0.185,        # V/A
    "sensitivity_min": 0.180,        # V/A (datasheet min/max over the part population)
    "sensitivity_max": 0.190,
    "noise_pp": 0.021,               # V peak-to-peak output noise (typ.), ≈ 6 σ → σ ≈ 3.5 mV ≈ 0.72 ADC counts
    "offset_max": 0.040,             # V electrical offset at 0 A (max) — removed by the zero-current calibration
}
ADC_VOLTS_PER_COUNT = 5.0 / 1024.0


@dataclass(frozen=True)
class Tolerances:
    """How far the truth may lie from the description (each drawn uniformly per seed unless said otherwise).

    mass: relative (±); com: absolute per axis (m, ±); inertia: relative per principal moment (±), applied to the
    second moments Σ_ii = ∫x_i² dm so that every drawn inertia is physically valid (I = tr(Σ)·1 − Σ, Σ ≥ 0: the
    triangle inequality holds); k_t: relative (±) per servo; coulomb: Coulomb friction as a fraction of the stall
    torque (lo, hi); viscous: viscous friction at the no-load speed as a fraction of the stall torque (lo, hi);
    current_offset_sigma: per-channel zero offset left after the zero-current calibration (A, 1 σ, Gaussian);
    rotor_inertia: reflected rotor inertia at the horn (kg·m², lo, hi); backlash: total gear play (rad, lo, hi);
    deadband: the servo amplifier's dead band (rad, total width; MG996R datasheet: 5 µs of pulse = 5/636.6 rad);
    horn_offset: where each horn sits on its servo's spline (rad, ±, uniform): the servo turns the horn to its
    set-point plus this offset (a 25-tooth spline leaves up to ±7.2° before the angle ↔ pulse calibration; 0 keeps
    the description's angle ↔ pulse exact)."""

    mass: float = 0.20
    com: float = 0.005
    inertia: float = 0.30
    k_t: float = 0.10
    coulomb: tuple[float, float] = (0.02, 0.07)
    viscous: tuple[float, float] = (0.0, 0.03)
    current_offset_sigma: float = 0.02
    rotor_inertia: tuple[float, float] = (1.0e-3, 3.0e-3)
    backlash: tuple[float, float] = (math.radians(0.3), math.radians(1.0))
    deadband: float = 5.0 / 636.6197723675814
    horn_offset: float = 0.0


@dataclass(frozen=True, eq=False)
class LinkTruth:
    """Mass (kg), COM (m, link frame) and inertia about the COM (3×3, kg·m², link frame) of one drawn link."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray

    def as_dict(self) -> dict[str, Any]:
        return {"mass": self.mass, "com": self.com.tolist(), "inertia": self.inertia.tolist()}


@dataclass(frozen=True, eq=False)
class RobotTruth:
    """The robot the simulator builds (never read by a node): each arm and rod its own, per-servo K_t, friction,
    rotor inertia, backlash and dead band, the sensor's per-channel gain and zero offset.

    k_t (6): N·m/A at the horn; coulomb (6): N·m; viscous (6): N·m·s/rad; rotor_inertia (6): kg·m²; backlash (6),
    deadband (6): rad; sensor_gain (6): true sensitivity / the driver's (ACS712 180–190 mV/A for 185);
    current_offset (6): A; horn_offset (6): rad, the horn's angle minus the servo's set-point at rest."""

    seed: int
    plate: LinkTruth
    arms: tuple[LinkTruth, ...]
    rods: tuple[LinkTruth, ...]
    k_t: np.ndarray
    coulomb: np.ndarray
    viscous: np.ndarray
    rotor_inertia: np.ndarray
    backlash: np.ndarray
    deadband: np.ndarray
    sensor_gain: np.ndarray
    current_offset: np.ndarray
    horn_offset: np.ndarray = field(default_factory=lambda: np.zeros(6))

    def currents(self, tau: np.ndarray) -> np.ndarray:
        """What the Mega's sensors read (A, the driver's sensitivity) for motor torques `tau` (N·m): (τ/K_t)·gain +
        offset."""
        return np.asarray(tau, dtype=float) / self.k_t * self.sensor_gain + self.current_offset

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"seed": self.seed, "plate": self.plate.as_dict(),
                               "arms": [a.as_dict() for a in self.arms], "rods": [r.as_dict() for r in self.rods]}
        for k in ("k_t", "coulomb", "viscous", "rotor_inertia", "backlash", "deadband", "sensor_gain",
                  "current_offset", "horn_offset"):
            out[k] = getattr(self, k).tolist()
        return out


def _link_nominal(desc: HexaDescription, name: str) -> LinkTruth:
    li = getattr(desc, name)
    I = np.asarray(li.inertia, dtype=float)
    return LinkTruth(float(li.mass), np.asarray(li.com, dtype=float).copy(), np.diag(I) if I.shape == (3,) else I)


def _draw_link(nominal: LinkTruth, rng: np.random.Generator, tol: Tolerances) -> LinkTruth:
    mass = nominal.mass * rng.uniform(1.0 - tol.mass, 1.0 + tol.mass)
    com = nominal.com + rng.uniform(-tol.com, tol.com, 3)
    # principal axes of the nominal inertia; scale the second moments Σ_ii (valid by construction)
    w, V = np.linalg.eigh(nominal.inertia)
    sigma = np.maximum(0.5 * (w.sum() - 2.0 * w), 0.0)          # Σ_ii = (I_jj + I_kk − I_ii) / 2
    sigma = sigma * rng.uniform(1.0 - tol.inertia, 1.0 + tol.inertia, 3)
    w_new = sigma.sum() - sigma
    inertia = V @ np.diag(w_new) @ V.T
    return LinkTruth(float(mass), com, 0.5 * (inertia + inertia.T))


def nominal_truth(desc: HexaDescription) -> RobotTruth:
    """The truth that *is* the description: the ideal robot (no friction, no play, exact K_t and sensor)."""
    z = np.zeros(6)
    return RobotTruth(seed=-1, plate=_link_nominal(desc, "plate"), arms=(_link_nominal(desc, "arm"),) * 6,
                      rods=(_link_nominal(desc, "rod"),) * 6, k_t=np.full(6, float(desc.K_t)), coulomb=z.copy(),
                      viscous=z.copy(), rotor_inertia=z.copy(), backlash=z.copy(), deadband=z.copy(),
                      sensor_gain=np.ones(6), current_offset=z.copy())


def draw_truth(desc: HexaDescription, seed: int, tolerances: Tolerances | None = None) -> RobotTruth:
    """The robot of `seed`: the description's values with errors drawn within `tolerances` (see `Tolerances`).

    The same (description, seed, tolerances) always gives the same truth; masses stay positive and inertias valid.
    """
    tol = tolerances or Tolerances()
    rng = np.random.default_rng([int(seed), 20])
    stall, speed = float(desc.torque_max), float(desc.speed_max)
    plate = _draw_link(_link_nominal(desc, "plate"), rng, tol)
    arm0, rod0 = _link_nominal(desc, "arm"), _link_nominal(desc, "rod")
    arms = tuple(_draw_link(arm0, rng, tol) for _ in range(6))
    rods = tuple(_draw_link(rod0, rng, tol) for _ in range(6))
    s = ACS712_05B
    return RobotTruth(
        seed=int(seed), plate=plate, arms=arms, rods=rods,
        k_t=float(desc.K_t) * rng.uniform(1.0 - tol.k_t, 1.0 + tol.k_t, 6),
        coulomb=stall * rng.uniform(*tol.coulomb, 6),
        viscous=stall / speed * rng.uniform(*tol.viscous, 6),
        rotor_inertia=rng.uniform(*tol.rotor_inertia, 6),
        backlash=rng.uniform(*tol.backlash, 6),
        deadband=np.full(6, tol.deadband),
        sensor_gain=rng.uniform(s["sensitivity_min"], s["sensitivity_max"], 6) / s["sensitivity_typ"],
        current_offset=rng.normal(0.0, tol.current_offset_sigma, 6),
        # its own stream: the draws above stay those of the seed whatever this tolerance is
        horn_offset=np.random.default_rng([int(seed), 21]).uniform(-tol.horn_offset, tol.horn_offset, 6))


@dataclass(frozen=True)
class JitterConfig:
    """Host timing of the offline runs (`hexa eval`): a command reaches the servo board `command_mean` s late on
    average (exponential, capped at `command_max`), a sample's host receive stamp is late by |N(0, sample_sigma)| plus,
    with probability `spike_rate` per sample, a scheduling spike up to `spike_max` s. Board times are exact. With
    probability `loss_rate` per sample the host loses the samples of the next U(0, `loss_max`) s (a stalled host whose
    serial buffer overflowed): the nodes see a gap in board time. Both presets lose none."""

    command_mean: float = 0.0
    command_max: float = 0.0
    sample_sigma: float = 0.0
    spike_rate: float = 0.0
    spike_max: float = 0.0
    loss_rate: float = 0.0
    loss_max: float = 0.0

    def command_delay(self, rng: np.random.Generator) -> float:
        if self.command_mean <= 0.0:
            return 0.0
        return float(min(rng.exponential(self.command_mean), self.command_max))

    def loss(self, rng: np.random.Generator) -> float:
        """Seconds of samples lost from this one on (0: none; draws from `rng` only when losses are on)."""
        if self.loss_rate <= 0.0 or rng.random() >= self.loss_rate:
            return 0.0
        return float(rng.uniform(0.0, self.loss_max))

    def sample_delay(self, rng: np.random.Generator) -> float:
        d = abs(rng.normal(0.0, self.sample_sigma)) if self.sample_sigma > 0 else 0.0
        if self.spike_rate > 0 and rng.random() < self.spike_rate:
            d += rng.uniform(0.0, self.spike_max)
        return float(d)


@dataclass(frozen=True)
class RealismConfig:
    """Which effects the simulated robot has (one switch each); `ideal()` and `realistic()` are the two presets.

    truth: build the robot from `draw_truth(desc, seed, tolerances)` (else the description itself); servo_mechanics:
    the servo law in Python with friction (Coulomb + viscous), rotor inertia, backlash and dead band of the truth
    (else MuJoCo position actuators, frictionless); frame_period: the servo board's pulse frame (s, None: the
    description's `sim.servo.frame_period`); current_noise_counts: ADC-count σ of the sensor noise (None: the
    description's); jitter: host timing of the offline runs."""

    name: str = "ideal"
    truth: bool = False
    servo_mechanics: bool = False
    frame_period: float | None = None
    current_noise_counts: float | None = None
    tolerances: Tolerances = field(default_factory=Tolerances)
    jitter: JitterConfig = field(default_factory=JitterConfig)

    @staticmethod
    def ideal() -> "RealismConfig":
        """The robot is its model, set-points at once, ADC noise only, a punctual host."""
        return RealismConfig()

    @staticmethod
    def realistic() -> "RealismConfig":
        """Every effect on: a drawn truth, servo friction/rotor inertia/backlash/dead band, the 20 ms pulse frame, the
        ACS712-05B's noise (21 mV p-p ≈ 3.5 mV σ ≈ 0.72 counts) and host jitter (commands 2 ms late on average,
        ≤ 15 ms; sample stamps σ 1 ms with 1 % spikes up to 10 ms)."""
        noise = ACS712_05B["noise_pp"] / 6.0 / ADC_VOLTS_PER_COUNT
        return RealismConfig(name="realistic", truth=True, servo_mechanics=True, frame_period=0.02,
                             current_noise_counts=float(noise),
                             jitter=JitterConfig(command_mean=0.002, command_max=0.015, sample_sigma=0.001,
                                                 spike_rate=0.01, spike_max=0.010))

    @staticmethod
    def named(name: str) -> "RealismConfig":
        """The preset called `name` ("ideal" | "realistic").

        Raises:
            ValueError: another name.
        """
        presets = {"ideal": RealismConfig.ideal, "realistic": RealismConfig.realistic}
        if name not in presets:
            raise ValueError(f"realism must be one of {sorted(presets)}, got {name!r}")
        return presets[name]()

    def replace(self, **changes: Any) -> "RealismConfig":
        return dataclasses.replace(self, **changes)


class ServoMechanics:
    """The six hobby servos of a truth, per physics step (vectorised): the amplifier's dead band and position loop,
    the stall-torque clamp, and the gear play between motor and horn.

    Motor torque τ_m = clip(kp·db(s − ζ) − kv·ζ̇, ±τ_max), db(e) = sign(e)·max(|e| − deadband/2, 0) (the servo does not
    react inside its dead band; its potentiometer is on the horn). The gear gap g (motor side minus horn, |g| ≤
    backlash/2) transmits τ_m while engaged (g at the stop τ_m pushes against); when τ_m reverses the motor crosses the
    gap on its rotor inertia, ġ̇ = τ_m/J_r − ζ̈, transmitting nothing, and re-engages at the other stop. The current
    sensors measure τ_m. Coulomb and viscous friction and the rotor inertia while engaged are the joint's MuJoCo
    `frictionloss`, `damping` and `armature` (see hexa.sim.mjcf)."""

    def __init__(self, truth: RobotTruth, kp: float, kv: float, torque_max: float) -> None:
        self.kp, self.kv, self.torque_max = float(kp), float(kv), float(torque_max)
        self.half_play = 0.5 * np.asarray(truth.backlash, dtype=float)
        self.half_band = 0.5 * np.asarray(truth.deadband, dtype=float)
        self.rotor = np.maximum(np.asarray(truth.rotor_inertia, dtype=float), 1e-6)
        self.reset()

    def reset(self) -> None:
        self.gap = np.zeros(6)
        self.gap_rate = np.zeros(6)
        self.engaged = np.zeros(6, dtype=bool)   # start centred: the first torque closes the gap

    def motor_torque(self, setpoint: np.ndarray, zeta: np.ndarray, zeta_dot: np.ndarray) -> np.ndarray:
        e = np.asarray(setpoint, dtype=float) - zeta
        e = np.sign(e) * np.maximum(np.abs(e) - self.half_band, 0.0)
        return np.clip(self.kp * e - self.kv * zeta_dot, -self.torque_max, self.torque_max)

    def step(self, tau_m: np.ndarray, zeta_ddot: np.ndarray, dt: float) -> np.ndarray:
        """Advance the gear gaps by `dt` under motor torques `tau_m`; returns the torques transmitted to the horns."""
        side = np.sign(self.gap)
        # an engaged servo stays engaged while its torque pushes against the stop it sits on
        release = self.engaged & (tau_m * side < 0.0)
        self.engaged &= ~release
        free = ~self.engaged
        if free.any():
            acc = tau_m[free] / self.rotor[free] - zeta_ddot[free]
            self.gap_rate[free] += acc * dt
            self.gap[free] += self.gap_rate[free] * dt
            hit = np.abs(self.gap[free]) >= self.half_play[free]
            idx = np.flatnonzero(free)[hit]
            self.gap[idx] = np.clip(self.gap[idx], -self.half_play[idx], self.half_play[idx])
            self.gap_rate[idx] = 0.0
            self.engaged[idx] = True
        return np.where(self.engaged, tau_m, 0.0)


def adc_counts(sensor: CurrentSensorModel, amps: np.ndarray, noise_counts: float,
               rng: np.random.Generator) -> np.ndarray:
    """The Mega's ADC counts for currents `amps` (A) through `sensor` (hexa.protocol.sensor_model), with Gaussian
    output noise of `noise_counts` σ (in counts) before quantisation — the virtual Mega's sampling, for offline runs."""
    volts = sensor.zero_voltage + sensor.sensitivity * np.asarray(amps, dtype=float)
    if noise_counts:
        volts = volts + rng.normal(0.0, noise_counts, np.shape(volts)) * (sensor.vref / sensor.full_scale)
    return sensor.counts_from_voltage(volts)
