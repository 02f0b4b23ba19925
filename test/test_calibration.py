"""`hexa calibrate` core (ROS-free): excitation design, regressor, identification of known perturbations, overlay."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hexa.calibration.excitation import BOUNDS, SLOW_SPEED, Excitation, ExcitationSettings, design_excitation
from hexa.calibration.identify import identify, prepare
from hexa.calibration.overlay import ServoTorqueModel, write_overlay
from hexa.calibration.recording import Recording, simulate_recording
from hexa.calibration.regressor import free_motion_torques, regressor, sym_from_params
from hexa.calibration.validate import compare
from hexa.dynamics.lagrange import HexaDynamicParameters
from hexa.robots.hexa_description import calibration_summary, load_hexa
from hexa.robots.schema import RobotDescriptionError
from hexa.servo_motion import servo_motion

DESC = load_hexa()
PRM = HexaDynamicParameters.from_description(DESC)


@pytest.fixture(scope="module")
def excitation() -> Excitation:
    return design_excitation(DESC, ExcitationSettings(period=4.0, harmonics=5, cycles=7, iterations=3, seed=1))


def _motion(e: Excitation, t: np.ndarray, prm=PRM):
    pose, vel, acc = e.evaluate(t)
    return pose, servo_motion(DESC, pose, vel, acc, prm)


def test_regressor_times_the_model_parameters_is_the_free_motion_torque(excitation):
    t = np.linspace(0.0, excitation.period, 40)
    _, state = _motion(excitation, t)
    reg = regressor(PRM, state)
    model = reg.torques(sym_from_params(PRM), np.full(6, PRM.J_a), np.full(6, PRM.m_a * PRM.s_a), np.zeros(6),
                        np.zeros(6))
    assert np.allclose(model, free_motion_torques(PRM, state), atol=1e-9)
    assert np.abs(model).max() > 0.05          # the arms carry the robot: not a trivially zero torque


def test_excitation_is_periodic_starts_at_rest_at_home_and_keeps_the_limits(excitation, tmp_path):
    e = excitation
    assert e.feasible and math.isfinite(e.condition)
    pose0, vel0, _ = e.evaluate(np.array([0.0]))
    assert np.allclose(pose0[0], DESC.home_pose) and np.allclose(vel0[0], 0.0, atol=1e-12)
    t = np.linspace(0.0, e.period, 200)
    pose, _, _ = e.evaluate(t)
    assert np.allclose(e.evaluate(t + e.period)[0], pose)
    assert np.all(np.abs(pose - e.q0) <= np.asarray(BOUNDS) + 1e-9)
    assert e.peak_speed <= 0.5 * DESC.speed_max and e.peak_torque <= 0.6 * DESC.torque_max
    path = e.write(tmp_path / "exc.csv")
    from hexa.trajectories import load_pose_file

    traj, duration = load_pose_file(path)
    assert duration == pytest.approx(e.duration)
    assert np.allclose(traj(1.234)[0], e.evaluate(1.234)[0], atol=2e-4)    # the file the trajectory node plays
    back = Excitation.read_design(path)
    assert back is not None and np.allclose(back.a, e.a) and back.period == e.period
    # the design's slow fraction is the time its slowest servo spends below SLOW_SPEED
    pose, vel, acc = e.evaluate(np.arange(64) * e.period / 64)
    zd = servo_motion(DESC, pose, vel, acc, PRM).zeta_dot
    assert e.slow == pytest.approx(np.mean(np.abs(zd) < SLOW_SPEED, axis=0).max())


def test_currents_locked_to_the_servo_frame_alias_its_ripple_into_a_speed_proportional_error(excitation):
    """The realistic robot's servos take a set-point per 20 ms pulse frame; their torque ripples at 50 Hz. Currents
    sampled at 200 Hz sit at four fixed phases of the frame and, low-passed, miss the mean torque by an error
    proportional to the arm's speed; at the calibration's 143 Hz the phases sweep the frame and the error vanishes.
    One 1 kHz recording, subsampled as each rate's recorder samples it."""
    from hexa.calibration.identify import _lowpass, frame_locked

    duration = 2.0
    rec, _ = simulate_recording(lambda t: excitation.evaluate(t)[0], duration, seed=3, desc=DESC, lead_in=0.5,
                                current_rate_hz=1000.0)
    t, cur = rec.t_current, rec.currents
    inner = (t > 0.8) & (t < t[-1] - 0.3)
    ref = _lowpass(cur, 1000.0)
    speed = np.gradient(_lowpass(rec.setpoints, 1000.0), t, axis=0)
    slopes = {}
    for rate, step in ((200.0, 5), (143.0, 7)):
        ts = t[::step]
        assert frame_locked(ts) == (rate == 200.0)
        low = _lowpass(cur[::step], 1000.0 / step)
        err = np.stack([np.interp(t, ts, low[:, k]) for k in range(6)], 1) - ref
        slopes[rate] = np.array([np.polyfit(speed[inner, k], err[inner, k], 1)[0] for k in range(6)])
    # A·s/rad: at 200 Hz ≥ 0.04 (0.02 N·m·s/rad, five times the truth's viscous friction) on some servo
    assert np.abs(slopes[200.0]).max() > 0.04, slopes
    assert np.abs(slopes[143.0]).max() < 0.25 * np.abs(slopes[200.0]).max(), slopes


