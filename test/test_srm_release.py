"""Closed-loop release in simulation (seed 003 sec 3.1): SRM-V1 releases every Table 3 trajectory."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hexa.kinematics import upsrpu as kin
from hexa.robots.upsrpu_description import load_upsrpu
from hexa.srm.experiment import run_release_experiment
from hexa.srm.plant import SimulatedUpsrpu, half_sine_push

pytestmark = pytest.mark.slow   # seconds of simulated release per trajectory: left out of `make check`

DESC = load_upsrpu()


@pytest.mark.parametrize("number", [1, 2, 3, 4, 5])
def test_srm_v1_releases_each_table3_trajectory_within_15_s(number):
    r = run_release_experiment(DESC, number, 1, wait=1.0, window=15.0)
    assert r.det_jd[r.k] < DESC.det_jd_limit or r.min_omega[r.k] < DESC.omega_limit   # starts singular
    assert r.released and r.release_time is not None and r.release_time <= 15.0
    assert abs(r.det_jd[-1]) >= DESC.det_jd_limit and r.min_omega[-1] >= DESC.omega_limit
    # before the enable pin the desired references equal the references
    np.testing.assert_allclose(r.q_d[: r.k], r.q_r[: r.k])
    assert set(r.implicated) <= set(r.moved_limbs)
    assert np.all(r.q_d < DESC.q_max) and np.all(r.q_d > DESC.q_min)


def test_v1_deviates_less_than_v2_on_trajectory_1():
    r1 = run_release_experiment(DESC, 1, 1, wait=1.0, window=8.0)
    r2 = run_release_experiment(DESC, 1, 2, wait=1.0, window=8.0)
    assert r1.implicated == (3, 4)
    assert r1.moved_limbs == (3, 4) and r2.moved_limbs == (1, 2)
    assert r1.metrics["mae_m"] < r2.metrics["mae_m"]
    assert r1.metrics["mdsr_m"] < r2.metrics["mdsr_m"]


def test_plant_tracks_a_step_and_keeps_the_fk_branch():
    X0 = np.array([0.0, 0.7, 0.0, 0.0])
    plant = SimulatedUpsrpu(DESC, X0)
    q_d = kin.inverse_kinematics(DESC, X0) + np.array([0.002, 0.0, -0.002, 0.001])
    for _ in range(100):
        s = plant.advance(q_d, DESC.t_s)
    np.testing.assert_allclose(s.q, q_d, atol=1e-5)
    np.testing.assert_allclose(kin.inverse_kinematics(DESC, s.X), s.q, atol=1e-10)
    assert np.max(np.abs(s.X - X0)) < 0.05          # stays on the branch continuous with X0


def test_push_moves_the_platform_more_near_the_singularity():
    push = half_sine_push(0.0, 1.0, np.array([10.0, 0.0, 0.0, 1.0]))
    far = SimulatedUpsrpu(DESC, np.array([0.0, 0.7, 0.0, 0.0]), push=push)
    near = SimulatedUpsrpu(DESC, DESC.singular_poses[3], push=push)
    dev_far = max(np.max(np.abs(far.advance(far.q, 0.01).X - far.X_kin)) for _ in range(60))
    dev_near = max(np.max(np.abs(near.advance(near.q, 0.01).X - near.X_kin)) for _ in range(60))
    assert dev_near > 2 * dev_far > 0


def test_hexa_srm_cli_json(capsys):
    from hexa_bringup.cli import main

    assert main(["srm", "--trajectory", "2", "--variant", "v1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["released"] is True and out["variant"] == "v1"
    assert out["implicated_limbs"] == [3, 4]
    assert math.isfinite(out["metrics"]["mae_m"]) and out["metrics"]["mae_m"] > 0


def test_v1_releases_with_x_c_from_noisy_markers():
    from hexa.srm.tracking import tracking_model

    noise = tracking_model(DESC).marker_noise
    r = run_release_experiment(DESC, 1, 1, wait=1.0, window=6.0, marker_noise=noise, seed=3)
    assert not np.allclose(r.X_c, r.X_kin)                       # the measurement is noisy
    assert r.released and r.moved_limbs == (3, 4)
    tail = slice(len(r.t) - 100, None)
    assert np.all(r.min_omega[tail] >= DESC.omega_limit) and np.all(np.abs(r.det_jd[tail]) >= DESC.det_jd_limit)
