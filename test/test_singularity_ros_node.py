"""The singularity node in /hexa (plate_pose -> 15 Omega pairs) as a separate process."""
from __future__ import annotations

import json
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")
pytest.importorskip("hexa_dynamics", reason="hexa_dynamics not installed (pip install -e hexa_dynamics)")
pytest.importorskip("hexa.kinematics.hexa6rus", reason="Hexa kinematics not available")

PY = sys.executable

PROBE = r"""
import json, time
import numpy as np
import rclpy
from rclpy.node import Node
from geometry_msgs.msg import PoseStamped
from hexa_msgs.msg import SingularityIndices
from hexa_bringup.rosenv import apply_defaults
from hexa.kinematics.hexa6rus import HOME_POSE
apply_defaults()
rclpy.init()
n = Node("sing_probe", namespace="/hexa")
got = []
n.create_subscription(SingularityIndices, "singularity", lambda m: got.append(m), 10)
pub = n.create_publisher(PoseStamped, "plate_pose", 10)
t0 = time.monotonic()
while time.monotonic() - t0 < 30 and not got:
    ps = PoseStamped()
    ps.header.frame_id = "base"
    ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = (float(v) for v in HOME_POSE[:3])
    ps.pose.orientation.w = 1.0
    pub.publish(ps)
    rclpy.spin_once(n, timeout_sec=0.2)
m = got[0] if got else None
print(json.dumps(None if m is None else {"robot": m.robot, "pairs": list(m.pairs), "omega": list(m.omega),
                                         "min_pair": m.min_pair, "min_omega": m.min_omega, "det_jd": m.det_jd,
                                         "near": m.near, "frame": m.header.frame_id}))
"""


def test_hexa_singularity_node_publishes_fifteen_pairs_for_a_plate_pose(procs, ros_env):
    import numpy as np

    from hexa import singularity as sg
    from hexa.kinematics.hexa6rus import HOME_POSE
    from hexa.robots.hexa_description import load_hexa

    procs.start([PY, "-m", "hexa_dynamics.singularity_node", "--ros-args", "-r", "__ns:=/hexa"], ros_env)
    probe = procs.start([PY, "-c", PROBE], ros_env)
    out, err = probe.communicate(timeout=90)
    assert probe.returncode == 0, err
    r = json.loads(out.strip().splitlines()[-1])
    assert r is not None, "no singularity message received"
    ref = sg.hexa_indices(load_hexa(), np.asarray(HOME_POSE, dtype=float))
    assert r["robot"] == "hexa" and r["frame"] == "base"
    assert r["pairs"] == list(ref.pairs) and len(r["pairs"]) == 15
    np.testing.assert_allclose(r["omega"], ref.omega, atol=1e-9)
    assert r["det_jd"] == pytest.approx(ref.det_jd)
    assert r["near"] == bool(ref.min_omega < np.radians(1.8))
