"""Hexa closed-form inverse kinematics (seed 000 eqs 14–18) and the description it stands on."""
from __future__ import annotations


import numpy as np
import pytest

from hexa.kinematics import hexa6rus as kin
from hexa.robots.hexa_description import load_hexa


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


def test_home_arm_angles_are_minus_148_5_deg_on_the_plus_branch(desc):
    zeta = kin.inverse_kinematics(desc, desc.home_pose)
    assert np.allclose(np.degrees(zeta), -148.5125, atol=1e-3)


def test_ik_closes_every_rod_to_its_length(desc):
    pose = np.array([0.05, -0.03, -0.52, 0.1, -0.2, 0.15])
    zeta = kin.inverse_kinematics(desc, pose)
    rods = kin.plate_joints(desc, pose) - kin.elbows(desc, zeta)
    assert np.allclose(np.linalg.norm(rods, axis=1), desc.l_d, atol=1e-12)


def test_ik_satisfies_eq15_with_eq17_coefficients(desc):
    pose = np.array([-0.04, 0.06, -0.57, -0.1, 0.2, 0.05])
    zeta = kin.inverse_kinematics(desc, pose)
    a, b, c = kin.ik_coefficients(desc, pose)
    assert np.allclose(b * np.cos(zeta) + c * np.sin(zeta), a, atol=1e-12)


def test_batched_ik_equals_single_ik(desc):
    rng = np.random.default_rng(1)
    poses = desc.home_pose + rng.uniform(-1, 1, (50, 6)) * [0.05, 0.05, 0.03, 0.2, 0.2, 0.2]
    batch = kin.inverse_kinematics_batch(desc, poses)
    single = np.array([kin.inverse_kinematics(desc, p) for p in poses])
    assert np.allclose(batch, single, atol=1e-13)


def test_ik_rejects_unreachable_pose_naming_the_chain(desc):
    with pytest.raises(kin.UnreachablePoseError, match=r"chain \d") as err:
        kin.inverse_kinematics(desc, [0.0, 0.0, -0.9, 0.0, 0.0, 0.0])
    assert err.value.reason == "out_of_reach"
    assert 1 <= err.value.chain <= 6


def test_ik_rejects_a_pose_pushing_one_chain_out_of_reach_and_names_it(desc):
    # Moving far along +X stretches the chains whose motors sit at alpha = 180° ... chain 1/2 sit at alpha = 0.
    with pytest.raises(kin.UnreachablePoseError) as err:
        kin.inverse_kinematics(desc, [0.35, 0.0, -0.55, 0.0, 0.0, 0.0])
    assert f"chain {err.value.chain}" in str(err.value)


def test_batched_ik_names_the_first_bad_pose(desc):
    poses = np.tile(desc.home_pose, (5, 1))
    poses[3, 2] = -0.95
    with pytest.raises(kin.UnreachablePoseError, match="pose 3") as err:
        kin.inverse_kinematics_batch(desc, poses)
    assert err.value.pose_index == 3
