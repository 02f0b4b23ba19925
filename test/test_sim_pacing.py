"""The simulator's real-time pacing (hexa.sim.pacing.Pacer) on a fake wall clock: after a stall (a camera render)
the loop does not catch up in a burst, so sim time never runs faster than the requested real-time factor."""
from __future__ import annotations

import math

import numpy as np
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
    burst, _ = _run(max_lag=math.inf)          # the old behaviour: always catch up
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
    assert sum(1 for k, _ in held if k == "spin") == 3                    # 1.2 s held in 0.5 s sleeps
    count = {k: sum(1 for kk, _ in stepped if kk == k) for k in ("clock", "truth", "cameras", "spin")}
    assert count == {"clock": 250, "truth": 100, "cameras": 30, "spin": 19}
    cams = [t for k, t in stepped if k == "cameras"]
    assert cams[0] == pytest.approx(1 / 30, abs=1e-3) and all(b - a < 0.035 for a, b in zip(cams, cams[1:]))
    assert sim.time == pytest.approx(1.0) and wall.t == pytest.approx(1.2 + 1.0, abs=0.01)


def _camera_run(pieces: list[float], rtf: float = 1.0, sim_s: float = 1.0):
    """SimRunner at `rtf` on a fake wall, 1 ms steps costing 0.05 ms, a frame pair at 30 Hz whose work is `pieces`
    (wall seconds each, one piece per `next`). Returns the runner and its log of (event, frame instant, sim time)."""
    from hexa.sim.pacing import SimRunner

    wall = FakeWall()

    class Sim:
        timestep = 0.001

        def __init__(self) -> None:
            self.time = 0.0

        def step(self, n: int) -> None:
            self.time += n * self.timestep
            wall.t += 0.00005 * n

    sim = Sim()

    class Out:
        def __init__(self) -> None:
            self.log: list[tuple[str, float, float]] = []
            self.walls: list[float] = []          # wall time at each kept instant

        def clock(self) -> None: ...

        def truth(self) -> None: ...

        def spin(self) -> None: ...

        def cameras(self):
            instant = round(sim.time, 6)          # kept when asked, done later
            self.log.append(("kept", instant, instant))
            self.walls.append(wall.t)

            def work():
                for k, cost in enumerate(pieces):
                    wall.t += cost
                    self.log.append((f"piece {k}", instant, round(sim.time, 6)))
                    if k < len(pieces) - 1:
                        yield
            return work()

    runner = SimRunner(sim, Pacer(rtf, clock=wall.clock, sleep=wall.sleep), clock_rate=0, truth_rate=0,
                       camera_rate=30, duration=sim_s, clock=wall.clock, sleep=wall.sleep)
    out = Out()
    runner.run(out, lambda: True)
    return runner, out.log, np.diff(out.walls[1:])       # after the held first pair: wall between instants


def test_a_frame_pair_done_in_pieces_between_steps_costs_the_loop_no_wall_time():
    """Eight pieces of ≤ 4.5 ms (a pair's GL renders, noise and publications: 20 ms in all) fit in the loop's
    sleeps at 1×: no stall, no dropped time, every pair done in order, each within its frame period."""
    runner, log, periods = _camera_run([0.0045, 0.001, 0.001, 0.0005] * 2)
    assert runner.pacer.stalls == 0 and runner.pacer.dropped == 0.0
    assert periods == pytest.approx(1 / 30, abs=0.002)             # sim time at 1x of wall time (1 ms steps)
    kept = [t for e, t, _ in log if e == "kept"]
    assert len(kept) == 31                                         # 0 (held) and 30 stepped
    done = {}
    for event, instant, at in log:
        if event.startswith("piece"):
            assert instant == max(t for t in kept if t <= at)      # the newest kept frame's work, none older left
            done.setdefault(instant, []).append((event, at))
    for instant, events in done.items():
        assert [e for e, _ in events] == [f"piece {k}" for k in range(8)]
        assert events[-1][1] - instant < 1 / 30                    # finished before the next instant
    # the same 20 ms as one block at each instant: the loop falls behind and drops that time (the run gets longer);
    # 29 stalls: the pair at the last instant is done after the final step
    blocked, _, periods_b = _camera_run([0.020])
    assert blocked.pacer.stalls == 29 and periods_b == pytest.approx(1 / 30 + 0.020, abs=0.002)
