"""`hexa sim run` and `hexa sim snapshot` from the command line."""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.skipif(importlib.util.find_spec("hexa.trajectories") is None,
                                reason="hexa.trajectories not installed")


def _hexa(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, MUJOCO_GL="egl")
    return subprocess.run([sys.executable, "-m", "hexa_bringup.cli", *args], capture_output=True, text=True,
                          env=env, timeout=120)


def test_sim_run_json_reports_the_contact_and_writes_the_truth_log(tmp_path):
    out = tmp_path / "truth.npz"
    p = _hexa("sim", "run", "--case", "arm", "--seed", "6", "--randomize", "--json", "--out", str(out))
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["link"] == "arm" and r["chain"] in (3, 4)
    assert 5.0 <= r["peak_force"] <= 6.0
    assert 0.35 <= r["peak_time"] - r["onset"] <= 0.45
    log = np.load(out)
    assert set(log.files) >= {"time", "force", "point", "link", "chain", "plate_pose", "zeta", "tau"}
    k = int(np.argmax(np.linalg.norm(log["force"], axis=1)))
    np.testing.assert_allclose(log["point"][k], r["point_at_peak"])


def test_sim_snapshot_writes_a_png_per_camera_at_the_collision(tmp_path):
    cv2 = pytest.importorskip("cv2")
    p = _hexa("sim", "snapshot", "--case", "plate", "--out", str(tmp_path), "--json")
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)[0]
    assert r["link"] == "plate" and r["force"] != [0.0, 0.0, 0.0]
    for cam in ("cam_top", "cam_side"):
        img = cv2.imread(r["files"][cam]["rgb"])
        depth = cv2.imread(r["files"][cam]["depth"])
        assert img.shape == (480, 640, 3) and depth.shape == (480, 640, 3)
        assert img.std() > 10                      # a real picture, not a blank frame
