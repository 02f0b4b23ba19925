"""Hexa constraint Jacobians J_D, J_I (analytic vs finite differences), twist ↔ arm rates, IK derivatives."""
from __future__ import annotations

import numpy as np
from hypothesis import assume, given, settings, strategies as st

from hexa.kinematics import hexa6rus as kin
from hexa.robots.hexa_description import load_hexa

DESC = load_hexa()
SPAN = np.array([0.10, 0.10, 0.06, 0.35, 0.35, 0.35])
poses = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6).map(
    lambda u: DESC.home_pose + np.asarray(u) * SPAN)


def _ik(pose):
    try:
        return kin.inverse_kinematics(DESC, pose)
    except kin.UnreachablePoseError:
        return None


def _phi(pose, zeta):
    """Rod-length residual scaled so that dΦ/dt = J_D t − J_I ζ̇ (rod length error, m)."""
    d = kin.plate_joints(DESC, pose) - kin.elbows(DESC, zeta)
    return np.linalg.norm(d, axis=1) - DESC.l_d


@settings(max_examples=60, deadline=None)
@given(poses)
def test_jd_matches_finite_differences_of_the_loop_closures(pose):
    zeta = _ik(pose)
    assume(zeta is not None)
    J_D, _ = kin.constraint_jacobians(DESC, pose, zeta)
    h = 1e-6
    fd = np.empty((6, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        fd[:, j] = (_phi(pose + e, zeta) - _phi(pose - e, zeta)) / (2 * h)
    assert np.allclose(J_D @ kin.pose_rate_matrix(pose), fd, atol=1e-7)


@settings(max_examples=60, deadline=None)
@given(poses)
def test_ji_matches_finite_differences_in_the_arm_angles(pose):
    zeta = _ik(pose)
    assume(zeta is not None)
    _, J_I = kin.constraint_jacobians(DESC, pose, zeta)
    h = 1e-6
    fd = np.empty((6, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        fd[:, j] = -(_phi(pose, zeta + e) - _phi(pose, zeta - e)) / (2 * h)
    assert np.allclose(J_I, fd, atol=1e-7)
    assert np.count_nonzero(J_I - np.diag(np.diag(J_I))) == 0


@settings(max_examples=40, deadline=None)
@given(poses, st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6))
def test_twist_and_arm_rates_are_inverse_maps_and_match_ik_differences(pose, v):
    zeta = _ik(pose)
    assume(zeta is not None)
    pose_dot = np.asarray(v) * [0.1, 0.1, 0.1, 0.5, 0.5, 0.5]
    twist = kin.twist_from_pose_rate(pose, pose_dot)
    zd = kin.arm_rates(DESC, pose, zeta, twist)
    assert np.allclose(kin.plate_twist(DESC, pose, zeta, zd), twist, atol=1e-9)
    h = 1e-6
    zp, zm = _ik(pose + h * pose_dot), _ik(pose - h * pose_dot)
    assume(zp is not None and zm is not None)
    assert np.allclose(zd, (zp - zm) / (2 * h), atol=1e-6)


def test_ik_derivatives_match_finite_differences_along_a_motion():
    t = np.linspace(0.0, 2.0, 2001)
    w = 1.3
    pose = np.stack([0.05 * np.sin(w * t), 0.04 * np.cos(w * t), -0.55 + 0.02 * np.sin(2 * w * t),
                     0.2 * np.sin(w * t), 0.15 * np.cos(w * t), 0.1 * np.sin(3 * w * t)], 1)
    pose_dot = np.gradient(pose, t, axis=0, edge_order=2)
    pose_ddot = np.gradient(pose_dot, t, axis=0, edge_order=2)
    zeta, zd, zdd = kin.inverse_kinematics_derivatives(DESC, pose, pose_dot, pose_ddot)
    fd_zd = np.gradient(zeta, t, axis=0, edge_order=2)
    fd_zdd = np.gradient(fd_zd, t, axis=0, edge_order=2)
    inner = slice(10, -10)
    assert np.allclose(zd[inner], fd_zd[inner], atol=1e-5)
    assert np.allclose(zdd[inner], fd_zdd[inner], atol=1e-3)


def test_rod_wrench_screws_are_unit_lines_through_the_plate_joints():
    pose = np.array([0.02, -0.05, -0.53, 0.1, 0.2, -0.1])
    S = kin.rod_wrench_screws(DESC, pose)
    C = kin.plate_joints(DESC, pose)
    assert np.allclose(np.linalg.norm(S[:, :3], axis=1), 1.0)
    assert np.allclose(S[:, 3:], np.cross(C, S[:, :3]), atol=1e-15)
    # the line also passes through B_i
    B = kin.elbows(DESC, kin.inverse_kinematics(DESC, pose))
    assert np.allclose(np.cross(B, S[:, :3]), S[:, 3:], atol=1e-12)


def test_home_pose_is_far_from_type_two_singularity():
    zeta = kin.inverse_kinematics(DESC, DESC.home_pose)
    J_D, J_I = kin.constraint_jacobians(DESC, DESC.home_pose, zeta)
    assert abs(np.linalg.det(J_D)) > 1e-4
    assert np.all(np.abs(np.diag(J_I)) > 0.05)


def test_batched_jd_equals_single_jd():
    rng = np.random.default_rng(3)
    poses = DESC.home_pose + rng.uniform(-1, 1, (20, 6)) * SPAN * 0.5
    zetas = kin.inverse_kinematics_batch(DESC, poses)
    batch = kin.constraint_jacobian_jd_batch(DESC, poses, zetas)
    for p, z, J in zip(poses, zetas, batch):
        assert np.allclose(kin.constraint_jacobians(DESC, p, z)[0], J, atol=1e-14)
