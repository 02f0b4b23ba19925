"""`hexa service call` and `hexa param get/set` against a node in another process."""
from __future__ import annotations

import json
import sys

import pytest

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable


def _hexa(procs, env, *args):
    p = procs.start([PY, "-m", "hexa_bringup.cli", *args], env)
    out, err = p.communicate(timeout=60)
    return p.returncode, out, err


def test_service_call_holds_and_resumes_the_trajectory_node(procs, ros_env):
    procs.start([PY, "-m", "hexa_dynamics.trajectory_node", "--ros-args", "-r", "__ns:=/hexa",
                 "-p", "start_delay:=0.2", "-p", "require_monitoring:=false"], ros_env)   # no observer here
    rc, out, err = _hexa(procs, ros_env, "service", "call", "/hexa/trajectory/hold", "--json", "--timeout", "30")
    assert rc == 0, err
    assert json.loads(out) == {"success": True, "message": "held"}
    rc, out, err = _hexa(procs, ros_env, "service", "call", "/hexa/trajectory/resume", "std_srvs/srv/Trigger", "{}",
                         "--json")
    assert rc == 0 and json.loads(out)["message"] == "resumed", err
    rc, _out, err = _hexa(procs, ros_env, "service", "call", "/hexa/trajectory/resume", "std_srvs/srv/Trigger",
                          "{bogus: 1}")
    assert rc != 0 and "no field 'bogus'" in err


def test_param_set_then_get_round_trips_on_a_running_node(procs, ros_env):
    """A runtime parameter (the observer's marker_scale); start-up ones refuse a set (test_observer_node_params)."""
    procs.start([PY, "-m", "hexa_dynamics.observer_node", "--ros-args", "-r", "__ns:=/hexa"], ros_env)
    rc, _out, err = _hexa(procs, ros_env, "param", "set", "/hexa/observer", "marker_scale", "0.035",
                          "--timeout", "30")
    assert rc == 0, err
    rc, out, err = _hexa(procs, ros_env, "param", "get", "/hexa/observer", "marker_scale")
    assert rc == 0 and json.loads(out) == 0.035, err
    rc, _out, err = _hexa(procs, ros_env, "param", "get", "/hexa/observer", "no_such_parameter")
    assert rc == 1 and "no parameter 'no_such_parameter'" in err
