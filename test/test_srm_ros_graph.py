"""The /upsrpu graph: simulated robot + singularity node + SRM node in separate processes; the enable service
releases the robot from Table 3 pose 1 (seed 003 sec 2.5)."""
from __future__ import annotations

import json
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")
pytest.importorskip("hexa_dynamics", reason="hexa_dynamics not installed (pip install -e hexa_dynamics)")

PY = sys.executable
POSE1 = "[0.01, 0.70, 0.15, 0.31]"

PROBE = r"""
import json, sys, time
import rclpy
from rclpy.node import Node
from hexa_msgs.msg import SingularityIndices
from hexa_msgs.srv import EnableSrm
from sensor_msgs.msg import JointState
from hexa_bringup.rosenv import apply_defaults
apply_defaults()
rclpy.init()
n = Node("srm_probe", namespace="/upsrpu")
ind, cmd, ref = [], [], []
n.create_subscription(SingularityIndices, "singularity",
                      lambda m: ind.append([m.near, m.min_omega, m.det_jd, m.min_pair, len(m.omega)]), 10)
n.create_subscription(JointState, "joint_commands", lambda m: cmd.append(list(m.position)), 10)
n.create_subscription(JointState, "joint_references", lambda m: ref.append(list(m.position)), 10)
cli = n.create_client(EnableSrm, "enable_srm")
t0 = time.monotonic()
while time.monotonic() - t0 < 40 and (len(ind) < 20 or len(cmd) < 20):
    rclpy.spin_once(n, timeout_sec=0.05)
before = ind[-1] if ind else None
cmd_before = cmd[-1] if cmd else None
ok = cli.wait_for_service(timeout_sec=20)
bad = cli.call_async(EnableSrm.Request(enable=True, variant=7))
rclpy.spin_until_future_complete(n, bad, timeout_sec=10)
fut = cli.call_async(EnableSrm.Request(enable=True, variant=1))
rclpy.spin_until_future_complete(n, fut, timeout_sec=10)
n_at_enable = len(ind)
t1 = time.monotonic()
while time.monotonic() - t1 < 6.0:
    rclpy.spin_once(n, timeout_sec=0.05)
after = ind[n_at_enable:]
print(json.dumps({"service": ok, "bad_variant": [bad.result().success, bad.result().message] if bad.result() else None,
                  "response": [fut.result().success, fut.result().message] if fut.result() else None,
                  "before": before, "after_last": after[-30:], "n_after": len(after),
                  "cmd_before": cmd_before, "cmd_last": cmd[-1] if cmd else None,
                  "ref_last": ref[-1] if ref else None}))
"""


def test_enable_service_releases_the_simulated_robot_through_the_ros_graph(procs, ros_env):
    ns = ["--ros-args", "-r", "__ns:=/upsrpu"]
    procs.start([PY, "-m", "hexa_dynamics.upsrpu_sim_node", *ns, "-p", f"initial_pose:={POSE1}",
                 "-p", "marker_noise:=0.0"], ros_env)
    procs.start([PY, "-m", "hexa_dynamics.singularity_node", *ns, "-p", "robot:=upsrpu", "-p", "input:=markers"],
                ros_env)
    procs.start([PY, "-m", "hexa_dynamics.srm_node", *ns, "-p", "input:=markers", "-p", "variant:=2"], ros_env)
    probe = procs.start([PY, "-c", PROBE], ros_env)
    out, err = probe.communicate(timeout=120)
    assert probe.returncode == 0, err
    r = json.loads(out.strip().splitlines()[-1])
    assert r["service"] is True
    assert r["bad_variant"][0] is False and "variant" in r["bad_variant"][1]
    assert r["response"][0] is True and "SRM-V1 enabled" in r["response"][1]
    near, min_omega, det_jd, pair, n_pairs = r["before"]
    assert near is True and pair == "3-4" and n_pairs == 6      # Table 3 pose 1 is near-singular
    assert r["n_after"] > 50
    assert all(not m[0] for m in r["after_last"]), r["after_last"][-3:]   # released and staying released
    moved = [abs(a - b) > 1e-6 for a, b in zip(r["cmd_last"], r["ref_last"])]
    assert moved == [False, False, True, True]                 # V1 moved only limbs 3 and 4


PROBE_TRAJ = r"""
import json, time
import rclpy
from rclpy.node import Node
from hexa_msgs.msg import SingularityIndices
from sensor_msgs.msg import JointState
from hexa_bringup.rosenv import apply_defaults
apply_defaults()
rclpy.init()
n = Node("srm_probe_traj", namespace="/upsrpu")
ind, ref = [], []
n.create_subscription(SingularityIndices, "singularity", lambda m: ind.append([time.monotonic(), m.near]), 10)
n.create_subscription(JointState, "joint_references", lambda m: ref.append(list(m.position)), 10)
t0 = time.monotonic()
while time.monotonic() - t0 < 45:
    rclpy.spin_once(n, timeout_sec=0.05)
    near = [m[1] for m in ind]
    if True in near and near.index(True) < len(near) - 1 and len(near) > near.index(True) + 200 \
            and not any(near[-100:]):
        break
near = [m[1] for m in ind]
print(json.dumps({"n": len(ind), "first_near": near.index(True) if True in near else None,
                  "last_100_near": sum(near[-100:]), "ref_first": ref[0] if ref else None,
                  "ref_last": ref[-1] if ref else None}))
"""


def test_srm_node_plays_trajectory_2_and_auto_enables_the_release(procs, ros_env):
    ns = ["--ros-args", "-r", "__ns:=/upsrpu"]
    procs.start([PY, "-m", "hexa_dynamics.upsrpu_sim_node", *ns, "-p", "publish_markers:=false"], ros_env)
    procs.start([PY, "-m", "hexa_dynamics.singularity_node", *ns], ros_env)
    procs.start([PY, "-m", "hexa_dynamics.srm_node", *ns, "-p", "trajectory:=2", "-p", "auto_enable_after:=1.0"],
                ros_env)
    probe = procs.start([PY, "-c", PROBE_TRAJ], ros_env)
    out, err = probe.communicate(timeout=120)
    assert probe.returncode == 0, err
    r = json.loads(out.strip().splitlines()[-1])
    assert r["first_near"] is not None, "the robot never reached the near-singular end of trajectory 2"
    assert r["last_100_near"] == 0, "not released after the automatic enable"
    assert r["ref_first"] != r["ref_last"]                 # the reference trajectory was played
