"""Self-consistency of the Hexa Lagrange model (hexa.dynamics.lagrange): power balance, momentum vs inverse dynamics,
agreement with the kinematics module, θ = 0 handling and the Z-Y-Z output mapping."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexa.dynamics.lagrange import (DynamicsError, HexaDynamicParameters, chain_jacobian, generalized_momentum,
                                    inverse_dynamics, loop_constraints, mass_matrix, mechanical_energy,
                                    momentum_terms, motion_from_joint_rates, motion_from_plate,
                                    pose_to_position_rotation, wrench_to_generalized_zyz, zyz_rate_matrix)
from hexa.kinematics import hexa6rus as kin
from hexa.robots.hexa_description import load_hexa

DESC = load_hexa()
HOME = np.array([0.0, 0.0, -0.55, 0.0, 0.0, 0.0])
AMP = np.array([0.03, 0.02, 0.02, 0.2, 0.15, 0.1])
FREQ = np.array([2.0, 3.0, 1.3, 1.5, 2.5, 2.0])
PHASE = np.array([0.0, 0.5, 0.2, 0.0, 0.3, 1.0])


def _params(**over) -> HexaDynamicParameters:
    base = HexaDynamicParameters.from_description(DESC).__dict__.copy()
    base.update(over)
    return HexaDynamicParameters(**base)


# A model with every term switched on: off-centre plate COM, full plate inertia, damping, rotor inertia.
PRM = _params(arm_damping=0.01, J_a=9e-4, c_p=np.array([0.01, -0.005, 0.02]),
              I_p=np.array([[9e-4, 1e-5, 2e-5], [1e-5, 8e-4, 0.0], [2e-5, 0.0, 1.8e-3]]))


def _path(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.atleast_1d(t)[:, None]
    ph = FREQ * t + PHASE
    return HOME + AMP * np.sin(ph), AMP * FREQ * np.cos(ph), -AMP * FREQ**2 * np.sin(ph)


def _motion(prm: HexaDynamicParameters, t: np.ndarray, accel: bool = True):
    pose, pd, pdd = _path(t)
    zeta = kin.inverse_kinematics_batch(DESC, pose)
    V = kin.twist_from_pose_rate(pose, pd)
    Vd = None
    if accel:
        Vd = np.concatenate([pdd[:, :3], kin.angular_acceleration_zyx(pose[:, 3:], pd[:, 3:], pdd[:, 3:])], 1)
    return motion_from_plate(prm, zeta, pose, V, Vd)


T = np.linspace(0.0, 3.0, 31)
TAU = np.random.default_rng(0).normal(scale=0.3, size=(T.size, 6))


def test_constraints_and_geometry_match_h1_kinematics():
    s = _motion(PRM, T)
    assert np.abs(loop_constraints(PRM, s.zeta, s.p, s.R)).max() < 1e-12
    # arm rates from the twist agree with the inverse velocity kinematics
    for k in (0, 7, 19):
        pose = _path(T[k])[0][0]
        ref = kin.arm_rates(DESC, pose, s.zeta[k], s.V[k])
        np.testing.assert_allclose(s.zeta_dot[k], ref, rtol=1e-9, atol=1e-12)


def test_arm_accelerations_match_finite_differences_of_ik():
    s = _motion(PRM, T)
    h = 1e-4
    z = [kin.inverse_kinematics_batch(DESC, _path(T + k * h)[0]) for k in (-1, 0, 1)]
    zdd = (z[2] - 2 * z[1] + z[0]) / h**2
    assert np.abs(zdd - s.zeta_ddot).max() < 1e-5 * max(1.0, np.abs(zdd).max())


def test_momentum_rate_equals_known_terms_plus_inverse_dynamics_wrench():
    """dπ/dt (central differences of π along the path) = J_ζᵀτ + G + β + W, with W from eqs 21–22."""
    s = _motion(PRM, T)
    mt = momentum_terms(PRM, s, TAU)
    W = inverse_dynamics(PRM, s, TAU).wrench
    h = 1e-5
    dpi = (generalized_momentum(PRM, _motion(PRM, T + h, False))
           - generalized_momentum(PRM, _motion(PRM, T - h, False))) / (2 * h)
    np.testing.assert_allclose(dpi - mt.known_rate, W, atol=1e-6 * np.abs(W).max())


def test_power_balance_along_a_trajectory():
    """d/dt (T + U) = τ·ζ̇ + W·V − b|ζ̇|² (virtual power of the actuators, the external wrench and friction)."""
    s = _motion(PRM, T)
    W = inverse_dynamics(PRM, s, TAU).wrench
    h = 1e-5

    def energy(t):
        Tk, U = mechanical_energy(PRM, _motion(PRM, t, False))
        return Tk + U

    dE = (energy(T + h) - energy(T - h)) / (2 * h)
    power = (TAU * s.zeta_dot).sum(1) + (W * s.V).sum(1) - PRM.arm_damping * (s.zeta_dot**2).sum(1)
    np.testing.assert_allclose(dE, power, atol=1e-7)


def test_mass_matrix_is_symmetric_positive_definite_and_gives_momentum():
    s = _motion(PRM, T[:5], False)
    M = mass_matrix(PRM, s)
    np.testing.assert_allclose(M, np.swapaxes(M, 1, 2), atol=1e-15)
    assert np.all(np.linalg.eigvalsh(M) > 0)
    np.testing.assert_allclose(np.einsum("nab,nb->na", M, s.V), generalized_momentum(PRM, s), atol=1e-15)


def test_static_equilibrium_needs_the_gravity_torques_only():
    """At rest with no external wrench, the torques that hold the robot give W = 0 (and λ is the rod load)."""
    prm = _params()  # the YAML's symmetric robot (plate COM on the axis)
    s = motion_from_plate(prm, kin.inverse_kinematics(DESC, HOME)[None], HOME[None], np.zeros((1, 6)),
                          np.zeros((1, 6)))
    # τ that makes W = 0: solve J_ζᵀ τ = −G (gravity wrench) for the 6 torques
    mt = momentum_terms(prm, s, np.zeros((1, 6)))
    J = chain_jacobian(prm, s.zeta, s.p, s.R)[0]
    tau = np.linalg.solve(J.T, -mt.gravity[0])
    res = inverse_dynamics(prm, s, tau[None])
    np.testing.assert_allclose(res.wrench[0], 0.0, atol=1e-12)
    # the loads are symmetric about the base axis at home: all six torques equal
    np.testing.assert_allclose(tau, tau[0], rtol=1e-9)
    # the six multipliers are equal too (same rod load in every chain)
    np.testing.assert_allclose(res.lam[0], res.lam[0, 0], rtol=1e-9)


def test_home_pose_theta_zero_is_regular_and_q_maps_exactly():
    """θ = 0 (home) — Z-Y-Z is singular there, the model is not: W is finite and Q = diag(1, Eᵀ)·W."""
    s = motion_from_plate(PRM, kin.inverse_kinematics(DESC, HOME)[None], HOME[None],
                          np.array([[0.01, 0.0, 0.02, 0.1, -0.2, 0.3]]), np.array([[0.1, 0.2, 0.0, 1.0, 0.5, -1.0]]))
    res = inverse_dynamics(PRM, s, np.full((1, 6), 0.1))
    assert np.all(np.isfinite(res.wrench)) and np.all(np.isfinite(res.Q)) and np.all(np.isfinite(res.lam))
    angles, E = zyz_rate_matrix(s.R)
    assert angles[0, 1] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(res.Q[0, :3], res.wrench[0, :3])
    np.testing.assert_allclose(res.Q[0, 3:], E[0].T @ res.wrench[0, 3:])
    # at θ = 0 the φ and ψ generalized torques are both the moment about z
    assert res.Q[0, 3] == pytest.approx(res.wrench[0, 5]) and res.Q[0, 5] == pytest.approx(res.wrench[0, 5])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6), st.lists(st.floats(-5.0, 5.0), min_size=6,
                                                                        max_size=6))
def test_generalized_zyz_forces_do_the_same_virtual_work(angles_frac, wrench):
    """Q·(ẋ, φ̇, θ̇, ψ̇) = W·V for any Z-Y-Z rates: the paper's Q_7..Q_12 are the wrench in its coordinates."""
    pose = HOME + np.array([0.02, -0.01, 0.02, 0.4, 0.3, 0.2]) * np.asarray(angles_frac)
    _, R = pose_to_position_rotation(pose[None])
    _, E = zyz_rate_matrix(R)
    rng = np.random.default_rng(1)
    rates = rng.normal(size=6)
    V = np.concatenate([rates[:3], E[0] @ rates[3:]])
    W = np.asarray(wrench)[None]
    Q = wrench_to_generalized_zyz(W, R)
    assert Q[0] @ rates == pytest.approx(W[0] @ V, abs=1e-9)


