"""Hexa forward kinematics (damped Newton–Raphson) round trips with the closed-form IK, as properties."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from hexa.kinematics import hexa6rus as kin
from hexa.robots.hexa_description import load_hexa

DESC = load_hexa()
SPAN = np.array([0.10, 0.10, 0.06, 0.35, 0.35, 0.35])

poses = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6).map(
    lambda u: DESC.home_pose + np.asarray(u) * SPAN)


def _reachable(pose):
    try:
        return kin.inverse_kinematics(DESC, pose)
    except kin.UnreachablePoseError:
        return None


@settings(max_examples=150, deadline=None)
@given(poses)
def test_fk_of_ik_returns_the_pose_to_1e9(pose):
    zeta = _reachable(pose)
    assume(zeta is not None)
    back = kin.forward_kinematics(DESC, zeta)
    assert np.max(np.abs(back[:3] - pose[:3])) < 1e-9
    assert np.max(np.abs(back[3:] - pose[3:])) < 1e-9


@settings(max_examples=100, deadline=None)
@given(poses)
def test_ik_of_fk_returns_the_arm_angles_to_1e9(pose):
    zeta = _reachable(pose)
    assume(zeta is not None)
    again = kin.inverse_kinematics(DESC, kin.forward_kinematics(DESC, zeta))
    assert np.max(np.abs(again - zeta)) < 1e-9


@settings(max_examples=60, deadline=None)
@given(poses, st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6))
def test_warm_started_solver_tracks_a_small_motion(pose, du):
    zeta = _reachable(pose)
    step = pose + 0.01 * np.asarray(du) * SPAN
    zeta2 = _reachable(step)
    assume(zeta is not None and zeta2 is not None)
    solver = kin.ForwardKinematicsSolver(DESC)
    assert np.allclose(solver.solve(zeta), pose, atol=1e-9)
    assert np.allclose(solver.solve(zeta2), step, atol=1e-9)
    assert np.allclose(solver.last, step, atol=1e-9)


def test_fk_residual_vanishes_at_the_solution():
    pose = np.array([0.03, 0.02, -0.56, -0.1, 0.25, -0.2])
    zeta = kin.inverse_kinematics(DESC, pose)
    sol = kin.forward_kinematics(DESC, zeta)
    assert np.max(np.abs(kin.loop_closure_residual(DESC, sol, zeta))) < 1e-13


def test_fk_reports_non_convergence_with_the_arm_angles():
    zeta = kin.inverse_kinematics(DESC, [0.08, -0.08, -0.5, 0.3, -0.3, 0.3])
    with pytest.raises(kin.ForwardKinematicsError, match="did not converge"):
        kin.forward_kinematics(DESC, zeta, max_iter=2)
