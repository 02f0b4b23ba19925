"""`hexa bringup sim` on TF: an independent listener receives /tf_static (cameras), /tf (plate, arms, rods) and
external_wrench / external_joint_torques; composing its transforms (as a tf2 lookup does) gives the robot YAML's camera
poses within 1 mm and a robot whose rods close on the plate joints; a late joiner gets the latched states."""
from __future__ import annotations

import json
import sys

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")
pytest.importorskip("tf2_msgs.msg", reason="tf2_msgs not built: run `make setup`")

from hexa import frames  # noqa: E402
from hexa.rotations import matrix_from_quaternion  # noqa: E402

PY = sys.executable
CAMERAS = ("cam_top", "cam_side")
MOVING = [frames.PLATE] + [frames.arm(i) for i in range(1, 7)] + [frames.rod(i) for i in range(1, 7)]
OPTICAL = [frames.camera_optical_frame(c, s) for c in CAMERAS for s in frames.CAMERA_SENSORS]


def lookup(tree: dict, target: str, source: str) -> np.ndarray:
    """T_target_source from the received transforms, composed along the tree (tf2's lookupTransform)."""
    def to_root(frame: str) -> tuple[list[str], np.ndarray]:
        path, T = [frame], np.eye(4)
        while frame in tree:
            e = tree[frame]
            E = np.eye(4)
            E[:3, :3], E[:3, 3] = matrix_from_quaternion(*e["q"]), e["t"]
            T, frame = E @ T, e["parent"]
            path.append(frame)
        return path, T
    (pt, Tt), (ps, Ts) = to_root(target), to_root(source)
    assert pt[-1] == ps[-1], f"{target} and {source} are not connected: {pt} vs {ps}"
    return np.linalg.inv(Tt) @ Ts


def test_bringup_sim_publishes_tf_and_external_wrench_for_an_independent_listener(procs, ros_env, tmp_path):
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim.config import sim_config_of

    env = dict(ros_env, MUJOCO_GL="egl")
    procs.start([PY, "-m", "hexa_bringup.cli", "bringup", "sim", "--log-dir", str(tmp_path)], env)
    peer = procs.start([PY, "test/tf_listener_peer.py", "90", *MOVING, *OPTICAL], env)
    out, err = peer.communicate(timeout=120)
    assert peer.returncode == 0, (out[-2000:], err[-2000:])
    r = json.loads(out.strip().splitlines()[-1])
    tree = r["frames"]
    assert r["type"].startswith("tf2_msgs.msg")
    # cameras: latched on /tf_static, the YAML's optical-frame pose within 1 mm (and 1 mrad)
    desc = load_hexa()
    for cam in sim_config_of(desc).cameras.values():
        assert tree[frames.camera_link(cam.name)]["source"] == "tf_static"
        T = lookup(tree, frames.BASE, cam.frame_id)
        assert np.linalg.norm(T[:3, 3] - cam.T_base_camera[:3, 3]) < 1e-3
        assert np.allclose(T[:3, :3], cam.T_base_camera[:3, :3], atol=1e-3)
        # realsense-ros: optical z is the link's x (forward), optical x is the link's -y
        L = lookup(tree, frames.camera_link(cam.name), frames.camera_optical_frame(cam.name, "depth"))
        assert np.allclose(L[:3, :3], frames.R_LINK_OPTICAL, atol=1e-9)
    # the robot from TF alone: each rod leaves its arm's tip and ends at its plate joint C_i
    for i in range(6):
        assert tree[frames.rod(i + 1)]["source"] == "tf" and tree[frames.rod(i + 1)]["parent"] == frames.BASE
        arm = lookup(tree, frames.BASE, frames.arm(i + 1))
        rod = lookup(tree, frames.BASE, frames.rod(i + 1))
        plate = lookup(tree, frames.BASE, frames.PLATE)
        assert np.linalg.norm(arm[:3, 3] - desc.A[i]) < 1e-9
        assert np.linalg.norm(arm[:3, 3] + desc.l_a * arm[:3, 0] - rod[:3, 3]) < 1e-6      # the elbow B_i
        C = plate[:3, :3] @ desc.C[i] + plate[:3, 3]
        assert np.linalg.norm(rod[:3, 3] + desc.l_d * rod[:3, 0] - C) < 2e-3               # loop closure (m)
    assert 0.1 < -plate[2, 3] < 0.6                                                          # plate below the base
    # the residual as a wrench in the plate frame, and in servo space
    assert all(w["frame_id"] == frames.PLATE and np.all(np.isfinite(w["force"])) for w in r["wrenches"])
    assert r["torques"][-1]["name"] == [f"arm_{i}" for i in range(1, 7)] and len(r["torques"][-1]["effort"]) == 6
    # a late joiner gets the cameras, the collision state and the trajectory state at once (transient local)
    late = procs.start([PY, "test/tf_listener_peer.py", "30", "--latched"], env)
    out, err = late.communicate(timeout=60)
    assert late.returncode == 0, (out[-2000:], err[-2000:])
    s = json.loads(out.strip().splitlines()[-1])["states"]
    assert s["collision"][0] in (0, 1) and s["trajectory"] in (
        "waiting", "waiting_for_monitoring", "waiting_for_pose", "approaching", "running", "held", "retracting",
        "resuming", "finished")
