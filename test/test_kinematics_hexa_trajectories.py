"""The paper's trajectories (seed 000 eqs 37, 40, 41): values, derivatives, reachability with margin."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hexa import trajectories as tr
from hexa.kinematics import hexa6rus as kin
from hexa.robots.hexa_description import load_hexa

DESC = load_hexa()


def test_circle_matches_eq37_in_si_units():
    pose, _, _ = tr.circle(1.25)  # quarter period: cos = 0, sin = 1
    assert np.allclose(pose, [0.0, 0.1, -0.55, math.radians(-6), math.radians(1), math.radians(31)], atol=1e-12)


def test_helix_rises_5_mm_per_second_and_ellipse_has_its_semi_axes():
    assert np.isclose(tr.helix(4.0)[0][2], -0.55 + 0.020)
    t = np.linspace(0, 5, 1001)
    p = tr.ellipse(t)[0]
    assert np.isclose(p[:, 0].max(), 0.08) and np.isclose(p[:, 1].max(), 0.11, atol=1e-6)


@pytest.mark.parametrize("name", sorted(tr.TRAJECTORIES))
def test_velocities_and_accelerations_are_the_time_derivatives(name):
    t = np.linspace(0, 10, 4001)
    pose, vel, acc = tr.TRAJECTORIES[name](t)
    assert np.allclose(np.gradient(pose, t, axis=0)[5:-5], vel[5:-5], atol=1e-4)
    assert np.allclose(np.gradient(vel, t, axis=0)[5:-5], acc[5:-5], atol=1e-3)


@pytest.mark.parametrize("name", sorted(tr.TRAJECTORIES))
def test_trajectory_is_reachable_with_margin(name):
    t, pose, vel, acc = tr.sample(name, rate_hz=200.0)
    zeta, zd, _ = kin.inverse_kinematics_derivatives(DESC, pose, vel, acc)   # raises if any pose is unreachable
    a, b, c = kin.ik_coefficients(DESC, pose)
    assert np.max(np.abs(a / np.hypot(b, c))) < 0.8                          # far from arm/rod alignment
    margin = math.radians(15)
    assert zeta.min() > DESC.zeta_min + margin and zeta.max() < DESC.zeta_max - margin
    assert np.max(np.abs(zd)) < 0.5 * DESC.speed_max                         # servos keep up
    home_det = abs(np.linalg.det(kin.constraint_jacobians(DESC, DESC.home_pose,
                                                          kin.inverse_kinematics(DESC, DESC.home_pose))[0]))
    dets = [abs(np.linalg.det(kin.constraint_jacobians(DESC, p, z)[0])) for p, z in zip(pose[::20], zeta[::20])]
    assert min(dets) > 0.5 * home_det                                        # far from type II singularity


def test_sample_rejects_unknown_names():
    with pytest.raises(KeyError, match="square"):
        tr.sample("square")


def test_a_sequence_plays_each_part_in_turn_and_cross_fades_continuously():
    traj, duration = tr.trajectory_named("circle+helix+ellipse")
    assert duration == 30.0
    t = np.linspace(0.0, 30.0, 12001)
    pose, vel, acc = traj(t)
    # away from the junctions each part as it is; inside a blend neither part alone
    for k, part in enumerate((tr.circle, tr.helix, tr.ellipse)):
        x = np.linspace(tr.SEQUENCE_BLEND + 0.01, 9.99, 50)
        assert np.allclose(traj(10.0 * k + x)[0], part(x)[0], atol=1e-12)
    mid = traj(11.0)[0]
    assert not np.allclose(mid, tr.helix(1.0)[0], atol=1e-3) and not np.allclose(mid, tr.circle(11.0)[0], atol=1e-3)
    # the helix ends 50 mm up, the ellipse starts at z0: taken up over the blend, never as a step
    assert np.isclose(traj(19.999)[0][2], tr.helix(9.999)[0][2]) and np.isclose(traj(22.0)[0][2], tr.Z0)
    assert np.abs(np.diff(pose, axis=0)).max() < 0.01                       # 2.5 ms steps: no jump anywhere
    # rates are the time derivatives across the junctions too, and accelerations everywhere but at a blend's two
    # ends (the smoothstep's second derivative steps there, as the player's loop blend does)
    assert np.allclose(np.gradient(pose, t, axis=0)[5:-5], vel[5:-5], atol=1e-3)
    edges = np.isin(np.round(t, 6), [10.0, 12.0, 20.0, 22.0])
    ok = ~np.convolve(edges, np.ones(5, bool), mode="same")
    ok[:5] = ok[-5:] = False
    assert np.allclose(np.gradient(vel, t, axis=0)[ok], acc[ok], atol=1e-3)
    assert traj(12.5)[0].shape == (6,) and traj(np.zeros((2, 3)))[0].shape == (2, 3, 6)


def test_a_sequence_is_refused_with_a_file_or_an_unknown_part():
    with pytest.raises(ValueError, match="not 'file'"):
        tr.trajectory_named("circle+file")
    with pytest.raises(ValueError, match="square"):
        tr.trajectory_named("circle+square")
    with pytest.raises(ValueError, match="longer than"):
        tr.sequence([(tr.circle, 1.0)], blend=2.0)
