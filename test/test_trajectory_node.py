"""The trajectory node in its own process: commands flow, a collision START holds the pose, ~/resume continues."""
from __future__ import annotations

import json
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable


def test_trajectory_node_holds_on_collision_and_resumes_on_service_call(procs, ros_env):
    procs.start([PY, "-m", "hexa_dynamics.trajectory_node", "--ros-args", "-r", "__ns:=/hexa",
                 "-p", "start_delay:=0.5", "-p", "trajectory:=circle", "-p", "require_monitoring:=false"], ros_env)
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


@pytest.mark.ros_parallel   # starts a node that refuses its parameters: no live timing
def test_trajectory_node_rejects_an_unknown_trajectory_with_a_clear_error(procs, ros_env):
    p = procs.start([PY, "-m", "hexa_dynamics.trajectory_node", "--ros-args", "-p", "trajectory:=square"], ros_env)
    _out, err = p.communicate(timeout=60)
    assert p.returncode == 2 and "'square'" in err


def test_trajectory_node_approaches_the_start_slowly_from_the_measured_pose(procs, ros_env):
    """approach_speed > 0: nothing is commanded before a plate_pose (servos stay limp), a bad or 2 s old pose is not
    used, then the first command is the measured pose's IK and the arms move no faster than approach_speed to the
    start."""
    procs.start([PY, "-m", "hexa_dynamics.trajectory_node", "--ros-args", "-r", "__ns:=/hexa",
                 "-p", "start_delay:=0.0", "-p", "trajectory:=circle", "-p", "approach_speed:=0.3",
                 "-p", "require_monitoring:=false"], ros_env)
    peer = procs.start([PY, "test/trajectory_approach_peer.py"], ros_env)
    out, err = peer.communicate(timeout=120)
    assert peer.returncode == 0, err
    r = json.loads(out.strip().splitlines()[-1])
    assert r["commands_before_pose"] == 0 and r["state_before_pose"] == "waiting_for_pose"
    assert r["commands_after_bad_pose"] == 0
    assert r["commands_after_stale_pose"] == 0 and r["state_after_stale_pose"] == "waiting_for_pose"
    assert r["first_command_error"] < 1e-6
    assert r["saw_approaching"] and r["approach_commands"] > 20       # ≈ 1.5 · 0.08 rad / 0.3 rad/s at 100 Hz
    assert r["gap_first"] > 0.05 and r["gap_last"] < 0.01
    assert r["approach_peak_rate"] < 0.3 * 1.3                        # stamps jitter: 30 % margin


@pytest.mark.ros_parallel   # starts a node that refuses its parameters: no live timing
def test_trajectory_node_refuses_a_negative_approach_speed(procs, ros_env):
    p = procs.start([PY, "-m", "hexa_dynamics.trajectory_node", "--ros-args", "-p", "approach_speed:=-1.0"],
                    ros_env)
    _out, err = p.communicate(timeout=60)
    assert p.returncode == 2 and "approach_speed" in err
