"""hexa.sim.realism: the truth drawn per seed within its tolerances, the servo mechanics (friction, dead band, gear
play), the current sensor's noise, host jitter — and the simulator built from them."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.protocol.sensor_model import CurrentSensorModel
from hexa.robots.hexa_description import load_hexa
from hexa.sim.realism import (ACS712_05B, JitterConfig, RealismConfig, RobotTruth, ServoMechanics, Tolerances,
                              adc_counts, draw_truth, nominal_truth)


def _valid_inertia(I: np.ndarray) -> bool:
    w = np.linalg.eigvalsh(I)
    return bool(np.all(w > 0) and w[0] + w[1] >= w[2] * (1 - 1e-9))


def _principal(I: np.ndarray) -> np.ndarray:
    return np.sort(np.linalg.eigvalsh(I))


def test_truth_differs_from_the_description_within_the_tolerances_and_is_valid():
    desc = load_hexa()
    tol = Tolerances()
    nominal = nominal_truth(desc)
    seen_mass_ratio = []
    for seed in range(40):
        t = draw_truth(desc, seed)
        for link, nom in [(t.plate, nominal.plate), *[(a, nominal.arms[0]) for a in t.arms],
                          *[(r, nominal.rods[0]) for r in t.rods]]:
            ratio = link.mass / nom.mass
            seen_mass_ratio.append(ratio)
            assert link.mass > 0 and 1 - tol.mass - 1e-12 <= ratio <= 1 + tol.mass + 1e-12
            assert np.all(np.abs(link.com - nom.com) <= tol.com + 1e-12)
            assert _valid_inertia(link.inertia)
            r = _principal(link.inertia) / _principal(nom.inertia)
            assert np.all(r >= 1 - tol.inertia - 1e-9) and np.all(r <= 1 + tol.inertia + 1e-9), r
        assert np.all(np.abs(t.k_t / desc.K_t - 1) <= tol.k_t + 1e-12)
        assert np.all(t.coulomb + t.viscous * desc.speed_max <= 0.10 * desc.torque_max + 1e-12)
        assert np.all(t.coulomb > 0) and np.all(t.rotor_inertia > 0) and np.all(t.backlash > 0)
        assert np.all((t.sensor_gain >= 180 / 185 - 1e-12) & (t.sensor_gain <= 190 / 185 + 1e-12))
    # the errors use their range, not a sliver of it
    assert min(seen_mass_ratio) < 0.85 and max(seen_mass_ratio) > 1.15


def test_truth_is_reproducible_per_seed_and_differs_between_seeds():
    desc = load_hexa()
    a, b, c = draw_truth(desc, 7), draw_truth(desc, 7), draw_truth(desc, 8)
    assert a.as_dict() == b.as_dict()
    assert a.as_dict() != c.as_dict()
    assert len({arm.mass for arm in a.arms}) == 6          # each arm its own


def test_simulator_builds_the_world_from_the_truth_and_the_ideal_one_from_the_description():
    from hexa.sim import Simulator

    desc = load_hexa()
    real = Simulator(cameras=False, seed=5, realism=RealismConfig(truth=True), settle=0.0)
    ideal = Simulator(cameras=False, seed=5, settle=0.0)
    truth = draw_truth(desc, 5)
    assert isinstance(real.truth, RobotTruth) and real.truth.as_dict() == truth.as_dict()
    assert ideal.truth is None
    m = real.model
    for i in range(6):
        assert m.body_mass[m.body(f"arm_{i + 1}").id] == pytest.approx(truth.arms[i].mass, rel=1e-6)
        assert m.body_mass[m.body(f"rod_{i + 1}").id] == pytest.approx(truth.rods[i].mass, rel=1e-6)
        j = m.joint(f"arm_{i + 1}").id
        assert m.dof_frictionloss[m.jnt_dofadr[j]] == pytest.approx(truth.coulomb[i], rel=1e-6)
        assert m.dof_armature[m.jnt_dofadr[j]] == pytest.approx(truth.rotor_inertia[i], rel=1e-6)
        assert ideal.model.body_mass[m.body(f"arm_{i + 1}").id] == pytest.approx(desc.arm.mass)
    assert m.body_mass[m.body("plate").id] == pytest.approx(truth.plate.mass, rel=1e-6)
    # the Mega's currents follow the truth's K_t, sensor gain and offset
    tau = np.full(6, 0.3)
    assert np.allclose(real.motor_currents(tau), tau / truth.k_t * truth.sensor_gain + truth.current_offset)
    assert np.allclose(ideal.motor_currents(tau), tau / desc.K_t)


def _run_torques(tol: Tolerances, seconds: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    from hexa.sim import Simulator

    sim = Simulator(trajectory="circle", cameras=False, seed=2, realism=RealismConfig(truth=True, tolerances=tol))
    tau, vel = [], []
    while sim.time < seconds:
        sim.step(5)
        s = sim.state()
        tau.append(s.tau)
        vel.append(s.zeta_dot)
    return np.array(tau), np.array(vel)


def test_coulomb_friction_opposes_the_motion():
    none = dict(mass=0.0, com=0.0, inertia=0.0, k_t=0.0, viscous=(0.0, 0.0), rotor_inertia=(0.0, 0.0))
    f = 0.05
    tau_f, vel = _run_torques(Tolerances(**none, coulomb=(f, f)))
    tau_0, vel_0 = _run_torques(Tolerances(**none, coulomb=(0.0, 0.0)))
    moving = np.abs(vel) > 0.1
    assert moving.sum() > 200
    extra = (tau_f - tau_0)[moving] * np.sign(vel[moving])   # the motor pays for the friction against the motion
    stall = load_hexa().torque_max
    assert np.median(extra) == pytest.approx(f * stall, rel=0.3)
    assert np.mean(extra > 0) > 0.9


def test_dead_band_gives_no_torque_inside_it():
    t = nominal_truth(load_hexa())
    t = RobotTruth(**{**t.__dict__, "deadband": np.full(6, 0.01)})
    mech = ServoMechanics(t, kp=40.0, kv=0.6, torque_max=0.94)
    z = np.zeros(6)
    e = np.array([0.004, -0.004, 0.006, -0.006, 0.02, 0.0])
    tau = mech.motor_torque(e, z, z)
    assert np.allclose(tau[:2], 0.0) and np.allclose(tau[5], 0.0)
    assert tau[2] == pytest.approx(40.0 * 0.001) and tau[3] == pytest.approx(-40.0 * 0.001)
    assert tau[4] == pytest.approx(40.0 * 0.015)


def test_backlash_transmits_nothing_while_the_motor_crosses_the_gear_play():
    t = nominal_truth(load_hexa())
    play = np.radians(1.0)
    t = RobotTruth(**{**t.__dict__, "backlash": np.full(6, play), "rotor_inertia": np.full(6, 2e-3)})
    mech = ServoMechanics(t, kp=40.0, kv=0.6, torque_max=0.94)
    dt, acc = 1e-3, np.zeros(6)
    tau = np.full(6, 0.2)
    out = [mech.step(tau, acc, dt) for _ in range(50)]
    assert np.all(out[-1] == tau) and np.allclose(mech.gap, play / 2)        # engaged on the + stop
    rev = -tau
    crossing = 0
    for _ in range(200):
        o = mech.step(rev, acc, dt)
        assert np.all(np.abs(mech.gap) <= play / 2 + 1e-12)
        if np.all(o == 0.0):
            crossing += 1
        else:
            break
    # crossing the full play from rest at τ/J_r: t = sqrt(2·play·J_r/τ) ≈ 19 ms
    expected = np.sqrt(2 * play * 2e-3 / 0.2) / dt
    assert crossing == pytest.approx(expected, abs=2)
    assert np.all(o == rev) and np.allclose(mech.gap, -play / 2)


def test_adc_noise_of_the_acs712_preset_has_the_datasheet_spread():
    cfg = RealismConfig.realistic()
    sigma_v = ACS712_05B["noise_pp"] / 6
    assert cfg.current_noise_counts == pytest.approx(sigma_v / (5.0 / 1024))
    sensor = CurrentSensorModel()
    rng = np.random.default_rng(0)
    amps = np.full((20000, 6), 0.5)
    counts = adc_counts(sensor, amps, cfg.current_noise_counts, rng)
    i = sensor.current_from_counts(counts)
    lsb = sensor.amps_per_count
    expected = np.sqrt((cfg.current_noise_counts * lsb) ** 2 + lsb ** 2 / 12)
    assert i.std() == pytest.approx(expected, rel=0.1)
    assert abs(i.mean() - 0.5) < 0.6 * lsb
    quiet = sensor.current_from_counts(adc_counts(sensor, amps[:100], 0.0, rng))
    assert np.ptp(quiet) == 0.0


def test_host_jitter_draws_late_never_early_within_its_caps():
    j = RealismConfig.realistic().jitter
    rng = np.random.default_rng(1)
    cmd = np.array([j.command_delay(rng) for _ in range(5000)])
    smp = np.array([j.sample_delay(rng) for _ in range(5000)])
    assert cmd.min() >= 0 and cmd.max() <= j.command_max and cmd.mean() == pytest.approx(j.command_mean, rel=0.15)
    assert smp.min() >= 0 and smp.max() <= 6 * j.sample_sigma + j.spike_max
    assert JitterConfig().command_delay(rng) == 0.0 and JitterConfig().sample_delay(rng) == 0.0


def test_realism_presets_by_name():
    assert RealismConfig.named("ideal") == RealismConfig()
    r = RealismConfig.named("realistic")
    assert r.truth and r.servo_mechanics and r.frame_period == 0.02
    with pytest.raises(ValueError, match="realism must be one of"):
        RealismConfig.named("kind")
