"""The paper's ANN forward kinematics (seed 000 §2.2.2): dataset, exported numpy weights, accuracy vs exact FK."""
from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from hexa import trajectories
from hexa.kinematics import hexa6rus as kin
from hexa.kinematics.hexa_ann import AnnModelError, DEFAULT_WEIGHTS, load_ann_fk, sample_training_set
from hexa.robots.hexa_description import DEFAULT_PATH, load_hexa, parse_hexa

DESC = load_hexa()
ROOT = Path(__file__).resolve().parents[1]


def test_training_set_is_reachable_nonsingular_and_reproducible():
    zeta, pose = sample_training_set(DESC, 500, seed=7)
    zeta2, pose2 = sample_training_set(DESC, 500, seed=7)
    assert np.array_equal(zeta, zeta2) and np.array_equal(pose, pose2)
    assert np.allclose(kin.inverse_kinematics_batch(DESC, pose), zeta)   # every sample passes the IK checks
    home_det = abs(np.linalg.det(kin.constraint_jacobians(DESC, DESC.home_pose,
                                                          kin.inverse_kinematics(DESC, DESC.home_pose))[0]))
    dets = np.abs(np.linalg.det(kin.constraint_jacobian_jd_batch(DESC, pose, zeta)))
    assert dets.min() > 0.2 * home_det


@pytest.fixture(scope="module")
def model():
    if not DEFAULT_WEIGHTS.is_file():
        pytest.skip("ANN weights not trained yet (scripts/train_ann_fk.py)")
    return load_ann_fk(desc=DESC)


def test_committed_network_is_small_and_matches_the_geometry(model):
    assert model.matches(DESC)
    assert DEFAULT_WEIGHTS.stat().st_size < 1_000_000
    assert model.predict(np.zeros((3, 6))).shape == (3, 6) and model.predict(np.zeros(6)).shape == (6,)


def test_network_approximates_fk_on_the_paper_trajectories(model):
    for name in trajectories.TRAJECTORIES:
        _, pose, _, _ = trajectories.sample(name, rate_hz=20.0)
        err = model.predict(kin.inverse_kinematics_batch(DESC, pose)) - pose
        assert np.max(np.linalg.norm(err[:, :3], axis=1)) < 0.005       # 5 mm
        assert np.degrees(np.max(np.abs(err[:, 3:]))) < 1.0            # 1 deg


def test_network_seeds_newton_raphson_to_the_exact_pose(model):
    pose = np.array([0.06, -0.04, -0.53, -0.1, 0.3, -0.2])
    zeta = kin.inverse_kinematics(DESC, pose)
    assert np.allclose(kin.forward_kinematics(DESC, zeta, model.predict(zeta)), pose, atol=1e-9)


def test_network_refuses_another_geometry(model):
    raw = copy.deepcopy(yaml.safe_load(DEFAULT_PATH.read_text()))
    raw["geometry"]["rod_length"] = 0.45
    other = parse_hexa(raw)
    assert not model.matches(other)
    with pytest.raises(AnnModelError, match="another geometry"):
        load_ann_fk(desc=other)


def test_missing_weights_are_named(tmp_path):
    with pytest.raises(AnnModelError, match="absent.npz"):
        load_ann_fk(tmp_path / "absent.npz")


@pytest.mark.slow
def test_training_script_runs_and_exports_loadable_weights(tmp_path):
    pytest.importorskip("torch")
    out = tmp_path / "tiny.npz"
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "train_ann_fk.py"), "--samples", "2000", "--test",
                          "200", "--epochs", "2", "--hidden", "16", "--out", str(out)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    tiny = load_ann_fk(out, desc=DESC)
    assert tiny.n_parameters == 6 * 16 + 16 + 2 * (16 * 16 + 16) + 16 * 6 + 6
    assert tiny.meta["samples"] == 2000 and "test" in tiny.meta
