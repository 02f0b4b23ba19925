"""hexa_params.yaml against the nodes: every key exists with the node's declared default; the observer's runtime
parameter callback changes the detector and the estimator, rejects bad values and start-up-only keys (in-process);
every parameter has a descriptor, and a read-only one refuses a runtime set with the reason (`hexa param set` too)."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

REPO = Path(__file__).resolve().parents[1]
PARAMS = REPO / "hexa_bringup" / "hexa_bringup" / "config" / "hexa_params.yaml"
SOURCES = {"trajectory": "hexa_dynamics/hexa_dynamics/trajectory_node.py",
           "singularity": "hexa_dynamics/hexa_dynamics/singularity_node.py",
           "driver": "hexa_driver/hexa_driver/driver_node.py", "pose": "hexa_vision/hexa_vision/pose_node.py",
           "isolation": "hexa_vision/hexa_vision/isolation_node.py", "sim": "hexa_bringup/hexa_bringup/sim_params.py"}


def _blocks() -> dict[str, dict]:
    data = yaml.safe_load(PARAMS.read_text())
    return {key.split("/")[-1]: val["ros__parameters"] for key, val in data.items()}


@pytest.fixture
def rcl(ros_domain_id, monkeypatch):
    import rclpy

    monkeypatch.setenv("ROS_DOMAIN_ID", str(ros_domain_id))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init()
    nodes = []
    try:
        yield nodes
    finally:
        for n in nodes:
            n.destroy_node()
        rclpy.shutdown()


def test_params_file_has_a_block_per_node_and_only_keys_the_nodes_declare(rcl):
    """Each block's keys are parameters its node declares: the nodes that start without hardware are built in-process
    and asked; the driver (serial ports) and the simulator (MuJoCo) are read from their sources."""
    from hexa_dynamics.singularity_node import SingularityNode
    from hexa_dynamics.trajectory_node import TrajectoryNode
    from hexa_vision.isolation_node import IsolationNode
    from hexa_vision.pose_node import PoseNode

    blocks = _blocks()
    assert set(blocks) == {"observer", "rnea", "trajectory", "singularity", "driver", "pose", "isolation", "sim"}
    for name, cls in (("trajectory", TrajectoryNode), ("singularity", SingularityNode), ("pose", PoseNode),
                      ("isolation", IsolationNode)):
        node = cls()
        rcl.append(node)
        declared = set(node._parameters)
        assert set(blocks[name]) <= declared, (name, set(blocks[name]) - declared)
    for name, path in SOURCES.items():
        if name not in ("driver", "sim"):
            continue
        src = (REPO / path).read_text()
        declared = set(re.findall(r'(?:declare_parameter|\bp)\(\s*"(\w+)"', src))
        if re.search(r"declare_parameter\(DESCRIPTION\b", src):     # hexa_ros.node's robot-YAML parameter
            declared.add("description")
        if re.search(r"declare_parameter\(REALTIME_PRIORITY\b", src):   # hexa_ros.realtime's
            declared.add("realtime_priority")
        declared |= set(re.findall(r'^\s+"(\w+)": Param\(', src, re.M))   # a PARAMETERS table of hexa_ros.node.Param
        if name == "driver":
            declared |= {"uno_port", "mega_port", "baud", "stream_rate_hz", "command_rate_hz", "max_speed"}
        assert set(blocks[name]) <= declared, (name, set(blocks[name]) - declared)


def test_observer_and_rnea_blocks_equal_the_declared_defaults(rcl):
    from hexa_dynamics.observer_node import ObserverNode
    from hexa_dynamics.rnea_node import RneaNode

    blocks = _blocks()
    for cls, name in ((ObserverNode, "observer"), (RneaNode, "rnea")):
        node = cls()
        rcl.append(node)
        for key, val in blocks[name].items():
            assert node.has_parameter(key), (name, key)
            got = node.get_parameter(key).value
            got = list(got) if isinstance(got, (list, tuple)) or hasattr(got, "tolist") else got
            assert got == val, (name, key, got, val)


def test_runtime_parameters_reach_the_detector_and_the_estimator(rcl):
    from rclpy.parameter import Parameter

    from hexa_dynamics.observer_node import ObserverNode

    node = ObserverNode()
    rcl.append(node)
    res = node.set_parameters([Parameter("thresholds", value=[3.0, 3.0, 4.0, 0.3, 0.3, 0.5]),
                               Parameter("gains", value=[50.0] * 6), Parameter("camera_sigma", value=0.01),
                               Parameter("min_duration", value=0.025)])
    assert all(r.successful for r in res)
    assert node.monitor.observer.detector.thresholds.tolist() == [3.0, 3.0, 4.0, 0.3, 0.3, 0.5]
    assert node.monitor.observer.detector.config.min_duration == 0.025
    assert node.monitor.observer._K.tolist() == [50.0] * 6
    assert node.monitor.estimator.config.camera_sigma == 0.01
    bad = node.set_parameters([Parameter("thresholds", value=[3.0, -1.0, 4.0, 0.3, 0.3, 0.5])])
    assert not bad[0].successful and "thresholds" in bad[0].reason
    assert node.monitor.observer.detector.thresholds[1] == 3.0          # unchanged
    res = node.set_parameters([Parameter("servo_thresholds", value=[0.5, 0.5, 0.5, 0.0, 0.5, 0.6])])
    servo = node.monitor.observer.detector.servo_thresholds.tolist()
    assert res[0].successful and servo == [0.5, 0.5, 0.5, 0.0, 0.5, 0.6]
    bad = node.set_parameters([Parameter("servo_thresholds", value=[0.5, 0.5, -0.5, 0.0, 0.5, 0.6])])
    assert not bad[0].successful and "servo_thresholds" in bad[0].reason
    assert node.monitor.observer.detector.servo_thresholds[2] == 0.5    # unchanged
    ro = node.set_parameters([Parameter("zeta_source", value="measured")])
    assert not ro[0].successful and node.monitor.config.zeta_source == "estimator"
    # the threshold detector (the default) refuses the CUSUM's settings; the CUSUM detector takes them at run time,
    # and refuses a bad one naming it
    (no,) = node.set_parameters([Parameter("cusum_alarm", value=0.02)])
    assert not no.successful and "cusum" in no.reason
    node = ObserverNode(parameter_overrides=[Parameter("detector", value="cusum")])
    rcl.append(node)
    res = node.set_parameters([Parameter("cusum_alarm", value=0.02), Parameter("cusum_baseline_tau", value=0.5)])
    assert all(r.successful for r in res)
    cusum = node.monitor.observer.detector.cusum
    assert (cusum.alarm, cusum.baseline_tau, cusum.drift) == (0.02, 0.5, 0.5)
    bad = node.set_parameters([Parameter("cusum_accel_tau", value=0.0)])
    assert not bad[0].successful and "accel_tau" in bad[0].reason
    assert node.monitor.observer.detector.cusum.accel_tau == 0.02      # unchanged
    ro = node.set_parameters([Parameter("detector", value="threshold")])
    assert not ro[0].successful and "read-only" in ro[0].reason


def test_reset_with_recalibrate_removes_a_rest_offset(rcl):
    """~/reset(recalibrate=true) at rest: a wrong I₀ (+0.05 N·m on every servo) shows as a steady residual; after the
    calibration window it is averaged into the offset and the residual returns to ≈ 0."""
    from hexa_msgs.srv import ResetObserver

    from hexa.sim import Simulator
    from hexa_dynamics.observer_node import ObserverNode

    node = ObserverNode()
    rcl.append(node)
    node.set["calibration_duration"] = 0.5
    sim = Simulator(cameras=False)
    s = sim.state()
    node.monitor.observer.update_pose(0.0, s.pose)
    node.monitor.estimator.update_camera(0.0, s.pose)
    u = s.zeta.copy()
    outs = []

    def run(t0: float, t1: float) -> None:
        t = t0
        while t < t1:
            sim.step(5)
            st = sim.state()
            out = node.monitor._sample(t, u, st.tau + 0.05, None)
            if out is not None:
                outs.append((t, out.residual.wrench.copy()))
            t += 0.005

    run(0.005, 1.0)
    before = np.abs(outs[-1][1][:3]).max()
    resp = node._on_reset(ResetObserver.Request(recalibrate=True), ResetObserver.Response())
    assert resp.success and "recalibrating" in resp.message
    run(1.0, 2.5)
    after = np.abs(outs[-1][1][:3]).max()
    assert before > 0.5                                # N: the wrong I₀ is visible
    assert after < 0.1 and np.abs(node.monitor.observer.offset[:3]).max() > 0.5


def test_every_parameter_has_a_description_and_only_runtime_ones_are_writable(rcl):
    from hexa_dynamics.observer_node import ObserverNode
    from hexa_dynamics.observer_params import RUNTIME
    from hexa_dynamics.rnea_node import RneaNode
    from hexa_dynamics.singularity_node import SingularityNode
    from hexa_dynamics.trajectory_node import TrajectoryNode
    from hexa_vision.isolation_node import IsolationNode
    from hexa_vision.pose_node import PoseNode

    for cls in (ObserverNode, RneaNode, TrajectoryNode, PoseNode, IsolationNode, SingularityNode):
        node = cls()
        rcl.append(node)
        names = [n for n in node._parameters if n != "use_sim_time"]
        assert "description" in names, cls.__name__               # the robot YAML, one name on every node
        for d in node.describe_parameters(names):
            assert d.description, (cls.__name__, d.name)
            assert d.read_only == (cls is not ObserverNode or d.name not in RUNTIME), (cls.__name__, d.name)
    traj = next(n for n in rcl if isinstance(n, TrajectoryNode))
    (rate,) = traj.describe_parameters(["rate_hz"])
    assert rate.floating_point_range and rate.floating_point_range[0].to_value == 1000.0
    (policy,) = traj.describe_parameters(["collision_policy"])
    assert "hold, retract, ignore" in policy.additional_constraints


def test_a_start_up_parameter_refuses_a_runtime_set_with_the_reason(rcl):
    from rclpy.parameter import Parameter

    from hexa_dynamics.trajectory_node import TrajectoryNode

    node = TrajectoryNode()
    rcl.append(node)
    (res,) = node.set_parameters([Parameter("collision_policy", value="ignore")])
    assert not res.successful and "read-only" in res.reason and "collision_policy" in res.reason
    assert node.get_parameter("collision_policy").value == "hold"
    assert node.runner.player.policy == "hold"


@pytest.mark.parametrize("override, shown", [(("rate_hz", 5000.0), "rate_hz"),
                                             (("collision_policy", "stop"), "'stop'")])
def test_a_start_up_value_out_of_range_or_choices_is_a_configuration_error_naming_it(rcl, override, shown):
    from rclpy.parameter import Parameter

    from hexa_dynamics.trajectory_node import TrajectoryNode

    with pytest.raises(ValueError, match=shown):
        TrajectoryNode(parameter_overrides=[Parameter(override[0], value=override[1])])


def test_hexa_param_set_on_a_read_only_parameter_prints_the_reason(procs, ros_env):
    import subprocess
    import sys
    import time

    procs.start([sys.executable, "-m", "hexa_dynamics.trajectory_node", "--ros-args", "-r", "__ns:=/hexa"], ros_env)
    deadline, r = time.monotonic() + 40, None
    while time.monotonic() < deadline:
        r = subprocess.run([sys.executable, "-m", "hexa_bringup.cli", "param", "set", "/hexa/trajectory",
                            "collision_policy", "ignore", "--timeout", "5"], env=ros_env, capture_output=True,
                           text=True, timeout=30)
        if "refused" in r.stderr or r.returncode == 0:
            break
    assert r is not None and r.returncode == 1 and "read-only parameter: collision_policy" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_every_driver_parameter_has_a_description():
    from hexa.protocol.driver_core import SCALAR_KEYS
    from hexa_driver.driver_params import TEXT, driver_descriptor

    assert set(SCALAR_KEYS) | {"config"} <= set(TEXT)
    d = driver_descriptor("max_speed", 1.5)
    assert d.read_only and d.description.startswith("rad/s")
