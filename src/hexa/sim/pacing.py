"""Real-time pacing of the simulator's stepping loop, and the loop itself (SimRunner: the sim node publishes
what it asks for).

The simulator steps as fast as it can and sleeps to keep sim time at `real_time_factor` × wall time. A host stall,
or a camera render done in the loop (≈ 22 ms per camera; the sim node renders on hexa.sim.render_thread instead),
makes it fall behind that pace. Catching up means stepping without sleeping
until the pace is restored: sim time then runs several times faster than the rest of the graph, whose commands
(trajectory → driver → virtual Uno) then reach the simulated servos sparser in sim time than they were played —
gaps of 20–50 ms followed by a burst of set-point steps, which the arms really follow with jerks that the observer
sees as unmodelled torque (docs/history/observer_node.md, "Command timing"). So when the loop is more than `max_lag`
wall seconds behind, the lost wall time is dropped instead: the run gets longer, and sim time never runs ahead of the
requested factor.
"""
from __future__ import annotations

import math
import time
from typing import Callable, Protocol


#: shortest sleep (s): the loop is paced every step, so the virtual boards' threads (which run while it sleeps) apply a
#: command within about a step of sim time
MIN_SLEEP = 0.0005
#: default wall seconds behind the pace before the lost time is dropped (sim_node's `max_lag`)
MAX_LAG = 0.005
#: the largest real-time factor the simulator node takes (its `real_time_factor` parameter's range; 0 = unpaced)
MAX_REAL_TIME_FACTOR = 100.0


