"""The simulator's real-time pacing (hexa.sim.pacing.Pacer) on a fake wall clock: after a stall (a camera render)
the loop does not catch up in a burst, so sim time never runs faster than the requested real-time factor."""
from __future__ import annotations

import math

import pytest

from hexa.sim.pacing import Pacer


class FakeWall:
    def __init__(self) -> None:
        self.t = 0.0

    def clock(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def _run(max_lag: float, rtf: float = 0.3, sim_s: float = 1.0, render_every: float = 1 / 30,
         render_wall: float = 0.044, step_wall: float = 0.0002):
    """Step 1 ms at a time (each costing step_wall), pace every step as sim_node does, 'render' every render_every
    sim s.
    Returns [(wall, sim)] after each pace call and the pacer."""
    wall = FakeWall()
    pacer = Pacer(rtf, max_lag, clock=wall.clock, sleep=wall.sleep)
    pacer.start(0.0)
    trace, next_render = [], render_every
    for k in range(1, int(round(sim_s / 0.001)) + 1):
        sim = k * 0.001
        wall.t += step_wall
        if sim + 1e-9 >= next_render:
            wall.t += render_wall
            next_render += render_every
        pacer.pace(sim)
        trace.append((wall.t, sim))
    return trace, pacer


def _fastest_rate(trace, window: float = 0.005) -> float:
    """Largest sim-time advance per wall second over any `window` of wall time."""
    best = 0.0
    j = 0
    for i in range(len(trace)):
        while trace[i][0] - trace[j][0] > window:
            j += 1
        if trace[i][0] - trace[j][0] >= window / 2:
            best = max(best, (trace[i][1] - trace[j][1]) / (trace[i][0] - trace[j][0]))
    return best


def test_after_a_render_the_loop_does_not_catch_up_in_a_burst():
    burst, _ = _run(max_lag=math.inf)          # no pacing: always catch up
    paced, pacer = _run(max_lag=0.005)
    assert _fastest_rate(burst) > 2 * 0.3      # catching up runs sim time at several times the factor
    assert _fastest_rate(paced) < 1.3 * 0.3    # dropped instead: never much faster than requested
    assert pacer.stalls >= 25                  # one per render (30 per sim second)
    # each render costs 44 ms of wall time, of which the 3.3 ms pace of its 1 ms step was due anyway
    assert pacer.dropped == pytest.approx(pacer.stalls * (0.044 + 0.0002 - 0.001 / 0.3), rel=0.05)


def test_without_stalls_the_pace_is_the_requested_factor():
    trace, pacer = _run(max_lag=0.005, render_wall=0.0)
    (w0, s0), (w1, s1) = trace[0], trace[-1]
    assert (s1 - s0) / (w1 - w0) == pytest.approx(0.3, rel=0.02)
    assert pacer.stalls == 0


def test_factor_zero_never_sleeps_and_bad_values_are_refused():
    slept = []
    pacer = Pacer(0.0, 0.005, clock=lambda: 0.0, sleep=slept.append)
    pacer.start(0.0)
    pacer.pace(10.0)
    assert slept == []
    with pytest.raises(ValueError, match="max_lag"):
        Pacer(0.3, -1.0)
    with pytest.raises(ValueError, match="max_lag"):
        Pacer(0.3, float("nan"))
    with pytest.raises(ValueError, match="real_time_factor"):
        Pacer(float("inf"))


def test_sim_runner_publishes_clock_truth_and_cameras_at_their_sim_rates():
    from hexa.sim.pacing import SimRunner

    class Sim:
        timestep = 0.001

        def __init__(self) -> None:
            self.time = 0.0

        def step(self, n: int) -> None:
            self.time += n * self.timestep

    class Out:
        def __init__(self, sim: Sim) -> None:
            self.sim, self.log = sim, []

        def clock(self) -> None:
            self.log.append(("clock", round(self.sim.time, 6)))

        def truth(self) -> None:
            self.log.append(("truth", round(self.sim.time, 6)))

        def cameras(self) -> None:
            self.log.append(("cameras", round(self.sim.time, 6)))

        def spin(self) -> None:
            self.log.append(("spin", round(self.sim.time, 6)))

    wall = FakeWall()
    sim = Sim()
    runner = SimRunner(sim, Pacer(1.0, clock=wall.clock, sleep=wall.sleep), clock_rate=250, truth_rate=100,
                       camera_rate=30, duration=1.0, start_delay=1.2, clock=wall.clock, sleep=wall.sleep)
    out = Out(sim)
    runner.run(out, lambda: True)
    held = [e for e in out.log if e[1] == 0.0]
    stepped = [e for e in out.log if e[1] > 0.0]
    assert sum(1 for k, _ in held if k == "clock") == 3                   # 1.2 s held, re-published every 0.5 s
    assert runner.held == pytest.approx(1.2)
    count = {k: sum(1 for kk, _ in stepped if kk == k) for k in ("clock", "truth", "cameras", "spin")}
    assert count == {"clock": 250, "truth": 100, "cameras": 30, "spin": 19}
    cams = [t for k, t in stepped if k == "cameras"]
    assert cams[0] == pytest.approx(1 / 30, abs=1e-3) and all(b - a < 0.035 for a, b in zip(cams, cams[1:]))
    assert sim.time == pytest.approx(1.0) and wall.t == pytest.approx(1.2 + 1.0, abs=0.01)


def test_the_hold_ends_once_the_graph_is_ready_and_never_later_than_start_delay():
    from hexa.sim.pacing import SimRunner

    class Sim:
        timestep, time = 0.001, 0.0

        def step(self, n: int) -> None:
            self.time += n * self.timestep

    class Out:
        def clock(self) -> None: ...

        def truth(self) -> None: ...

        def cameras(self) -> None: ...

        def spin(self) -> None: ...

    for ready_at, held in ((0.3, 0.3), (5.0, 1.2)):            # up after 0.3 s; never up: the whole delay
        wall = FakeWall()
        runner = SimRunner(Sim(), Pacer(1.0, clock=wall.clock, sleep=wall.sleep), 250, 100, None, duration=0.1,
                           start_delay=1.2, clock=wall.clock, sleep=wall.sleep, ready=lambda: wall.t >= ready_at)
        runner.run(Out(), lambda: True)
        assert runner.held == pytest.approx(held, abs=0.051) and runner.sim.time == pytest.approx(0.1)


def test_a_later_scenario_start_lengthens_the_run_and_the_summary_says_what_was_held():
    from hexa.sim.pacing import SimRunner

    class Sim:
        timestep, time = 0.001, 0.0

        def __init__(self, shift):
            self.shift = shift

        def step(self, n: int) -> None:
            self.time += n * self.timestep

        def start_scenario_at(self, t0: float):
            return self.shift

    for shift, duration in ((0.8, 5.8), (-0.2, 5.0), (None, 5.0)):
        wall = FakeWall()
        runner = SimRunner(Sim(shift), Pacer(1.0, clock=wall.clock, sleep=wall.sleep), 250, 100, None,
                           duration=5.0, start_delay=1.0, clock=wall.clock, sleep=wall.sleep)
        assert runner.start_scenario_at(1.8) == shift and runner.duration == pytest.approx(duration)
    assert runner.summary() == ["sim time held at its start for 0.00 s of wall time (at most 1 s) while the graph "
                                "started"]                # not run yet: nothing held, no stall
