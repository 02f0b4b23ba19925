"""The observer node in its own process, fed by a peer replaying a MuJoCo run as driver-like joint_states (commanded
angles + ADC-quantized torques, 200 Hz) and noisy 30 Hz plate poses: no collision in free motion, START on fz after
3 N upwards on the plate, END after release, runtime thresholds, bad input counted and the node alive, clean exit
on SIGINT."""
from __future__ import annotations

import json
import signal
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable


def test_observer_node_detects_the_push_and_takes_runtime_thresholds(procs, ros_env):
    node = procs.start([PY, "-m", "hexa_dynamics.observer_node", "--ros-args", "-r", "__ns:=/hexa"], ros_env)
    peer = procs.start([PY, "test/observer_node_peer.py", "observer"], ros_env)
    out, err = peer.communicate(timeout=120)
    assert peer.returncode == 0, err
    r = json.loads(out.strip().splitlines()[-1])
    ev = r["events"]
    starts = [e for e in ev if e["event"] == 0]
    ends = [e for e in ev if e["event"] == 1]
    assert starts and all(e["onset"] > r["f_on"] for e in starts), ev          # nothing in free motion
    assert len(starts) == 1 and starts[0]["axis_name"] == "fz" and starts[0]["axis"] == 2
    assert starts[0]["t"] - r["f_on"] < 0.1                                    # lag to 2 N of 3 N + min_duration
    assert len(ends) == 1 and ends[0]["id"] == starts[0]["id"] and ends[0]["t"] > r["f_off"]
    assert max(r["free_peak"]) < 1.5                                           # N, below r_low = 2 N
    assert r["forced_mean"][2] == pytest.approx(3.0, abs=0.3)
    # runtime thresholds: accepted, visible on `residual`, and the same push no longer triggers
    assert r["set_thresholds_ok"] and r["set_negative_rejected"]
    assert r["threshold_seen"] == [20.0, 20.0, 20.0, 2.0, 2.0, 2.0] + [3.0] * 6   # plate axes, then servos
    assert r["events_phase2"] == 0 and r["residuals_phase2"] > 100
    # bad input is counted by reason; the node keeps publishing
    d = r["diag"]
    assert int(d["reject_input_states_non_finite"]) == 5 and int(d["reject_node_bad_joint_names"]) == 3
    assert r["alive_after_bad_input"] > 10
    assert node.poll() is None
    node.send_signal(signal.SIGINT)                                            # clean Ctrl-C
    _out, err = node.communicate(timeout=20)
    assert node.returncode == 0 and "Traceback" not in err, err


@pytest.mark.ros_parallel   # starts a node that refuses its parameters: no live timing
@pytest.mark.parametrize("module, param", [("hexa_dynamics.observer_node", "zeta_source"),
                                           ("hexa_dynamics.observer_node", "servo_thresholds"),
                                           ("hexa_dynamics.rnea_node", "arm_force_model"),
                                           ("hexa_dynamics.rnea_node", "arm_friction")])
def test_observer_node_rejects_a_bad_parameter_at_start_naming_it(procs, ros_env, module, param):
    value = {"servo_thresholds": "[0.3,0.3,-1.0,0.3,0.3,0.3]", "arm_friction": "-0.5"}.get(param, "guess")
    p = procs.start([PY, "-m", module, "--ros-args", "-p", f"{param}:={value}"], ros_env)
    _out, err = p.communicate(timeout=60)
    shown = {"servo_thresholds": "-1.0", "arm_friction": "-0.5"}.get(param, "'guess'")
    assert p.returncode == 2 and param in err and shown in err, err


@pytest.mark.parametrize("module", ["hexa_dynamics.observer_node", "hexa_dynamics.rnea_node"])
def test_node_on_sim_time_stops_cleanly_on_sigint_with_no_clock(procs, ros_env, module):
    """With use_sim_time and no /clock (the simulator already gone) nothing wakes the executor: Ctrl-C must still
    end the node at once with exit code 0, not after the supervisor's 10 s kill."""
    import signal
    import time

    p = procs.start([PY, "-m", module, "--ros-args", "-p", "use_sim_time:=true"], ros_env)
    time.sleep(4.0)  # initialised and waiting
    assert p.poll() is None
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    p.wait(timeout=8)
    assert p.returncode == 0
    assert time.monotonic() - t0 < 5.0
