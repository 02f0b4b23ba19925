"""`hexa bringup upsrpu` starts the 3UPS+RPU graph: the singularity monitor answers from the simulated tracking."""
from __future__ import annotations

import json
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable


def test_bringup_upsrpu_publishes_singularity_indices_from_the_simulated_markers(procs, ros_env, tmp_path):
    procs.start([PY, "-m", "hexa_bringup.cli", "bringup", "upsrpu", "--log-dir", str(tmp_path)], ros_env)
    echo = procs.start([PY, "-m", "hexa_bringup.cli", "topic", "echo", "/upsrpu/singularity", "--once", "--json",
                        "--timeout", "40"], ros_env)
    out, err = echo.communicate(timeout=60)
    assert echo.returncode == 0, err
    msg = json.loads(out.strip().splitlines()[-1])
    assert msg["robot"] == "upsrpu" and len(msg["omega"]) == 6
    assert msg["pairs"] == ["1-2", "1-3", "1-4", "2-3", "2-4", "3-4"]
    assert msg["min_omega"] == min(msg["omega"])
