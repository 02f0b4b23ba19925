"""The trajectory node in its own process: commands flow, a collision START holds the pose, ~/resume continues."""
from __future__ import annotations

import json
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable


def test_trajectory_node_holds_on_collision_and_resumes_on_service_call(procs, ros_env):
    procs.start([PY, "-m", "hexa_dynamics.trajectory_node", "--ros-args", "-r", "__ns:=/hexa",
                 "-p", "start_delay:=0.5", "-p", "trajectory:=circle"], ros_env)
    peer = procs.start([PY, "test/trajectory_peer.py"], ros_env)
    out, err = peer.communicate(timeout=90)
    assert peer.returncode == 0, err
    r = json.loads(out.strip().splitlines()[-1])
    assert r["running_moves"] > 1e-3          # ζ changes while running
    assert r["held_state"] == "held"
    assert r["held_moves"] < 1e-9             # frozen while held
    assert r["resume"] is True
    assert r["after_resume_state"] in ("running", "resuming")
    assert r["after_resume_moves"] > 1e-3


def test_trajectory_node_rejects_an_unknown_trajectory_with_a_clear_error(procs, ros_env):
    p = procs.start([PY, "-m", "hexa_dynamics.trajectory_node", "--ros-args", "-p", "trajectory:=square"], ros_env)
    _out, err = p.communicate(timeout=60)
    assert p.returncode == 2 and "'square'" in err
