"""Residual observer (hexa.dynamics.observer) on model-generated data with a known external wrench: convergence,
irregular timing, camera-rate poses, momentum vs direct form, detection events, calibration, reset, bad input."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hexa.dynamics.lagrange import (HexaDynamicParameters, chain_jacobian, inverse_dynamics, motion_from_plate)
from hexa.dynamics._kernel import SampleKernel
from hexa.dynamics.contact_map import plate_equivalent_wrench
from hexa.dynamics.observer import (CollisionDetector, ObserverConfig, ObserverError, ResidualObserver,
                                    momentum_residual_batch, servo_torque_residual)
from hexa.kinematics import hexa6rus as kin
from hexa.robots.hexa_description import load_hexa

DESC = load_hexa()
PRM = HexaDynamicParameters.from_description(DESC)
HOME = np.array([0.0, 0.0, -0.55, 0.0, 0.0, 0.0])
AMP = np.array([0.03, 0.02, 0.02, 0.2, 0.15, 0.1])
FREQ = np.array([2.0, 3.0, 1.3, 1.5, 2.5, 2.0])
W_EXT = np.array([1.5, -2.5, 3.0, 0.05, -0.1, 0.08])
T_ON = 0.8


def _data(t: np.ndarray, wrench_on: float = T_ON, tau_offset: np.ndarray | None = None) -> dict:
    """Samples of the model robot on a path with W_EXT applied from `wrench_on`: τ solves the dynamics exactly."""
    t = np.asarray(t, dtype=float)
    ph = FREQ * t[:, None]
    pose, pd, pdd = HOME + AMP * np.sin(ph), AMP * FREQ * np.cos(ph), -AMP * FREQ**2 * np.sin(ph)
    zeta = kin.inverse_kinematics_batch(DESC, pose)
    V = kin.twist_from_pose_rate(pose, pd)
    Vd = np.concatenate([pdd[:, :3], kin.angular_acceleration_zyx(pose[:, 3:], pd[:, 3:], pdd[:, 3:])], 1)
    s = motion_from_plate(PRM, zeta, pose, V, Vd)
    W0 = inverse_dynamics(PRM, s, np.zeros((t.size, 6))).wrench  # W(τ) = W0 − J_ζᵀ τ
    Wext = np.where((t >= wrench_on)[:, None], W_EXT, 0.0)
    J = chain_jacobian(PRM, s.zeta, s.p, s.R)
    tau = np.linalg.solve(np.swapaxes(J, 1, 2), (W0 - Wext)[..., None])[..., 0]
    if tau_offset is not None:
        tau = tau + tau_offset
    return {"t": t, "zeta": zeta, "zeta_dot": s.zeta_dot, "zeta_ddot": s.zeta_ddot, "tau": tau, "pose": pose,
            "wext": Wext}


T = np.arange(0, 1.6, 0.001)
DATA = _data(T)
K = 40.0
# plate axes only here; the servo-torque criterion has its own tests below
CFG = ObserverConfig(gains=(K,) * 6, thresholds=(1.0, 1.0, 1.0, 0.04, 0.04, 0.04), servo_thresholds=(0.0,) * 6,
                     min_duration=0.005)


def _run(obs: ResidualObserver, d: dict, pose_every: int = 1, rates: bool = True, accel: bool = False) -> np.ndarray:
    out = np.full((d["t"].size, 6), np.nan)
    for k, t in enumerate(d["t"]):
        pose = d["pose"][k] if pose_every == 1 else None
        if pose_every > 1 and k % pose_every == 0:
            obs.update_pose(t, d["pose"][k])
        res = obs.update_arm(t, d["zeta"][k], d["tau"][k], d["zeta_dot"][k] if rates else None, pose=pose,
                             zeta_ddot=d["zeta_ddot"][k] if accel else None)
        if res is not None:
            out[k] = res.wrench
    return out


def _expected(t: np.ndarray) -> np.ndarray:
    """First-order response of each axis to the step W_EXT at T_ON."""
    return np.where((t >= T_ON)[:, None], W_EXT * (1 - np.exp(-K * np.clip(t - T_ON, 0, None)))[:, None], 0.0)


def test_momentum_observer_follows_the_external_wrench_with_first_order_lag():
    r = _run(ResidualObserver(PRM, CFG), DATA)
    assert np.abs(r[T < T_ON]).max() < 1e-3  # free motion: nothing
    err = np.abs(r - _expected(T))[T > 0.01]
    assert err.max() < 0.05 * np.abs(W_EXT).max()  # the lag of eq 25, not a model error
    np.testing.assert_allclose(r[-1], W_EXT, rtol=2e-3, atol=1e-4)


def test_irregular_sample_spacing_and_camera_rate_poses():
    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.0004, 0.0016, size=1500))
    d = _data(t)
    obs = ResidualObserver(PRM, CFG)
    obs.update_pose(-0.05, d["pose"][0])
    r = _run(obs, d, pose_every=33)  # plate pose from "cameras" at ~30 Hz, tracked from ζ in between
    assert obs.rejected["pose_tracking"] == 0
    ok = np.isfinite(r[:, 0])
    late = ok & (t > T_ON + 0.2)
    np.testing.assert_allclose(r[late], np.broadcast_to(W_EXT, r[late].shape), rtol=0.01, atol=2e-3)
    assert np.abs(r[ok & (t < T_ON)]).max() < 2e-3


def test_rates_by_differencing_when_the_sample_carries_none():
    r = _run(ResidualObserver(PRM, CFG), DATA, rates=False)
    late = T > T_ON + 0.2
    np.testing.assert_allclose(r[late], np.broadcast_to(W_EXT, r[late].shape), rtol=0.02, atol=0.02)


def test_direct_form_agrees_with_momentum_form_on_noiseless_data():
    mom = _run(ResidualObserver(PRM, CFG), DATA)
    direct = _run(ResidualObserver(PRM, CFG, form="direct"), DATA, accel=True)
    sel = T > 0.05
    # both converge to the same wrench; they differ only by the discretisation of the lag (O(K·Δt) at the step)
    assert np.abs(mom[sel] - direct[sel]).max() < 0.05 * np.abs(W_EXT).max()
    np.testing.assert_allclose(direct[-1], mom[-1], rtol=1e-3, atol=1e-4)


def test_batch_matches_streaming_observer():
    obs = ResidualObserver(PRM, CFG)
    stream = _run(obs, DATA)
    batch = momentum_residual_batch(PRM, DATA["t"], DATA["zeta"], DATA["zeta_dot"], DATA["tau"], DATA["pose"], K)
    np.testing.assert_allclose(batch.wrench, stream, atol=1e-9)


def test_detection_start_and_end_events():
    obs = ResidualObserver(PRM, CFG)
    events = []
    d = _data(T, wrench_on=0.5)
    d["tau"] = d["tau"].copy()
    # remove the wrench again at 1.0 s
    d_off = _data(T, wrench_on=10.0)
    d["tau"][T >= 1.0] = d_off["tau"][T >= 1.0]
    for k, t in enumerate(T):
        res = obs.update_arm(t, d["zeta"][k], d["tau"][k], d["zeta_dot"][k], pose=d["pose"][k])
        events.extend(res.events)
    kinds = [e.kind for e in events]
    assert kinds == ["START", "END"]
    start, end = events
    assert start.id == end.id == 1
    assert 0.5 <= start.onset < 0.52 and start.time - start.onset == pytest.approx(CFG.min_duration, abs=1.5e-3)
    assert abs(start.value) > CFG.thresholds[start.axis]
    assert 1.0 < end.time < 1.2 and end.duration == pytest.approx(end.time - start.onset)
    ratio = np.abs(W_EXT) / np.asarray(CFG.thresholds)
    assert end.axis == int(np.argmax(ratio)) and end.peak == pytest.approx(abs(W_EXT[end.axis]), rel=0.01)


def test_detector_hysteresis_and_minimum_duration():
    cfg = ObserverConfig(thresholds=(2.0,) * 6, release_ratio=0.5, min_duration=0.01)
    det = CollisionDetector(cfg)
    ev = []
    t = 0.0
    # a 5 ms blip over threshold: too short, no event
    for v in [3.0] * 5 + [0.0] * 5:
        t += 0.001
        ev += det.update(t, np.array([v, 0, 0, 0, 0, 0]))[1]
    assert ev == []
    # sustained: START once; then wandering between 1.2 and 2.5 (above the 1.0 release level): no END
    for v in [3.0] * 20 + [1.2, 2.5] * 50:
        t += 0.001
        ev += det.update(t, np.array([0, -v, 0, 0, 0, 0]))[1]
    assert [e.kind for e in ev] == ["START"] and ev[0].axis == 1 and ev[0].value < 0
    for v in [0.5] * 9:
        t += 0.001
        ev += det.update(t, np.array([0, v, 0, 0, 0, 0]))[1]
    assert len(ev) == 1  # released for less than min_duration
    for v in [0.5] * 3:
        t += 0.001
        ev += det.update(t, np.array([0, v, 0, 0, 0, 0]))[1]
    assert [e.kind for e in ev] == ["START", "END"] and ev[1].peak == 3.0


def test_a_start_needs_one_channel_over_for_min_duration_not_spikes_passed_between_channels():
    """Short spikes that move from servo to servo (a model error at each new set-point) keep some channel over the
    threshold for longer than min_duration, but no channel for min_duration: no START. A push that keeps one
    channel over starts, with the onset and the axis of that channel, while another channel spikes beside it."""
    det = CollisionDetector(ObserverConfig(servo_thresholds=(0.3,) * 6, min_duration=0.005))
    zero, ev, t = np.zeros(6), [], 0.0
    for k in range(60):        # servo 1, 2, 3, 4, … over for 2 samples each, one after another
        t += 0.001
        servo = np.zeros(6)
        servo[(k // 2) % 6] = 0.5
        ev += det.update(t, zero, servo)[1]
    assert ev == []
    onset = t + 0.001
    for k in range(10):        # servo 3 held over; servo 6 spikes every other sample, higher
        t += 0.001
        ev += det.update(t, zero, np.array([0, 0, 0.4, 0, 0, 0.9 * (k % 2)]))[1]
    assert [e.kind for e in ev] == ["START"] and ev[0].axis_name == "servo3"
    assert ev[0].onset == pytest.approx(onset) and ev[0].time == pytest.approx(onset + 0.005)


def test_bad_input_is_rejected_counted_and_leaves_the_state_intact():
    clean = _run(ResidualObserver(PRM, CFG), DATA)
    obs = ResidualObserver(PRM, CFG)
    out = np.full((T.size, 6), np.nan)
    for k, t in enumerate(T):
        if k == 900:
            assert obs.update_arm(t + 0.0001, np.full(6, np.nan), DATA["tau"][k], DATA["zeta_dot"][k],
                                  pose=DATA["pose"][k]) is None
            assert obs.update_arm(t + 0.0002, DATA["zeta"][k], [np.inf] * 6, DATA["zeta_dot"][k],
                                  pose=DATA["pose"][k]) is None
            assert obs.update_arm(t - 0.5, DATA["zeta"][k], DATA["tau"][k], DATA["zeta_dot"][k],
                                  pose=DATA["pose"][k]) is None
            assert obs.update_arm(t, DATA["zeta"][k][:5], DATA["tau"][k], pose=DATA["pose"][k]) is None
            assert not obs.update_pose(t, [np.nan] * 6)
        res = obs.update_arm(t, DATA["zeta"][k], DATA["tau"][k], DATA["zeta_dot"][k], pose=DATA["pose"][k])
        out[k] = res.wrench
    assert obs.rejected["non_finite"] == 3 and obs.rejected["time_not_increasing"] == 1
    assert obs.rejected["bad_shape"] == 1
    # rejected samples (even those stamped after sample 900) never advance the clock: the run equals the clean one
    np.testing.assert_allclose(out, clean, atol=1e-12)


def test_gap_is_counted_and_integration_restarts_with_r_kept():
    cfg = ObserverConfig(gains=(K,) * 6, max_gap=0.02)
    obs = ResidualObserver(PRM, cfg)
    keep = (T < 1.2) | (T > 1.3)
    r_before = None
    for k in np.flatnonzero(keep):
        res = obs.update_arm(T[k], DATA["zeta"][k], DATA["tau"][k], DATA["zeta_dot"][k], pose=DATA["pose"][k])
        if T[k] < 1.2:
            r_before = res.wrench
        elif r_before is not None and T[k] > 1.3:
            np.testing.assert_allclose(res.wrench, r_before)  # first sample after the gap: no integration
            r_before = None
        last = res.wrench
    assert obs.rejected["gap"] == 1
    np.testing.assert_allclose(last, W_EXT, rtol=2e-3, atol=1e-4)


def test_a_run_over_the_threshold_does_not_span_a_gap_in_the_stream():
    """A residual over its threshold just before the stream stops (a quiet board) and again at the first sample
    after it: a run counted across the gap would START at once; it starts over after the gap and needs min_duration
    of samples there."""
    cfg = dataclasses.replace(CFG, min_duration=0.02, max_gap=0.05)
    d = _data(T, wrench_on=0.5)
    obs = ResidualObserver(PRM, cfg)
    k, events, first_over = 0, [], None
    while first_over is None:                    # up to the first sample over a threshold: a run begins
        res = obs.update_arm(T[k], d["zeta"][k], d["tau"][k], d["zeta_dot"][k], pose=d["pose"][k])
        assert res.events == ()
        if np.any(np.abs(res.wrench) > np.asarray(cfg.thresholds)):
            first_over = T[k]
        k += 1
    resume = int(np.searchsorted(T, first_over + 0.1))    # 100 ms without samples (max_gap 50 ms)
    for j in range(resume, T.size):
        res = obs.update_arm(T[j], d["zeta"][j], d["tau"][j], d["zeta_dot"][j], pose=d["pose"][j])
        events.extend((T[j], e) for e in res.events)
        if events:
            break
    assert obs.rejected["gap"] == 1
    t_start, start = events[0]
    assert start.kind == "START" and start.onset == pytest.approx(T[resume])
    assert t_start - T[resume] == pytest.approx(cfg.min_duration, abs=1.5e-3)


def test_detector_break_runs_restarts_the_runs_to_start_and_to_end_but_keeps_a_collision():
    det = CollisionDetector(ObserverConfig(thresholds=(2.0,) * 6, servo_thresholds=(0.0,) * 6, min_duration=0.01))
    over, under = np.array([3.0, 0, 0, 0, 0, 0]), np.zeros(6)
    ev = list(det.update(0.000, over)[1]) + list(det.update(0.005, over)[1])
    det.break_runs()
    ev += det.update(0.200, over)[1]             # 200 ms after the run began, but its first sample after the gap
    assert ev == []
    ev += det.update(0.205, over)[1]
    ev += det.update(0.210, over)[1]
    assert [e.kind for e in ev] == ["START"] and ev[0].onset == pytest.approx(0.2)
    ev += det.update(0.215, under)[1]
    det.break_runs()
    assert det.active                            # the collision in progress stays active
    ev += det.update(0.400, under)[1]
    assert [e.kind for e in ev] == ["START"]
    ev += det.update(0.410, under)[1]
    assert [e.kind for e in ev] == ["START", "END"]


def test_calibration_at_rest_removes_a_torque_offset_and_reset_rezeros():
    t = np.arange(0, 1.0, 0.001)
    offset = np.array([0.02, -0.01, 0.015, 0.0, 0.01, -0.02])  # current-sensor offsets (N·m at the horns)
    d = _data(t, wrench_on=10.0, tau_offset=offset)
    # robot at rest at the first pose: hold ζ, zero rates
    obs = ResidualObserver(PRM, CFG)
    rest_pose, rest_zeta = d["pose"][0], d["zeta"][0]
    s = motion_from_plate(PRM, rest_zeta[None], rest_pose[None], np.zeros((1, 6)), np.zeros((1, 6)))
    J = chain_jacobian(PRM, s.zeta, s.p, s.R)[0]
    tau_rest = np.linalg.solve(J.T, inverse_dynamics(PRM, s, np.zeros((1, 6))).wrench[0]) + offset
    obs.start_calibration()
    for k in range(300):
        obs.update_arm(k * 0.001, rest_zeta, tau_rest, np.zeros(6), pose=rest_pose)
    before = obs.r.copy()
    assert np.abs(before).max() > 0.05  # the offset shows as a wrench
    off = obs.finish_calibration()
    assert np.abs(obs.r).max() < 1e-5 and np.abs(off).max() > 0.05
    for k in range(300, 600):
        res = obs.update_arm(k * 0.001, rest_zeta, tau_rest, np.zeros(6), pose=rest_pose)
    assert np.abs(res.wrench).max() < 1e-6
    obs.r[:] = 5.0
    obs.reset()
    assert np.all(obs.r == 0.0)
    res = obs.update_arm(0.7, rest_zeta, tau_rest, np.zeros(6), pose=rest_pose)
    assert np.abs(res.wrench).max() < 1e-9 and not res.in_collision


def test_rejects_bad_configuration_naming_it():
    with pytest.raises(ObserverError, match="gains"):
        ObserverConfig(gains=(1.0, 2.0))
    with pytest.raises(ObserverError, match="thresholds"):
        ObserverConfig(thresholds=(2.0, 2.0, 2.0, 0.2, 0.2, -1.0))
    with pytest.raises(ObserverError, match="form"):
        ResidualObserver(PRM, form="magic")
    for bad in ((0.3,) * 5, (0.3, 0.3, 0.3, 0.3, 0.3, -0.1), (0.3, 0.3, float("nan"), 0.3, 0.3, 0.3)):
        with pytest.raises(ObserverError, match="servo_thresholds"):
            ObserverConfig(servo_thresholds=bad)


def _geometry(pose: np.ndarray) -> tuple[list, np.ndarray]:
    from hexa.dynamics.lagrange import pose_to_position_rotation

    zeta = kin.inverse_kinematics(DESC, pose)
    p, R = pose_to_position_rotation(pose[None])
    geo, _ = SampleKernel(PRM).geometry(zeta.tolist(), p[0].tolist(), R[0].ravel().tolist())
    return geo, zeta


@pytest.mark.parametrize("chain", [1, 4, 6])
def test_an_arm_force_as_servo_torques_is_its_moment_about_that_servo_axis(chain):
    """τ_r = J_ζ⁻ᵀ W of an arm contact's plate-equivalent wrench (hexa.dynamics.contact_map, point velocities by
    finite differences) is the force's moment about the arm's motor axis on that servo and zero on the others."""
    pose = np.array([0.02, -0.015, -0.56, 0.05, -0.04, 0.1])
    geo, zeta = _geometry(pose)
    k = chain - 1
    axis = np.array([-math.sin(PRM.alpha[k]), math.cos(PRM.alpha[k]), 0.0])
    u = np.array([-math.cos(PRM.alpha[k]) * math.cos(zeta[k]), -math.sin(PRM.alpha[k]) * math.cos(zeta[k]),
                  math.sin(zeta[k])])
    D = PRM.A[k] + 0.6 * PRM.l_a * u + 0.01 * axis      # on the arm, 10 mm off its centre line
    F = np.array([2.0, -3.0, 1.5])
    tau = servo_torque_residual(geo, plate_equivalent_wrench(DESC, pose, "arm", chain, D, F))
    moment = float(np.cross(D - PRM.A[k], F) @ axis)
    assert abs(moment) > 0.05
    assert tau[k] == pytest.approx(moment, rel=1e-4)
    assert np.abs(np.delete(tau, k)).max() < 1e-4 * abs(moment)


def test_servo_torque_criterion_detects_what_the_plate_axes_do_not():
    """0.5 N·m more on servo 3 from 0.5 s to 1.0 s (a torque the model does not explain, as an arm contact gives):
    τ_r converges to it, the plate thresholds (set out of reach) stay quiet, a START on servo3 then an END; with the
    servo thresholds at 0 the same data raise nothing."""
    offset = np.zeros((T.size, 6))
    offset[(T >= 0.5) & (T < 1.0), 2] = 0.5
    d = _data(T, wrench_on=10.0, tau_offset=offset)
    base = dict(gains=(K,) * 6, thresholds=(1e3, 1e3, 1e3, 1e2, 1e2, 1e2), min_duration=0.005)
    obs = ResidualObserver(PRM, ObserverConfig(**base, servo_thresholds=(0.35,) * 6))
    quiet = ResidualObserver(PRM, ObserverConfig(**base, servo_thresholds=(0.0,) * 6))
    events, tau_r, quiet_events = [], np.full((T.size, 6), np.nan), []
    for k, t in enumerate(T):
        args = (t, d["zeta"][k], d["tau"][k], d["zeta_dot"][k])
        out = obs.update_arm(*args, pose=d["pose"][k])
        events += out.events
        tau_r[k] = out.servo_torque
        quiet_events += quiet.update_arm(*args, pose=d["pose"][k]).events
        assert not out.over.any()
    # the measured torque exceeds the model by 0.5 N·m: the residual (external torque) is −0.5 N·m on servo 3
    late = (T > 0.7) & (T < 1.0)
    np.testing.assert_allclose(tau_r[late], np.broadcast_to([0, 0, -0.5, 0, 0, 0], tau_r[late].shape), atol=2e-3)
    assert np.abs(tau_r[T < 0.5]).max() < 1e-3
    assert [e.kind for e in events] == ["START", "END"] and quiet_events == []
    start, end = events
    assert start.axis == 8 and start.axis_name == "servo3" and start.value < -0.35
    # the first-order lag of eq 25 crosses 0.35 of a 0.5 N·m step after ln(0.5/0.15)/K
    assert start.onset == pytest.approx(0.5 + math.log(0.5 / 0.15) / K, abs=2e-3)
    assert end.axis == 8 and end.peak == pytest.approx(0.5, rel=0.01) and 1.0 < end.time < 1.1


def test_detector_servo_channels_have_the_same_hysteresis_and_can_be_switched_off():
    det = CollisionDetector(ObserverConfig(servo_thresholds=(0.3, 0.3, 0.3, 0.0, 0.3, 0.3), min_duration=0.005))
    zero, ev, t = np.zeros(6), [], 0.0
    for v in [5.0] * 20:  # servo 4 is switched off: any value passes
        t += 0.001
        ev += det.update(t, zero, np.array([0, 0, 0, v, 0, 0]))[1]
    for v in [0.0, np.nan] * 10:  # NaN (a singular J_ζ) is not a detection either
        t += 0.001
        ev += det.update(t, zero, np.array([0, 0, 0, 0, v, 0]))[1]
    assert ev == []
    for v in [0.4] * 10 + [0.2] * 10:  # over, then between release (0.15) and threshold: START, no END
        t += 0.001
        ev += det.update(t, zero, np.array([0, v, 0, 0, 0, 0]))[1]
    assert [e.kind for e in ev] == ["START"] and ev[0].axis_name == "servo2"
    for v in [0.1] * 10:
        t += 0.001
        ev += det.update(t, zero, np.array([0, v, 0, 0, 0, 0]))[1]
    assert [e.kind for e in ev] == ["START", "END"] and ev[1].peak == pytest.approx(0.4)
    det.set_servo_thresholds([0.0] * 6)
    for _ in range(20):
        t += 0.001
        ev += det.update(t, zero, np.full(6, 9.0))[1]
    assert len(ev) == 2
    with pytest.raises(ObserverError, match="servo_thresholds"):
        det.set_servo_thresholds([0.3] * 5)


def test_arm_samples_before_any_pose_are_rejected_as_no_pose():
    obs = ResidualObserver(PRM, CFG)
    assert obs.update_arm(0.0, DATA["zeta"][0], DATA["tau"][0], DATA["zeta_dot"][0]) is None
    assert obs.rejected["no_pose"] == 1
    assert math.isinf(-obs._last_t)


def test_vectorized_lag_equals_the_sample_by_sample_recursion():
    """The batch lag (blockwise closed form) is the recursion r_k = a_k r_{k−1} + (1 − a_k) w_k, even with large gains,
    irregular spacing and long runs."""
    from hexa.dynamics.observer import _first_order_lag

    rng = np.random.default_rng(7)
    n = 20000
    dt = rng.uniform(0.0002, 0.003, n - 1)
    dt[5000] = 0.5  # a long interval
    w = rng.normal(size=(n, 6)) + np.where(np.arange(n) > 10000, 3.0, 0.0)[:, None]
    K = np.array([25.0, 5.0, 400.0, 1.0, 60.0, 25.0])
    r = _first_order_lag(w, dt, K)
    a = np.exp(-dt[:, None] * K)
    ref = np.zeros_like(w)
    rk = np.zeros(6)
    for k in range(n - 1):
        rk = a[k] * rk + (1 - a[k]) * w[k + 1]
        ref[k + 1] = rk
    np.testing.assert_allclose(r, ref, atol=1e-10)


def test_one_sample_time_far_off_is_rejected_and_a_clock_restart_is_adopted_with_detection_and_camera_anew():
    obs = ResidualObserver(PRM, dataclasses.replace(CFG, adopt_after=3))
    d = DATA
    for k in range(100):
        obs.update_arm(T[k], d["zeta"][k], d["tau"][k], d["zeta_dot"][k], pose=d["pose"][k])
    assert obs.update_pose(T[99], d["pose"][99])
    assert obs.update_arm(1e6, d["zeta"][100], d["tau"][100], d["zeta_dot"][100]) is None      # one far ahead
    assert obs.update_arm(-5.0, d["zeta"][100], d["tau"][100], d["zeta_dot"][100]) is None     # one far back
    assert obs.update_arm(T[100], d["zeta"][100], d["tau"][100], d["zeta_dot"][100]) is not None   # goes on
    assert obs.rejected["time_jump"] == 1 and obs.rejected["time_not_increasing"] == 1
    # the clock restarts near 0 (a restarted simulator): adopted at the 3rd sample, r and the detector start over
    out = [obs.update_arm(T[k] - 0.09, d["zeta"][k], d["tau"][k], d["zeta_dot"][k]) for k in range(101, 104)]
    assert out[:2] == [None, None] and out[2] is not None and obs.clock_jumps == 1
    assert np.allclose(out[2].wrench, 0.0, atol=1e-6)
    assert obs.update_pose(T[103] - 0.09, d["pose"][103])       # camera poses on the new time axis are taken
