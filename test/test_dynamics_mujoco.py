"""Validation of the Hexa dynamics against MuJoCo (the simulator, built from the same YAML): free motion on the paper's
three trajectories, known forces on the plate, rods and arms of several chains, momentum vs direct form, and the
streaming observer with camera-rate poses."""
from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from hexa.dynamics.identification import identify_contact_force  # noqa: E402
from hexa.dynamics.lagrange import HexaDynamicParameters, motion_from_joint_rates  # noqa: E402
from hexa.dynamics.observer import ObserverConfig, ResidualObserver, momentum_residual_batch  # noqa: E402
from hexa.dynamics.validation import (CONTACT_CASES, R_LOW, _trajectory, contact_figures,  # noqa: E402
                                      free_motion_figures, simulate)
from hexa.robots.hexa_description import load_hexa  # noqa: E402

DESC = load_hexa()
PRM = HexaDynamicParameters.from_description(DESC)


@pytest.fixture(scope="module", params=["circle", "helix", "ellipse"])
def free_run(request):
    return request.param, simulate(_trajectory(request.param), 2.5, desc=DESC)


def test_free_motion_residual_stays_below_r_low(free_run):
    name, run = free_run
    f = free_motion_figures(run, PRM)
    peak, rms = np.asarray(f["peak"]), np.asarray(f["rms"])
    print(f"\n{name}: peak {np.round(peak, 4)} rms {np.round(rms, 4)}")
    assert np.all(peak[:3] < R_LOW) and np.all(peak[3:] < 0.1 * R_LOW)
    # the model is the simulator's physics: what is left is discretisation and constraint softness
    assert np.all(peak[:3] < 0.05) and np.all(rms[:3] < 0.02)
    assert np.abs(run.zeta_dot).max() > 0.1  # it did move


def test_free_motion_residual_with_adc_quantized_currents_stays_below_r_low(free_run):
    """The same run with τ through the current sensor's 10-bit ADC (11.9 mN·m steps): still far below r_low."""
    from hexa.dynamics.validation import free_motion_figures_adc

    _, run = free_run
    peak = np.asarray(free_motion_figures_adc(run, PRM)["peak"])
    assert np.all(peak[:3] < 0.25 * R_LOW) and np.all(peak[3:] < 0.02)


def test_momentum_and_direct_forms_agree_on_noiseless_data(free_run):
    _, run = free_run
    f = free_motion_figures(run, PRM)
    assert np.all(np.asarray(f["direct_minus_momentum_peak"])[:3] < 0.2)
    assert np.all(np.asarray(f["direct_minus_momentum_peak"])[3:] < 0.02)


@pytest.fixture(scope="module", params=range(len(CONTACT_CASES)),
                ids=[f"{c['link']}{c['chain']}" for c in CONTACT_CASES])
def contact_run(request):
    case = dict(CONTACT_CASES[request.param], t_on=0.8)
    return case, simulate(_trajectory("circle"), 1.5, contact=case, desc=DESC)


def test_known_force_is_seen_by_the_residual_and_identified(contact_run):
    case, run = contact_run
    f = contact_figures(run, PRM, case["link"], case["chain"])
    err = np.asarray(f["identified_error"])
    print(f"\n{case['link']} {case['chain']}: truth {f['truth']} identified {np.round(f['identified'], 3)} "
          f"error {np.round(err, 3)} rank {f['rank']}")
    assert np.abs(err).max() < 0.1  # N, on forces of 2–3.6 N
    if case["link"] == "plate":
        assert f["rank"] == 3 and f["observable"]
        res_err = np.asarray(f["residual_error_peak"])
        assert np.all(res_err[:3] < 0.05) and np.all(res_err[3:] < 0.01)  # steady residual = applied wrench
    elif case["link"] == "rod":
        assert f["rank"] == 3 and f["observable"] and f["condition"] < 10
        assert np.linalg.norm(f["residual_steady"][:3]) > 0.5  # a rod contact moves the plate residual too
    else:
        # an arm contact: only the moment about the motor axis reaches the robot; the rest goes into the bearing
        assert f["rank"] == 1 and not f["observable"]
        assert np.linalg.norm(f["truth_observable_part"]) > 0.3


