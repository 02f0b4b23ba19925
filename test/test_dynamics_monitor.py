"""hexa.dynamics.monitor: the observer node's pipeline without ROS — board-clocked sample times, pairing of the two
driver streams in any delivery order, estimator → observer, collision events, recalibration."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.dynamics.monitor import CollisionMonitor, MonitorConfig, SampleClock
from hexa.robots.hexa_description import load_hexa


def test_sample_clock_unwraps_the_microsecond_counter_and_rejects_repeats():
    c = SampleClock(fixed_offset=0.0)
    assert c.time(0.0, 0xFFFFFFFF - 999) == pytest.approx((0xFFFFFFFF - 999) * 1e-6)
    t = c.time(0.0, 1000)                    # wrapped: 2000 µs later
    assert t == pytest.approx((0xFFFFFFFF - 999) * 1e-6 + 2000e-6)
    assert c.time(0.0, 1000) is None and c.time(0.0, 500) is None
    assert c.backwards == 2


def test_sample_clock_follows_the_host_stamps_and_reanchors_on_a_board_reset():
    c = SampleClock(tau=1.0, jump=0.5)
    assert c.time(100.0, 5_000_000) == 100.0
    jittered = [c.time(100.0 + 0.001 * k + 0.002 * (k % 3), 5_000_000 + 1000 * k) for k in range(1, 2000)]
    steps = np.diff(jittered)
    assert np.allclose(steps, 0.001, atol=2e-5)          # the board's Δt, not the host's jitter
    t = c.time(110.0, 42)                                  # the board restarted: its clock jumped back
    assert t is None                                       # an older board time is a repeat, not a new sample
    c2 = SampleClock(tau=1.0, jump=0.5)
    c2.time(0.0, 0)
    assert c2.time(5.0, 1000) == pytest.approx(5.0)        # 5 s of host time against 1 ms of board time: re-anchor


def test_sample_clock_says_its_offset_from_the_boards_own_clock():
    """board_offset + a sample's raw board time = the time the clock gives it: what a subscriber needs to trace a
    residual's stamp back to its sample (hexa bench graph's robot mode)."""
    c = SampleClock(tau=1.0, jump=0.5)
    assert c.board_offset is None
    for k in range(500):
        raw = 7_000_000 + 1000 * k
        t = c.time(200.0 + 0.001 * k + 0.003 * (k % 5), raw)
        assert t == pytest.approx(c.board_offset + raw * 1e-6, abs=1e-9)
    assert SampleClock(fixed_offset=2.5).board_offset is None
    fixed = SampleClock(fixed_offset=2.5)
    assert fixed.time(0.0, 1000) == pytest.approx(fixed.board_offset + 1000e-6)


def _streams(n: int, tau_extra: np.ndarray | None = None, seed: int = 0):
    """Rest-pose samples of the simulator, as the driver publishes them: (stamp, board µs, currents, commanded)."""
    from hexa.sim import Simulator

    sim = Simulator(cameras=False)
    desc = load_hexa()
    s0 = sim.state()
    out = []
    for k in range(n):
        sim.step(5)
        st = sim.state()
        tau = st.tau + (0 if tau_extra is None or k < n // 2 else tau_extra)
        out.append((0.005 * (k + 1), int(round(sim.time * 1e6)), tau / desc.K_t, s0.zeta.copy()))
    return sim, s0, out


def test_monitor_pairs_the_streams_in_either_order_and_detects_a_push_on_a_servo():
    desc = load_hexa()
    push = np.array([0.0, 0.0, 0.8, 0.0, 0.0, 0.0])   # N·m on servo 3 from the middle on
    _, s0, samples = _streams(300, push)
    results = []
    for order in ("currents first", "states first"):
        mon = CollisionMonitor(desc, MonitorConfig(sim_clock=True))
        mon.observer.update_pose(0.0, s0.pose)
        mon.estimator.update_camera(0.0, s0.pose)
        out = []
        for stamp, board_us, cur, cmd in samples:
            if order == "currents first":
                out += mon.push_currents(stamp, board_us, cur)
                out += mon.push_states(stamp, cmd, None, None)
            else:
                out += mon.push_states(stamp, cmd, None, None)
                out += mon.push_currents(stamp, board_us, cur)
        assert mon.board_seen and mon.sequencer.unpaired == 0
        assert len(out) >= 280                                   # every sample but the estimator's settling
        events = [e for s in out for e in s.residual.events]
        assert [e.kind for e in events][:1] == ["START"]
        assert events[0].axis_name == "servo3"
        assert events[0].onset >= samples[150][1] * 1e-6 - 1e-9   # not before the push
        results.append([(s.time, s.residual.wrench.tolist()) for s in out])
    assert results[0] == results[1]                              # delivery order does not change the output


def test_monitor_counts_bad_input_and_keeps_running():
    desc = load_hexa()
    mon = CollisionMonitor(desc, MonitorConfig(sim_clock=True))
    assert mon.push_currents(0.0, 1000, [1.0, 2.0]) == []
    assert mon.push_pose(0.0, np.array([np.nan] * 6)) == []
    assert mon.push_states(0.0, None, None, None) == []
    mon.push_currents(0.0, 2000, np.zeros(6))
    assert mon.push_currents(0.0, 2000, np.zeros(6)) == []     # repeated board time
    c = mon.counters()
    assert (c["reject_node_bad_currents"], c["reject_node_bad_pose"], c["reject_node_bad_joint_names"],
            c["reject_node_board_time"]) == (1, 1, 1, 1)


def test_monitor_rejects_a_bad_setting_naming_it():
    with pytest.raises(ValueError, match="zeta_source"):
        MonitorConfig(zeta_source="guess")
    with pytest.raises(ValueError, match="pose_delay"):
        MonitorConfig(pose_delay=2.0)


def test_monitor_takes_the_set_points_a_current_sample_carries_and_falls_back_to_joint_states():
    """motor_currents with their set-points: the same samples as paired with joint_states; joint_states is then
    ignored (the monitoring watch expects motor_currents only); bad set-points cost only their sample, counted by
    reason; a stream without them (an older bag) pairs with joint_states again."""
    from hexa.dynamics.monitoring import MonitoringWatch

    desc = load_hexa()
    push = np.array([0.0, 0.0, 0.8, 0.0, 0.0, 0.0])
    _, s0, samples = _streams(300, push)
    runs = []
    for carried in (False, True):
        mon = CollisionMonitor(desc, MonitorConfig(sim_clock=True))
        mon.observer.update_pose(0.0, s0.pose)
        mon.estimator.update_camera(0.0, s0.pose)
        out = []
        for stamp, board_us, cur, cmd in samples:
            out += mon.push_currents(stamp, board_us, cur, cmd if carried else [])
            out += mon.push_states(stamp, cmd + (0.3 if carried else 0.0), None, None)   # ignored when carried
        assert mon.carries_setpoint == carried and mon.sequencer.unpaired == 0
        assert MonitoringWatch(mon).streams == (("motor_currents",) if carried else ("joint_states", "motor_currents"))
        runs.append([(s.time, s.residual.wrench.tolist(), [e.kind for e in s.residual.events]) for s in out])
    assert len(runs[1]) >= 280 and runs[0] == runs[1]
    stamp, board_us, cur, cmd = samples[-1]
    bad = [("setpoint_non_finite", [np.nan] * 6), ("setpoint_bad_shape", cmd[:5]), ("setpoint_range", cmd + 10.0)]
    for k, (reason, sp) in enumerate(bad):
        assert mon.push_currents(stamp + 0.005 * (k + 1), board_us + 5000 * (k + 1), cur, sp) == []
        assert mon.counters()[f"reject_input_{reason}"] == 1
    n = len(bad) + 1
    assert len(mon.push_currents(stamp + 0.005 * n, board_us + 5000 * n, cur, cmd)) == 1   # the next good one
    n += 1
    assert mon.push_currents(stamp + 0.005 * n, board_us + 5000 * n, cur) == []    # no set-points: waits for its
    assert not mon.carries_setpoint                                                  # joint_states
    assert len(mon.push_states(stamp + 0.005 * n, cmd, None, None)) == 1
