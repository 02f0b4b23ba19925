"""Random smooth reachable plate trajectories, beside the paper's three: per seed, a periodic Fourier series per plate
DOF (`hexa.trajectories.FourierTrajectory`, the form of the calibration's excitation) that starts at the home pose at
rest and stays inside the workspace and the servos' limits all along.

The draw (reproducible per seed): a period in `period`, L = `harmonics`, coefficients a_kl, b_kl uniform in
±WORKSPACE_k / l (the amplitude falls as 1/l, so that speed and acceleration stay bounded at the higher harmonics),
projected so that the motion starts at rest and without acceleration (Σ_l l a_kl = 0: q̇(0) = 0; Σ_l l² b_kl = 0:
q̈(0) = 0) — the trajectory node's start blend and the servos see no step. That shape is scaled by the largest
factor (bisection) that keeps, on one period, every pose within WORKSPACE of home and reachable by the inverse
kinematics (hexa.servo_motion: the serial-singularity margin and the joint range included), |ζ̇| ≤
`speed_fraction`·speed_max, |ζ̈| ≤ `accel_max` and the nominal model's free-motion |τ| ≤ `torque_fraction`·
torque_max (the servo's acceleration limit under load); then by an `intensity` drawn in its range, so that some
trajectories crawl and others reach a limit. The result is checked again at `check_rate_hz`, the rate of the file
`write` gives the trajectory node (`hexa trajectory random:SEED --out FILE`, `hexa bringup sim --trajectory FILE`).
"""
from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hexa.servo_motion import MotionPeaks, motion_peaks
from hexa.trajectories import RANDOM_PREFIX, FourierTrajectory

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from hexa.robots.hexa_description import HexaDescription

#: largest excursion from the home pose per DOF (m, m, m, rad, rad, rad): the paper's workspace (x, y ± 0.1 m,
#: z −0.60…−0.50 m, tilts ± 30°; the paper's yaw is fixed, ± 20° here)
WORKSPACE = (0.10, 0.10, 0.05, math.radians(20.0), math.radians(30.0), math.radians(30.0))
#: bisection steps of the scale search (the scale is then within 2⁻¹² of its largest feasible value)
BISECTIONS = 12


class RandomTrajectoryError(ValueError):
    """Bad settings, or no feasible trajectory for a seed; the message says which."""


@dataclass(frozen=True)
class RandomTrajectorySettings:
    """The draw (module docstring): `period` range (s), `harmonics` L, `cycles` per run, `intensity` range (the
    fraction of the largest feasible scale), limits as fractions of the servo's speed and stall torque and `accel_max`
    (rad/s²; 20: the realistic servos' unmodelled rotor inertia, ≤ 3·10⁻³ kg·m², then takes ≤ 0.06 N·m, a sixth of
    the observer's servo threshold), `samples` per period in the search, `check_rate_hz` of the final check."""

    period: tuple[float, float] = (4.0, 12.0)
    harmonics: int = 4
    cycles: int = 2
    intensity: tuple[float, float] = (0.4, 1.0)
    speed_fraction: float = 0.25
    accel_max: float = 20.0
    torque_fraction: float = 0.6
    samples: int = 200
    check_rate_hz: float = 100.0

    def __post_init__(self) -> None:
        lo, hi = self.period
        if not (1.0 <= lo <= hi <= 60.0):
            raise RandomTrajectoryError(f"period range must lie in 1..60 s, low <= high, got {self.period}")
        if not (1 <= self.harmonics <= 10):
            raise RandomTrajectoryError(f"harmonics must be 1..10, got {self.harmonics}")
        if not (1 <= self.cycles <= 1000):
            raise RandomTrajectoryError(f"cycles must be 1..1000, got {self.cycles}")
        lo, hi = self.intensity
        if not (0.0 < lo <= hi <= 1.0):
            raise RandomTrajectoryError(f"intensity range must lie in (0, 1], low <= high, got {self.intensity}")
        for name in ("speed_fraction", "torque_fraction"):
            v = getattr(self, name)
            if not (0.0 < v <= 1.0):
                raise RandomTrajectoryError(f"{name} must be in (0, 1], got {v}")
        if not (math.isfinite(self.accel_max) and self.accel_max > 0):
            raise RandomTrajectoryError(f"accel_max must be > 0 rad/s², got {self.accel_max}")
        if self.samples < 16 or not self.check_rate_hz > 0:
            raise RandomTrajectoryError(f"samples must be >= 16 and check_rate_hz > 0, got {self.samples}, "
                                        f"{self.check_rate_hz}")


@dataclass
class RandomTrajectory(FourierTrajectory):
    """The random trajectory of `seed`: its series, the `scale` and `intensity` it was drawn at, and the servo `peaks`
    of the final check (hexa.servo_motion.MotionPeaks)."""

    seed: int = 0
    scale: float = 0.0
    intensity: float = 0.0
    peaks: MotionPeaks = field(default_factory=lambda: MotionPeaks(math.nan, math.nan, math.nan))

    @property
    def name(self) -> str:
        return f"{RANDOM_PREFIX}{self.seed}"

    def write(self, path: str | Path, rate_hz: float = 100.0, title: Sequence[str] = ()) -> Path:
        """Write the pose file the trajectory node plays (hexa.trajectories.FourierTrajectory.write), with the draw and
        its peaks in the comment lines."""
        p = self.peaks
        head = [f"hexa trajectory {self.name}: {self.cycles} x {self.period:.3f} s random Fourier trajectory, "
                f"{self.a.shape[1]} harmonics, scale {self.scale:.4f} x intensity {self.intensity:.3f}",
                f"peak |zeta_dot| {p.speed:.3f} rad/s, |zeta_ddot| {p.accel:.3f} rad/s^2, |tau| (nominal model) "
                f"{p.torque:.3f} N*m", *title]
        return super().write(path, rate_hz, head)


