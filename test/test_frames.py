"""hexa.frames: the camera frames compose to the YAML's optical pose; the robot's frames close the loop at any
reachable pose; a camera frame_id other than the realsense-ros name is refused naming it."""
from __future__ import annotations

import numpy as np
import pytest

from hexa import frames
from hexa.kinematics.hexa6rus import inverse_kinematics
from hexa.robots.hexa_description import load_hexa
from hexa.sim.config import SimConfigError, sim_config_of


def _chain(tree: dict, frame: str) -> np.ndarray:
    T = np.eye(4)
    while frame in tree:
        parent, E = tree[frame]
        T, frame = E @ T, parent
    assert frame == frames.BASE
    return T


def test_camera_frames_compose_to_the_descriptions_optical_pose_with_realsense_axes():
    desc = load_hexa()
    tree = {c: (p, T) for p, c, T in frames.static_transforms(desc)}
    for cam in sim_config_of(desc).cameras.values():
        for sensor in frames.CAMERA_SENSORS:
            T = _chain(tree, frames.camera_optical_frame(cam.name, sensor))
            assert np.allclose(T, cam.T_base_camera, atol=1e-12)
        link = _chain(tree, frames.camera_link(cam.name))
        # the link's x axis is the optical z (forward), its z axis the image's up (-y optical)
        R = cam.T_base_camera[:3, :3]
        assert np.allclose(link[:3, 0], R[:, 2]) and np.allclose(link[:3, 2], -R[:, 1])


@pytest.mark.parametrize("pose", [[0.0, 0.0, -0.45, 0.0, 0.0, 0.0], [0.03, -0.02, -0.5, 0.1, -0.15, 0.2]])
def test_robot_frames_place_arms_and_rods_so_each_rod_ends_at_its_plate_joint(pose):
    desc = load_hexa()
    pose = np.array(pose)
    zeta = inverse_kinematics(desc, pose)
    T = {c: M for _p, c, M in frames.robot_transforms(desc, pose, zeta)}
    plate = T[frames.PLATE]
    for i in range(6):
        arm, rod = T[frames.arm(i + 1)], T[frames.rod(i + 1)]
        for M in (arm, rod):
            assert np.allclose(M[:3, :3].T @ M[:3, :3], np.eye(3)) and np.linalg.det(M[:3, :3]) > 0
        assert np.allclose(arm[:3, 3] + desc.l_a * arm[:3, 0], rod[:3, 3])
        assert np.allclose(rod[:3, 3] + desc.l_d * rod[:3, 0], plate[:3, :3] @ desc.C[i] + plate[:3, 3], atol=1e-9)


def test_a_camera_frame_id_off_the_realsense_name_is_refused_naming_it(tmp_path):
    import yaml

    from hexa.robots.hexa_description import DEFAULT_PATH

    data = yaml.safe_load(DEFAULT_PATH.read_text())
    data["cameras"]["cam_side"]["frame_id"] = "side_camera"
    path = tmp_path / "hexa.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(SimConfigError, match="cam_side.frame_id 'side_camera'"):
        frames.static_transforms(load_hexa(path))