def _truth(rng: np.random.Generator) -> dict:
    """Known perturbations of the kind the realistic robot has (hexa.sim.realism.Tolerances)."""
    c = rng.uniform(-0.005, 0.005, 3)
    I_c = np.diag(np.diag(PRM.I_p) * rng.uniform(0.8, 1.2, 3))
    prm = dataclasses.replace(PRM, m_p=PRM.m_p * 1.15, c_p=c, I_p=I_c)
    return {"prm": prm, "K": DESC.K_t * rng.uniform(0.9, 1.1, 6), "b": rng.normal(0.0, 0.02, 6),
            "fc": DESC.torque_max * rng.uniform(0.02, 0.07, 6), "fv": rng.uniform(0.0, 0.005, 6),
            "J": PRM.J_a + rng.uniform(1e-3, 3e-3, 6), "ms": PRM.m_a * PRM.s_a * rng.uniform(0.8, 1.2, 6),
            "horn": rng.uniform(-0.03, 0.03, 6)}


def _record(e: Excitation, truth: dict, payload: float, rng: np.random.Generator) -> Recording:
    """A run of `e` by the model with the truth's parameters: currents (25 Hz, ACS712 noise and 10-bit steps), set-
    points (the horn offset and the servo's compliance) and camera poses (30 Hz, 0.5 mm / 0.1° noise), 1 s at rest
    before and after."""
    lead = 1.0
    tc = np.arange(0.0, e.duration + 2 * lead, 0.04)
    pose, state = _motion(e, np.clip(tc - lead, 0.0, e.duration), truth["prm"])
    th = sym_from_params(truth["prm"]) + np.array([payload] + [0.0] * 12)
    tau = regressor(PRM, state).torques(th, truth["J"], truth["ms"], truth["fc"], truth["fv"])
    amps = tau / truth["K"] + truth["b"] + rng.normal(0.0, 0.013, tau.shape)
    amps = np.round(amps / 0.0264) * 0.0264                        # the ADC's steps (26 mA)
    setpoints = state.zeta - truth["horn"] + tau / 40.0            # kp = 40 N·m/rad
    tp = np.arange(0.0, tc[-1], 1.0 / 30.0)
    poses = np.stack([np.interp(tp, tc, pose[:, k]) for k in range(6)], 1)
    poses += np.concatenate([rng.normal(0, 5e-4, (tp.size, 3)), rng.normal(0, math.radians(0.1), (tp.size, 3))], 1)
    return Recording(tc, amps, tc, setpoints, tp, poses, payload=payload, source=f"model run payload {payload}")