def test_tangential_force_on_an_arm_is_fully_identified():
    """A force along the arm's direction of motion (⟂ arm and motor axis) is the observable one: recovered whole."""
    from hexa.dynamics.validation import contact_point
    from hexa.kinematics import hexa6rus as kin

    chain = 2
    run0 = simulate(_trajectory("circle"), 0.05, desc=DESC)
    B = kin.elbows(DESC, run0.zeta[-1])[chain - 1]
    A = np.asarray(DESC.A)[chain - 1]
    e = np.array([-np.sin(DESC.alpha[chain - 1]), np.cos(DESC.alpha[chain - 1]), 0.0])
    tangential = np.cross(e, (B - A) / np.linalg.norm(B - A))
    case = {"link": "arm", "chain": chain, "fraction": 0.7, "force": 2.5 * tangential, "t_on": 0.5}
    run = simulate(_trajectory("circle"), 1.0, contact=case, desc=DESC)
    k = int(np.searchsorted(run.t, 0.52))  # identification is instantaneous: look soon after the onset
    ms = motion_from_joint_rates(PRM, run.zeta[k], run.zeta_dot[k], run.pose[k], run.zeta_ddot[k])
    est = identify_contact_force(PRM, ms, run.tau[k], "arm", chain, run.point[k])
    assert contact_point(DESC, run.zeta[k], run.pose[k], "arm", chain, 0.7) == pytest.approx(run.point[k], abs=1e-4)
    # the force keeps its direction in base while the arm turns: compare with what is observable at that instant
    n = est.unobservable_directions
    seen = run.force[k] - n.T @ (n @ run.force[k])
    assert est.rank == 1 and np.linalg.norm(seen) > 2.45
    np.testing.assert_allclose(est.force, seen, atol=0.05)


def test_streaming_observer_with_camera_rate_poses_on_simulated_data():
    """1 kHz arm samples (ζ, ζ̇, τ), plate pose only every 33 ms: tracks the batch residual and raises START/END."""
    case = dict(CONTACT_CASES[0], t_on=0.6)
    run = simulate(_trajectory("ellipse"), 1.4, contact=case, desc=DESC)
    cfg = ObserverConfig(gains=(25.0,) * 6)
    obs = ResidualObserver(PRM, cfg)
    out = np.full((run.t.size, 6), np.nan)
    events = []
    for k, t in enumerate(run.t):
        if k % 33 == 0:
            obs.update_pose(t, run.pose[k])
        res = obs.update_arm(t, run.zeta[k], run.tau[k], run.zeta_dot[k])
        if res is not None:
            out[k] = res.wrench
            events += res.events
    assert sum(obs.rejected.values()) == 0
    batch = momentum_residual_batch(PRM, run.t, run.zeta, run.zeta_dot, run.tau, run.pose, 25.0)
    assert np.abs(out[1:] - batch.wrench[1:]).max() < 0.01
    starts = [e for e in events if e.kind == "START"]
    assert len(starts) == 1 and 0.6 <= starts[0].onset < 0.65
    assert not any(e.kind == "END" for e in events)  # the force stays on to the end of the run


def test_servo_armature_and_friction_of_the_description_are_modelled():
    """With rotor inertia and viscous friction in `sim.servo`, the simulator and the model read the same YAML keys."""
    import yaml

    from hexa.robots.hexa_description import DEFAULT_PATH, parse_hexa

    data = yaml.safe_load(DEFAULT_PATH.read_text())
    data["sim"]["servo"].update(armature=3e-4, damping=0.02)
    desc = parse_hexa(data)
    prm = HexaDynamicParameters.from_description(desc)
    assert prm.arm_damping == 0.02 and prm.J_a == pytest.approx(PRM.J_a + 3e-4)
    run = simulate(_trajectory("circle"), 1.5, desc=desc)
    peak = np.asarray(free_motion_figures(run, prm)["peak"])
    assert np.all(peak[:3] < 0.05)
    # the model without them would be wrong by far more (sanity: the terms matter)
    wrong = np.asarray(free_motion_figures(run, PRM)["peak"])
    assert wrong[:3].max() > 5 * peak[:3].max()


def test_pose_driven_observer_with_noisy_camera_poses_and_commanded_angles():
    """The paper's set-up: currents at 1 kHz, plate pose from the cameras at 30 Hz with 1 mm / 5 mrad noise, ζ only
    as the commanded angle (a seed). No false alarm in free motion; the plate contact is detected at its onset."""
    case = dict(CONTACT_CASES[0], t_on=1.5)
    run = simulate(_trajectory("ellipse"), 2.3, contact=case, desc=DESC)
    from hexa.dynamics.validation import pose_driven_residual

    out, events, obs = pose_driven_residual(run, PRM, pose_noise=(1e-3, 5e-3), seed=0)
    commanded = run.zeta + 0.01
    assert sum(obs.rejected.values()) == 0
    free = (run.t > 0.3) & (run.t < case["t_on"])
    peak = np.nanmax(np.abs(out[free]), axis=0)
    print(f"\npose-driven free peak {np.round(peak, 3)}")
    assert np.all(peak[:3] < 0.25 * R_LOW)
    on = run.t > case["t_on"] + 0.3
    W = np.concatenate([run.force, np.cross(run.point - run.pose[:, :3], run.force)], axis=1)
    assert np.nanmax(np.abs(out[on] - W[on])[:, :3]) < 0.4
    assert [e.kind for e in events] == ["START"] and case["t_on"] <= events[0].onset < case["t_on"] + 0.05
    # an arm sample long after the last camera pose is stale
    assert obs.update_arm(run.t[-1] + 0.5, commanded[-1], run.tau[-1]) is None
    assert obs.rejected["pose_stale"] == 1
