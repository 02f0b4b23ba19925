"""Loading and validating the Hexa robot description (src/hexa/robots/hexa.yaml)."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import yaml

from hexa.robots.hexa_description import DEFAULT_PATH, load_hexa, parse_hexa
from hexa.robots.schema import RobotDescriptionError


@pytest.fixture(scope="module")
def raw():
    return yaml.safe_load(DEFAULT_PATH.read_text())


def test_default_description_has_design_md_geometry():
    d = load_hexa()
    assert d.A.shape == (6, 3) and d.C.shape == (6, 3)
    assert np.allclose(d.A[0], [0.125, 0.040, 0.0]) and np.allclose(d.A[1], [0.125, -0.040, 0.0])
    c45 = 0.1 * math.cos(math.pi / 4)
    assert np.allclose(d.C[0], [c45, c45, 0.0]) and np.allclose(d.C[1], [c45, -c45, 0.0])
    assert np.allclose(np.linalg.norm(d.A, axis=1), math.hypot(0.125, 0.04))
    assert d.l_a == 0.2 and d.l_d == 0.5
    assert np.allclose(d.alpha, np.array([0, 0, 2, 2, 4, 4]) * math.pi / 3)
    assert d.m_plate == 0.30 and d.m_rod == 0.03 and d.m_arm == 0.05
    assert 0.4 <= d.K_t <= 0.5
    with pytest.raises(ValueError):
        d.A[0, 0] = 1.0  # read-only


def test_chains_come_in_pairs_rotated_by_120_degrees():
    d = load_hexa()
    rz = np.array([[math.cos(2 * math.pi / 3), -math.sin(2 * math.pi / 3), 0],
                   [math.sin(2 * math.pi / 3), math.cos(2 * math.pi / 3), 0], [0, 0, 1]])
    assert np.allclose(d.A[2:4], d.A[0:2] @ rz.T) and np.allclose(d.C[4:6], d.C[2:4] @ rz.T)


@pytest.mark.parametrize("key, value, fragment", [
    ("geometry.arm_length", -0.2, "geometry.arm_length"),
    ("geometry.rod_length", "500 mm", "geometry.rod_length"),
    ("geometry.sigma", [1, 1, 1, 1, 1, 0], "geometry.sigma"),
    ("geometry.alpha", [0, 0, 1, 1, 2], "geometry.alpha"),
    ("kinematics.branch", 2, "kinematics.branch"),
    ("kinematics.zeta_max", -5.0, "kinematics.zeta_max"),
    ("inertia.rod.mass", 0.0, "inertia.rod.mass"),
    ("inertia.plate.inertia", [[1, 0, 0], [0, 1, 0], [0, 0, 3]], "inertia.plate.inertia"),
    ("actuators.K_t", -0.45, "actuators.K_t"),
    ("geometry.arm_length", 200.0, "geometry.arm_length.*mm given"),
    ("geometry.alpha", [0, 0, 120, 120, 240, 240], "geometry.alpha.*degrees given"),
    ("kinematics.home_pose", [0, 0, -550, 0, 0, 0], "kinematics.home_pose"),
])
def test_bad_values_are_rejected_naming_the_key(raw, key, value, fragment):
    data = copy.deepcopy(raw)
    node = data
    *parents, last = key.split(".")
    for p in parents:
        node = node[p]
    node[last] = value
    with pytest.raises(RobotDescriptionError, match=fragment.replace(".", r"\.").replace(r"\.*", ".*")):
        parse_hexa(data)


def test_missing_key_is_named(raw):
    data = copy.deepcopy(raw)
    del data["geometry"]["plate_radius"]
    with pytest.raises(RobotDescriptionError, match=r"geometry\.plate_radius"):
        parse_hexa(data)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(RobotDescriptionError, match="nope.yaml"):
        load_hexa(tmp_path / "nope.yaml")


def test_a_different_file_changes_the_robot_and_extra_sections_are_kept(raw, tmp_path):
    data = copy.deepcopy(raw)
    data["geometry"]["rod_length"] = 0.45
    data["sim"] = {"timestep": 0.001, "nested": {"k": [1, 2]}}
    path = tmp_path / "other.yaml"
    path.write_text(yaml.safe_dump(data))
    d = load_hexa(path)
    assert d.l_d == 0.45
    assert d.section("sim") == {"timestep": 0.001, "nested": {"k": [1, 2]}}
    d.section("sim")["timestep"] = 1.0
    assert d.section("sim")["timestep"] == 0.001  # copies, the model stays immutable
    with pytest.raises(RobotDescriptionError, match="no_such_section"):
        d.section("no_such_section")


def test_description_is_hashable_by_identity():
    d = load_hexa()
    assert {d: 1}[d] == 1 and d == d