def test_identify_recovers_known_perturbations_within_the_targets(excitation, tmp_path):
    rng = np.random.default_rng(5)
    truth = _truth(rng)
    runs = [_record(excitation, truth, m, rng) for m in (0.0, 0.25)]    # 2 × 28 s: 56 s of excitation
    cal = identify([prepare(r, DESC, period=excitation.period) for r in runs], DESC)
    assert cal.scale == "payload"
    assert np.all(np.abs(cal.k_t / truth["K"] - 1.0) <= 0.03), cal.k_t / truth["K"]
    assert np.all(np.abs(cal.coulomb / truth["fc"] - 1.0) <= 0.20), cal.coulomb / truth["fc"]
    assert abs(cal.plate_mass / truth["prm"].m_p - 1.0) <= 0.05
    assert np.all(np.abs(cal.horn_offset - truth["horn"]) <= 0.005)
    # a zero offset is loosely separated from the arm's first moment (both make a nearly constant torque over the
    # arm's travel; the prior keeps it near the sensor's): only a loose bound
    assert np.all(np.abs(cal.current_offset - truth["b"]) <= 0.08)
    # the confidence intervals are of the size of the errors (all within twice the 95 % half-width)
    assert np.all(np.abs(cal.k_t - truth["K"]) <= 2.0 * cal.ci95["k_t"])
    # the overlay: written, loaded by the one description loader, used by the nodes' torque model
    path = write_overlay(tmp_path / "calibration.yaml", cal, DESC)
    cdesc = load_hexa(path)
    assert "calibration overlay" in calibration_summary(cdesc) and str(path) in calibration_summary(cdesc)
    assert cdesc.plate.mass == pytest.approx(cal.plate_mass) and cdesc.K_t == pytest.approx(cal.k_t.mean())
    stm = ServoTorqueModel(cdesc)
    assert np.allclose(stm.from_currents(np.ones(6)), cal.k_t * (1.0 - cal.current_offset))
    from hexa.protocol.driver_core import servo_calibrations_from_description

    refs = [s.zeta_ref for s in servo_calibrations_from_description(cdesc)]
    assert np.allclose(np.array(refs) - DESC.zeta_center, cal.horn_offset)
    # held-out motion (the paper's circle) by the same robot: the residual falls on every plate axis
    from hexa import trajectories

    circle = Excitation(q0=np.zeros(6), a=np.zeros((6, 1)), b=np.zeros((6, 1)), period=5.0, cycles=2)
    circle.evaluate = lambda t: trajectories.circle(np.asarray(t))         # same interface as an excitation
    held_out = _record(circle, truth, 0.0, rng)
    cmp = compare(held_out, DESC, cdesc)
    rms = cmp.rms()["axes"]
    assert all(r["after"] <= r["before"] / 3.0 for r in rms.values()), rms


def test_overlay_errors_name_the_file(tmp_path):
    own = tmp_path / "self.yaml"
    own.write_text("calibration_of: self.yaml\n", encoding="utf-8")
    with pytest.raises(RobotDescriptionError, match="names itself"):
        load_hexa(own)
    missing = tmp_path / "o.yaml"
    missing.write_text("calibration_of: nowhere.yaml\n", encoding="utf-8")
    with pytest.raises(RobotDescriptionError, match="nowhere.yaml"):
        load_hexa(missing)
    assert "no calibration overlay" in calibration_summary(DESC)
    assert ServoTorqueModel(DESC).from_currents(np.ones(6)) == pytest.approx(np.full(6, DESC.K_t))



def test_prepared_currents_of_the_ideal_robot_are_its_model_torques_with_no_speed_term(excitation, monkeypatch):
    """The simulated robot that is its model (`ideal`: the description's masses and K_t, the 20 ms pulse frame),
    exact camera poses and currents: the prepared currents are the model's free-motion torques over K_t, with no part
    proportional to the arms' speed. The servos' frame ripple is removed at the currents' own rate before they are
    resampled onto the analysis grid (100 Hz, a multiple of the 50 Hz frame): resampled first, the ripple aliases to
    −0.013 N·m·s/rad here, which biases K_t and the plate mass. Every regressor column gets the currents' low-pass
    (parallel filtering): with it on the currents alone, a motion with harmonics near the cut-off misses by 1.3 %."""
    import hexa.sim.boards as boards
    from hexa.sim.realism import RealismConfig

    monkeypatch.setattr(boards, "camera_pose", lambda pose, rng: np.asarray(pose, dtype=float).copy())
    monkeypatch.setattr(boards.CurrentReadout, "amps", lambda self, tau, rng: np.asarray(tau) / float(DESC.K_t))
    rec, _ = simulate_recording(lambda t: excitation.evaluate(np.array([t]))[0][0], 3 * excitation.period, seed=0,
                                realism=RealismConfig.ideal(), desc=DESC)
    for harmonics in (15, 25):       # 25: harmonics past the low-pass's cut-off, which both sides must see alike
        mo = prepare(rec, DESC, period=excitation.period, harmonics=harmonics)
        model = mo.reg.torques(sym_from_params(PRM), np.full(6, PRM.J_a), np.full(6, PRM.m_a * PRM.s_a),
                               np.zeros(6), np.zeros(6))
        err = mo.currents * DESC.K_t - model
        zd = mo.zeta_dot
        slope = (err * zd).sum(0) / (zd * zd).sum(0)                 # N·m·s/rad per servo
        assert np.all(np.abs(slope) < 0.002), (harmonics, slope)
        rel = np.sqrt(np.mean(err ** 2)) / np.sqrt(np.mean(model ** 2))
        assert rel < 0.008, (harmonics, rel)


