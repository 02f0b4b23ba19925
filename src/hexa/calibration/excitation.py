"""Periodic excitation of the Hexa for identification (Swevers et al.: finite Fourier series, optimized for the
condition number of the identification regressor).

Each plate DOF k (x y z α β γ) follows

    q_k(t) = q0_k + Σ_{l=1..L} a_kl sin(l ω t) + b_kl (cos(l ω t) − 1),      ω = 2π / period,

so the motion is periodic (averaging over periods removes noise), starts at the home pose q0 (q(0) = q0) and at rest
(Σ_l l a_kl = 0 per DOF: q̇(0) = 0, enforced by projection). The coefficients minimize cond(W) of the column-scaled
regressor W (hexa.calibration.regressor, nominal model, one period) subject to: every pose inside the workspace
(IK with margin from the serial singularity, the amplitude bounds `BOUNDS`), |ζ̇| ≤ `speed_fraction`·speed_max and
the model's servo torques ≤ `torque_fraction`·torque_max, with a penalty on the time any servo spends below
`SLOW_SPEED` (`slow_fraction`): Coulomb friction is told from viscous friction and the current offset by the speed
at which it saturates, so every servo reverses briskly instead of dwelling near rest. The search is a seeded random
start followed by a (1+λ) evolution strategy — reproducible, no gradient of cond needed.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from hexa.trajectories import FourierTrajectory

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from hexa.calibration.regressor import Regressor
    from hexa.dynamics.lagrange import HexaDynamicParameters
    from hexa.robots.hexa_description import HexaDescription

#: largest excursion from home per DOF (m, m, m, rad, rad, rad): inside the paper's workspace (±0.1 m, tilts ±30°).
#: ±6 cm in z: the plate's weight reaches every servo as a nearly constant torque, like the arms' own first moments
#: and the current offsets, and only a large change of the arm angles tells them apart (±4 cm left the plate mass
#: 4–7 % low on the realistic robot, ±6 cm 0–3 %)
BOUNDS = (0.08, 0.08, 0.06, math.radians(20.0), math.radians(20.0), math.radians(20.0))
#: rad/s: below this arm speed a servo's friction is in its transition from rest to Coulomb's (the realistic
#: robot's reaches ≈ 70 % of the Coulomb torque at 0.05 rad/s and all of it above ≈ 0.2 rad/s)
SLOW_SPEED = 0.05


class ExcitationError(ValueError):
    """A bad excitation request (period, harmonics, limits) or no feasible design; the message says which."""


@dataclass(frozen=True)
class ExcitationSettings:
    """Design knobs: `period` (s) of one cycle, `harmonics` L, `cycles` in the file, limits as fractions of the
    servo's speed and stall torque, `slow_fraction`: the time per period any servo may spend below SLOW_SPEED before
    the design is penalised, `iterations` of the search, `seed`, `rate_hz` of the written file."""

    period: float = 4.0
    harmonics: int = 5
    cycles: int = 7
    speed_fraction: float = 0.5
    torque_fraction: float = 0.6
    slow_fraction: float = 0.06
    iterations: int = 100
    seed: int = 0
    rate_hz: float = 100.0

    def __post_init__(self) -> None:
        if not (1.0 <= self.period <= 60.0):
            raise ExcitationError(f"period must be 1..60 s, got {self.period}")
        if not (1 <= self.harmonics <= 10):
            raise ExcitationError(f"harmonics must be 1..10, got {self.harmonics}")
        if not (1 <= self.cycles <= 100):
            raise ExcitationError(f"cycles must be 1..100, got {self.cycles}")
        for name in ("speed_fraction", "torque_fraction", "slow_fraction"):
            v = getattr(self, name)
            if not (0.0 < v <= 1.0):
                raise ExcitationError(f"{name} must be in (0, 1], got {v}")
        if self.iterations < 0:
            raise ExcitationError(f"iterations must be >= 0, got {self.iterations}")


@dataclass
class Excitation(FourierTrajectory):
    """A designed excitation: the Fourier series (hexa.trajectories.FourierTrajectory: coefficients a, b (6, L),
    home pose q0, period (s), cycles), and what the design achieved (`condition`, peak |ζ̇| and |τ| of the nominal
    model, `slow`: the largest fraction of a period a servo spends below SLOW_SPEED, `feasible`)."""

    condition: float = math.inf
    peak_speed: float = math.nan
    peak_torque: float = math.nan
    slow: float = math.nan
    feasible: bool = False
    history: list[float] = field(default_factory=list)

    def write(self, path: str | Path, rate_hz: float = 100.0, title: Sequence[str] = ()) -> Path:
        """Write the trajectory file the trajectory node plays (`--trajectory FILE`: CSV rows t x y z α β γ, SI),
        `cycles` periods long, with the design in `#` comment lines."""
        head = [f"hexa calibrate excite: {self.cycles} x {self.period:g} s Fourier excitation, "
                f"{self.a.shape[1]} harmonics, cond {self.condition:.1f}",
                f"peak |zeta_dot| {self.peak_speed:.3f} rad/s, peak |tau| (nominal model) {self.peak_torque:.3f} N*m, "
                f"slowest servo below {SLOW_SPEED:g} rad/s for {100 * self.slow:.1f} % of the period",
                *title]
        return super().write(path, rate_hz, head)

    @classmethod
    def read_design(cls, path: str | Path) -> "Excitation | None":
        """The design in a file written by `write` (None when the file has no design lines)."""
        series = FourierTrajectory.read_design(path)
        if series is None:
            return None
        return cls(q0=series.q0, a=series.a, b=series.b, period=series.period, feasible=True)


def _project_rest(a: NDArray) -> NDArray:
    """a with Σ_l l a_kl = 0 per DOF (q̇(0) = 0), by orthogonal projection."""
    l = np.arange(1, a.shape[1] + 1, dtype=float)
    return a - np.outer(a @ l, l) / float(l @ l)


class _Scorer:
    """cond(W), the limits and the slow fraction of one candidate, on one period sampled at `samples` points."""

    def __init__(self, desc: HexaDescription, settings: ExcitationSettings, samples: int = 64) -> None:
        from hexa.dynamics.lagrange import HexaDynamicParameters

        self.desc, self.s = desc, settings
        self.prm = HexaDynamicParameters.from_description(desc)
        self.t = np.arange(samples) * settings.period / samples
        self.scale: NDArray | None = None

    def __call__(self, exc: Excitation) -> tuple[float, float, float, float, bool]:
        from hexa.calibration.regressor import regressor
        from hexa.dynamics.lagrange import DynamicsError
        from hexa.servo_motion import servo_motion

        pose, vel, acc = exc.evaluate(self.t)
        if np.any(np.abs(pose - exc.q0) > np.asarray(BOUNDS) * 1.0001):
            return math.inf, math.nan, math.nan, math.nan, False
        try:
            state = servo_motion(self.desc, pose, vel, acc, self.prm)
            reg = regressor(self.prm, state)
        except (ValueError, DynamicsError):
            return math.inf, math.nan, math.nan, math.nan, False
        speed = float(np.abs(state.zeta_dot).max())
        slow = float(np.mean(np.abs(state.zeta_dot) < SLOW_SPEED, axis=0).max())
        n = self.prm
        tau = reg.torques(_sym(n), np.full(6, n.J_a), np.full(6, n.m_a * n.s_a), np.zeros(6), np.zeros(6))
        torque = float(np.abs(tau).max())
        W = identification_matrix(reg)
        if self.scale is None:
            self.scale = np.linalg.norm(W, axis=0) + 1e-12
        sv = np.linalg.svd(W / self.scale, compute_uv=False)
        cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
        ok = (speed <= self.s.speed_fraction * float(self.desc.speed_max)
              and torque <= self.s.torque_fraction * float(self.desc.torque_max))
        return cond, speed, torque, slow, ok


def _sym(prm: HexaDynamicParameters) -> NDArray:
    from hexa.calibration.regressor import sym_from_params

    return sym_from_params(prm)


def identification_matrix(reg: Regressor) -> NDArray:
    """The stacked (6N × P) regressor of the parameters the design must excite: the identifiable plate and rod
    columns, the per-servo J, (ms), friction columns and a constant per servo (the current sensor's zero offset,
    which an arm's slowly varying gravity torque resembles)."""
    from hexa.calibration.regressor import BASE_SYM

    n = reg.Y_sym.shape[0]
    ones = np.broadcast_to(np.eye(6), (n, 6, 6))
    # the arms' first moments across their line (the last 6 servo columns) are a small correction beside the
    # first moments along it: the design conditions the main parameters and identification adds them
    Y = np.concatenate([reg.Y_sym[..., list(BASE_SYM)], reg.servo_columns()[..., :24], ones], axis=2)
    return Y.reshape(n * 6, -1)


def design_excitation(desc: HexaDescription | None = None, settings: ExcitationSettings | None = None,
                      progress: Callable[[int, float], None] | None = None) -> Excitation:
    """The excitation of `settings` for the robot `desc` (default the packaged one): see the module docstring.

    progress: called with (iteration, best condition number so far).

    Raises:
        ExcitationError: no feasible design was found (limits too tight for the period).
    """
    from hexa.robots.hexa_description import load_hexa

    desc = desc or load_hexa()
    s = settings or ExcitationSettings()
    rng = np.random.default_rng([int(s.seed), 31])
    L = s.harmonics
    q0 = np.asarray(desc.home_pose, dtype=float)
    score = _Scorer(desc, s)
    # amplitude per harmonic falls as 1/l so that the speed and acceleration stay bounded at higher harmonics
    amp = np.asarray(BOUNDS)[:, None] / (np.arange(1, L + 1)[None, :] * L ** 0.5)
    best: Excitation | None = None
    best_cost = math.inf

    def cost(cond: float, speed: float, torque: float, slow: float, ok: bool) -> float:
        if not math.isfinite(cond):
            return math.inf
        over = max(0.0, speed / (s.speed_fraction * desc.speed_max) - 1.0) + \
            max(0.0, torque / (s.torque_fraction * desc.torque_max) - 1.0)
        return cond * (1.0 + 20.0 * over + 4.0 * max(0.0, slow / s.slow_fraction - 1.0)) + (0.0 if ok else 1e6)

    def trial(a: NDArray, b: NDArray) -> tuple[float, Excitation]:
        e = Excitation(q0=q0, a=_project_rest(a), b=b, period=s.period, cycles=s.cycles)
        cond, speed, torque, slow, ok = score(e)
        e.condition, e.peak_speed, e.peak_torque, e.slow, e.feasible = cond, speed, torque, slow, ok
        return cost(cond, speed, torque, slow, ok), e

    for scale in (1.0, 0.7, 0.5, 0.3, 0.15):   # random starts, shrinking until feasible ones appear
        for _ in range(12):
            c, e = trial(amp * scale * rng.uniform(-1, 1, amp.shape), amp * scale * rng.uniform(-1, 1, amp.shape))
            if c < best_cost:
                best_cost, best = c, e
        if best is not None and best.feasible:
            break
    if best is None or not math.isfinite(best_cost):
        raise ExcitationError("no excitation inside the workspace was found; lengthen the period or fewer harmonics")
    sigma = 0.2
    for it in range(s.iterations):
        for _ in range(4):
            step_a, step_b = rng.normal(size=amp.shape), rng.normal(size=amp.shape)
            c, e = trial(best.a + sigma * amp * step_a, best.b + sigma * amp * step_b)
            if c < best_cost:
                best_cost, best = c, e
                sigma = min(0.5, sigma * 1.5)
                break
        else:
            sigma = max(0.01, sigma * 0.85)
        best.history.append(best.condition)
        if progress is not None:
            progress(it + 1, best.condition)
    if not best.feasible:
        raise ExcitationError(f"no excitation within the limits (speed ≤ {s.speed_fraction:g}·speed_max, torque ≤ "
                              f"{s.torque_fraction:g}·torque_max) was found; lengthen the period or raise the limits")
    return best
