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
