"""CUSUM collision detector on the residual whitened by a motion-dependent uncertainty (beside seed 000 §3.1).

The paper's criterion (seed 000 §3.1, |r_j| > r_low, `hexa.dynamics.observer.CollisionDetector`) compares each sample
with a fixed threshold. This detector asks a sequential question instead, per channel j (the six plate axes of r,
then the residual as the six servo torques τ_r = J_ζ⁻ᵀ r):

    s_j(t) = th_j · (1 + c_v‖ζ̇‖∞ + c_a‖ζ̈‖∞)              the channel's scale: the threshold, widened with motion
    b_j   ← b_j + (Δt/τ_b)(x_j/th_j − b_j) while g_j = 0    the channel's slow baseline (model error), τ_b
    z_j    = |x_j/th_j − b_j| · th_j / s_j               the whitened residual (1 = at the scaled threshold)
    g_j   ← max(0, g_j + Δt·(z_j − ν))                   one-sided CUSUM (Page 1954) on z_j with drift ν
    START when some g_j ≥ h; its onset is the last time g_j was 0 (the CUSUM's change-point estimate)
    END when every z_j < release_ratio for min_duration; then every g_j restarts at 0

Why each part:
- On a robot that is not its model the residual carries a slowly varying bias: a mass error is a constant force
  against gravity (up to 0.4 r_low on fz on the realistic simulated robot), inertia and friction errors follow the
  trajectory at < 2 Hz. The baseline b_j takes it out; it follows only while the channel's sum is 0 (no evidence
  of a contact) and stands still from the first sample of evidence to the END, so a contact is never learnt as
  model error. A contact that builds up over longer than τ_b without ever moving the sum is partly absorbed.
- The residual's error in free motion is model error (masses, inertias, friction, K_t of a robot that is not its
  model) and the servos' set-point timing (a 20 ms pulse frame: the set-point lags the command by up to
  ‖ζ̇‖·20 ms). Both grow with the motion — velocity (friction, the pulse frame's lag) and acceleration (inertia) — so
  the scale widens with ‖ζ̇‖∞ and ‖ζ̈‖∞ (c_v, c_a) and narrows at rest and in slow motion, where a contact shows
  sooner.
- A fixed threshold with a minimum duration waits min_duration after every crossing. The CUSUM weighs how far
  over the drift the residual is: a strong contact crosses h in one or two samples, a weak one after its excess
  has summed to h, and a noise peak that stays near ν never does.
- The plate axes and the servo torques are one detector (a START from either), as in the live detector: plate
  contacts show on the plate axes, arm and rod contacts on their servo.

ζ̈ is the derivative of the ζ̇ given with `motion`, low-pass filtered with time constant `accel_tau`. Without
`motion` calls the scale is the threshold itself (c_v, c_a unused).

Cost: a handful of whole-array operations on twelve values per sample (`hexa bench dynamics`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable

import numpy as np

from hexa.dynamics.observer import CollisionDetector, CollisionEvent, ObserverConfig, ObserverError

if TYPE_CHECKING:
    from numpy.typing import NDArray

DETECTORS = ("threshold", "cusum")
#: longest sample spacing (s) one CUSUM step integrates; a longer gap counts as this much
MAX_STEP = 0.05


@dataclass(frozen=True)
class CusumConfig:
    """Settings of the CUSUM detector (module docstring), beside the observer's thresholds, release_ratio and
    min_duration (`ObserverConfig`), which it shares with the threshold detector.

    drift: ν, in threshold units (z = 1 at the scaled threshold); alarm: h, threshold units × s; velocity_gain: c_v
    (s/rad); accel_gain: c_a (s²/rad); accel_tau: s, time constant of ζ̈ from ζ̇; baseline_tau: τ_b (s), 0 = no
    baseline.
    """

    # tuned on the realistic simulated robot (`hexa eval`, docs/detectors.md "The CUSUM detector against the
    # paper's"): with the node's thresholds, no false alarm down to thresholds × 0.8 in free motion; c_v = 0: the
    # campaign's trajectories move at nearly constant speed, so velocity does not separate free-motion peaks there
    drift: float = 0.5
    alarm: float = 0.01
    velocity_gain: float = 0.0
    accel_gain: float = 0.01
    accel_tau: float = 0.02
    baseline_tau: float = 0.25

    def __post_init__(self) -> None:
        for name in ("drift", "alarm", "velocity_gain", "accel_gain", "accel_tau", "baseline_tau"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ObserverError(f"cusum {name} must be a finite value >= 0, got {v!r}")
        if self.alarm <= 0:
            raise ObserverError(f"cusum alarm must be > 0 (threshold units × s), got {self.alarm!r}")
        if self.accel_tau <= 0:
            raise ObserverError(f"cusum accel_tau must be > 0 s, got {self.accel_tau!r}")


class CusumDetector(CollisionDetector):
    """CUSUM on the motion-whitened residual (module docstring); the interface of `CollisionDetector`, whose
    thresholds it takes as its scales: `update(t, r, servo)` → (twelve over-scaled-threshold flags, events),
    `active`, `count`, `reset()`, `thresholds` and `servo_thresholds` (the configured ones, as published on
    `residual`; `scaled_thresholds()` gives them × the motion's factor), `set_thresholds`, `set_servo_thresholds`;
    and `motion(t, zeta_dot)` before a sample to follow the motion.

    Raises (constructor, set_*): ObserverError naming a bad value.
    """

    def __init__(self, config: ObserverConfig, cusum: CusumConfig | None = None) -> None:
        self.cusum = cusum or CusumConfig()
        self._u = 1.0
        self._motion: tuple[float, list[float]] | None = None   # (t, ζ̇) of the last motion sample
        self._accel = 0.0
        super().__init__(config)   # thresholds → self._scale (1/threshold per channel, 0 = not checked), reset()

    def reset(self) -> None:
        super().reset()
        # per-channel state as Python lists: twelve values cost less in plain floats than in numpy calls
        self._g = [0.0] * 12
        self._b = [0.0] * 12   # the slow baseline of each channel (threshold units)
        self._zero_t = [-math.inf] * 12   # last time each g_j was 0: the change-point estimate
        self._pk = [0.0] * 12
        self._t: float | None = None

    def break_runs(self) -> None:
        """The input stream had a gap: no CUSUM step integrates across it (the next sample's Δt is 0) and every sum
        starts over from the next sample, so evidence before the gap never adds to evidence after it; a collision
        in progress stays active and its release run restarts (`CollisionDetector.break_runs`)."""
        super().break_runs()
        self._t = None
        self._g = [0.0] * 12   # each g_j is 0 at the next sample, which becomes its zero time (its change point)

    def set_thresholds(self, thresholds: Iterable[float]) -> None:
        super().set_thresholds(thresholds)
        self._sc = self._scale.tolist()

    def set_servo_thresholds(self, thresholds: Iterable[float]) -> None:
        super().set_servo_thresholds(thresholds)
        self._sc = self._scale.tolist()

    def set_cusum(self, cusum: CusumConfig) -> None:
        """New CUSUM settings at run time; the sums go on."""
        self.cusum = cusum

    @property
    def uncertainty(self) -> float:
        """The factor 1 + c_v‖ζ̇‖∞ + c_a‖ζ̈‖∞ on every threshold at the last sample."""
        return self._u

    def scaled_thresholds(self) -> NDArray:
        """The twelve thresholds (plate axes, then servos) × the uncertainty factor at the last sample."""
        return np.concatenate([self._th, self._th_servo]) * self._u

    def motion(self, t: float, zeta_dot: NDArray | None) -> None:
        """ζ̇ (rad/s) at time t, before the residual sample of t: it sets the uncertainty factor."""
        if zeta_dot is None or len(zeta_dot) != 6:
            return
        zd: list[float] = zeta_dot.tolist() if hasattr(zeta_dot, "tolist") else [float(v) for v in zeta_dot]
        v = max(abs(x) for x in zd)
        if not math.isfinite(v):
            return
        c = self.cusum
        prev = self._motion
        if prev is not None and t > prev[0]:
            dt = t - prev[0]
            a = max(abs(x - y) for x, y in zip(zd, prev[1])) / dt
            self._accel += (a - self._accel) * min(1.0, dt / c.accel_tau)
        self._motion = (t, zd)
        self._u = 1.0 + c.velocity_gain * v + c.accel_gain * self._accel

    def update(self, t: float, r: NDArray, servo: NDArray | None = None) -> tuple[NDArray, tuple[CollisionEvent, ...]]:
        """Feed one residual sample r (plate axes) and optionally τ_r (servo torques; None or NaN: not checked);
        returns the twelve over-scaled-threshold flags (plate axes, then servos) and the events it caused."""
        value = r.tolist() + ([0.0] * 6 if servo is None else servo.tolist())
        c = self.cusum
        sc, g, b, u = self._sc, self._g, self._b, 1.0 / self._u
        dt = 0.0 if self._t is None else min(max(t - self._t, 0.0), MAX_STEP)
        self._t = t
        follow = min(1.0, dt / c.baseline_tau) if c.baseline_tau > 0 else 0.0
        active, drift = self.active, c.drift
        z = [0.0] * 12
        top_j, top_g = 0, -1.0
        for j in range(12):
            v = value[j]
            if v != v:   # NaN servo torques (a singular J_ζ): not checked
                value[j] = v = 0.0
            x = v * sc[j] - b[j]
            zj = z[j] = abs(x) * u
            if active:
                continue
            gj = g[j] + dt * (zj - drift)
            if gj <= 0.0:
                gj = 0.0
                self._zero_t[j] = t
                b[j] += follow * x   # the baseline follows only channels without evidence of a contact
            g[j] = gj
            if gj > top_g:
                top_j, top_g = j, gj
        over = np.array(z) > 1.0
        if not active:
            if top_g >= c.alarm:
                self.active = True
                self.count += 1
                self._onset = self._zero_t[top_j]
                self._pk = [abs(v) for v in value]
                self._release_since = None
                return over, (CollisionEvent("START", self.count, t, self._onset, top_j, value[top_j],
                                             abs(value[top_j]), 0.0),)
            return over, ()
        self._pk = [max(p, abs(v)) for p, v in zip(self._pk, value)]
        if max(z) < self.config.release_ratio:
            if self._release_since is None:
                self._release_since = t
            if t - self._release_since >= self.config.min_duration - 1e-12:
                self.active = False
                self._g = [0.0] * 12
                self._zero_t = [t] * 12
                ax = max(range(12), key=lambda j: self._pk[j] * sc[j])
                return over, (CollisionEvent("END", self.count, t, self._onset, ax, value[ax], self._pk[ax],
                                             t - self._onset),)
        else:
            self._release_since = None
        return over, ()


def make_detector(kind: str, config: ObserverConfig, cusum: CusumConfig | None = None):
    """The collision detector named `kind`: "threshold" (the paper's criterion with the servo-torque one,
    `CollisionDetector`) or "cusum" (`CusumDetector`).

    Raises:
        ObserverError: another kind, named.
    """
    if kind not in DETECTORS:
        raise ObserverError(f"detector must be one of {DETECTORS}, got {kind!r}")
    return CollisionDetector(config) if kind == "threshold" else CusumDetector(config, cusum)
