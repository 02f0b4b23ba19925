"""Simulator model: MJCF from the description, closed loops, exact state, free-motion tracking, scripted collisions."""
from __future__ import annotations

import math

import importlib.util

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

mujoco = pytest.importorskip("mujoco")

from hexa.robots.hexa_description import load_hexa  # noqa: E402
from hexa.sim import Simulator, SimulatorError, build_mjcf  # noqa: E402
from hexa.sim.config import SimConfigError, parse_sim_config  # noqa: E402
from hexa.sim.scenarios import ScenarioError, draw_collision, load_scenario, parse_scenario  # noqa: E402

needs_trajectories = pytest.mark.skipif(importlib.util.find_spec("hexa.trajectories") is None,
                                        reason="hexa.trajectories not installed")

# Free-motion tracking tolerance (documented in docs/simulator.md): position loop of a hobby servo (kp = 40 N·m/rad)
# lags the paper's trajectories by < 1 deg at the arms, i.e. a few mm at the plate.
TRACK_POS_TOL = 0.008      # m
TRACK_ANG_TOL = np.radians(1.5)


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


def test_mjcf_is_assembled_closed_at_the_home_pose_with_zeta_as_joint_angles(desc):
    from hexa.kinematics import hexa6rus as kin

    model = mujoco.MjModel.from_xml_string(build_mjcf(desc))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert model.nu == 6 and model.neq == 6
    zeta = np.array([data.joint(f"arm_{i}").qpos[0] for i in range(1, 7)])
    np.testing.assert_allclose(zeta, kin.inverse_kinematics(desc, desc.home_pose), atol=1e-9)
    tips = np.array([data.site(f"rod_tip_{i}").xpos for i in range(1, 7)])
    joints = np.array([data.site(f"plate_joint_{i}").xpos for i in range(1, 7)])
    np.testing.assert_allclose(tips, joints, atol=1e-7)
    np.testing.assert_allclose(joints, kin.plate_joints(desc, desc.home_pose), atol=1e-7)
    assert model.body("plate").mass[0] == pytest.approx(desc.plate.mass)


def test_state_is_one_consistent_instant_and_holds_the_loop_closed(desc):
    sim = Simulator(desc, cameras=False)
    sim.step(200)
    s = sim.state()
    assert s.time == pytest.approx(sim.time - sim.timestep)
    # hold still under gravity: accelerations and rates ~0, torques carry the weight
    assert np.abs(s.zeta_dot).max() < 1e-3 and np.abs(s.zeta_ddot).max() < 0.05
    assert 0.02 < np.abs(s.tau).max() < desc.torque_max
    from hexa.kinematics import hexa6rus as kin

    assert np.abs(kin.loop_closure_residual(desc, s.pose, s.zeta)).max() < 1e-4


def test_external_force_on_the_plate_is_reported_as_ground_truth_and_moves_the_plate_down(desc):
    sim = Simulator(desc, cameras=False)
    p0 = sim.state().pose
    point = p0[:3] + np.array([0.0, 0.0, 0.0])
    sim.apply_external_force("plate", 0, point, [0.0, 0.0, -4.0])
    sim.step(300)
    g = sim.ground_truth()
    assert g.link == "plate" and g.in_contact
    np.testing.assert_allclose(g.force, [0, 0, -4.0])
    assert np.linalg.norm(g.point - sim.state().pose[:3]) < 1e-9   # the point moves with the plate
    assert sim.state().pose[2] < p0[2] - 1e-4
    sim.clear_external_force()
    sim.step(1)
    assert not sim.ground_truth().in_contact
    with pytest.raises(SimulatorError, match="chain"):
        sim.apply_external_force("arm", 7, point, [1.0, 0, 0])
    with pytest.raises(SimulatorError, match="link"):
        sim.apply_external_force("wheel", 1, point, [1.0, 0, 0])


