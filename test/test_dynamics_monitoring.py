"""hexa.dynamics.monitoring: the monitoring-alive contract without ROS — a real CollisionMonitor fed the simulator's
rest samples as the driver publishes them (200 Hz, board time = sim time) and camera poses (30 Hz), evaluated every
10 ms of the node's clock: settling → OK, LOST naming the silent or rejected input within the bound, recovery through
settling, the wall-clock bound under a stalled clock, the pose bound, a reset."""
from __future__ import annotations

import math

import pytest

from hexa.dynamics.monitor import CollisionMonitor, MonitorConfig
from hexa.dynamics.monitoring import DEGRADED, LOST, OK, MonitoringError, MonitoringWatch, WatchConfig
from hexa.robots.hexa_description import load_hexa

DT = 0.005       # the driver's 200 Hz
EVAL = 0.01      # the node's evaluation period


@pytest.fixture(scope="module")
def rest():
    """4 s of the simulated robot at rest: (sim time, currents A, commanded ζ) per sample, and the plate pose."""
    from hexa.sim import Simulator

    sim = Simulator(cameras=False)
    desc = load_hexa()
    s0 = sim.state()
    out = []
    for _ in range(800):
        sim.step(5)
        out.append((sim.time, sim.state().tau / desc.K_t, s0.zeta.copy()))
    return out, s0.pose.copy()


class Feed:
    """Plays the rest samples into a watch on a node clock = sim time; `wall` runs with it unless frozen."""

    def __init__(self, rest, config: WatchConfig | None = None, monitor_config: MonitorConfig | None = None):
        self.samples, self.pose = rest
        self.mon = CollisionMonitor(load_hexa(), monitor_config or MonitorConfig(sim_clock=True))
        self.watch = MonitoringWatch(self.mon, config or WatchConfig(), now=0.0)
        self.k = 0
        self.now = 0.0
        self.wall = 100.0
        self.events: list = []     # (now, level, reason)
        self.board = self.mon.config.time_source != "stamp"

    def run(self, until: float, currents: bool = True, states: bool = True, poses: bool = True,
            board_us=None) -> None:
        """Advance the node clock to `until`, delivering each stream's samples due (or dropping them)."""
        while self.now < until - 1e-9:
            self.now = round(self.now + DT, 9)
            self.wall += DT
            if self.k < len(self.samples):
                t, cur, cmd = self.samples[self.k]
                self.k += 1
                us = int(round(t * 1e6)) if board_us is None else board_us(t)
                if currents:
                    self.watch.push_currents(t, us, cur)
                if states:   # without the current board, joint_states carry τ (the driver's effort)
                    self.watch.push_states(t, cmd, None, None if self.board else cur * self.mon.k_t)
                if poses and self.k % 7 == 0:
                    self.watch.push_pose(t, self.pose)
            if round(self.wall / DT) % round(EVAL / DT) == 0:
                st = self.watch.evaluate(self.now, self.wall)
                if st is not None:
                    self.events.append((self.now, st.level, st.reason))

    def first(self, level: str, after: float = 0.0) -> tuple[float, str]:
        return next((t, r) for t, lv, r in self.events if lv == level and t >= after)


def test_start_is_degraded_settling_until_residuals_have_been_fresh_for_the_settle_time(rest):
    f = Feed(rest)
    assert f.watch.status.level == DEGRADED and "no joint_states" in f.watch.status.reason
    f.run(0.3, poses=False)
    assert f.watch.status.level == DEGRADED and "plate_pose" in f.watch.status.reason   # the observer needs a seed
    f.run(2.5)
    t_ok, _ = f.first(OK)
    first_residual = f.mon.observer.accepted
    assert first_residual > 0
    # the first pose (0.3 s) is released at +pose_delay (0.5 s), then settle_time (0.5 s) of residuals
    assert 0.3 + 0.5 + 0.5 - 0.02 <= t_ok <= 0.3 + 0.5 + 0.5 + 0.1, f.events
    assert all(lv == DEGRADED for t, lv, _r in f.events if t < t_ok)
    assert any("residuals fresh for" in r for _t, _lv, r in f.events)
    assert f.watch.ever_ok and f.watch.status.reason == ""


def test_a_silent_current_stream_is_lost_within_the_timeout_naming_it_then_recovers_through_settling(rest):
    f = Feed(rest, WatchConfig(timeout=0.05, settle_time=0.3))
    f.run(1.6)
    assert f.watch.status.level == OK
    f.run(2.0, currents=False)                         # the Mega stops streaming; joint_states go on
    t_lost, reason = f.first(LOST)
    assert 1.6 + 0.05 <= t_lost <= 1.6 + 0.05 + 2 * EVAL + 1e-9, f.events   # confirmed at the next evaluation
    assert "motor_currents silent" in reason and "joint_states" not in reason, reason
    assert f.watch.status.residual_age >= 0.05
    f.run(3.0)                                         # it streams again
    t_back, reason = f.first(DEGRADED, after=t_lost)
    assert reason.startswith("settling") and t_back <= 2.0 + 0.05 + EVAL
    t_ok, _ = f.first(OK, after=t_lost)
    assert t_ok - t_back == pytest.approx(0.3, abs=2 * EVAL + DT)
    assert f.watch.lost_count == 1