def test_twist_from_arm_rates_round_trips():
    s = _motion(PRM, T[:8])
    pose = _path(T[:8])[0]
    back = motion_from_joint_rates(PRM, s.zeta, s.zeta_dot, pose, s.zeta_ddot)
    np.testing.assert_allclose(back.V, s.V, atol=1e-10)
    np.testing.assert_allclose(back.V_dot, s.V_dot, atol=1e-7)


def test_bad_parameters_are_named():
    with pytest.raises(DynamicsError, match="m_p"):
        _params(m_p=-1.0)
    with pytest.raises(DynamicsError, match="kappa"):
        _params(kappa=1.5)
    with pytest.raises(DynamicsError, match="A must"):
        _params(A=np.zeros((5, 3)))


def test_inverse_dynamics_requires_accelerations():
    s = _motion(PRM, T[:2], accel=False)
    with pytest.raises(DynamicsError, match="V_dot"):
        inverse_dynamics(PRM, s, TAU[:2])


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6), st.lists(st.floats(-2.0, 2.0), min_size=12,
                                                                        max_size=12))
def test_single_sample_kernel_equals_the_vectorized_model(pose_frac, rates_tau):
    """The 1 kHz path (plain floats) computes the same V, π and J_ζᵀτ + G + β as the batched model."""
    from hexa.dynamics._kernel import SampleKernel

    pose = HOME + np.array([0.02, 0.02, 0.02, 0.2, 0.2, 0.2]) * np.asarray(pose_frac)
    zeta = kin.inverse_kinematics(DESC, pose)
    zd, tau = np.asarray(rates_tau[:6]), np.asarray(rates_tau[6:])
    s = motion_from_joint_rates(PRM, zeta, zd, pose)
    mt = momentum_terms(PRM, s, tau)
    ker = SampleKernel(PRM)
    geo, fmax = ker.geometry(zeta.tolist(), s.p[0].tolist(), s.R[0].ravel().tolist())
    assert fmax < 1e-12
    V, pi, u = ker.terms(geo, zd.tolist(), tau.tolist(), s.p[0].tolist(), s.R[0].ravel().tolist())
    np.testing.assert_allclose(V, s.V[0], atol=1e-12)
    np.testing.assert_allclose(pi, mt.momentum[0], atol=1e-13)
    np.testing.assert_allclose(u, mt.known_rate[0], atol=1e-12)
    # the pose-driven path: twist given, ζ̇ = J_ζ V inside
    V2, pi2, u2 = ker.terms(geo, None, tau.tolist(), s.p[0].tolist(), s.R[0].ravel().tolist(), twist=s.V[0].tolist())
    np.testing.assert_allclose(pi2, mt.momentum[0], atol=1e-13)
    np.testing.assert_allclose(u2, mt.known_rate[0], atol=1e-12)
    # arm angles of the pose by Newton from a nearby guess
    np.testing.assert_allclose(ker.arm_angles((zeta + 0.05).tolist(), s.p[0].tolist(), s.R[0].ravel().tolist()),
                               zeta, atol=1e-10)
    # pose tracking from a disturbed start converges back to the pose of ζ
    _, p, R = ker.track_pose(zeta.tolist(), (s.p[0] + 0.002).tolist(), (s.R[0] @ kin.rotation_zyx(0.01, -0.02, 0.01))
                             .ravel().tolist(), 1e-14, 6)
    np.testing.assert_allclose(p, s.p[0], atol=1e-9)
    np.testing.assert_allclose(np.reshape(R, (3, 3)), s.R[0], atol=1e-9)
