"""The CUSUM collision detector on the motion-whitened residual (hexa.dynamics.cusum): its sums, its scale, its events,
and its place in the CollisionMonitor."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.dynamics.cusum import CusumConfig, CusumDetector, make_detector
from hexa.dynamics.observer import CollisionDetector, ObserverConfig, ObserverError

DT = 0.005


def feed(det, values, t0=0.0, servo=None):
    """Feed plate-axis fx values at 200 Hz; returns [(t, event)]."""
    out = []
    for k, v in enumerate(values):
        t = t0 + k * DT
        for e in det.update(t, np.array([v, 0, 0, 0, 0, 0.0]), servo)[1]:
            out.append((t, e))
    return out


def test_a_residual_below_the_drift_never_alarms_however_long():
    det = CusumDetector(ObserverConfig(), CusumConfig(drift=0.5, alarm=0.01))
    assert feed(det, [0.99] * 2000) == []   # 0.495 threshold units: under ν for 10 s
    assert not det.active and det.count == 0


def test_a_step_alarms_once_its_excess_sums_to_h_and_dates_its_onset_at_the_step():
    cfg = CusumConfig(drift=0.5, alarm=0.01)
    det = CusumDetector(ObserverConfig(), cfg)
    # 4 N on fx = 2 threshold units: (2 − 0.5)·Δt per sample, so h = 0.01 takes ceil(0.01 / 0.0075) = 2 steps
    ev = feed(det, [0.0] * 100 + [4.0] * 10)
    assert len(ev) == 1
    t, e = ev[0]
    assert e.kind == "START" and e.axis_name == "fx"
    assert t == pytest.approx(101 * DT)
    assert e.onset == pytest.approx(99 * DT)   # the last sample at which the sum was 0
    # a weaker step (1.2 threshold units) needs longer: 0.01 / (0.7·0.005) → 3 steps
    det2 = CusumDetector(ObserverConfig(), cfg)
    (t2, _), = feed(det2, [0.0] * 100 + [2.4] * 10)
    assert t2 == pytest.approx(102 * DT)


def test_a_strong_contact_is_detected_sooner_than_by_the_fixed_threshold_with_min_duration():
    ramp = np.r_[np.zeros(50), np.linspace(0.0, 6.0, 60)]   # 0 → 6 N over 0.3 s
    t_cusum = feed(CusumDetector(ObserverConfig(), CusumConfig()), ramp)[0][0]
    t_fixed = feed(CollisionDetector(ObserverConfig()), ramp)[0][0]
    assert t_cusum < t_fixed


def test_the_scale_widens_with_velocity_and_acceleration_and_is_the_threshold_at_rest():
    det = CusumDetector(ObserverConfig(), CusumConfig(velocity_gain=0.5, accel_gain=0.1, accel_tau=1e-3))
    det.motion(0.0, np.zeros(6))
    assert det.uncertainty == 1.0
    np.testing.assert_allclose(det.thresholds, ObserverConfig().thresholds)
    det.motion(0.01, np.array([0.0, 2.0, 0, 0, 0, 0]))   # ‖ζ̇‖∞ = 2 rad/s, ζ̈ = 200 rad/s² (filter τ ≪ Δt)
    assert det.uncertainty == pytest.approx(1.0 + 0.5 * 2.0 + 0.1 * 200.0)
    np.testing.assert_allclose(det.scaled_thresholds()[6:],
                               np.array(ObserverConfig().servo_thresholds) * det.uncertainty)
    np.testing.assert_allclose(det.servo_thresholds, ObserverConfig().servo_thresholds)   # the configured ones
    # the same residual that alarms at rest does not alarm while moving that fast
    moving = feed(det, [4.0] * 20)
    assert moving == []
    det.motion(1.0, np.zeros(6))
    det.motion(1.1, np.zeros(6))
    assert det.uncertainty == pytest.approx(1.0)


def test_end_after_release_for_min_duration_and_the_sums_restart():
    det = CusumDetector(ObserverConfig(min_duration=0.02), CusumConfig())
    ev = feed(det, [5.0] * 20 + [0.0] * 10 + [5.0] * 20)
    kinds = [e.kind for _, e in ev]
    assert kinds == ["START", "END", "START"]
    assert ev[1][1].duration > 0 and ev[2][1].id == 2
    assert ev[1][0] - 20 * DT == pytest.approx(0.02, abs=DT + 1e-9)


def test_servo_torques_alarm_and_nan_servo_torques_are_not_checked():
    det = CusumDetector(ObserverConfig(), CusumConfig())
    nan = np.full(6, np.nan)
    assert feed(det, [0.0] * 20, servo=nan) == []
    servo = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])   # 1 N·m on servo 3, threshold 0.35
    (_, e), = feed(det, [0.0] * 5, servo=servo)
    assert e.axis_name == "servo3"
    off = CusumDetector(ObserverConfig(servo_thresholds=(0.35, 0.35, 0.0, 0.35, 0.35, 0.35)), CusumConfig())
    assert feed(off, [0.0] * 50, servo=servo) == []   # servo 3's check is off


@pytest.mark.parametrize("field,value", [("drift", -0.1), ("alarm", 0.0), ("velocity_gain", float("nan")),
                                         ("accel_tau", 0.0)])
def test_bad_cusum_settings_are_refused_naming_them(field, value):
    with pytest.raises(ObserverError, match=field):
        CusumConfig(**{field: value})
    with pytest.raises(ObserverError, match="detector"):
        make_detector("bayes", ObserverConfig())


def test_the_monitor_runs_the_chosen_detector_and_takes_its_settings_at_run_time():
    from hexa.dynamics.monitor import CollisionMonitor
    from hexa.robots.hexa_description import load_hexa

    desc = load_hexa()
    mon = CollisionMonitor(desc, detector="cusum", cusum=CusumConfig(alarm=0.02))
    assert isinstance(mon.observer.detector, CusumDetector)
    mon.configure(cusum=CusumConfig(alarm=0.03, velocity_gain=0.2))
    assert mon.observer.detector.cusum.alarm == 0.03
    mon.configure(ObserverConfig(thresholds=(3.0, 3.0, 3.0, 0.3, 0.3, 0.3)))
    np.testing.assert_allclose(mon.observer.detector.thresholds[:3], 3.0)
    plain = CollisionMonitor(desc)
    assert isinstance(plain.observer.detector, CollisionDetector)
    with pytest.raises(ValueError, match="cusum"):
        plain.configure(cusum=CusumConfig())


def test_the_baseline_learns_a_slow_model_error_but_not_a_contact_held_for_seconds():
    det = CusumDetector(ObserverConfig(), CusumConfig(baseline_tau=0.25))
    bias = list(np.linspace(0.0, 1.8, 600))   # 0 → 0.9 r_low on fx over 3 s: model error, learnt
    assert feed(det, bias) == []
    held = feed(det, [1.8 + 3.0] * 1000, t0=3.0)   # a 3 N push on top, held for 5 s
    assert [e.kind for _, e in held] == ["START"]
    assert det.active
    without = CusumDetector(ObserverConfig(), CusumConfig(baseline_tau=0.0))
    assert [e.kind for _, e in feed(without, bias)] == ["START"]   # the same drift alarms without a baseline


def test_a_gap_integrates_nothing_and_the_sums_start_over_after_it():
    """Across a gap (`break_runs`, the observer's max_gap) no step integrates the gap's length and the evidence
    before it is dropped: a weak residual that would alarm summed over both sides does not, and one that stays
    alarms with its onset at the first sample after the gap."""
    cfg = CusumConfig(drift=0.5, alarm=0.01, baseline_tau=0.0)
    det = CusumDetector(ObserverConfig(), cfg)
    # 1.6 N on fx = 0.8 threshold units: (0.8 − 0.5)·Δt = 0.0015 per sample, so h = 0.01 takes 7 samples
    assert feed(det, [1.6] * 4) == []
    det.break_runs()
    t0 = 1.0
    assert feed(det, [1.6] * 6, t0=t0) == []      # 4 + 6 samples would have summed past h; 6 after the gap do not
    ev = feed(det, [1.6] * 2, t0=t0 + 6 * DT)
    assert [e.kind for _t, e in ev] == ["START"]
    assert ev[0][0] == pytest.approx(t0 + 7 * DT) and ev[0][1].onset == pytest.approx(t0)
    # without the gap's reset, the first sample after it would have integrated MAX_STEP of evidence
    plain = CusumDetector(ObserverConfig(), cfg)
    feed(plain, [1.6] * 4)
    assert [e.kind for _t, e in feed(plain, [1.6], t0=t0)] == ["START"]
