"""The plate-equivalent wrench W = J_Dᵀ F of a contact force (what the residual estimates), checked against the
virtual work of independently computed point velocities (IK rates, eq 17 differentiated)."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.dynamics.contact_map import contact_point_jacobian, plate_equivalent_wrench
from hexa.kinematics import hexa6rus
from hexa.robots.hexa_description import load_hexa
from hexa.trajectories import TRAJECTORIES


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


def _pose():
    return np.asarray(TRAJECTORIES["helix"](1.3)[0], dtype=float)


def _arm_rates(desc, pose, twist):
    return hexa6rus.inverse_kinematics_derivatives(desc, pose, hexa6rus.pose_rate_from_twist(pose, twist),
                                                   np.zeros(6))[1]


def test_a_plate_force_is_itself_with_its_moment_about_the_plate_centre(desc):
    pose = _pose()
    D = pose[:3] + np.array([0.06, -0.03, 0.01])
    F = np.array([1.5, -2.0, 3.0])
    W = plate_equivalent_wrench(desc, pose, "plate", 0, D, F)
    assert np.allclose(W[:3], F, atol=1e-6) and np.allclose(W[3:], np.cross(D - pose[:3], F), atol=1e-6)


def test_an_arm_force_does_the_virtual_work_of_its_motor_torque(desc):
    rng = np.random.default_rng(3)
    pose = _pose()
    zeta = hexa6rus.inverse_kinematics(desc, pose)
    i = 3                                                       # arm 4
    A, R = desc.A[i], hexa6rus.arm_rotations(desc, zeta)[i]
    D = A + R @ np.array([0.6 * desc.l_a, 0.004, 0.006])         # on the arm's surface, off its axis
    F = np.array([0.5, 2.0, -1.0])
    W = plate_equivalent_wrench(desc, pose, "arm", i + 1, D, F)
    axis = R[:, 2]
    for _ in range(5):
        V = rng.normal(size=6) * np.array([0.05, 0.05, 0.05, 0.5, 0.5, 0.5])
        v_D = _arm_rates(desc, pose, V)[i] * np.cross(axis, D - A)   # D turns about the motor axis with ζ_i
        assert W @ V == pytest.approx(F @ v_D, rel=1e-5, abs=1e-9)
    assert np.linalg.matrix_rank(contact_point_jacobian(desc, pose, "arm", i + 1, D), tol=1e-6) == 1


def test_a_rod_force_does_the_virtual_work_of_the_rod_point_between_its_joints(desc):
    rng = np.random.default_rng(5)
    pose = _pose()
    zeta = hexa6rus.inverse_kinematics(desc, pose)
    i, f = 1, 0.4                                               # rod 2, 40 % from the elbow
    B, C = hexa6rus.elbows(desc, zeta)[i], hexa6rus.plate_joints(desc, pose)[i]
    D = B + f * (C - B)
    F = np.array([-1.0, 1.5, 2.5])
    W = plate_equivalent_wrench(desc, pose, "rod", i + 1, D, F)
    axis = hexa6rus.arm_rotations(desc, zeta)[i][:, 2]
    for _ in range(5):
        V = rng.normal(size=6) * np.array([0.05, 0.05, 0.05, 0.5, 0.5, 0.5])
        v_B = _arm_rates(desc, pose, V)[i] * np.cross(axis, B - desc.A[i])
        v_C = V[:3] + np.cross(V[3:], C - pose[:3])
        assert W @ V == pytest.approx(F @ ((1 - f) * v_B + f * v_C), rel=1e-5, abs=1e-9)
    assert np.linalg.norm(W[:3]) < np.linalg.norm(F)            # only part of it reaches the plate coordinates


def test_bad_link_or_chain_is_refused(desc):
    with pytest.raises(ValueError, match="link"):
        contact_point_jacobian(desc, _pose(), "wheel", 1, np.zeros(3))
    with pytest.raises(ValueError, match="chain"):
        contact_point_jacobian(desc, _pose(), "rod", 7, np.zeros(3))