def test_servo_targets_are_reached_at_the_speed_limit(desc):
    sim = Simulator(desc, cameras=False)
    z0 = sim.state().zeta
    target = z0 + 0.1
    sim.set_servo_targets(target)
    sim.step(5)
    commanded = sim.state().targets
    assert np.all(commanded - z0 <= desc.speed_max * 6 * sim.timestep + 1e-12)
    sim.step(600)
    np.testing.assert_allclose(sim.state().zeta, target, atol=0.02)
    with pytest.raises(SimulatorError, match="six finite"):
        sim.set_servo_targets([0.0, np.nan, 0, 0, 0, 0])


def test_servos_take_a_new_target_only_at_their_pulse_in_the_boards_frame(desc):
    """With the servo board's pulse frame simulated (sim.servo.frame_period 0.02; off by default) each servo gets a
    new set-point only at the end of its pulse, once per 20 ms frame, one servo after the other (firmware
    uno_servo): the newest target when the board read its width — at the start of the previous servo's slot, for
    servo 1 just before the frame — so a target that arrives after that read waits a frame."""
    assert Simulator(desc, cameras=False).config.servo.frame_period == 0.0     # default: set-points at once
    sim = Simulator(desc, cameras=False, seed=4, servo_frame_period=0.02)
    z0 = sim.state().targets.copy()
    sim.set_servo_targets(z0 + 0.05)
    sim.step(1)
    sim.set_servo_targets(z0 - 0.05)            # replaces it 1 ms later, before any pulse (the seed's phase)
    first_move = np.full(6, np.nan)
    t0 = sim.time
    for _ in range(60):
        sim.step(1)
        moved = (np.abs(sim.state().targets - z0) > 1e-12) & np.isnan(first_move)
        first_move[moved] = sim.time - t0
    # at most a frame plus the slot between the read and the pulse's end (1 ms steps)
    assert np.all(np.isfinite(first_move)) and np.all(first_move <= 0.02 + 0.003 + 0.001), first_move
    steps = np.diff(first_move[1:])             # servos 2-6: one pulse after the other, 1.5 ms apart
    assert np.all((steps > 0.0) & (steps < 0.0025)), first_move
    # servo 1 reads before the frame: its first move is a whole frame after its pulse's slot, or before servo 2's
    assert first_move[0] < first_move[1] or first_move[0] > 0.02, first_move
    assert np.all(sim.state().targets < z0)     # only the second target ever reached the servos
    changes = []                                # a new target every 1 ms: servo 1 takes one per frame
    for k in range(100):
        sim.set_servo_targets(z0 + 0.0005 * k)
        before = sim._setpoints[0]
        sim.step(1)
        if sim._setpoints[0] != before:
            changes.append(sim.time)
    np.testing.assert_allclose(np.diff(changes), 0.02, atol=1e-9)
    instant = Simulator(desc, cameras=False, seed=4, servo_frame_period=0.0)   # set-points at once
    instant.set_servo_targets(z0 + 0.05)
    instant.step(1)
    assert np.all(instant.state().targets > z0)


@needs_trajectories
@pytest.mark.parametrize("name", ["circle", "helix", "ellipse"])
def test_free_motion_tracks_the_papers_trajectories_within_tolerance(desc, name):
    from hexa import trajectories

    sim = Simulator(desc, trajectory=name, cameras=False)
    sim.run_until(5.0)                                     # one full period of eqs 37, 40, 41 (0.4π rad/s)
    log = sim.truth_log()
    ref = np.asarray(trajectories.TRAJECTORIES[name](log["time"])[0])
    assert np.all(log["link"] == 255)
    pos_err = np.linalg.norm(log["plate_pose"][:, :3] - ref[:, :3], axis=1)
    ang_err = np.abs(log["plate_pose"][:, 3:] - ref[:, 3:])
    assert pos_err.max() < TRACK_POS_TOL
    assert ang_err.max() < TRACK_ANG_TOL
    assert pos_err.max() > 1e-4                           # a real servo loop lags: not a kinematic replay


