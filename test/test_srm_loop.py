"""The SRM and singularity nodes' logic without ROS: the outer loop (reference, enable pin, automatic enable, stale
X_c), X_c from the two marker streams, and the indices monitor with its limits."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hexa.kinematics import upsrpu as kin
from hexa.robots.upsrpu_description import load_upsrpu
from hexa.singularity import SingularityError, SingularityMonitor
from hexa.srm.loop import ReleaseLoop
from hexa.srm.tracking import MarkerTracker, markers_from_pose, tracking_model

DESC = load_upsrpu()
POSE1 = np.array([0.01, 0.70, 0.15, 0.31])         # Table 3 pose 1: near-singular, limbs 3-4


def test_nothing_is_commanded_before_a_pose_and_the_first_pose_is_held():
    loop = ReleaseLoop(DESC)
    assert loop.step(0.0) is None
    assert not loop.set_pose(np.array([0.0, np.nan, 0.0, 0.0]), 0.0) and loop.rejected == 1
    assert loop.set_pose(POSE1, 0.0)
    s = loop.step(0.01)
    np.testing.assert_allclose(s.q_r, kin.inverse_kinematics(DESC, POSE1))
    np.testing.assert_allclose(s.q_d, s.q_r)                           # pin not set: q_d = q_r
    assert loop.set_pose(POSE1 + 0.01, 0.02)
    np.testing.assert_allclose(loop.step(0.03).q_r, s.q_r)             # the first measured pose stays the reference


def test_the_enable_pin_releases_only_with_a_fresh_pose():
    loop = ReleaseLoop(DESC, variant=1, pose_timeout=0.1)
    loop.set_pose(POSE1, 0.0)
    assert loop.enable(True, 7) == (False, "variant must be 0 (keep), 1 or 2, got 7") and not loop.enabled
    assert loop.enable(True, 0) == (True, "SRM-V1 enabled")
    assert loop.step(1.0) is not None and not loop.srm.delta.any()       # X_c 1 s old: Δ frozen
    s = loop.step(0.05)
    moved = np.abs(s.q_d - s.q_r) > 1e-9
    assert moved.tolist() == [False, False, True, True] and loop.steps_active == 1   # V1 moves limbs 3 and 4
    assert loop.enable(False, 2) == (True, "SRM-V2 disabled")


def test_a_reference_is_played_then_the_pin_is_set_automatically():
    ref = np.array([POSE1 + [0.0, 0.02, 0.0, 0.0], POSE1 + [0.0, 0.01, 0.0, 0.0], POSE1])
    loop = ReleaseLoop(DESC, reference=ref, auto_enable_after=2 * DESC.t_s)
    loop.set_pose(ref[0], 0.0)
    qs = [loop.step(0.0) for _ in range(5)]
    np.testing.assert_allclose(qs[0].q_r, kin.inverse_kinematics(DESC, ref[0]))
    np.testing.assert_allclose(qs[2].q_r, kin.inverse_kinematics(DESC, ref[2]))
    assert [s.auto_enabled for s in qs] == [False, False, False, True, False] and loop.enabled


def test_x_c_comes_from_each_mobile_marker_set_and_the_newest_fixed_set():
    tr = MarkerTracker(tracking_model(DESC))
    fixed, mobile = markers_from_pose(tr.model, POSE1, noise=0.0)
    assert tr.add_mobile(mobile) is None                               # no fixed set yet
    tr.add_fixed(fixed)
    np.testing.assert_allclose(tr.add_mobile(mobile), POSE1, atol=1e-9)
    with pytest.raises(ValueError):
        tr.add_mobile(mobile[:2])                                       # too few markers


def test_the_monitor_uses_each_robots_limits_and_names_an_unknown_robot():
    up = SingularityMonitor("upsrpu")
    assert (up.det_jd_limit, up.omega_limit) == (DESC.det_jd_limit, DESC.omega_limit)
    rep = up.report(POSE1)
    assert up.near(rep) and rep.min_pair == "3-4" and len(rep.omega) == 6
    up.omega_limit, up.det_jd_limit = 0.0, 0.0
    assert not up.near(rep)
    hexa = SingularityMonitor("hexa")
    assert (hexa.det_jd_limit, hexa.omega_limit) == (0.0, math.radians(1.8))
    with pytest.raises(SingularityError, match="'delta'"):
        SingularityMonitor("delta")