class Pacer:
    """Keeps sim time at `real_time_factor` × wall time; drops the wall time lost in stalls longer than `max_lag`.

    Args:
        real_time_factor: sim seconds per wall second (> 0; 0 or less = as fast as possible, `pace` never sleeps).
        max_lag: wall seconds the loop may fall behind before the lost time is dropped (math.inf = always catch up).
        clock, sleep: wall clock and sleep (replaceable in tests).
    """

    def __init__(self, real_time_factor: float, max_lag: float = MAX_LAG,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
        if not math.isfinite(real_time_factor):
            raise ValueError(f"real_time_factor must be finite, got {real_time_factor!r}")
        if math.isnan(max_lag) or max_lag < 0.0:
            raise ValueError(f"max_lag must be >= 0 s, got {max_lag!r}")
        self.rtf = float(real_time_factor)
        self.max_lag = float(max_lag)
        self._clock, self._sleep = clock, sleep
        self._wall0 = 0.0
        self._sim0 = 0.0
        self.stalls = 0          # times the loop fell more than max_lag behind
        self.dropped = 0.0       # wall seconds dropped in them

    def start(self, sim_time: float) -> None:
        """Anchor the pace: `sim_time` now."""
        self._wall0 = self._clock()
        self._sim0 = float(sim_time)

    def pace(self, sim_time: float) -> None:
        """Called every step: sleep while ahead of the pace; re-anchor when more than max_lag behind."""
        if self.rtf <= 0.0:
            return
        ahead = (sim_time - self._sim0) / self.rtf - (self._clock() - self._wall0)
        if ahead > MIN_SLEEP:
            self._sleep(ahead)
        elif ahead < -self.max_lag:
            self._wall0 -= ahead
            self.stalls += 1
            self.dropped -= ahead


class SteppedSim(Protocol):
    """What the stepping loop needs of the simulator (hexa.sim.Simulator): its clock and one physics step."""

    @property
    def time(self) -> float: ...

    @property
    def timestep(self) -> float: ...

    def step(self, n: int) -> None: ...

    def start_scenario_at(self, t0: float) -> float | None: ...


class SimOutputs(Protocol):
    """What the stepping loop asks its owner to publish (the sim node's publishers)."""

    def clock(self) -> None: ...

    def truth(self) -> None: ...

    def cameras(self) -> None: ...

    def spin(self) -> None: ...


class SimRunner:
    """The simulator's stepping loop: one `step` of the physics at a time, /clock every `clock_rate` Hz, ground truth
    every `truth_rate` Hz and a camera frame pair every 1/`camera_rate` s of sim time, paced by `pacer`.

    The output does not depend on wall time (only the pacing does): for a given seed a run publishes the same
    messages at the same sim times. Before stepping, sim time is held at its start for at most `start_delay` wall
    seconds while the rest of the graph starts, re-publishing the clock, the truth and the cameras every 0.5 s; the
    hold ends early once `ready()` is true (checked every 50 ms), so a graph that is up does not wait out the delay.

    Args:
        sim: the hexa.sim.Simulator (`step(n)`, `time`, `timestep`).
        pacer: the real-time pacing.
        clock_rate, truth_rate: Hz of sim time (0 = never); camera_rate: Hz (0 or None = no cameras).
        duration: sim seconds to run (0 = until `ok()` turns false).
        start_delay: most wall seconds with sim time frozen before stepping.
        ready: true once the graph is up (None: the hold lasts `start_delay`).
        spin_every: steps between two `outputs.spin()` calls (the node's own service/parameter callbacks).
    """

    def __init__(self, sim: SteppedSim, pacer: Pacer, clock_rate: float, truth_rate: float, camera_rate: float | None,
                 duration: float = 0.0, start_delay: float = 0.0, spin_every: int = 50,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 ready: Callable[[], bool] | None = None) -> None:
        dt = sim.timestep
        self.sim, self.pacer, self.duration, self.start_delay = sim, pacer, float(duration), float(start_delay)
        self.clock_every = max(1, int(round(1.0 / (clock_rate * dt)))) if clock_rate > 0 else 0
        self.truth_every = max(1, int(round(1.0 / (truth_rate * dt)))) if truth_rate > 0 else 0
        self.camera_period = 1.0 / camera_rate if camera_rate else None
        self.spin_every = max(1, int(spin_every))
        self._clock, self._sleep = clock, sleep
        self.ready = ready
        self.steps = 0
        self.held = 0.0          # wall seconds sim time was held before stepping

    def summary(self) -> list[str]:
        """What an operator reads at the end: how long sim time was held at the start, the pacing's stalls."""
        out = []
        if self.start_delay > 0:
            out.append(f"sim time held at its start for {self.held:.2f} s of wall time "
                       f"(at most {self.start_delay:g} s) while the graph started")
        if self.pacer.stalls:
            out.append(f"pacing: {self.pacer.stalls} stalls over max_lag, {self.pacer.dropped:.1f} s of wall time "
                       f"dropped (not caught up)")
        return out

    def start_scenario_at(self, t0: float) -> float | None:
        """Time the simulator's scripted collision from trajectory time 0 at sim time `t0`
        (hexa.sim.Simulator.start_scenario_at) and lengthen the run by a later start, so that the scenario's end is
        still simulated. The move (s), or None when nothing moved."""
        shift = self.sim.start_scenario_at(t0)
        if shift is not None and self.duration > 0:
            self.duration += max(0.0, shift)
        return shift

    def run(self, outputs: SimOutputs, ok: Callable[[], bool]) -> None:
        """Hold, then step until `duration` or until `ok()` is false."""
        sim = self.sim
        next_cam = 0.0
        if self.camera_period is not None:
            outputs.cameras()
            next_cam = self.camera_period
        held_from = self._clock()
        hold_until = held_from + self.start_delay
        republish = held_from
        while ok() and self._clock() < hold_until:   # sim time frozen while the graph starts
            if self._clock() >= republish:
                outputs.clock()
                outputs.truth()
                if self.camera_period is not None:
                    outputs.cameras()
                republish += 0.5
            outputs.spin()
            if self.ready is not None and self.ready():
                break
            self._sleep(min(0.05, max(0.0, hold_until - self._clock())))
        self.held = self._clock() - held_from
        self.pacer.start(sim.time)
        k = 0
        while ok():
            sim.step(1)
            k += 1
            self.steps = k
            if self.clock_every and k % self.clock_every == 0:
                outputs.clock()
            if self.truth_every and k % self.truth_every == 0:
                outputs.truth()
            if self.camera_period is not None and sim.time + 1e-9 >= next_cam:
                outputs.cameras()
                next_cam += self.camera_period
            if self.duration > 0 and sim.time >= self.duration:
                break
            # every step: the virtual boards' threads run while the loop sleeps, so the servos take each command
            # within 1 ms of sim time; after a render the loop does not catch up in a burst (Pacer)
            self.pacer.pace(sim.time)
            if k % self.spin_every == 0:
                outputs.spin()