@needs_trajectories
@pytest.mark.parametrize("case,seed", [("plate", 0), ("arm", 0), ("rod", 0), ("plate", 7), ("arm", 6), ("rod", 4),
                                       ("rod", 9)])
def test_scripted_collision_contacts_the_intended_link_with_a_peak_in_range(desc, case, seed):
    from hexa import trajectories

    spec = load_scenario(case)
    sim = Simulator(desc, scenario=case, cameras=False, seed=seed, randomize=seed > 0)
    c = sim.collision
    sim.run_until(c.end_time + 1.0)
    log = sim.truth_log()
    f = np.linalg.norm(log["force"], axis=1)
    touching = f > 0
    assert touching.any()
    codes = {"plate": 0, "arm": 1, "rod": 2}
    assert set(log["link"][touching].tolist()) == {codes[case]}
    assert set(log["chain"][touching].tolist()) == {c.chain}
    assert c.chain in spec.chains
    t_on = log["time"][touching][0]
    assert abs(t_on - c.onset) <= 2 * sim.timestep
    assert spec.onset.lo - 1e-9 <= c.onset <= spec.onset.hi + 1e-9
    k = int(np.argmax(f))
    assert spec.peak_force.lo - 1e-6 <= f[k] <= spec.peak_force.hi + 1e-6
    assert abs(log["time"][k] - c.peak_time) <= 2 * sim.timestep
    assert 0.3 <= c.peak_time - c.onset <= 0.5
    assert not touching[-1]                                # released
    ref = np.asarray(trajectories.TRAJECTORIES[c.trajectory](log["time"][-1])[0])
    assert np.linalg.norm(log["plate_pose"][-1, :3] - ref[:3]) < TRACK_POS_TOL   # back on the path 1 s later


def test_scenario_draws_are_deterministic_for_a_seed_and_vary_across_seeds():
    spec = load_scenario("rod")
    a = draw_collision(spec, np.random.default_rng(3))
    b = draw_collision(spec, np.random.default_rng(3))
    others = {draw_collision(spec, np.random.default_rng(s)).position for s in range(10)}
    assert a == b and len(others) > 5
    nominal = draw_collision(spec)
    assert nominal.onset == spec.onset.nominal and nominal.chain == spec.chains[0]


def test_bad_scenarios_and_sections_name_the_key():
    with pytest.raises(ScenarioError, match="link"):
        parse_scenario({"name": "x", "trajectory": "circle", "link": "wheel", "chains": [1]})
    with pytest.raises(ScenarioError, match="chains"):
        parse_scenario({"name": "x", "trajectory": "circle", "link": "arm", "chains": [9]})
    with pytest.raises(ScenarioError, match="not found"):
        load_scenario("nonexistent_case")
    with pytest.raises(SimConfigError, match="cameras"):
        parse_sim_config({"markers": {}, "appearance": {}, "sim": {}})


def test_physics_is_deterministic_for_a_seed(desc):
    logs = []
    for _ in range(2):
        sim = Simulator(desc, cameras=False, seed=4)
        sim.apply_external_force("rod", 2, sim.data.site("rod_tip_2").xpos.copy(), [1.0, -2.0, 0.5])
        sim.step(150)
        logs.append(sim.truth_log())
    for key in logs[0]:
        np.testing.assert_array_equal(logs[0][key], logs[1][key])


