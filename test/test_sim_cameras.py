"""Simulated RGB-D cameras: markers and blue arms appear where the camera model projects them; depth is aligned."""
from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("mujoco")
cv2 = pytest.importorskip("cv2")

from hexa.robots.hexa_description import load_hexa  # noqa: E402
from hexa.sim import Simulator  # noqa: E402
from hexa.sim.camera import RenderError  # noqa: E402


@pytest.fixture(scope="module")
def sim():
    try:
        s = Simulator(load_hexa(), seed=1, pose=np.array([0.03, -0.02, -0.55, 0.1, 0.08, -0.05]))
    except RenderError as exc:
        pytest.skip(f"no headless GL: {exc}")
    s.step(50)
    yield s
    s.close()


def _hue_sat(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(rgb.reshape(1, -1, 3).astype(np.uint8), cv2.COLOR_RGB2HSV).reshape(-1, 3)


def test_image_shapes_types_and_intrinsics(sim):
    for cam in ("cam_top", "cam_side"):
        rgb, depth = sim.render(cam)
        model = sim.camera_model(cam)
        assert rgb.shape == (model.height, model.width, 3) and rgb.dtype == np.uint8
        assert depth.shape == (model.height, model.width) and depth.dtype == np.uint16
        assert model.K[0, 2] == pytest.approx((model.width - 1) / 2)
        assert (depth > 0).mean() > 0.9             # plain room behind everything: almost all valid


def test_plate_markers_appear_where_the_camera_model_projects_them(sim):
    from hexa.kinematics import hexa6rus as kin

    cfg = sim.config
    pose = sim.state().pose
    R = kin.rotation_zyx(*pose[3:])
    rgb, depth = sim.render("cam_top", noise=False)
    model = sim.camera_model("cam_top")
    top = cfg.appearance["plate_thickness"] / 2 + cfg.markers.thickness
    for mk in cfg.markers.items:
        centre = pose[:3] + R @ (mk.position + np.array([0.0, 0.0, top]))
        (u, v), z = model.project(centre[None])[0][0], model.project(centre[None])[1][0]
        ui, vi = int(round(u)), int(round(v))
        patch = rgb[vi - 2:vi + 3, ui - 2:ui + 3].reshape(-1, 3).astype(float)
        expected = np.clip(mk.rgb * 255, 0, 255)
        # hue of the patch matches the marker's colour (shading changes brightness, not hue)
        h_img = np.median(_hue_sat(patch)[:, 0])
        h_exp = _hue_sat(expected[None])[0, 0]
        assert min(abs(h_img - h_exp), 180 - abs(h_img - h_exp)) < 8, mk.name
        assert np.median(_hue_sat(patch)[:, 1]) > 120, mk.name
        assert depth[vi, ui] / 1000.0 == pytest.approx(z, abs=0.004), mk.name


def test_blue_arms_appear_where_the_side_camera_projects_them(sim):
    from hexa.kinematics import hexa6rus as kin

    s = sim.state()
    A = np.asarray(sim.desc.A)
    B = kin.elbows(sim.desc, s.zeta)
    rgb, depth = sim.render("cam_side", noise=False)
    model = sim.camera_model("cam_side")
    seen = 0
    for i in range(6):
        for frac in (0.5, 0.7):
            p = A[i] + frac * (B[i] - A[i])
            uv, z = model.project(p[None])
            u, v = (int(round(x)) for x in uv[0])
            if not (0 <= u < model.width and 0 <= v < model.height):
                continue
            if abs(depth[v, u] / 1000.0 - z[0]) > 0.02:     # something in front of this arm point
                continue
            hsv = _hue_sat(rgb[v, u][None])[0]
            assert 100 <= hsv[0] <= 130 and hsv[1] > 100, (i + 1, frac, hsv)   # OpenCV blue hue ≈ 120
            seen += 1
    assert seen >= 4


def test_depth_noise_grows_with_range_and_images_are_deterministic_per_seed(sim):
    _, d1 = sim.render("cam_side")
    _, d2 = sim.render("cam_side")
    _, raw = sim.render_raw("cam_side")
    valid = (d1 > 0) & np.isfinite(raw)
    err = d1[valid] / 1000.0 - raw[valid]
    z = raw[valid]
    near, far = z < np.percentile(z, 20), z > np.percentile(z, 80)
    assert np.std(err[far]) > 1.5 * np.std(err[near])
    rel = np.std(err / z)
    assert 0.006 < rel < 0.014                          # ≈ 1 % σ (+ 1 mm quantisation)
    assert not np.array_equal(d1, d2)                   # fresh noise every frame
    other = Simulator(sim.desc, seed=1, pose=sim.start_pose)
    try:
        other.step(50)
        a = other.render("cam_top")[0]
        sim2 = Simulator(sim.desc, seed=1, pose=sim.start_pose)
        try:
            sim2.step(50)
            np.testing.assert_array_equal(a, sim2.render("cam_top")[0])
        finally:
            sim2.close()
    finally:
        other.close()


def test_randomize_scene_is_seeded_changes_the_image_and_restores_exactly(sim):
    from hexa.sim.randomize import randomize_scene, restore_scene

    before, depth_before = sim.render_raw("cam_top")
    a = randomize_scene(sim, np.random.default_rng(11))
    img_a = sim.render_raw("cam_top")[0]
    b = randomize_scene(sim, np.random.default_rng(11))
    assert a == b
    np.testing.assert_array_equal(img_a, sim.render_raw("cam_top")[0])
    assert np.abs(img_a.astype(int) - before.astype(int)).mean() > 5
    restore_scene(sim)
    after, depth_after = sim.render_raw("cam_top")
    np.testing.assert_array_equal(after, before)
    np.testing.assert_array_equal(depth_after, depth_before)
    assert sim.rgb_noise_sigma == sim.config.rgb_noise_sigma


def test_a_skipped_frame_advances_the_noise_as_a_rendered_one(sim):
    """The sim node skips rendering a camera nobody subscribes to; the frames after it stay those of the seed."""
    gen = sim._noise["cam_top"].rng.bit_generator
    start = gen.state
    sim.render("cam_top")
    rgb, depth = sim.render("cam_top")
    gen.state = start
    sim.skip_render("cam_top")
    rgb_skip, depth_skip = sim.render("cam_top")
    np.testing.assert_array_equal(rgb_skip, rgb)
    np.testing.assert_array_equal(depth_skip, depth)
    gen.state = start
    assert not np.array_equal(sim.render("cam_top")[0], rgb)     # the noise does move from frame to frame


def test_a_kept_frame_state_renders_later_as_its_instant_did():
    """`frame_state` keeps an instant (joints, the pushing object) that `render_frame` renders later exactly as
    `render` did then, while the robot has moved on; keeping it leaves the physics untouched."""
    from hexa.eval.campaign import draw_contact

    c = draw_contact(2, 8, "paper")                       # a plate push: the object is in view at its peak
    with Simulator(load_hexa(), seed=3, scenario=c) as sim, Simulator(load_hexa(), seed=3, scenario=c,
                                                                      cameras=False) as plain:
        sim.run_until(c.peak_time)
        plain.run_until(c.peak_time)
        kept = sim.frame_state()
        then = {cam: sim.render(cam, noise=False) for cam in ("cam_top", "cam_side")}
        sim.run_until(c.peak_time + 0.5)
        plain.run_until(c.peak_time + 0.5)
        np.testing.assert_array_equal(sim.state().zeta, plain.state().zeta)
        for cam, (rgb, depth) in then.items():
            rgb_later, depth_later = sim.render_frame(cam, kept, noise=False)
            np.testing.assert_array_equal(rgb_later, rgb)
            np.testing.assert_array_equal(depth_later, depth)
            assert np.abs(sim.render(cam, noise=False)[1].astype(int) - depth.astype(int)).max() > 20   # moved on


def test_the_image_noise_in_place_equals_the_plain_formulas(sim):
    """noisy_rgb and depth_image_mm run fused (one saturated add, in-place float32 operations); their output is the
    module's formulas written out plainly, from the same draws of the bank."""
    from hexa.sim.camera import NoiseBank, depth_image_mm, noisy_rgb

    rgb, depth = sim.render_raw("cam_top")
    cfg = sim.config.cameras["cam_top"]
    for sigma, rel in ((2.0, 0.01), (3.5, 0.02)):
        fused, plain = NoiseBank(rgb.size * 2, seed=4), NoiseBank(rgb.size * 2, seed=4)
        for _ in range(3):
            n = plain.draw(rgb.size).reshape(rgb.shape)
            want = np.clip(rgb.astype(np.int32) + np.rint(np.float32(sigma) * n).astype(np.int32), 0, 255)
            got = noisy_rgb(rgb, sigma, fused)
            np.testing.assert_array_equal(got, want.astype(np.uint8))
            assert 0 < np.count_nonzero(got != rgb)
            z = depth
            valid = np.isfinite(z) & (z >= cfg.depth_min) & (z <= cfg.depth_max)
            zn = np.where(valid, z, 0.0) * (1.0 + rel * plain.draw(z.size).reshape(z.shape))
            want_mm = np.clip(np.rint(zn * 1000.0), 0, 65535).astype(np.uint16)
            want_mm[~valid] = 0
            got_mm = depth_image_mm(depth, cfg, rel, fused)
            np.testing.assert_array_equal(got_mm, want_mm)
            assert np.count_nonzero(got_mm) > 0.5 * got_mm.size