def test_rejected_currents_are_lost_naming_the_reject_reason(rest):
    f = Feed(rest)
    f.run(1.6)
    assert f.watch.status.level == OK
    f.run(1.8, board_us=lambda t: 1)                   # one board time, repeated: every sample a repeat
    t_lost, reason = f.first(LOST)
    assert t_lost <= 1.6 + 0.05 + 2 * EVAL + 1e-9
    assert "input rejected" in reason and "node_board_time" in reason, reason


def test_both_streams_silent_names_both(rest):
    f = Feed(rest)
    f.run(1.6)
    f.run(1.8, currents=False, states=False)
    _t, reason = f.first(LOST)
    assert "joint_states silent" in reason and "motor_currents silent" in reason, reason


def test_a_stalled_node_clock_is_degraded_after_the_wall_timeout_and_ok_when_it_runs_again(rest):
    f = Feed(rest, WatchConfig(wall_timeout=0.3))
    f.run(1.6)
    assert f.watch.status.level == OK
    wall0 = f.wall
    for _ in range(100):                               # the clock stands still, wall time runs on
        f.wall += EVAL
        st = f.watch.evaluate(f.now, f.wall)
        if st is not None:
            break
    assert f.watch.status.level == DEGRADED and "clock stalled" in f.watch.status.reason
    assert 0.3 <= f.wall - wall0 <= 0.3 + 2 * EVAL + DT
    f.run(1.7)                                         # the clock and the samples run again
    assert f.watch.status.level == OK and f.watch.lost_count == 0


def test_one_late_evaluation_is_not_a_loss(rest):
    """A timer that runs after a starved node's clock jumped, before the samples queued for it: not LOST yet."""
    f = Feed(rest)
    f.run(1.6)
    assert f.watch.evaluate(f.now + 0.2, f.wall + 0.2) is None and f.watch.status.level == OK
    assert f.watch.evaluate(f.now + 0.2, f.wall + 0.2005) is None   # the other timer in the same wake-up
    f.run(1.8)
    assert f.watch.lost_count == 0 and f.watch.status.level == OK


def test_missing_plate_poses_are_lost_after_the_pose_timeout_where_the_estimator_uses_them(rest):
    f = Feed(rest, WatchConfig(pose_timeout=0.4))
    assert f.watch.pose_needed                          # ζ from the estimator with camera updates
    f.run(1.6)
    assert f.watch.status.level == OK
    f.run(2.6, poses=False)
    t_lost, reason = f.first(LOST)
    # the last pose is used at its stamp + pose_delay: the camera went quiet then, plus the bound
    assert t_lost <= 1.6 + 0.5 + 0.4 + 0.05, f.events
    assert reason.startswith("plate_pose unusable") and "none received" in reason, reason


def test_measured_zeta_does_not_need_the_pose(rest):
    f = Feed(rest, monitor_config=MonitorConfig(sim_clock=True, zeta_source="measured"))
    assert not f.watch.pose_needed


def test_a_reset_settles_again_without_a_lost(rest):
    f = Feed(rest, WatchConfig(settle_time=0.2))
    f.run(1.6)
    assert f.watch.status.level == OK
    f.mon.reset()
    f.watch.restart(f.now)
    assert f.watch.status.level == DEGRADED and "reset" in f.watch.status.reason
    f.run(2.4)
    levels = [lv for t, lv, _r in f.events if t >= 1.6]
    assert LOST not in levels and levels[-1] == OK, f.events


def test_the_watch_rejects_bad_bounds_naming_them():
    with pytest.raises(MonitoringError, match="timeout"):
        WatchConfig(timeout=0.0)
    with pytest.raises(MonitoringError, match="wall_timeout"):
        WatchConfig(wall_timeout=math.nan)
    with pytest.raises(MonitoringError, match="settle_time"):
        WatchConfig(settle_time=-1.0)


def test_joint_states_alone_are_the_only_stream_expected_without_the_current_board(rest):
    f = Feed(rest, monitor_config=MonitorConfig(sim_clock=True, time_source="stamp"))
    f.run(1.6, currents=False)
    assert f.watch.streams == ("joint_states",) and f.watch.status.level == OK
    f.run(1.8, currents=False, states=False)
    _t, reason = f.first(LOST)
    assert "joint_states silent" in reason and "motor_currents" not in reason, reason


def test_a_clock_that_goes_back_does_not_make_old_residuals_fresh(rest):
    """A restarted simulator starts its clock at 0 again: the residual age runs on across the jump (LOST when no
    residual follows), instead of counting from a time that now lies in the future."""
    f = Feed(rest)
    f.run(1.6)
    assert f.watch.status.level == OK
    st = None
    for k in range(1, 10):                       # no samples; the clock restarted near 0 and runs on
        st = f.watch.evaluate(0.01 * k, f.wall + 0.01 * k) or st
    assert st is not None and st.level == LOST and "silent" in st.reason, st
