"""3UPS+RPU description, IK, analytic J_D, Newton-Raphson FK, spherical joints and trajectories (seed 003)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from hexa.kinematics import upsrpu as kin
from hexa.robots.schema import RobotDescriptionError
from hexa.robots.upsrpu_description import DEFAULT_UPSRPU_PATH, load_upsrpu

DESC = load_upsrpu()

poses = st.tuples(st.floats(-0.08, 0.14), st.floats(0.63, 0.80), st.floats(-0.2, 0.2), st.floats(-0.35, 0.35)
                  ).map(np.array)


def test_description_has_table1_joints_and_table2_limits():
    np.testing.assert_allclose(DESC.base_joints[0], [-0.4, 0, 0])
    np.testing.assert_allclose(DESC.base_joints[1], [0, 0.4, 0], atol=1e-15)
    np.testing.assert_allclose(DESC.base_joints[2], [0.4 * np.cos(np.pi / 4), -0.4 * np.sin(np.pi / 4), 0])
    np.testing.assert_allclose(DESC.base_joints[3], [0.15, 0, 0])
    np.testing.assert_allclose(DESC.platform_joints[1], [0.3 * np.cos(np.radians(50)), 0.3 * np.sin(np.radians(50)), 0])
    np.testing.assert_allclose(DESC.platform_joints[2], [0, -0.3, 0], atol=1e-15)
    np.testing.assert_allclose(DESC.q_max, [0.93, 0.92, 0.93, 0.82])
    np.testing.assert_allclose(DESC.q_min, [0.65, 0.64, 0.65, 0.54])
    assert np.degrees(DESC.spherical_max) == pytest.approx(38.0)
    assert np.degrees(DESC.omega_limit) == pytest.approx(1.8)
    assert DESC.det_jd_limit == 0.015
    with pytest.raises(ValueError):
        DESC.q_min[0] = 1.0  # read-only


def test_description_error_names_the_bad_key(tmp_path):
    text = DEFAULT_UPSRPU_PATH.read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("R2: 0.40", "R2: -0.40"))
    with pytest.raises(RobotDescriptionError, match="geometry.R2"):
        load_upsrpu(bad)
    bad.write_text(text.replace("q_max: [0.93, 0.92, 0.93, 0.82]", "q_max: [0.93, 0.92, 0.93]"))
    with pytest.raises(RobotDescriptionError, match="limits.q_max"):
        load_upsrpu(bad)
    bad.write_text(text.replace("  d_s: 0.15\n", ""))
    with pytest.raises(RobotDescriptionError, match="geometry.d_s"):
        load_upsrpu(bad)


def test_a_different_file_changes_the_robot(tmp_path):
    other = tmp_path / "wide.yaml"
    other.write_text(DEFAULT_UPSRPU_PATH.read_text().replace("d_s: 0.15", "d_s: 0.20"))
    X = np.array([0.0, 0.7, 0.0, 0.0])
    assert kin.inverse_kinematics(load_upsrpu(other), X)[3] == pytest.approx(np.hypot(0.2, 0.7))


def test_ik_home_pose_matches_hand_computation():
    q = kin.inverse_kinematics(DESC, np.array([0.0, 0.7, 0.0, 0.0]))
    assert q[0] == pytest.approx(np.hypot(0.1, 0.7))           # A0 (-0.4,0,0) -> A1 (-0.3,0,0.7)
    assert q[3] == pytest.approx(np.hypot(0.15, 0.7))          # D0 (0.15,0,0) -> O_m (0,0,0.7)
    b1 = 0.3 * np.array([np.cos(np.radians(50)), np.sin(np.radians(50)), 0]) + [0, 0, 0.7]
    assert q[1] == pytest.approx(np.linalg.norm(b1 - [0, 0.4, 0]))


def test_ik_outside_stroke_names_the_limb():
    with pytest.raises(kin.UnreachablePoseError, match="limb 1 length 0.5099"):
        kin.inverse_kinematics(DESC, np.array([0.0, 0.50, 0.0, 0.0]), check_limits=True)


@given(st.lists(poses, min_size=1, max_size=8))
@settings(max_examples=30, deadline=None)
def test_batch_ik_equals_single_ik(Xs):
    X = np.array(Xs)
    q = kin.inverse_kinematics_batch(DESC, X)
    for k in range(len(X)):
        np.testing.assert_allclose(q[k], kin.inverse_kinematics(DESC, X[k]), atol=1e-14)


@given(poses)
@settings(max_examples=60, deadline=None)
def test_jacobian_jd_matches_finite_differences(X):
    J = kin.jacobian_jd(DESC, X)
    h = 1e-6
    Jn = np.array([(kin.inverse_kinematics(DESC, X + h * e) - kin.inverse_kinematics(DESC, X - h * e)) / (2 * h)
                   for e in np.eye(4)]).T
    np.testing.assert_allclose(J, Jn, atol=1e-8)


@given(poses, st.tuples(*[st.floats(-1.0, 1.0)] * 4).map(np.array))
@settings(max_examples=80, deadline=None)
def test_fk_inverts_ik_to_1e_9(X, dir_):
    assume(abs(np.linalg.det(kin.jacobian_jd(DESC, X))) > 2e-3)     # keep away from type II singularities
    q = kin.inverse_kinematics(DESC, X)
    X0 = X + 0.01 * dir_                                           # initial pose near the true one (Algorithm 1)
    Xf = kin.forward_kinematics(DESC, q, X0)
    np.testing.assert_allclose(Xf, X, atol=1e-9)
    np.testing.assert_allclose(kin.inverse_kinematics(DESC, Xf), q, atol=1e-12)


def test_fk_reports_nonconvergence():
    q = kin.inverse_kinematics(DESC, DESC.home)
    with pytest.raises(kin.ForwardKinematicsError):
        kin.forward_kinematics(DESC, q * 3.0, DESC.home, max_iter=5)


def test_spherical_joint_angle_is_limb_vs_platform_normal():
    a = kin.spherical_joint_angles(DESC, np.array([0.0, 0.7, 0.0, 0.0]))
    assert a[0] == pytest.approx(np.arctan2(0.1, 0.7))             # limb 1 tilts 0.1 m over 0.7 m
    assert np.all(a < DESC.spherical_max)


@pytest.mark.parametrize("number", [1, 2, 3, 4, 5])
def test_table3_trajectory_is_constant_velocity_and_ends_at_singular_pose(number):
    t, X = kin.table3_trajectory(DESC, number)
    np.testing.assert_allclose(X[0], DESC.home)
    np.testing.assert_allclose(X[-1], DESC.singular_poses[number - 1])
    v = np.abs(np.diff(X, axis=0)) / np.diff(t)[:, None]
    assert v[:, :2].max() <= 0.02 + 1e-9 and v[:, 2:].max() <= 0.03 + 1e-9
    moving = v.max(axis=0) > 0
    speeds = np.array([0.02, 0.02, 0.03, 0.03])
    for k in np.flatnonzero(moving):    # each DOF moves at its constant speed (except the last partial sample)
        assert np.median(v[v[:, k] > 0, k]) == pytest.approx(speeds[k], rel=1e-6)
    kin.inverse_kinematics_batch(DESC, X)
    for x in X[::50]:
        kin.inverse_kinematics(DESC, x, check_limits=True)
        assert np.all(kin.spherical_joint_angles(DESC, x) < DESC.spherical_max)


def test_reference_trajectory_tr15_runs_through_ik():
    if kin.reference_data_dir() is None:
        pytest.skip("reference data ../shared/data/upsrpu not present next to the repository")
    t, X = kin.load_reference_trajectory("TR15")
    assert X.shape[1] == 4 and t[1] - t[0] == pytest.approx(0.01)
    for x in X[::10]:
        kin.inverse_kinematics(DESC, x, check_limits=True)
    np.testing.assert_allclose(X[-1], DESC.singular_poses[0], atol=0.01)   # ends at Table 3 pose 1