def test_external_force_is_exactly_mj_applyFT_at_the_point(desc):
    """The scripted/manual wrench equals MuJoCo's own point-force application (same trajectory to 1e-12)."""
    a = Simulator(desc, cameras=False, seed=0)
    b = Simulator(desc, cameras=False, seed=0)
    body = b.model.body("rod_3").id
    mujoco.mj_kinematics(b.model, b.data)
    R0, x0 = b.data.xmat[body].reshape(3, 3).copy(), b.data.xpos[body].copy()
    local = np.array([0.3, 0.004, -0.002])
    f = np.array([1.5, -2.0, 0.7])
    a.apply_external_force("rod", 3, x0 + R0 @ local, f)
    for _ in range(200):
        a.step(1)
        # b: same servo commands, force applied through mj_applyFT at the moving point into qfrc_applied
        m, d = b.model, b.data
        mujoco.mj_step1(m, d)
        step = b._omega_max * b.timestep
        d.ctrl[:] = d.ctrl + np.clip(b._targets - d.ctrl, -step, step)
        p = d.xpos[body] + d.xmat[body].reshape(3, 3) @ local
        d.qfrc_applied[:] = 0.0
        mujoco.mj_applyFT(m, d, f, np.zeros(3), p, body, d.qfrc_applied)
        mujoco.mj_step2(m, d)
    np.testing.assert_allclose(a.data.qpos, b.data.qpos, atol=1e-12)
    np.testing.assert_allclose(a.ground_truth().point, p, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), case=st.sampled_from(["plate", "arm", "rod"]),
       t=st.floats(0.0, 10.0, allow_nan=False))
def test_drawn_collisions_stay_in_their_ranges_and_the_force_profile_is_bounded(seed, case, t):
    spec = load_scenario(case)
    c = draw_collision(spec, np.random.default_rng(seed))
    for name in ("onset", "rise_time", "release_time", "peak_force", "position", "elevation"):
        r = getattr(spec, name)
        assert r.lo - 1e-12 <= getattr(c, name) <= r.hi + 1e-12, name
    assert c.chain in spec.chains
    f = c.force_magnitude(t)
    assert 0.0 <= f <= c.peak_force + 1e-12
    if t < c.onset or t >= c.end_time:
        assert f == 0.0
    assert c.force_magnitude(c.peak_time) == pytest.approx(c.peak_force)
    d = c.object_distance(t)
    assert d is None or 0.0 <= d <= c.approach_distance + 1e-12
    if c.onset <= t <= c.end_time:
        assert d == 0.0


@needs_trajectories
def test_lead_in_holds_the_start_pose_then_shifts_trajectory_and_collision(desc):
    sim = Simulator(desc, scenario="arm", cameras=False, lead_in=1.0)
    assert sim.collision.onset == pytest.approx(load_scenario("arm").onset.nominal + 1.0)
    z0 = sim.state().zeta
    sim.run_until(0.9)
    assert np.abs(sim.state().zeta - z0).max() < 2e-3            # at rest during the lead-in
    sim.run_until(sim.collision.onset + 0.1)
    log = sim.truth_log()
    assert log["time"][np.argmax(np.linalg.norm(log["force"], axis=1) > 0)] == pytest.approx(
        sim.collision.onset, abs=2e-3)
    with pytest.raises(SimulatorError, match="lead_in"):
        Simulator(desc, cameras=False, lead_in=-1.0)


def test_a_late_trajectory_start_moves_the_scripted_collision_once_and_never_after_its_approach(desc):
    onset = load_scenario("plate").onset.nominal + 1.0
    sim = Simulator(desc, scenario="plate", cameras=False, lead_in=1.0, drive="external")
    sim.run_until(0.9)
    assert sim.start_scenario_at(1.812) == pytest.approx(0.812) and sim.scenario_shift == pytest.approx(0.812)
    assert sim.collision.onset == pytest.approx(onset + 0.812)
    assert sim.start_scenario_at(2.5) is None and sim.collision.onset == pytest.approx(onset + 0.812)   # once
    sim.run_until(sim.collision.onset + 0.05)
    log = sim.truth_log()
    assert log["time"][np.argmax(np.linalg.norm(log["force"], axis=1) > 0)] == pytest.approx(onset + 0.812, abs=2e-3)
    late = Simulator(desc, scenario="plate", cameras=False, lead_in=1.0, drive="external")
    late.run_until(late.collision.onset - late.collision.approach_time + 0.01)   # the object is on its way: too late
    assert late.start_scenario_at(onset) is None and late.collision.onset == pytest.approx(onset)
    with pytest.raises(SimulatorError, match="finite"):
        late.start_scenario_at(math.nan)
    free = Simulator(desc, cameras=False, trajectory="circle", drive="external")
    assert free.start_scenario_at(1.0) is None                   # no scripted collision