def test_pseudo_inertia_maps_are_inverse_and_their_cholesky_jacobian_is_exact():
    from hexa.calibration.identify import _TRIL, _plate_of_cholesky, plate_of_pseudo_inertia, pseudo_inertia

    theta = sym_from_params(PRM)[:10]
    assert np.allclose(plate_of_pseudo_inertia(pseudo_inertia(theta)), theta)
    # the nominal plate is a 10 mm disc: its second moment across the plate, m t²/12, is J's smallest eigenvalue
    assert np.linalg.eigvalsh(pseudo_inertia(theta))[0] == pytest.approx(PRM.m_p * 0.01 ** 2 / 12, rel=0.05)
    ell = np.linalg.cholesky(pseudo_inertia(theta))[_TRIL] * np.random.default_rng(1).uniform(0.8, 1.2, 10)
    th0, D = _plate_of_cholesky(ell)
    for k in range(10):
        d = np.zeros(10)
        d[k] = 1e-6 * max(abs(ell[k]), 1e-3)
        assert np.allclose((_plate_of_cholesky(ell + d)[0] - th0) / d[k], D[:, k], atol=1e-6 * np.abs(D).max())


def test_identified_flat_plate_is_a_valid_body_with_the_constraint_active_and_no_correction(excitation):
    """A flat plate (the truth's COM inertia on the triangle inequality's edge, as the Hexa's disc) from 12 s of
    noisy excitation: the inertia's errors (tens of %) put the least squares' optimum past the edge — the solution
    stops on it (J ≻ 0 active: an unconstrained solve ends outside, and projecting its inertia afterwards would
    leave the rest of the fit unadjusted) and is a valid body as it comes out of the pseudo-inertia solve (J = L Lᵀ)."""
    from hexa.calibration.identify import pseudo_inertia

    rng = np.random.default_rng(6)
    short = dataclasses.replace(excitation, cycles=3)
    truth = _truth(rng)
    I_flat = np.diag([8.0e-4, 1.0e-3, 1.8e-3])                 # I_zz = I_xx + I_yy: a plane lamina
    truth["prm"] = dataclasses.replace(truth["prm"], I_p=I_flat)
    runs = [_record(short, truth, m, rng) for m in (0.0, 0.25)]
    cal = identify([prepare(r, DESC, period=short.period) for r in runs], DESC)
    assert "pseudo-inertia" in cal.consistency                 # the constraint J ≻ 0 is active …
    w = np.linalg.eigvalsh(cal.plate_inertia)                  # … and the solution is valid as it is:
    assert cal.plate_mass > 0 and w[0] >= 0 and w[0] + w[1] >= w[2] * (1 - 1e-9)   # the triangle inequality
    c, Ic = cal.plate_com, cal.plate_inertia
    theta = np.concatenate([[cal.plate_mass], cal.plate_mass * c, [0.0] * 6])
    I_P = Ic + cal.plate_mass * (float(c @ c) * np.eye(3) - np.outer(c, c))
    theta[4:] = [I_P[0, 0], I_P[1, 1], I_P[2, 2], I_P[0, 1], I_P[0, 2], I_P[1, 2]]
    assert np.linalg.eigvalsh(pseudo_inertia(theta))[0] > -1e-12
    assert abs(cal.plate_mass / truth["prm"].m_p - 1.0) <= 0.05
