"""Rotations of seed 000 (eqs 1, 3, 10, 38): Z-Y-Z ↔ Z-Y-X conversions robust at θ = 0, angular velocity."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from hexa.kinematics import hexa6rus as kin
from hexa.robots.hexa_description import load_hexa

angle = st.floats(-np.pi, np.pi)
tilt = st.floats(-1.5, 1.5)


@settings(max_examples=200, deadline=None)
@given(angle, tilt, angle)
def test_zyx_to_zyz_describes_the_same_rotation(a, b, g):
    phi, theta, psi = kin.zyx_to_zyz(a, b, g)
    assert 0.0 <= theta <= np.pi
    assert np.allclose(kin.rotation_zyz(phi, theta, psi), kin.rotation_zyx(a, b, g), atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(angle, st.floats(0.0, 3.1), angle)
def test_zyz_to_zyx_describes_the_same_rotation(phi, theta, psi):
    a, b, g = kin.zyz_to_zyx(phi, theta, psi)
    assert np.allclose(kin.rotation_zyx(a, b, g), kin.rotation_zyz(phi, theta, psi), atol=1e-12)


def test_conversion_is_finite_and_exact_at_theta_zero_and_near_it():
    for eps in (0.0, 1e-14, 1e-9, 1e-7):
        phi, theta, psi = kin.zyx_to_zyz(0.4, eps, 0.0)
        assert np.isfinite([phi, theta, psi]).all()
        assert np.allclose(kin.rotation_zyz(phi, theta, psi), kin.rotation_zyx(0.4, eps, 0.0), atol=1e-12)
    phi, theta, psi = kin.zyx_to_zyz(0.0, 0.0, 0.0)
    assert theta == 0.0 and phi == 0.0 and psi == 0.0
    a, b, g = kin.zyz_to_zyx(0.3, 0.0, 0.2)
    assert np.allclose([a, b, g], [0.5, 0.0, 0.0], atol=1e-15)


def test_rotation_zyx_is_rz_ry_rx():
    def rz(t):
        return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])

    def ry(t):
        return np.array([[np.cos(t), 0, np.sin(t)], [0, 1, 0], [-np.sin(t), 0, np.cos(t)]])

    def rx(t):
        return np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])

    assert np.allclose(kin.rotation_zyx(0.3, -0.2, 0.7), rz(0.3) @ ry(-0.2) @ rx(0.7))
    assert np.allclose(kin.rotation_zyz(0.3, -0.2, 0.7), rz(0.3) @ ry(-0.2) @ rz(0.7))


def _skew_inv(W):
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


@settings(max_examples=50, deadline=None)
@given(angle, st.floats(0.05, 3.0), angle, st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_eq3_angular_velocity_matches_rdot_rt(phi, theta, psi, rates):
    h = 1e-6
    ang = np.array([phi, theta, psi])
    rates = np.asarray(rates)
    Rp, Rm = kin.rotation_zyz(*(ang + h * rates)), kin.rotation_zyz(*(ang - h * rates))
    W = (Rp - Rm) / (2 * h) @ kin.rotation_zyz(*ang).T
    assert np.allclose(kin.angular_velocity_zyz(ang, rates), _skew_inv(W), atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(angle, tilt, angle, st.lists(st.floats(-2, 2), min_size=3, max_size=3),
       st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_zyx_angular_velocity_and_acceleration_match_differences(a, b, g, rates, accels):
    h = 1e-5
    ang, rates, accels = np.array([a, b, g]), np.asarray(rates), np.asarray(accels)
    W = (kin.rotation_zyx(*(ang + h * rates)) - kin.rotation_zyx(*(ang - h * rates))) / (2 * h)
    assert np.allclose(kin.angular_velocity_zyx(ang, rates), _skew_inv(W @ kin.rotation_zyx(*ang).T), atol=1e-6)

    def w_at(t):
        return kin.angular_velocity_zyx(ang + rates * t + 0.5 * accels * t * t, rates + accels * t)

    fd = (w_at(h) - w_at(-h)) / (2 * h)
    assert np.allclose(kin.angular_acceleration_zyx(ang, rates, accels), fd, atol=1e-5)


def test_twist_and_pose_rate_round_trip():
    pose = np.array([0.0, 0.0, -0.55, 0.3, -0.2, 0.1])
    pose_dot = np.array([0.1, -0.2, 0.05, 0.4, -0.3, 0.2])
    assert np.allclose(kin.pose_rate_from_twist(pose, kin.twist_from_pose_rate(pose, pose_dot)), pose_dot)


def test_arm_direction_is_the_first_column_of_eq10():
    desc = load_hexa()
    zeta = np.linspace(-2.0, 1.0, 6)
    u = kin.arm_directions(desc, zeta)
    for i in range(6):
        a, z = desc.alpha[i], zeta[i]
        R10 = np.array([[-np.cos(a) * np.cos(z), np.cos(a) * np.sin(z), -np.sin(a)],
                        [-np.sin(a) * np.cos(z), np.sin(a) * np.sin(z), np.cos(a)],
                        [np.sin(z), np.cos(z), 0.0]])
        assert np.allclose(u[i], R10[:, 0])
        # eq 10 = R_Oi (eq 4) · R_A1i (eq 6) · R_A2i (eq 7)
        Ro = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        R6 = np.array([[-1, 0, 0], [0, 0, 1], [0, 1, 0]])
        R7 = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
        assert np.allclose(Ro @ R6 @ R7, R10)


def test_rod_frames_of_eq13_equal_the_eq11_product_and_point_along_the_rods():
    desc = load_hexa()
    pose = np.array([0.05, -0.03, -0.52, 0.1, -0.2, 0.15])
    zeta = kin.inverse_kinematics(desc, pose)
    R, beta, gamma = kin.rod_rotations(desc, pose, zeta)
    RA = kin.arm_rotations(desc, zeta)
    n = kin.plate_joints(desc, pose) - kin.elbows(desc, zeta)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    for i in range(6):
        b, g = beta[i], gamma[i]
        R9 = np.array([[np.cos(b) * np.cos(g), -np.cos(b) * np.sin(g), np.sin(b)],
                       [np.sin(b) * np.cos(g), -np.sin(b) * np.sin(g), -np.cos(b)],
                       [np.sin(g), np.cos(g), 0.0]])
        assert np.allclose(RA[i] @ R9, R[i], atol=1e-12)          # eq 11 = eq 10 · eq 8 · eq 9
        assert np.allclose(R[i][:, 0], n[i], atol=1e-12)           # x_2i along B_i → C_i
        assert np.isclose(np.linalg.det(R[i]), 1.0)
        assert -np.pi / 2 < b + zeta[i] < np.pi / 2 or -np.pi / 2 < b + zeta[i] - 2 * np.pi < np.pi / 2
    assert np.allclose(RA[:, :, 2], np.stack([-np.sin(desc.alpha), np.cos(desc.alpha), 0 * desc.alpha], 1))
