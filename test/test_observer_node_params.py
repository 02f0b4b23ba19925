"""hexa_params.yaml against the nodes: every key exists with the node's declared default; the observer's runtime
parameter callback changes the detector and the estimator, rejects bad values and start-up-only keys (in-process)."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

REPO = Path(__file__).resolve().parents[1]
PARAMS = REPO / "hexa_bringup" / "hexa_bringup" / "config" / "hexa_params.yaml"
SOURCES = {"trajectory": "hexa_dynamics/hexa_dynamics/trajectory_node.py",
           "singularity": "hexa_dynamics/hexa_dynamics/singularity_node.py",
           "driver": "hexa_driver/hexa_driver/driver_node.py", "pose": "hexa_vision/hexa_vision/pose_node.py",
           "isolation": "hexa_vision/hexa_vision/isolation_node.py", "sim": "hexa_bringup/hexa_bringup/sim_node.py"}


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