def _project_start(a: NDArray, b: NDArray) -> tuple[NDArray, NDArray]:
    """(a, b) with Σ_l l a_kl = 0 and Σ_l l² b_kl = 0 per DOF (q̇(0) = q̈(0) = 0), by orthogonal projection."""
    l1 = np.arange(1, a.shape[1] + 1, dtype=float)
    l2 = l1 * l1
    return a - np.outer(a @ l1, l1) / float(l1 @ l1), b - np.outer(b @ l2, l2) / float(l2 @ l2)


class _Limits:
    """Whether a scaled shape stays inside the workspace and the servos' limits on given sample times."""

    def __init__(self, desc: HexaDescription, s: RandomTrajectorySettings, t: NDArray) -> None:
        from hexa.dynamics.lagrange import HexaDynamicParameters

        self.desc, self.s, self.t = desc, s, t
        self.prm = HexaDynamicParameters.from_description(desc)
        self.speed = s.speed_fraction * float(desc.speed_max)
        self.torque = s.torque_fraction * float(desc.torque_max)

    def peaks(self, traj: FourierTrajectory) -> MotionPeaks | None:
        """The peaks along `traj`, None when a pose leaves the workspace or a limit is exceeded."""
        pose, vel, acc = traj.evaluate(self.t)
        if np.any(np.abs(pose - traj.q0) > np.asarray(WORKSPACE) * (1.0 + 1e-9)):
            return None
        p = motion_peaks(self.desc, pose, vel, acc, self.prm)
        ok = p.reachable and p.speed <= self.speed and p.accel <= self.s.accel_max and p.torque <= self.torque
        return p if ok else None


def random_trajectory(seed: int, desc: HexaDescription | None = None,
                      settings: RandomTrajectorySettings | None = None) -> RandomTrajectory:
    """The random trajectory of `seed` for the robot `desc` (default the packaged one); see the module docstring.
    With the defaults (desc and settings None) the result is cached per seed and shared: do not modify it.

    Raises:
        RandomTrajectoryError: a negative seed, or no feasible scale for the drawn shape (not seen with the
            defaults).
    """
    if desc is None and settings is None:
        return _default_random_trajectory(int(seed))
    return _draw(int(seed), desc, settings or RandomTrajectorySettings())


@functools.lru_cache(maxsize=256)
def _default_random_trajectory(seed: int) -> RandomTrajectory:
    return _draw(seed, None, RandomTrajectorySettings())


def _draw(seed: int, desc: HexaDescription | None, s: RandomTrajectorySettings) -> RandomTrajectory:
    from hexa.robots.hexa_description import load_hexa

    if seed < 0:
        raise RandomTrajectoryError(f"seed must be >= 0, got {seed}")
    desc = desc or load_hexa()
    rng = np.random.default_rng([seed, 0x7261])
    L = s.harmonics
    period = round(float(rng.uniform(*s.period)), 2)   # whole 10 ms steps: a 100 Hz file holds whole periods
    amp = np.asarray(WORKSPACE)[:, None] / np.arange(1, L + 1)[None, :]
    a, b = _project_start(amp * rng.uniform(-1.0, 1.0, (6, L)), amp * rng.uniform(-1.0, 1.0, (6, L)))
    intensity = float(rng.uniform(*s.intensity))
    q0 = np.asarray(desc.home_pose, dtype=float)

    def shaped(scale: float) -> RandomTrajectory:
        return RandomTrajectory(q0=q0, a=scale * a, b=scale * b, period=period, cycles=s.cycles, seed=seed,
                                scale=scale)

    search = _Limits(desc, s, np.arange(s.samples) * period / s.samples)
    # the scale at which the shape touches the workspace's box, then the largest one within every limit below it
    excursion = np.abs(shaped(1.0).evaluate(search.t)[0] - q0).max(axis=0)
    hi = float(np.min(np.asarray(WORKSPACE) / np.maximum(excursion, 1e-12)))
    lo = 0.0
    if search.peaks(shaped(hi)) is not None:
        lo = hi
    else:
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if search.peaks(shaped(mid)) is not None else (lo, mid)
    if lo <= 0.0:
        raise RandomTrajectoryError(f"random trajectory {seed}: no feasible scale for its shape")
    check = _Limits(desc, s, np.arange(int(math.ceil(period * s.check_rate_hz)) + 1) / s.check_rate_hz)
    scale = intensity * lo
    for _ in range(20):   # the limits are not exactly monotonic in the scale: shrink until the fine check passes
        traj = shaped(scale)
        peaks = check.peaks(traj)
        if peaks is not None:
            traj.intensity, traj.peaks = scale / lo, peaks
            return traj
        scale *= 0.9
    raise RandomTrajectoryError(f"random trajectory {seed}: the drawn shape fails the check at "
                                f"{s.check_rate_hz:g} Hz")