@needs_trajectories
def test_plate_twist_and_arm_rates_match_finite_differences_of_the_pose(desc):
    from hexa.kinematics import hexa6rus as kin

    sim = Simulator(desc, trajectory="helix", cameras=False)
    sim.run_until(1.0)
    s0 = sim.state()
    sim.step(1)
    s1 = sim.state()
    dt = s1.time - s0.time
    R0, R1 = kin.rotation_zyx(*s0.pose[3:]), kin.rotation_zyx(*s1.pose[3:])
    W = (R1 @ R0.T - np.eye(3)) / dt                       # ≈ [ω]× for a small step
    omega_fd = np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2
    omega_mid = (s0.twist[3:] + s1.twist[3:]) / 2
    assert np.linalg.norm(omega_fd - omega_mid) < 0.02 * max(np.linalg.norm(omega_mid), 0.05)
    # semi-implicit Euler (the model's integrator): ζ̇(t+h) = ζ̇(t) + h·ζ̈(t), ζ(t+h) = ζ(t) + h·ζ̇(t+h), exactly
    np.testing.assert_allclose((s1.pose[:3] - s0.pose[:3]) / dt, s1.twist[:3], atol=1e-9)
    np.testing.assert_allclose((s1.zeta - s0.zeta) / dt, s1.zeta_dot, atol=1e-9)
    np.testing.assert_allclose((s1.zeta_dot - s0.zeta_dot) / dt, s0.zeta_ddot, atol=1e-8)
    np.testing.assert_allclose((s1.twist - s0.twist) / dt, s0.accel, atol=1e-6)


def test_set_pose_reassembles_the_closed_robot_at_rest_without_rebuilding(desc):
    sim = Simulator(desc, cameras=False)
    model_id = id(sim.model)
    for pose in ([0.05, -0.03, -0.50, 0.2, -0.3, 0.1], [-0.1, 0.08, -0.60, -0.1, 0.25, -0.2]):
        sim.set_pose(np.array(pose))
        tips = np.array([sim.data.site(f"rod_tip_{i}").xpos for i in range(1, 7)])
        joints = np.array([sim.data.site(f"plate_joint_{i}").xpos for i in range(1, 7)])
        np.testing.assert_allclose(tips, joints, atol=1e-8)
        s = sim.state()
        np.testing.assert_allclose(s.pose, pose, atol=1e-12)
        assert np.all(s.zeta_dot == 0.0)
        sim.step(300)                                        # the servos hold it there
        assert np.linalg.norm(sim.state().pose[:3] - pose[:3]) < 0.005
    assert id(sim.model) == model_id


@needs_trajectories
@pytest.mark.parametrize("case", ["plate", "arm", "rod"])
def test_physical_contact_mode_touches_only_the_intended_link_through_mujoco_contacts(desc, case):
    sim = Simulator(desc, scenario=case, cameras=False, contact_model="physical")
    c = sim.collision
    assert sim.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT == 0
    sim.run_until(c.end_time + 0.3)
    log = sim.truth_log()
    f = np.linalg.norm(log["force"], axis=1)
    on = f > 0
    assert on.any()
    codes = {"plate": 0, "arm": 1, "rod": 2}
    assert set(log["link"][on].tolist()) == {codes[case]} and set(log["chain"][on].tolist()) == {c.chain}
    k = int(np.argmax(f))
    assert 0.8 * c.peak_force <= f[k] <= 1.3 * c.peak_force        # MuJoCo's contact force, near the script
    assert abs(log["time"][k] - c.peak_time) < 0.1
    assert log["force"][k] @ sim._scripted_dir > 0.5 * f[k]   # pushes (along the surface normal, not the script)
    assert not on[log["time"] > c.end_time + 0.1].any()            # released


def test_contact_model_is_checked(desc):
    with pytest.raises(SimulatorError, match="contact_model"):
        Simulator(desc, cameras=False, contact_model="magnetic")
