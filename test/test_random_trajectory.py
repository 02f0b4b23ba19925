"""Random smooth reachable trajectories (hexa.random_trajectory), ROS-free: reproducible per seed, inside the workspace
and reachable all along, within the servos' speed and acceleration limits by finite differences of the inverse
kinematics, smooth (starting at rest, periodic), and playable as the trajectory node's pose file."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hexa.kinematics import hexa6rus as kin
from hexa.random_trajectory import (WORKSPACE, RandomTrajectoryError, RandomTrajectorySettings,
                                    random_trajectory)
from hexa.robots.hexa_description import load_hexa
from hexa.trajectories import FourierTrajectory, load_pose_file, trajectory_named

DESC = load_hexa()
SEEDS = (0, 7, 300001)


def test_the_same_seed_gives_the_same_trajectory_and_another_seed_another():
    a = random_trajectory(7, DESC, RandomTrajectorySettings())    # drawn afresh, not the cached one
    b = random_trajectory(7)
    assert np.array_equal(a.a, b.a) and np.array_equal(a.b, b.b) and a.period == b.period
    c = random_trajectory(8)
    assert not np.allclose(c.a, a.a) and trajectory_named("random:7")[0] is b
    assert trajectory_named("random:7")[1] == pytest.approx(2 * b.period)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_random_trajectory_is_reachable_within_the_servo_limits_all_along(seed):
    s = RandomTrajectorySettings()
    traj = random_trajectory(seed)
    assert s.period[0] <= traj.period <= s.period[1] and 0 < traj.intensity <= 1.0
    dt = 1e-3
    t = np.arange(0.0, traj.duration + dt / 2, dt)
    pose = traj.evaluate(t)[0]
    assert np.all(np.abs(pose - DESC.home_pose) <= np.asarray(WORKSPACE) + 1e-12)
    zeta = kin.inverse_kinematics_batch(DESC, pose)               # raises on any unreachable pose
    # the servo rates by finite differences of the inverse kinematics, not by the Jacobians the draw used
    speed = np.abs(np.diff(zeta, axis=0)).max() / dt
    accel = np.abs(np.diff(zeta, 2, axis=0)).max() / dt ** 2
    assert speed <= s.speed_fraction * DESC.speed_max * 1.01, speed
    assert accel <= s.accel_max * 1.01, accel
    assert traj.peaks.torque <= s.torque_fraction * DESC.torque_max
    # it moves: every arm swings, the plate travels
    assert np.ptp(zeta, axis=0).min() > 0.02 and np.ptp(pose[:, :3], axis=0).max() > 0.01


@pytest.mark.parametrize("seed", SEEDS)
def test_a_random_trajectory_starts_at_home_at_rest_and_repeats_smoothly(seed):
    traj = random_trajectory(seed)
    pose, vel, acc = traj.evaluate(0.0)
    assert np.allclose(pose, DESC.home_pose) and np.allclose(vel, 0.0, atol=1e-12) and np.allclose(acc, 0.0,
                                                                                                   atol=1e-12)
    for k in range(3):                                               # pose, rate and acceleration repeat
        assert np.allclose(traj.evaluate(traj.period)[k], traj.evaluate(0.0)[k], atol=1e-9)
    # C²: the finite-difference rates agree with the analytic ones
    t = np.linspace(0.3, traj.period - 0.3, 50)
    h = 1e-4
    num = (traj.evaluate(t + h)[0] - traj.evaluate(t - h)[0]) / (2 * h)
    assert np.allclose(num, traj.evaluate(t)[1], atol=1e-6)


def test_the_pose_file_plays_the_same_trajectory_in_the_trajectory_runner(tmp_path):
    from hexa.trajectory_runner import TrajectoryRunner, TrajectorySettings

    traj = random_trajectory(7)
    path = traj.write(tmp_path / "random7.csv")
    played, duration = load_pose_file(path)
    assert duration == pytest.approx(traj.duration)
    t = 3.217
    assert np.allclose(played(t)[0], traj.evaluate(t)[0], atol=2e-4)
    assert np.allclose(played(t)[1], traj.evaluate(t)[1], atol=2e-3)
    back = FourierTrajectory.read_design(path)
    assert back is not None and np.allclose(back.a, traj.a) and back.period == pytest.approx(traj.period)
    # the trajectory node's core plays the file (start blend off: the trajectory itself starts at rest)
    runner = TrajectoryRunner.from_settings(DESC, TrajectorySettings(trajectory="file", file=str(path),
                                                                     start_time=1.0, start_blend=0.0,
                                                                     require_monitoring=False))
    for now in 1.0 + np.arange(0.0, t, 0.01):                          # the node's 100 Hz ticks
        runner.tick(now)
    tick = runner.tick(1.0 + t)
    assert tick.state == "running"
    assert np.allclose(tick.zeta, kin.inverse_kinematics(DESC, traj.evaluate(t)[0]), atol=2e-3)


def test_bad_names_and_settings_are_refused_with_their_name():
    for name in ("random:", "random:x", "random:-1"):
        with pytest.raises(ValueError, match="random:SEED"):
            trajectory_named(name)
    with pytest.raises(ValueError, match="'spiral'"):
        trajectory_named("spiral")
    with pytest.raises(RandomTrajectoryError, match="harmonics"):
        RandomTrajectorySettings(harmonics=0)
    with pytest.raises(RandomTrajectoryError, match="accel_max"):
        RandomTrajectorySettings(accel_max=0.0)
    with pytest.raises(RandomTrajectoryError, match="period"):
        RandomTrajectorySettings(period=(12.0, 4.0))


def test_cli_writes_a_random_trajectory_the_bringup_plays(tmp_path, capsys):
    from hexa_bringup.cli import main

    out = tmp_path / "r.csv"
    assert main(["trajectory", "random:7", "--out", str(out), "--cycles", "3", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["reachable"] and res["file"] == str(out) and res["duration"] == pytest.approx(3 * res["period"])
    assert 0 < res["peak_zeta_dot"] <= 0.25 * res["speed_max"]
    assert load_pose_file(out)[1] == pytest.approx(res["duration"])
    assert main(["trajectory", "circle", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["peak_zeta_dot"] > 0.1
    assert main(["trajectory", "random:abc"]) == 2
    assert "hexa trajectory: a random trajectory is named random:SEED" in capsys.readouterr().err
    assert main(["trajectory", "circle", "--cycles", "0"]) == 2
    assert "--cycles must be >= 1" in capsys.readouterr().err
