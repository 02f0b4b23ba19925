"""The hot paths `hexa bench realtime` measures give the reference's numbers: the collision monitor's streamed
residuals (plain-float kernel, cached lag exponentials, one J_ζ array per sample) against the vectorized batch
observer on the same ζ, ζ̇, τ and poses; the stream itself carries a collision the monitor detects."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.benchmarks.realtime import plate_case_stream, run_monitor


@pytest.fixture(scope="module")
def monitored():
    stream = plate_case_stream(duration=5.2)
    out, mon = run_monitor(stream)
    return stream, out, mon


def test_set_points_carried_by_the_current_samples_give_the_paired_streams_output(monitored):
    """motor_currents with their set-points (one input per sample) = motor_currents + joint_states paired by stamp
    (bags recorded before the field): the same samples, residuals and events."""
    stream, out, mon = monitored
    ref, ref_mon = run_monitor(stream, carried=False)
    assert mon.carries_setpoint and not ref_mon.carries_setpoint
    assert [s.time for s in out] == [s.time for s in ref]
    np.testing.assert_array_equal([s.residual.wrench for s in out], [s.residual.wrench for s in ref])
    assert [e for s in out for e in s.residual.events] == [e for s in ref for e in s.residual.events]


def test_the_benchmark_stream_is_the_plate_collision_at_1khz(monitored):
    stream, out, mon = monitored
    t = np.array([s[0] for s in stream.samples])
    assert np.allclose(np.diff(t), 1e-3, atol=1e-9)
    assert len(stream.poses) == pytest.approx(30 * t[-1], abs=2)
    assert mon.sequencer.unpaired == 0 and mon.rejects["board_time"] == 0
    events = [e for s in out for e in s.residual.events]
    assert [e.kind for e in events][:1] == ["START"]
    assert 4.2 < events[0].onset < 4.8            # the plate case's push starts at 1 s lead-in + its onset


def test_streamed_residual_equals_the_batch_observer_on_the_same_inputs(monitored):
    from hexa.dynamics.lagrange import HexaDynamicParameters
    from hexa.dynamics.observer import momentum_residual_batch
    from hexa.robots.hexa_description import load_hexa

    _, out, mon = monitored
    assert mon.observer.rejected["pose_tracking"] == 0 and mon.observer.rejected["singular"] == 0
    run = out
    assert len(run) > 4000
    assert np.diff([s.time for s in run]).max() < 1.5e-3   # one uninterrupted integration from the first sample
    t = np.array([s.time for s in run])
    zeta = np.array([s.zeta for s in run])
    zeta_dot = np.array([s.zeta_dot for s in run])
    tau = np.array([s.tau for s in run])
    poses = np.array([s.residual.pose for s in run])
    batch = momentum_residual_batch(HexaDynamicParameters.from_description(load_hexa()), t, zeta, zeta_dot, tau,
                                    poses, gains=mon.observer.config.gains)
    streamed = np.array([s.residual.wrench for s in run])
    expected = batch.wrench
    scale = np.abs(streamed).max()
    assert scale > 2.0                                # the push is in there
    np.testing.assert_allclose(streamed, expected, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("seed", range(5))
def test_plane_fit_equals_the_svd_of_the_centred_points(seed):
    """fit_plane (3×3 eigenproblem) against the reference: the last right-singular vector of the centred N×3 points,
    on a tilted, noisy plate patch seen at 0.5-1 m as the marker lift has it."""
    from hexa.vision.rigid import fit_plane

    rng = np.random.default_rng(seed)
    n_true = rng.normal(size=3)
    n_true /= np.linalg.norm(n_true)
    a = np.cross(n_true, [1.0, 0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(n_true, a)
    uv = rng.uniform(-0.06, 0.06, (6000, 2))
    pts = np.array([0.1, -0.05, 0.7]) + uv[:, :1] * a + uv[:, 1:] * b + rng.normal(0, 1e-3, (6000, 1)) * n_true
    c, n = fit_plane(pts.T)
    c_ref = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - c_ref, full_matrices=False)
    n_ref = vt[2] * np.sign(vt[2] @ n)
    np.testing.assert_allclose(c, c_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(n, n_ref, rtol=0, atol=1e-9)
    assert abs(abs(n @ n_true) - 1.0) < 1e-3          # and it is the plane the points were drawn on
