"""Demo metrics on a hand-checkable synthetic case."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hexa.report.collision_demo import CaseData, compute_metrics, markdown_table, plot_case, write_report


def _case() -> CaseData:
    t = np.arange(0, 3.0, 0.01)
    f = np.zeros((len(t), 3))
    on = (t >= 1.0) & (t < 2.0)
    f[on, 0] = 4.0 * (t[on] - 1.0) / 1.0 * 2  # ramps 0 → 8 N; exceeds 2 N at t = 1.25 (first sample > 2: 1.26)
    point = np.tile([0.1, 0.0, -0.55], (len(t), 1))
    link = np.full(len(t), 0)
    chain = np.zeros(len(t), dtype=int)
    wt = np.arange(1.3, 1.9, 0.1)
    wf = np.interp(wt, t, f[:, 0])[:, None] * np.array([[1.0, 0.0, 0.0]]) + np.array([[0.5, -1.0, 0.0]])
    return CaseData(
        case="plate", truth_t=t, truth_force=f, truth_point=point, truth_link=link, truth_chain=chain,
        events=[(0.5, "START", 1, "fx"), (0.6, "END", 1, "fx"), (1.27, "START", 2, "fx"), (2.1, "END", 2, "fx")],
        contact_t=np.array([1.3, 1.4, 1.5]), contact_link=np.array([0, 0, 1]), contact_chain=np.array([0, 0, 3]),
        contact_point=np.array([[0.1, 0.003, -0.55], [0.1, 0.004, -0.55], [0.2, 0.0, -0.55]]),
        wrench_t=wt, wrench_force=wf)


def test_metrics_of_a_hand_checkable_case():
    m = compute_metrics(_case())
    assert m.onset_true == pytest.approx(1.01)
    assert m.exceed_time == pytest.approx(1.26)
    assert m.detect_time == pytest.approx(1.27) and m.delay_ms == pytest.approx(10.0)
    assert m.false_starts == 1
    assert (m.found_link, m.found_chain) == ("plate", 0)      # majority of the three contacts
    assert m.point_error_median_mm == pytest.approx(4.0)
    assert m.force_rmse[0] == pytest.approx(0.5) and m.force_rmse[1] == pytest.approx(1.0)
    assert m.force_rmse[2] == pytest.approx(0.0)
    assert m.paper_rmse == (0.819, 0.476, 1.282)


def test_no_detection_and_no_outputs_give_nan_not_garbage():
    d = _case()
    d.events, d.contact_t, d.wrench_t = [], np.zeros(0), np.zeros(0)
    m = compute_metrics(d)
    assert math.isnan(m.delay_ms) and m.found_link == "none" and all(math.isnan(v) for v in m.force_rmse)
    assert "—" in markdown_table([m])


def test_case_without_true_contact_is_refused():
    d = _case()
    d.truth_force[:] = 0.0
    with pytest.raises(ValueError, match="no contact"):
        compute_metrics(d)


def test_report_and_plot_are_written(tmp_path):
    d = _case()
    m = compute_metrics(d)
    png = plot_case(d, m, tmp_path / "plate.png")
    rep = write_report([m], {"plate": png}, tmp_path)
    assert png.stat().st_size > 10_000
    text = rep.read_text()
    assert "| plate | plate 0 | plate 0 |" in text and "plate.png" in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plate.png", "report.md"]   # no part file left beside it


def test_observer_lag_is_measured_from_the_plate_equivalent_wrench():
    """A plate push 0.1 m off the centre: its moment about P (0.1·F) crosses a 0.15 N·m threshold at F = 1.5 N,
    before the force itself crosses 2 N — the observer lag counts from there; the plot shows W instead of F."""
    from hexa.trajectories import TRAJECTORIES

    d = _case()
    pose = np.asarray(TRAJECTORIES["circle"](0.0)[0], dtype=float)
    d.truth_pose = np.tile(pose, (len(d.truth_t), 1))
    d.truth_point = np.tile(pose[:3] + np.array([0.0, 0.1, 0.0]), (len(d.truth_t), 1))
    d.threshold = np.array([2.0, 2.0, 2.0, 0.15, 0.15, 0.15])
    m = compute_metrics(d)
    assert m.exceed_time == pytest.approx(1.26) and m.delay_ms == pytest.approx(10.0)
    assert m.plate_exceed_time == pytest.approx(1.19) and m.observer_delay_ms == pytest.approx(80.0)
    assert "| 1.190 | 80.0 |" in markdown_table([m])
    assert math.isnan(compute_metrics(_case()).observer_delay_ms)          # no pose: not measured, not invented
    assert m.load_peak == pytest.approx(0.1 * 7.92 / 0.15)          # the moment's peak over its threshold
    assert math.isnan(compute_metrics(_case()).load_peak)
    from hexa.report.collision_demo import plate_equivalent_truth

    W = plate_equivalent_truth(d)                   # computed once, given to both (the demo does)
    d.truth_tau = np.zeros((len(d.truth_t), 6))     # every field finite, so that the two compare equal
    m = compute_metrics(d)
    assert m.stall_s == 0.0
    assert compute_metrics(d, plate_equivalent=W) == m
    assert math.isnan(compute_metrics(d, plate_equivalent=np.zeros_like(W)).plate_exceed_time)   # it is the one used


def test_observer_lag_counts_the_servo_torque_criterion():
    """With the arm angles known, the plate-equivalent wrench is also mapped to servo torques τ_W = J_ζ⁻ᵀ W. Checked
    by virtual power, independently of J_ζ: for six plate motions (IK differences), τ_W · ζ̇ = W · V. With the plate
    thresholds out of reach and a servo threshold met at F = 1 N, the lag counts from F = 1 N (t = 1.125 s)."""
    from hexa.kinematics import hexa6rus as kin
    from hexa.report.collision_demo import plate_equivalent_truth, servo_equivalent_truth
    from hexa.robots.hexa_description import load_hexa
    from hexa.trajectories import TRAJECTORIES

    desc = load_hexa()
    d = _case()
    pose = np.asarray(TRAJECTORIES["circle"](0.0)[0], dtype=float)
    d.truth_pose = np.tile(pose, (len(d.truth_t), 1))
    d.truth_point = np.tile(pose[:3] + np.array([0.03, 0.1, 0.0]), (len(d.truth_t), 1))
    d.truth_zeta = np.tile(kin.inverse_kinematics(desc, pose), (len(d.truth_t), 1))
    W = plate_equivalent_truth(d, desc)
    tau = servo_equivalent_truth(d, W, desc)
    k = int(np.argmax(np.linalg.norm(d.truth_force, axis=1)))
    h = 1e-6
    V, zd = [], []
    for j in range(6):
        dq = np.eye(6)[j]
        V.append(kin.twist_from_pose_rate(pose[None], dq[None])[0])
        zd.append((kin.inverse_kinematics(desc, pose + h * dq) - kin.inverse_kinematics(desc, pose - h * dq)) / (2 * h))
    tau_vp = np.linalg.solve(np.array(zd), np.array(V) @ W[k])
    np.testing.assert_allclose(tau[k], tau_vp, rtol=1e-5, atol=1e-8)
    per_newton = np.abs(tau[k]).max() / np.linalg.norm(d.truth_force[k])
    d.threshold = np.array([100.0, 100.0, 100.0, 10.0, 10.0, 10.0])
    d.servo_threshold = np.full(6, 1.0 * per_newton)
    m = compute_metrics(d, desc=desc, plate_equivalent=W)
    assert m.plate_exceed_time == pytest.approx(1.13) and m.observer_delay_ms == pytest.approx(140.0)
    d.servo_threshold = np.zeros(6)                  # servo criterion off: nothing crosses
    assert math.isnan(compute_metrics(d, desc=desc, plate_equivalent=W).plate_exceed_time)


def test_stalled_seconds_count_the_contact_samples_with_a_servo_at_its_stall_torque():
    from hexa.report.collision_demo import SATURATION, stalled_seconds

    d = _case()
    tau = np.zeros((len(d.truth_t), 6))
    tau[(d.truth_t >= 1.5) & (d.truth_t < 1.7), 4] = -0.94          # servo 5 held at its stall torque for 0.2 s
    tau[(d.truth_t >= 2.5) & (d.truth_t < 2.6), 1] = 0.94           # after the contact: not counted
    tau[(d.truth_t >= 1.2) & (d.truth_t < 1.3), 2] = 0.94 * (SATURATION - 0.01)   # just below: not counted
    d.truth_tau = tau
    from hexa.robots.hexa_description import load_hexa

    desc = load_hexa()
    assert desc.torque_max == pytest.approx(0.94)
    assert compute_metrics(d, desc=desc).stall_s == pytest.approx(0.2)
    assert math.isnan(compute_metrics(_case()).stall_s)                  # no true torques: not measured
    assert math.isnan(stalled_seconds(d.truth_t, tau[:5], d.truth_t > 0, 0.94))   # misaligned: not measured
