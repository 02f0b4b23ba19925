"""Output twist screws and Omega_ij (seed 003 sec 2.3) for the 3UPS+RPU and, when present, the Hexa."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from hexa import singularity as sg
from hexa.kinematics import upsrpu as kin
from hexa.robots.upsrpu_description import load_upsrpu

DESC = load_upsrpu()
poses = st.tuples(st.floats(-0.08, 0.14), st.floats(0.63, 0.80), st.floats(-0.2, 0.2), st.floats(-0.35, 0.35)
                  ).map(np.array)
wrench_sets = arrays(np.float64, (6, 6), elements=st.floats(-1.0, 1.0))


def _reciprocal(T: np.ndarray, O: np.ndarray) -> np.ndarray:
    """Matrix of reciprocal products T_j o O_i (rows j, columns i)."""
    return T[:, :3] @ O[:, 3:].T + T[:, 3:] @ O[:, :3].T


def _shift(screws: np.ndarray, p: np.ndarray, wrench: bool) -> np.ndarray:
    """Express screws about point p instead of the origin (moment / velocity part changes)."""
    out = screws.copy()
    if wrench:                    # m_p = m_0 - p x f
        out[:, 3:] = screws[:, 3:] - np.cross(p, screws[:, :3])
    else:                         # v_p = v_0 + omega x p
        out[:, 3:] = screws[:, 3:] + np.cross(screws[:, :3], p)
    return out


@given(wrench_sets)
@settings(max_examples=80, deadline=None)
def test_each_ots_is_reciprocal_to_every_other_wrench(W):
    if abs(np.linalg.det(W)) < 1e-3:
        return
    O = sg.output_twist_screws(W)
    R = _reciprocal(W, O)
    off = R - np.diag(np.diag(R))
    assert np.max(np.abs(off)) < 1e-9 * max(1.0, np.max(np.abs(R)))
    assert np.all(np.abs(np.diag(R)) > 1e-9)          # the OTS is moved by its own actuator
    np.testing.assert_allclose(np.linalg.norm(O[:, :3], axis=1)[np.linalg.norm(O[:, :3], axis=1) > 0.5], 1.0)


@given(wrench_sets, arrays(np.float64, (3,), elements=st.floats(-2.0, 2.0)))
@settings(max_examples=60, deadline=None)
def test_omega_does_not_depend_on_the_reference_point(W, p):
    if abs(np.linalg.det(W)) < 1e-3:
        return
    om0, _ = sg.omega_angles(sg.output_twist_screws(W))
    om1, _ = sg.omega_angles(sg.output_twist_screws(_shift(W, p, wrench=True)))
    np.testing.assert_allclose(om0, om1, atol=1e-7)


def test_dependent_wrenches_give_zero_omega_for_the_implicated_limbs():
    rng = np.random.default_rng(3)
    W = rng.normal(size=(6, 6))
    W[5] = 0.3 * W[0] - 0.8 * W[1]        # limbs 1, 2 and 6 are linearly dependent: exact type II singularity
    om, pairs = sg.omega_angles(sg.output_twist_screws(W))
    d = dict(zip(pairs, om))
    assert d["1-2"] < 1e-6 and d["1-6"] < 1e-6 and d["2-6"] < 1e-6
    assert d["3-4"] == pytest.approx(math.pi / 2)   # uninvolved OTS are undefined there -> not implicated
    assert d["1-3"] == pytest.approx(math.pi / 2)
    rep = sg.indices_from_screws(0.0, W)
    assert rep.min_pair in ("1-2", "1-6", "2-6")


def test_pairs_follow_the_papers_v_omega_order():
    assert sg.limb_pairs(4) == ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
    r = sg.upsrpu_indices(DESC, DESC.home)
    assert r.pairs == ("1-2", "1-3", "1-4", "2-3", "2-4", "3-4")
    assert len(sg.limb_pairs(6)) == 15


@given(poses)
@settings(max_examples=60, deadline=None)
def test_upsrpu_ots_respect_locked_actuators_and_rpu_constraints(X):
    T = kin.transmission_wrench_screws(DESC, X)
    C = kin.constraint_wrench_screws(DESC, X)
    O = sg.output_twist_screws(T, C)
    R = _reciprocal(np.vstack([T, C]), O)
    for i in range(4):
        others = np.delete(R[:, i], i)
        assert np.max(np.abs(others)) < 1e-9
    # the OTS is the platform twist produced by unit rate of actuator i: J_D X_dot = e_i
    J = kin.jacobian_jd(DESC, X)
    Xdot = np.linalg.solve(J, np.eye(4))
    for i in range(4):
        th = X[2]
        w = Xdot[2, i] * np.array([0, 1.0, 0]) + Xdot[3, i] * np.array([np.sin(th), 0, np.cos(th)])
        w = w / np.linalg.norm(w)
        assert abs(abs(w @ O[i, :3]) - 1.0) < 1e-7


@given(poses)
@settings(max_examples=60, deadline=None)
def test_upsrpu_screw_matrix_determinant_equals_det_jd(X):
    W = np.vstack([kin.transmission_wrench_screws(DESC, X), kin.constraint_wrench_screws(DESC, X)])
    assert abs(np.linalg.det(W)) == pytest.approx(abs(np.linalg.det(kin.jacobian_jd(DESC, X))), rel=1e-9)


@given(poses)
@settings(max_examples=80, deadline=None)
def test_upsrpu_fast_indices_equal_the_screw_computation(X):
    fast = sg.upsrpu_indices(DESC, X)
    ref = sg.upsrpu_indices_from_screws(DESC, X)
    np.testing.assert_allclose(fast.omega, ref.omega, atol=1e-9)
    assert fast.det_jd == ref.det_jd and fast.pairs == ref.pairs


@pytest.mark.parametrize("number", [1, 2, 3, 4, 5])
def test_table3_poses_are_near_singular_and_home_is_not(number):
    r = sg.upsrpu_indices(DESC, DESC.singular_poses[number - 1])
    assert r.near(DESC.det_jd_limit, DESC.omega_limit)
    assert r.min_omega < DESC.omega_limit
    assert r.min_pair == "3-4"              # the paper: trajectory 1 has Omega_34 as min Omega
    home = sg.upsrpu_indices(DESC, np.array([0.0, 0.7, 0.0, 0.0]))
    assert not home.near(DESC.det_jd_limit, DESC.omega_limit)


def test_tr15_min_omega_along_the_path_is_below_the_limit():
    if kin.reference_data_dir() is None:
        pytest.skip("reference data ../shared/data/upsrpu not present next to the repository")
    _, X = kin.load_reference_trajectory("TR15")
    mins = np.array([sg.upsrpu_indices(DESC, x).min_omega for x in X[::20]])
    assert math.degrees(mins.min()) < 1.8
    assert math.degrees(mins[0]) > 1.8       # it starts outside the singular region


def test_hexa_indices_give_fifteen_pairs_and_match_rod_wrench_screws():
    pytest.importorskip("hexa.kinematics.hexa6rus", reason="Hexa kinematics not available")
    from hexa.kinematics import hexa6rus
    from hexa.robots.hexa_description import load_hexa

    h = load_hexa()
    rng = np.random.default_rng(0)
    for k in range(5):
        step = rng.uniform(-1, 1, 6) * np.array([0.02, 0.02, 0.02, 0.05, 0.05, 0.05])
        pose = np.asarray(hexa6rus.HOME_POSE, dtype=float) + (0.0 if k == 0 else step)
        r = sg.hexa_indices(h, pose)
        assert len(r.omega) == 15 and r.pairs[-1] == "5-6" and r.pairs[0] == "1-2"
        assert 0 <= r.min_omega <= math.pi / 2 and r.min_omega == r.omega.min()
        ref, _ = sg.omega_angles(sg.output_twist_screws(hexa6rus.rod_wrench_screws(h, pose)))
        np.testing.assert_allclose(r.omega, ref, atol=1e-8)
        J_D, _ = hexa6rus.constraint_jacobians(h, pose, hexa6rus.inverse_kinematics(h, pose))
        assert r.det_jd == pytest.approx(np.linalg.det(J_D))


def test_indices_stay_consistent_approaching_an_exact_singularity():
    from scipy.optimize import brentq

    def det_at(psi: float) -> float:
        return float(np.linalg.det(kin.jacobian_jd(DESC, np.array([0.125, 0.77, 0.05, psi]))))

    psi_s = brentq(det_at, 0.3, 0.4, xtol=1e-15)           # a true type II singularity (det J_D = 0)
    prev = math.inf
    for eps in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8):
        X = np.array([0.125, 0.77, 0.05, psi_s + eps])
        fast = sg.upsrpu_indices(DESC, X)
        ref = sg.upsrpu_indices_from_screws(DESC, X)
        np.testing.assert_allclose(fast.omega, ref.omega, atol=1e-8)
        assert fast.min_omega <= prev                               # Omega_34 -> 0 with det J_D -> 0
        if fast.min_omega > 0:  # closer than ~1e-8 rad the pose is numerically exact (rank <= 4): Omega = 0 exactly,
            assert fast.min_pair == "3-4"  # no pair is singled out (which eps gets there depends on the BLAS)
        prev = fast.min_omega
    assert prev < 1e-7
    # at the singularity itself every limb is in the dependency: all OTS coincide and every Omega vanishes
    # (near it Omega_34 is ~100 times smaller than the others, which is what names the pair)
    exact = sg.upsrpu_indices(DESC, np.array([0.125, 0.77, 0.05, psi_s]))
    assert np.all(exact.omega < 1e-6)
