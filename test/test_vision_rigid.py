"""Rigid registration (Kabsch/Umeyama): round trips, weights, 3-of-4 markers, degenerate input."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexa.vision.rigid import RigidFitError, fit_rigid_transform, residuals, rotation_angle


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(3, 12))
def test_fit_recovers_any_rigid_transform(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    model = rng.uniform(-0.1, 0.1, size=(n, 3))
    if np.linalg.svd(model - model.mean(0), compute_uv=False)[1] < 1e-3:
        return
    R = _random_rotation(rng)
    t = rng.uniform(-1, 1, size=3)
    R_fit, t_fit, rms = fit_rigid_transform(model, model @ R.T + t)
    assert rotation_angle(R, R_fit) < 1e-7
    assert np.allclose(t_fit, t, atol=1e-9)
    assert rms < 1e-9
    assert np.isclose(np.linalg.det(R_fit), 1.0)


def test_fit_with_three_of_four_markers_matches_the_full_fit() -> None:
    rng = np.random.default_rng(1)
    model = np.array([[0.06, 0.0, 0.0], [0.0, 0.06, 0.0], [-0.06, 0.0, 0.0], [0.02, -0.05, 0.0]])
    R = _random_rotation(rng)
    t = np.array([0.01, -0.02, -0.55])
    meas = model @ R.T + t
    for drop in range(4):
        keep = [i for i in range(4) if i != drop]
        R3, t3, rms = fit_rigid_transform(model[keep], meas[keep])
        assert rotation_angle(R, R3) < 1e-7 and np.allclose(t3, t) and rms < 1e-12


def test_zero_weight_ignores_an_outlier() -> None:
    model = np.array([[0.05, 0, 0], [0, 0.05, 0], [-0.05, 0, 0], [0, -0.05, 0.01]])
    meas = model + [0.0, 0.0, 0.3]
    meas[3] += [0.2, 0.0, 0.0]
    _, _, rms_all = fit_rigid_transform(model, meas)
    R_w, t_w, rms_w = fit_rigid_transform(model, meas, weights=[1, 1, 1, 0])
    assert rms_all > 0.01
    assert np.allclose(t_w, [0, 0, 0.3], atol=1e-12) and rms_w < 1e-12
    assert residuals(R_w, t_w, model, meas)[3] == pytest.approx(0.2)


def test_reflection_is_never_returned() -> None:
    model = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]])
    mirrored = model * [1, 1, -1]
    R, _, rms = fit_rigid_transform(model, mirrored)
    assert np.isclose(np.linalg.det(R), 1.0) and rms > 0.1


@pytest.mark.parametrize("model, meas, weights, fragment", [
    (np.zeros((2, 3)), np.zeros((2, 3)), None, "at least 3"),
    (np.zeros((3, 3)), np.zeros((4, 3)), None, "(3, 3)"),
    (np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.zeros((3, 3)), None, "collinear"),
    (np.eye(3), np.full((3, 3), np.nan), None, "non-finite"),
    (np.eye(3), np.eye(3), [1, -1, 1], "non-negative"),
    (np.eye(3), np.eye(3), [1, 0, 1], "at least 3"),
])
def test_bad_input_raises_naming_the_problem(model, meas, weights, fragment) -> None:
    with pytest.raises(RigidFitError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
        fit_rigid_transform(model, meas, weights)
