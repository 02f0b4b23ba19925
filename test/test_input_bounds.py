"""One bad message costs one message: the stream gates (hexa.stream_gate), the plate pose check (hexa.pose_check),
the board clock, the sequencer, the estimator and the observer reject a time or pose that breaks its stream, count
it by reason, and re-adopt a clock that jumped for good; the monitor's residual stream loses at most the bad sample."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.dynamics.monitor import CollisionMonitor, MonitorConfig, SampleClock
from hexa.dynamics.observer import ObserverConfig, ObserverError
from hexa.estimation import EstimationError, EstimatorConfig, SampleSequencer, ZetaEstimator
from hexa.pose_check import PoseCheck, PoseLimits
from hexa.robots.hexa_description import load_hexa
from hexa.rotations import quaternion_from_zyx
from hexa.stream_gate import StreamGate, TimeGate
from test_dynamics_monitor import _streams


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


def test_time_gate_rejects_one_outlier_either_way_and_keeps_its_reference():
    g = TimeGate(0.5)
    assert [g.check(t) for t in (1.0, 1.001, 1e6, 1.002, -5.0, 1.003, 1.003, float("nan"))] == [
        "ok", "ok", "time_future", "ok", "time_past", "ok", "time_past", "non_finite"]
    assert g.last == 1.003 and g.rejected == {"time_future": 1, "time_past": 2, "non_finite": 1}


def test_time_gate_adopts_a_clock_that_jumped_for_good_after_consistent_samples():
    g = TimeGate(0.5, adopt_after=3)
    g.check(100.0)
    verdicts = [g.check(0.001 * k) for k in range(1, 5)]      # a reset: the clock starts again near 0
    assert verdicts == ["time_past", "time_past", "adopted", "ok"] and g.adopted == 1 and g.last == 0.004
    # scattered bad times never agree with one another: never adopted
    g2 = TimeGate(0.5, adopt_after=3)
    g2.check(10.0)
    assert all(g2.check(t) != "adopted" for t in (1e6, -1e6, 2e6, 0.0, 3e6, -7.0))
    assert g2.last == 10.0 and g2.adopted == 0


def test_stream_gate_with_repeats_allows_equal_stamps_and_names_a_bad_adopt_after():
    g = TimeGate(0.5, repeats=True)
    assert [g.check(t) for t in (1.0, 1.0, 0.999)] == ["ok", "ok", "time_past"]
    with pytest.raises(ValueError, match="adopt_after"):
        StreamGate(lambda a, b: None, adopt_after=0)
    with pytest.raises(ValueError, match="max_step"):
        TimeGate(0.0)


def _quat(pose):
    return quaternion_from_zyx(*pose[3:6])


def test_pose_check_rejects_bad_quaternions_off_workspace_and_jumps_by_reason(desc):
    c = PoseCheck.for_hexa(desc)
    home = np.asarray(desc.home_pose, dtype=float)
    assert c.check(0.0, home[:3], _quat(home)) is not None
    assert c.check(0.033, home[:3], [0, 0, 0, 2]) is None                       # not a rotation
    assert c.check(0.066, [10.0, 0, 0], [0, 0, 0, 1]) is None                   # 10 m away
    assert c.check(0.002, home[:3] + [0.05, 0, 0], _quat(home)) is None         # 5 cm in 2 ms: 25 m/s
    assert c.check(0.1, [np.nan, 0, 0], [0, 0, 0, 1]) is None
    assert c.check(0.1, [0, 0], [0, 0, 0, 1]) is None
    assert c.check(-3.0, home[:3], _quat(home)) is None                         # before the last accepted
    T = c.check(0.133, home[:3] + [0.001, 0, 0], _quat(home))
    assert T is not None and T[0, 3] == pytest.approx(0.001)
    assert dict(c.rejected) == {"non_unit_quaternion": 1, "off_workspace": 1, "jump": 1, "non_finite": 1,
                                "bad_shape": 1, "time_past": 1}
    assert c.counters()["reject_pose_jump"] == 1


def test_pose_check_bounds_jumps_by_the_servo_speed_and_adopts_a_plate_that_moved(desc):
    lim = PoseLimits.for_hexa(desc)
    assert lim.max_speed == pytest.approx(2 * desc.l_a * desc.speed_max)
    c = PoseCheck.for_hexa(desc)
    home = np.asarray(desc.home_pose, dtype=float)
    moved = home + [0.03, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert c.check_pose6(0.0, home) is not None
    # 3 cm in 33 ms is 0.9 m/s beyond the noise: within 2.46 m/s; 3 cm in 1 ms is not
    assert c.check_pose6(0.001, moved) is None and c.rejected["jump"] == 1
    assert c.check_pose6(0.033, moved) is not None
    # the plate was moved while out of sight: three poses that agree with one another are adopted
    far = home + [-0.04, 0.03, 0.02, 0.1, 0.0, 0.0]
    verdicts = [c.check_pose6(0.034 + 0.001 * k, far) is not None for k in range(3)]
    assert verdicts == [False, False, True] and c.gate.adopted == 1


def test_sample_clock_costs_one_sample_for_a_board_time_far_ahead_and_adopts_a_reset():
    c = SampleClock(fixed_offset=0.0)
    times = [c.time(0.0, 1000 * k) for k in range(1, 5)]
    assert c.time(0.0, 4000 + 2_000_000_000) is None                 # 2e9 µs ahead: rejected, counted
    assert c.time(0.0, 5000) == pytest.approx(0.005)                 # the next good sample goes on
    assert c.rejected == {"time_future": 1} and times[-1] == pytest.approx(0.004)
    # a board reset: its clock restarts near 0 and stays there — adopted after adopt_after samples
    c2 = SampleClock(tau=1.0, jump=0.5, adopt_after=3)
    c2.time(100.0, 50_000_000)
    out = [c2.time(100.001 + 0.001 * k, 1000 * k) for k in range(1, 5)]
    assert out[:2] == [None, None] and out[2] == pytest.approx(100.004) and out[3] == pytest.approx(100.005)
    assert c2.backwards == 2 and c2.gate.adopted == 1


def test_a_board_that_was_silent_comes_back_at_once_on_its_later_board_time():
    c = SampleClock(tau=1.0, jump=0.5)
    for k in range(5):
        c.time(10.0 + 0.005 * k, 1_000_000 + 5000 * k)
    # 2 s of silence (a STOP_STREAM, a stall): board time and stamps both move on 2 s — not a bad board time
    assert c.time(12.025, 3_025_000) == pytest.approx(12.025, abs=0.01) and c.rejected == {}
    assert c.time(12.03, 3_030_000 + 2_000_000_000) is None and c.rejected == {"time_future": 1}


def test_sequencer_takes_both_topics_back_at_once_after_a_common_silence():
    seq = SampleSequencer("board", pose_delay=0.1, max_step=0.25, adopt_after=5)
    out = []
    for k in list(range(20)) + list(range(220, 240)):          # 1 s without either topic
        s = 0.005 * k
        out += seq.push_currents(s, s, np.zeros(6))
        out += seq.push_states(s, np.zeros(6), None, None)
    times = [o[1] for o in out if o[0] == "sample"]
    assert len(times) >= 39 and times[-1] == pytest.approx(1.195)   # at most the first sample after the silence
    assert seq.rejected["currents_time_future"] <= 1


def test_sequencer_drops_a_joint_states_stamped_far_away_and_keeps_pairing():
    seq = SampleSequencer("board", pose_delay=0.1)
    out = []
    for k in range(40):
        s = 0.005 * k
        if k == 10:
            out += seq.push_states(s + 1e6, np.zeros(6), None, None)     # 10^6 s in the future
        if k == 20:
            out += seq.push_states(s - 100.0, np.zeros(6), None, None)   # in the past
            out += seq.push_currents(s + 1e6, s, np.zeros(6))
        out += seq.push_currents(s, s, np.zeros(6))
        out += seq.push_states(s, np.zeros(6), None, None)
    samples = [o for o in out if o[0] == "sample"]
    assert len(samples) == 40 and seq.unpaired == 0
    assert seq.rejected == {"states_time_future": 1, "states_time_past": 1, "currents_time_future": 1}
    assert seq.push_pose(1e6, np.zeros(6)) == [] and seq.rejected["pose_time_future"] == 1


def test_sequencer_a_stamp_slightly_ahead_costs_at_most_adopt_after_samples():
    seq = SampleSequencer("board", pose_delay=0.1, max_step=0.25, adopt_after=5)
    out = []
    for k in range(100):
        s = 0.005 * k
        if k == 20:
            out += seq.push_states(s + 0.1, np.zeros(6), None, None)     # within max_step: accepted, then re-adopted
        out += seq.push_currents(s, s, np.zeros(6))
        out += seq.push_states(s, np.zeros(6), None, None)
    times = [o[1] for o in out if o[0] == "sample"]
    assert 100 - 6 <= len(times) < 100 and times[-1] == pytest.approx(0.495)
    assert max(np.diff(times)) <= 0.005 * 7 + 1e-9 and seq.adopted == 1


def test_sequencer_in_auto_mode_takes_motor_currents_that_come_after_it_settled_on_stamps():
    seq = SampleSequencer("auto", pose_delay=0.1, auto_wait=5)
    out = []
    for k in range(10):                                   # the motor_currents subscription matched late
        out += seq.push_states(0.005 * k, np.zeros(6), None, np.zeros(6))
    assert not seq.board and len(out) == 10
    for k in range(10, 20):
        out += seq.push_currents(0.005 * k, 0.005 * k - 0.0002, np.full(6, 1.0))
        out += seq.push_states(0.005 * k, np.zeros(6), None, np.zeros(6))
    assert seq.board and seq.to_board == 1 and seq.unpaired == 0
    samples = [o for o in out if o[0] == "sample"]
    assert len(samples) == 20 and samples[-1][1] == pytest.approx(0.0948) and samples[-1][3][0] == 1.0


def test_sequencer_adopts_stamps_that_jumped_back_for_good():
    seq = SampleSequencer("board", pose_delay=0.1, adopt_after=3)
    out = []
    for k in range(10):
        out += seq.push_currents(100 + 0.005 * k, 100 + 0.005 * k, np.zeros(6))
        out += seq.push_states(100 + 0.005 * k, np.zeros(6), None, None)
    for k in range(10):                                                # the simulator restarted
        out += seq.push_currents(0.005 * k, 0.005 * k, np.zeros(6))
        out += seq.push_states(0.005 * k, np.zeros(6), None, None)
    times = [o[1] for o in out if o[0] == "sample"]
    assert len(times) == 10 + 8 and times[-1] == pytest.approx(0.045) and seq.adopted == 2


def test_estimator_and_observer_reject_a_time_jump_and_adopt_a_lasting_one(desc):
    est = ZetaEstimator(desc, config=EstimatorConfig(adopt_after=3))
    z0 = np.full(6, -2.6)
    for k in range(5):
        assert est.update(0.001 * k, z0, np.zeros(6)) is not None
    assert est.update(1e6, z0, np.zeros(6)) is None and est.rejected["time_jump"] == 1
    assert est.update(0.005, z0, np.zeros(6)) is not None                 # the next good one goes on
    assert [est.update(-50 + 0.001 * k, z0, np.zeros(6)) is None for k in range(3)] == [True, True, False]
    assert est.clock_jumps == 1 and est.rejected["time_not_increasing"] == 2
    with pytest.raises(EstimationError, match="max_jump"):
        EstimatorConfig(max_jump=0.05)
    with pytest.raises(ObserverError, match="max_jump"):
        ObserverConfig(max_jump=0.01)


BAD = {  # one bad message of each kind, injected beside the good ones (stamp, board µs of the good sample given)
    "states_future": lambda m, s, b: m.push_states(s + 1e6, np.full(6, -2.6), None, None),
    "states_past": lambda m, s, b: m.push_states(s - 50.0, np.full(6, -2.6), None, None),
    "states_nan": lambda m, s, b: m.push_states(s, np.full(6, np.nan), None, None),
    "states_size": lambda m, s, b: m.push_states(s, np.full(5, -2.6), None, None),
    "states_range": lambda m, s, b: m.push_states(s, np.full(6, 1e9), None, None),
    "currents_board_future": lambda m, s, b: m.push_currents(s, b + 2_000_000_000, np.zeros(6)),
    "currents_board_past": lambda m, s, b: m.push_currents(s, b - 1_000_000_000, np.zeros(6)),
    "currents_stamp_future": lambda m, s, b: m.push_currents(s + 1e6, b + 1, np.zeros(6)),
    "currents_inf": lambda m, s, b: m.push_currents(s, b + 1, np.full(6, np.inf)),
    "currents_range": lambda m, s, b: m.push_currents(s, b + 1, np.full(6, 1e6)),
    "pose_quaternion": lambda m, s, b: m.push_pose(s, np.array([0, 0, -0.55, 0, 0, 0, 2.0])),
    "pose_far": lambda m, s, b: m.push_pose(s, np.array([10.0, 0, 0, 0, 0, 0, 1.0])),
    "pose_future": lambda m, s, b: m.push_pose(s + 1e6, np.array([0, 0, -0.55, 0, 0, 0, 1.0])),
}


@pytest.mark.parametrize("fault", sorted(BAD))
def test_one_bad_message_costs_at_most_one_residual_sample(desc, fault):
    _, s0, samples = _streams(250)       # 1.25 s: a pose injected at 0.3 s is released at 0.8 s (pose_delay)
    mon = CollisionMonitor(desc, MonitorConfig(sim_clock=True))
    mon.observer.update_pose(0.0, s0.pose)
    out = []
    for k, (stamp, board_us, cur, cmd) in enumerate(samples):
        if k == 60:
            out += BAD[fault](mon, stamp, board_us)
        out += mon.push_currents(stamp, board_us, cur)
        out += mon.push_states(stamp, cmd, None, None)
    times = np.array([s.time for s in out])
    gaps = np.diff(times[times > samples[30][0]])
    assert gaps.max() <= 2 * 0.005 + 1e-9, (fault, gaps.max())    # the residual goes on within 2 sample periods
    assert times[-1] == pytest.approx(samples[-1][0])               # ... to the end
    assert not any(e.kind == "START" for s in out for e in s.residual.events)
    c = mon.counters()
    rejected = {k: v for k, v in c.items() if "reject" in k and v}
    assert rejected, fault                                          # counted, by a reason
