"""The trajectory node's logic without ROS: when trajectory time starts (delay, set time, approach from a fresh
measured pose, the collision monitoring's first OK), the command per tick, requests before the clock runs, the hold on
a monitoring LOST and the resume refused until OK, settings refused by name."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.kinematics import hexa6rus
from hexa.robots.hexa_description import load_hexa
from hexa.trajectories import TRAJECTORIES, load_pose_file
from hexa.trajectory_runner import APPROACH_POSE_MAX_AGE, TrajectoryRunner, TrajectorySettings

START = np.asarray(TRAJECTORIES["circle"](0.0)[0])


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


def _runner(desc, log=None, **kw) -> TrajectoryRunner:
    kw.setdefault("require_monitoring", False)   # the monitoring contract has tests of its own below
    return TrajectoryRunner.from_settings(desc, TrajectorySettings(**kw), log)


def test_the_start_pose_is_held_at_rest_for_the_start_delay_then_the_trajectory_plays(desc):
    r = _runner(desc, start_delay=1.0, start_blend=0.0)
    assert r.tick(0.0).state is None                             # sim time not started: nothing
    first = r.tick(10.0)                                         # trajectory time 0 is 11.0
    assert first.state == "waiting" and not first.zeta_dot.any()
    assert np.allclose(first.zeta, hexa6rus.inverse_kinematics(desc, START))
    assert r.tick(11.5).state == "running" and r.time(11.5) == pytest.approx(0.5)
    assert r.start == pytest.approx(11.0)
    fixed = _runner(desc, start_time=0.0)
    assert fixed.start is None                                   # no tick yet
    assert fixed.tick(2.0).state == "running" and fixed.time(2.0) == pytest.approx(2.0)
    assert fixed.start == 0.0


def test_a_start_time_ahead_is_the_start_once_monitoring_is_ok_before_it(desc):
    r = _runner(desc, start_time=1.0, require_monitoring=True, monitoring_timeout=1e6)
    assert r.tick(0.2).state == "waiting_for_monitoring" and r.start is None
    r.on_monitoring("OK", "", 0.5)
    assert r.tick(0.51).state == "waiting" and r.start == pytest.approx(1.0)   # ahead of the clock, fixed
    late = _runner(desc, start_time=1.0, require_monitoring=True, monitoring_timeout=1e6)
    for now in (0.5, 1.0, 1.5, 1.8):
        late.tick(now)
    late.on_monitoring("OK", "", 1.812)                          # a late first OK moves trajectory time 0 to it
    late.tick(1.82)
    assert late.start == pytest.approx(1.812)


def test_with_an_approach_nothing_is_commanded_before_a_fresh_valid_pose(desc):
    logs: list[tuple[str, str]] = []
    r = _runner(desc, lambda lv, t: logs.append((lv, t)), start_delay=0.0, approach_speed=0.3)
    assert r.approach_pending
    tick = r.tick(5.0)
    assert tick.state == "waiting_for_pose" and tick.zeta is None
    r.on_pose(np.full(6, np.nan), 5.0, 5.0)                      # rejected, counted
    r.reject_pose("invalid quaternion")
    assert r.bad_poses == 2 and [lv for lv, _ in logs] == ["warn", "warn"]
    here = START + np.array([0.015, -0.02, 0.01, 0.04, 0.0, -0.03])
    r.on_pose(here, 5.0 - 2.0, 5.1)                              # 2 s old at 5.1: not used
    assert r.tick(5.1).zeta is None and r.state == "waiting_for_pose" and r.start is None
    assert r.collision(5.1) is None and not r.resume(5.1) and not r.hold(5.1)
    r.on_pose(here, 5.2, 5.2)
    first = r.tick(5.2 + APPROACH_POSE_MAX_AGE / 2)
    assert first.state == "approaching" and not r.approach_pending
    assert r.start == pytest.approx(5.2 + APPROACH_POSE_MAX_AGE / 2)   # the approach is trajectory time 0
    assert np.allclose(first.zeta, hexa6rus.inverse_kinematics(desc, here))
    assert logs[-1][0] == "info" and "approach from plate pose" in logs[-1][1]
    assert r.diagnostic_values()["rejected_poses"] == "2" and float(r.diagnostic_values()["approach_time_s"]) > 0


def test_an_unreachable_measured_pose_is_dropped_and_nothing_is_commanded(desc):
    logs: list[tuple[str, str]] = []
    r = _runner(desc, lambda lv, t: logs.append((lv, t)), start_delay=0.0, approach_speed=0.3)
    r.on_pose(START + np.array([0, 0, 1.0, 0, 0, 0]), 1.0, 1.0)   # 1 m away: no IK solution
    assert r.tick(1.1).zeta is None and r.approach_pending and r.bad_poses == 1
    assert logs[-1][0] == "error" and r.tick(1.2).state == "waiting_for_pose"


def test_an_ik_failure_repeats_the_previous_command(desc):
    logs: list[tuple[str, str]] = []
    r = _runner(desc, lambda lv, t: logs.append((lv, t)), start_time=0.0, start_blend=0.0, max_step=0.0)
    good = r.tick(1.0)
    r.player.trajectory = lambda t: (START + np.array([0, 0, 1.0, 0, 0, 0]), np.zeros(6), np.zeros(6))
    again = r.tick(1.01)
    assert np.array_equal(again.zeta, good.zeta) and logs[-1][0] == "error"
    assert r.diagnostic_values()["ik_failures"] == "1"


def test_hold_and_resume_requests_reach_the_player(desc):
    r = _runner(desc, start_time=0.0)
    r.tick(1.0)
    assert r.hold(1.0) and r.tick(1.5).state == "held"
    assert r.resume(2.0) and not r.resume(2.1)
    assert r.collision(3.0) == "held" and r.collisions == 1
    assert not _runner(desc, start_time=0.0, collision_policy="ignore").hold(1.0)


@pytest.mark.parametrize("kw, name", [({"approach_speed": -1.0}, "approach_speed"),
                                      ({"approach_tolerance": float("nan")}, "approach_tolerance"),
                                      ({"rate_hz": 0.0}, "rate_hz"), ({"start_blend": -0.1}, "start_blend"),
                                      ({"max_step": 0.001}, "max_step"), ({"trajectory": "square"}, "'square'"),
                                      ({"collision_policy": "stop"}, "'stop'")])
def test_bad_settings_are_refused_naming_the_setting(desc, kw, name):
    with pytest.raises(ValueError, match=name):
        _runner(desc, **kw)


def test_a_pose_file_is_interpolated_with_its_rates(tmp_path):
    f = tmp_path / "poses.csv"
    f.write_text("# t x y z alpha beta gamma\n0,0,0,-0.55,0,0,0\n2,0.1,0,-0.55,0,0,0.2\n")
    traj, duration = load_pose_file(f)
    pose, rate, _ = traj(1.0)
    assert duration == 2.0 and np.allclose(pose, [0.05, 0, -0.55, 0, 0, 0.1]) and rate[0] == pytest.approx(0.05)
    f.write_text("0,0,0,-0.55,0,0,0\n0,0.1,0,-0.55,0,0,0\n")
    with pytest.raises(ValueError, match="increase"):
        load_pose_file(f)


def test_nothing_moves_before_the_first_monitoring_ok_then_the_trajectory_starts_from_0(desc):
    r = _runner(desc, start_delay=1.0, start_blend=0.0, require_monitoring=True,
                monitoring_timeout=1e6)   # no heartbeats here
    z0 = hexa6rus.inverse_kinematics(desc, START)
    for now in (10.0, 11.0, 12.5):                               # past the start delay: still the start pose, at rest
        tick = r.tick(now)
        assert tick.state == "waiting_for_monitoring" and not tick.zeta_dot.any() and np.allclose(tick.zeta, z0)
    assert r.on_monitoring("DEGRADED", "settling: residuals fresh for 0.2 of 0.5 s", 12.6) is None
    assert r.tick(12.7).state == "waiting_for_monitoring"
    assert r.start is None                                      # not fixed before the first OK
    assert "may start" in r.on_monitoring("OK", "", 13.0)
    assert r.tick(13.0).state == "running" and r.time(13.5) == pytest.approx(0.5)   # from trajectory time 0
    assert r.start == pytest.approx(13.0)
    r.tick(20.0)
    assert r.start == pytest.approx(13.0)                       # fixed once known
    assert r.diagnostic_values()["monitoring"] == "OK"


def test_a_monitoring_lost_holds_and_resume_is_refused_until_ok(desc):
    r = _runner(desc, start_time=0.0, require_monitoring=True,
                monitoring_timeout=1e6)   # no heartbeats here
    r.on_monitoring("OK", "", 0.005)

    def play(t0: float, t1: float) -> list:                      # the node's 100 Hz ticks
        return [r.tick(t) for t in np.arange(t0, t1, 0.01)]

    before = play(0.01, 2.0)[-1]
    assert before.state == "running"
    text = r.on_monitoring("LOST", "no fresh residual for 60 ms: motor_currents silent for 60 ms", 2.0)
    assert "held" in text and "motor_currents silent" in text
    held = play(2.0, 3.1)
    assert all(h.state == "held" and np.allclose(h.zeta, held[0].zeta) and not h.zeta_dot.any() for h in held)
    assert np.abs(held[0].zeta - before.zeta).max() < 0.01          # held where it was
    assert not r.resume(3.1) and "LOST" in r.refusal and "motor_currents silent" in r.refusal
    r.on_monitoring("DEGRADED", "settling: residuals fresh for 0.1 of 0.5 s", 3.2)
    assert not r.resume(3.3) and "DEGRADED" in r.refusal and play(3.1, 3.6)[-1].state == "held"
    r.on_monitoring("OK", "", 3.6)
    assert play(3.6, 3.8)[-1].state == "held"                     # OK alone does not move the robot: the operator does
    assert r.resume(3.8) and r.refusal == ""
    assert play(3.8, 3.9)[-1].state == "resuming"
    assert r.monitoring_holds == 1 and r.diagnostic_values()["monitoring_holds"] == "1"


def test_without_required_monitoring_its_states_are_ignored(desc):
    r = _runner(desc, start_time=0.0)
    assert r.tick(1.0).state == "running"
    assert r.on_monitoring("LOST", "no fresh residual", 1.0) is None and r.tick(1.1).state == "running"


def test_with_an_approach_the_measured_pose_is_held_at_rest_until_monitoring_is_ok(desc):
    """Robot mode: the first command is the measured pose's IK (the driver's joint_states need a command before the
    observer can compute a residual); the approach moves only after the first OK."""
    r = _runner(desc, start_delay=0.0, approach_speed=0.3, require_monitoring=True,
                monitoring_timeout=1e6)   # no heartbeats here
    here = START + np.array([0.015, -0.02, 0.01, 0.04, 0.0, -0.03])
    assert r.tick(5.0).zeta is None and r.state == "waiting_for_pose"
    r.on_pose(here, 5.0, 5.0)
    z_here = hexa6rus.inverse_kinematics(desc, here)
    for now in (5.01, 5.5, 6.0):
        tick = r.tick(now)
        assert tick.state == "waiting_for_monitoring" and np.allclose(tick.zeta, z_here) and not tick.zeta_dot.any()
    r.on_monitoring("OK", "", 6.0)
    ticks = [r.tick(t) for t in np.arange(6.01, 6.5, 0.01)]
    assert ticks[0].state == "approaching" and np.abs(ticks[0].zeta - z_here).max() < 1e-3   # from rest, no step
    assert np.abs(ticks[-1].zeta - z_here).max() > 1e-3                                        # and it moves


def test_silence_on_monitoring_counts_as_lost_after_its_timeout(desc):
    """The observer killed or hung: no state (it re-publishes every 50 ms) for monitoring_timeout holds the robot."""
    logs: list[tuple[str, str]] = []
    r = _runner(desc, lambda lv, t: logs.append((lv, t)), start_time=0.0, require_monitoring=True,
                monitoring_timeout=0.25)
    for t in np.arange(0.0, 1.0, 0.05):                           # heartbeats
        r.on_monitoring("OK", "", t)
        r.tick(t + 0.01)
    assert r.tick(1.0 + 0.2).state == "running"                   # 0.25 s since the last state: not yet
    assert r.tick(0.95 + 0.26).state == "held"
    assert r.monitoring == "LOST" and "no monitoring state from the observer" in r.monitoring_reason
    assert logs[-1][0] == "error" and "held" in logs[-1][1]
    assert not r.resume(1.3) and "observer down" in r.refusal
    r.on_monitoring("DEGRADED", "settling: no joint_states received yet", 5.0)   # the observer respawned
    assert r.tick(5.1).state == "held" and not r.resume(5.1)
    r.on_monitoring("OK", "", 6.0)
    assert r.resume(6.0) and r.monitoring_holds == 1
