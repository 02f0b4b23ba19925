"""The trajectory player: IK commands along the paper's trajectories and the collision reaction policies."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.kinematics import hexa6rus
from hexa.robots.hexa_description import load_hexa
from hexa.trajectories import DURATIONS, TRAJECTORIES
from hexa.trajectory_player import TrajectoryPlayer, TrajectoryPlayerError


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


def test_commands_follow_the_trajectory_through_ik_with_consistent_rates(desc):
    p = TrajectoryPlayer(desc, TRAJECTORIES["circle"], DURATIONS["circle"])
    c1 = p.command(1.0)
    c2 = p.command(1.0 + 1e-5)
    pose, _, _ = TRAJECTORIES["circle"](1.0)
    assert np.allclose(c1.pose, pose) and c1.state == "running"
    assert np.allclose(c1.zeta, hexa6rus.inverse_kinematics(desc, pose))
    assert np.allclose((c2.zeta - c1.zeta) / 1e-5, c1.zeta_dot, atol=1e-3)


def test_hold_policy_freezes_the_pose_at_the_collision_and_resume_blends_back(desc):
    p = TrajectoryPlayer(desc, TRAJECTORIES["helix"], DURATIONS["helix"], policy="hold")
    before = p.command(3.0)
    assert p.on_collision(3.0) == "held"
    for t in (3.5, 5.0, 8.0):
        c = p.command(t)
        assert c.state == "held" and np.allclose(c.pose, before.pose) and not c.zeta_dot.any()
    assert p.resume(8.0)
    c = p.command(8.0 + 2.0)  # 2 s after resume = trajectory time 5.0 (held 5 s)
    assert c.state == "running"
    assert np.allclose(c.pose, TRAJECTORIES["helix"](5.0)[0])


def test_retract_policy_backs_off_along_the_external_force(desc):
    p = TrajectoryPlayer(desc, TRAJECTORIES["circle"], DURATIONS["circle"], policy="retract",
                         retract_distance=0.02, retract_time=0.5)
    before = p.command(2.0)
    assert p.on_collision(2.0, np.array([0.0, 3.0, 0.0])) == "retracting"
    mid = p.command(2.25)
    assert mid.state == "retracting"
    end = p.command(3.0)
    assert end.state == "held"
    assert np.allclose(end.pose[:3] - before.pose[:3], [0.0, 0.02, 0.0])


def test_ignore_policy_keeps_running_and_bad_policy_is_refused(desc):
    p = TrajectoryPlayer(desc, TRAJECTORIES["ellipse"], DURATIONS["ellipse"], policy="ignore")
    p.command(1.0)
    p.on_collision(1.0)
    assert p.command(2.0).state == "running"
    with pytest.raises(TrajectoryPlayerError, match="unknown collision policy 'stop'"):
        TrajectoryPlayer(desc, TRAJECTORIES["ellipse"], 10.0, policy="stop")


def test_after_the_duration_the_last_pose_is_held_as_finished(desc):
    p = TrajectoryPlayer(desc, TRAJECTORIES["circle"], 2.0)
    c = p.command(5.0)
    assert c.state == "finished" and np.allclose(c.pose, TRAJECTORIES["circle"](2.0)[0])
    assert np.allclose(c.zeta_dot, 0.0)                   # held at rest, not at the end's velocity


def test_loop_restarts_a_non_periodic_trajectory_without_a_jump(desc):
    """The helix ends 5 cm above its start: looping cross-fades onto the next cycle (C¹), the circle is unchanged."""
    traj, D = TRAJECTORIES["helix"], DURATIONS["helix"]
    assert abs(traj(D)[0][2] - traj(0.0)[0][2]) > 0.04
    p = TrajectoryPlayer(desc, traj, D, loop=True, loop_blend=2.0)
    h, prev, peak = 0.005, None, 0.0
    for k in range(int((D - 0.5) / h), int((D + 2.5) / h)):      # across the wrap and the whole blend
        c = p.command(k * h)
        assert c.state == "running"
        if prev is not None:
            fd = (c.zeta - prev.zeta) / h
            assert np.allclose(fd, 0.5 * (c.zeta_dot + prev.zeta_dot), atol=2e-2), k   # rates match, no jump
            assert np.abs(c.zeta - prev.zeta).max() < 0.01, k
            peak = max(peak, np.abs(c.zeta_dot).max())
        prev = c
    plain = max(np.abs(TrajectoryPlayer(desc, traj, D).command(x).zeta_dot).max() for x in np.arange(0, D, 0.05))
    assert peak < 1.5 * plain                                         # the offset costs little extra speed
    assert np.allclose(p.command(D + 3.0).pose, traj(3.0)[0])         # after the blend: the next cycle itself
    assert np.allclose(p.command(2 * D + 4.0).pose, traj(4.0)[0])
    circle = TrajectoryPlayer(desc, TRAJECTORIES["circle"], D, loop=True)
    for x in (0.3, 1.0, 1.7):                                         # periodic: the blend changes nothing
        assert np.allclose(circle.command(D + x).pose, TRAJECTORIES["circle"](x)[0])
    with pytest.raises(TrajectoryPlayerError, match="loop_blend"):
        TrajectoryPlayer(desc, traj, D, loop=True, loop_blend=0.0)


def test_a_late_caller_pauses_the_trajectory_instead_of_commanding_a_jump(desc):
    traj = TRAJECTORIES["circle"]
    p = TrajectoryPlayer(desc, traj, DURATIONS["circle"], max_step=0.03)
    for k in range(101):                      # on time: 100 Hz for 1 s, no lag
        c = p.command(0.01 * k)
    assert p.lag_events == 0 and np.allclose(c.pose, traj(1.0)[0])
    late = p.command(1.25)                    # 0.25 s late: advances only 0.03 s of trajectory
    assert p.lag_events == 1 and p.lag_time == pytest.approx(0.22)
    assert np.allclose(late.pose, traj(1.03)[0]) and late.trajectory_time == pytest.approx(1.03)
    assert np.max(np.abs(late.zeta - c.zeta)) < 0.03  # rad: a small step, not the 0.25 s jump
    jump = TrajectoryPlayer(desc, traj, DURATIONS["circle"])  # without max_step: a jump
    jump.command(1.0)
    assert np.allclose(jump.command(1.25).pose, traj(1.25)[0])
    with pytest.raises(TrajectoryPlayerError, match="max_step"):
        TrajectoryPlayer(desc, traj, 10.0, max_step=0.0)


def test_max_step_starts_a_late_first_command_at_the_trajectory_start_and_ignores_holds(desc):
    traj = TRAJECTORIES["helix"]
    p = TrajectoryPlayer(desc, traj, DURATIONS["helix"], max_step=0.05)
    assert np.allclose(p.command(5.0).pose, traj(0.05)[0])
    p.on_collision(5.0)
    p.command(9.0)                            # a long hold is not lag
    assert p.lag_events == 1
    p.resume(9.0)
    assert p.command(9.01).trajectory_time == pytest.approx(0.06)


def test_start_blend_starts_from_rest_and_joins_the_trajectory_without_a_time_shift(desc):
    traj = TRAJECTORIES["circle"]
    p = TrajectoryPlayer(desc, traj, DURATIONS["circle"], start_blend=0.5)  # player time 0..0.5 s: blended
    c0 = p.command(0.0)
    assert np.allclose(c0.pose, traj(0.0)[0]) and np.allclose(c0.zeta_dot, 0.0) and c0.state == "running"
    assert np.abs(traj(0.0)[1]).max() > 0.5          # the paper's trajectory itself starts moving at once
    prev, h, peak = c0, 0.001, 0.0
    for k in range(1, 700):                           # commanded rates match the commanded poses (no jumps)
        c = p.command(k * h)
        fd = (c.zeta - prev.zeta) / h
        assert np.allclose(fd, 0.5 * (c.zeta_dot + prev.zeta_dot), atol=2e-2), k
        peak = max(peak, np.abs(c.zeta_dot).max())
        prev = c
    plain = TrajectoryPlayer(desc, traj, DURATIONS["circle"])
    assert np.allclose(p.command(0.6).pose, traj(0.6)[0]) and np.allclose(p.command(0.6).zeta_dot,
                                                                           plain.command(0.6).zeta_dot)
    # catching up with the time-exact trajectory costs at most 1.7x its rate (smoothstep blend: max 1.69)
    assert peak < 1.75 * max(np.abs(plain.command(k * h).zeta_dot).max() for k in range(700))
    assert np.abs(p.command(0.6).zeta_dot - plain.command(0.6).zeta_dot).max() < 1e-12
    with pytest.raises(TrajectoryPlayerError, match="start_blend"):
        TrajectoryPlayer(desc, traj, 10.0, start_blend=-1.0)


def test_approach_moves_slowly_from_the_measured_pose_then_plays_the_trajectory_shifted(desc):
    traj = TRAJECTORIES["circle"]
    start = np.asarray(traj(0.0)[0])
    here = start + np.array([0.02, -0.015, -0.01, 0.05, 0.0, -0.04])     # where the camera sees the plate
    speed = 0.5
    p = TrajectoryPlayer(desc, traj, DURATIONS["circle"], start_blend=0.5)
    T = p.approach_from(here, speed)
    gap = np.abs(hexa6rus.inverse_kinematics(desc, start) - hexa6rus.inverse_kinematics(desc, here)).max()
    assert gap > 0.05 and 1.5 * gap / speed <= T < 1.2 * 1.5 * gap / speed   # ≥ the straight-line estimate
    c0 = p.command(0.0)
    assert c0.state == "approaching" and np.allclose(c0.pose, here) and np.allclose(c0.zeta_dot, 0.0)
    assert np.allclose(c0.zeta, hexa6rus.inverse_kinematics(desc, here))   # first command: where the arms are
    h, prev, peak = 0.002, c0, 0.0
    for k in range(1, int(T / h) + 1):
        c = p.command(k * h)
        assert c.state == "approaching", k
        peak = max(peak, np.abs((c.zeta - prev.zeta) / h).max())
        assert np.allclose((c.zeta - prev.zeta) / h, 0.5 * (c.zeta_dot + prev.zeta_dot), atol=2e-2), k
        prev = c
    assert 0.8 * speed < peak <= 1.005 * speed                              # slow: no arm faster than the speed
    end = p.command(T)
    assert np.allclose(end.pose, start) and np.allclose(end.zeta_dot, 0.0, atol=1e-9)
    plain = TrajectoryPlayer(desc, traj, DURATIONS["circle"], start_blend=0.5)
    for x in (0.0, 0.3, 0.7, 2.0):                                          # then the trajectory, shifted by T
        a, b = p.command(T + x), plain.command(x)
        assert a.state == b.state == "running" and np.allclose(a.pose, b.pose) and np.allclose(a.zeta, b.zeta)


def test_approach_is_skipped_near_the_start_and_refused_after_the_first_command(desc):
    traj = TRAJECTORIES["helix"]
    p = TrajectoryPlayer(desc, traj, DURATIONS["helix"])
    start = np.asarray(traj(0.0)[0])
    assert p.approach_from(start + np.array([1e-4, 0, 0, 0, 0, 0]), 0.3) == 0.0
    assert p.command(0.0).state == "running" and np.allclose(p.command(0.0).pose, start)
    with pytest.raises(TrajectoryPlayerError, match="before the first command"):
        p.approach_from(start, 0.3)
    q = TrajectoryPlayer(desc, traj, DURATIONS["helix"])
    with pytest.raises(TrajectoryPlayerError, match="speed"):
        q.approach_from(start, 0.0)
    with pytest.raises(hexa6rus.UnreachablePoseError):
        q.approach_from(start + np.array([0, 0, 1.0, 0, 0, 0]), 0.3)        # a pose 1 m away: no IK solution


def test_a_collision_during_the_approach_holds_there_and_resume_continues_it(desc):
    traj = TRAJECTORIES["ellipse"]
    start = np.asarray(traj(0.0)[0])
    p = TrajectoryPlayer(desc, traj, DURATIONS["ellipse"], policy="hold")
    T = p.approach_from(start + np.array([0.0, 0.03, 0.0, 0.0, 0.0, 0.0]), 0.1)
    assert T > 0.5
    mid = p.command(T / 2)
    assert p.on_collision(T / 2) == "held"
    assert np.allclose(p.command(T / 2 + 1.0).pose, mid.pose)               # held where it was
    assert p.resume(T / 2 + 1.0)
    assert np.allclose(p.command(T / 2 + 1.0 + 1e-3).pose, mid.pose, atol=1e-4)   # no jump at the resume
    assert p.command(T / 2 + 1.0 + 0.2).trajectory_time < 0                    # the approach goes on, ...
    later = p.command(T + 1.0 + 1.5)                                         # ... then the trajectory, 1 s (held) late
    assert later.state == "running" and np.allclose(later.pose, traj(1.5)[0])
