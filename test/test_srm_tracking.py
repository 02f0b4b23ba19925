"""3D tracking system model (seed 003 sec 2.4): X_c from marker sets and back; pose message conversions."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexa.kinematics.upsrpu import rotation_yz
from hexa.robots.upsrpu_description import load_upsrpu
from hexa.srm.tracking import markers_from_pose, pose_from_markers, pose_from_transform, tracking_model

DESC = load_upsrpu()
MODEL = tracking_model(DESC)
poses = st.tuples(st.floats(-0.1, 0.15), st.floats(0.6, 0.85), st.floats(-0.4, 0.4), st.floats(-0.6, 0.6)
                  ).map(np.array)


@given(poses)
@settings(max_examples=50, deadline=None)
def test_markers_round_trip_to_the_pose(X):
    fixed, mobile = markers_from_pose(MODEL, X, noise=0.0)
    Xc, rms = pose_from_markers(MODEL, fixed, mobile)
    np.testing.assert_allclose(Xc, X, atol=1e-12)
    assert rms < 1e-12


def test_marker_noise_gives_millimetre_level_pose_error():
    X = DESC.singular_poses[0]
    rng = np.random.default_rng(4)
    errs = []
    for _ in range(50):
        fixed, mobile = markers_from_pose(MODEL, X, rng, noise=1e-4)
        Xc, rms = pose_from_markers(MODEL, fixed, mobile)
        errs.append(Xc - X)
        assert 0 < rms < 5e-4
    errs = np.abs(np.array(errs))
    # the fixed frame's orientation error acts over the 0.7 m lever arm up to O_m
    assert errs[:, :2].max() < 3e-3 and errs[:, 2:].max() < 5e-3
    assert errs.mean() > 0


def test_pose_from_transform_drops_the_constrained_coordinates():
    R = rotation_yz(0.1, -0.2)
    X = pose_from_transform(R, np.array([0.03, 0.002, 0.71]))
    np.testing.assert_allclose(X, [0.03, 0.71, 0.1, -0.2])


def test_missing_tracking_section_names_it(tmp_path):
    from hexa.robots.schema import RobotDescriptionError
    from hexa.robots.upsrpu_description import DEFAULT_UPSRPU_PATH

    text = DEFAULT_UPSRPU_PATH.read_text()
    p = tmp_path / "no_tracking.yaml"
    p.write_text(text[: text.index("tracking:")])
    with pytest.raises(RobotDescriptionError, match="tracking"):
        tracking_model(load_upsrpu(p))


@given(poses)
@settings(max_examples=50, deadline=None)
def test_quaternion_conversions_round_trip(X):
    conv = pytest.importorskip("hexa_ros.conversions", reason="hexa_ros not installed")
    from hexa.rotations import matrix_from_quaternion

    class _P:   # a geometry_msgs/Pose look-alike (plain fields)
        class position:
            x = y = z = 0.0

        class orientation:
            x = y = z = 0.0
            w = 1.0

    pos, quat = conv.upsrpu_pose_to_msg_fields(X)
    p = _P()
    p.position.x, p.position.y, p.position.z = pos
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = quat
    np.testing.assert_allclose(conv.upsrpu_pose_from_msg(p), X, atol=1e-12)
    np.testing.assert_allclose(matrix_from_quaternion(*quat), rotation_yz(X[2], X[3]), atol=1e-12)
