"""SRM-V1/V2 (seed 003 Algorithm 1): which limbs move, limits respected, enable pin, M_inc."""
from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexa.kinematics import upsrpu as kin
from hexa.robots.upsrpu_description import load_upsrpu
from hexa.singularity import upsrpu_indices
from hexa.srm import M_INC, SingularityReleaseModule, SrmError, implicated_limbs

DESC = load_upsrpu()


def test_m_inc_holds_the_eight_nonzero_pairs_in_the_authors_order():
    cols = [tuple(int(v) for v in M_INC[:, c]) for c in range(M_INC.shape[1])]
    assert cols == [(1, 1), (-1, -1), (1, -1), (-1, 1), (1, 0), (-1, 0), (0, 1), (0, -1)]
    assert set(cols) == set(itertools.product((-1, 0, 1), repeat=2)) - {(0, 0)}


def test_implicated_limbs_follow_v_omega_order():
    expected = [((0, 1), (2, 3)), ((0, 2), (1, 3)), ((0, 3), (1, 2)), ((1, 2), (0, 3)), ((1, 3), (0, 2)),
                ((2, 3), (0, 1))]
    for k, (ch, nc) in enumerate(expected):
        i_ch, i_nc = implicated_limbs(k)
        assert tuple(i_ch) == ch and tuple(i_nc) == nc


def test_disabled_srm_returns_the_reference_and_keeps_delta():
    srm = SingularityReleaseModule(DESC, 1)
    X = DESC.singular_poses[0]
    q_r = kin.inverse_kinematics(DESC, X)
    np.testing.assert_array_equal(srm.step(q_r, X, enable=False), q_r)
    assert not srm.delta.any() and not srm.last.active


def test_far_from_singularity_the_srm_does_nothing():
    srm = SingularityReleaseModule(DESC, 1)
    X = np.array([0.0, 0.7, 0.0, 0.0])
    q_r = kin.inverse_kinematics(DESC, X)
    np.testing.assert_array_equal(srm.step(q_r, X, enable=True), q_r)
    assert not srm.delta.any()


@pytest.mark.parametrize("variant", [1, 2])
@given(number=st.integers(1, 5), offset=st.tuples(*[st.floats(-0.003, 0.003)] * 4).map(np.array))
@settings(max_examples=25, deadline=None)
def test_delta_changes_only_the_implicated_limbs_v1_or_the_others_v2(variant, number, offset):
    X = DESC.singular_poses[number - 1] + offset
    rep = upsrpu_indices(DESC, X)
    if not rep.near(DESC.det_jd_limit, DESC.omega_limit):
        return
    srm = SingularityReleaseModule(DESC, variant)
    q_r = kin.inverse_kinematics(DESC, X)
    q_d = srm.step(q_r, X, enable=True, report=rep)
    i_ch, i_nc = implicated_limbs(rep.min_index)
    moved, still = (i_ch, i_nc) if variant == 1 else (i_nc, i_ch)
    assert srm.last.active and srm.last.column >= 0
    assert np.all(srm.delta[still] == 0)
    assert np.any(srm.delta[moved] != 0)
    np.testing.assert_allclose(q_d - q_r, DESC.nu_d * DESC.t_s * srm.delta)
    # the chosen column is the feasible one with the largest Omega of the implicated pair
    v = srm.last.v_omega_ch
    assert v[srm.last.column] == pytest.approx(v[srm.last.feasible].max())


def test_candidates_outside_the_strokes_are_never_chosen():
    X = DESC.singular_poses[0]
    q_r = kin.inverse_kinematics(DESC, X)
    # put limb 3 at the top of its stroke and limb 4 at the bottom: every candidate lengthening 3 or
    # shortening 4 is infeasible
    q_max = DESC.q_max.copy()
    q_min = DESC.q_min.copy()
    q_max[2] = q_r[2] + 0.5 * DESC.nu_d * DESC.t_s
    q_min[3] = q_r[3] - 0.5 * DESC.nu_d * DESC.t_s
    tight = dataclasses.replace(DESC, q_max=q_max, q_min=q_min)
    srm = SingularityReleaseModule(tight, 1)
    srm.step(q_r, X, enable=True)
    feasible_cols = np.flatnonzero(srm.last.feasible)
    assert len(feasible_cols) > 0
    assert all(M_INC[0, c] <= 0 and M_INC[1, c] >= 0 for c in feasible_cols)
    assert M_INC[0, srm.last.column] <= 0 and M_INC[1, srm.last.column] >= 0
    for _ in range(20):
        q_d = srm.step(q_r, X, enable=True)
        assert np.all(q_d < q_max) and np.all(q_d > q_min)


def test_no_feasible_candidate_keeps_delta():
    X = DESC.singular_poses[0]
    q_r = kin.inverse_kinematics(DESC, X)
    eps = 0.5 * DESC.nu_d * DESC.t_s
    tight = dataclasses.replace(DESC, q_max=q_r + eps, q_min=q_r - eps)   # every move leaves a stroke
    srm = SingularityReleaseModule(tight, 1)
    np.testing.assert_array_equal(srm.step(q_r, X, enable=True), q_r)
    assert srm.last.active and not srm.last.feasible.any() and not srm.delta.any()


def test_spherical_joint_limit_rejects_candidates():
    X = DESC.singular_poses[0]
    q_r = kin.inverse_kinematics(DESC, X)
    tiny = dataclasses.replace(DESC, spherical_max=float(np.min(kin.spherical_joint_angles(DESC, X))) * 0.5)
    srm = SingularityReleaseModule(tiny, 1)
    srm.step(q_r, X, enable=True)
    assert not srm.last.feasible.any() and not srm.delta.any()


def test_bad_variant_and_shapes_raise():
    with pytest.raises(SrmError, match="3"):
        SingularityReleaseModule(DESC, 3)
    with pytest.raises(SrmError, match="shape"):
        SingularityReleaseModule(DESC, 1).step(np.zeros(3), np.zeros(4), True)
