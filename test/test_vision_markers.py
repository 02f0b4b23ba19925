"""Marker pose: synthetic RGB-D of a plate with four coloured discs; 3-of-4 fits; inconsistent fits rejected."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.vision.camera import CameraModel, intrinsics, look_at
from hexa.vision.markers import (
    MarkerDetector,
    MarkerError,
    MarkerLayout,
    fit_marker_set,
    pose_from_transform,
    quaternion_from_matrix,
)
from hexa.vision.rigid import rotation_angle

LAYOUT = MarkerLayout(("red", "green", "yellow", "magenta"),
                      np.array([[0.05, 0.0, 0.0], [-0.025, 0.043, 0.0], [-0.025, -0.043, 0.0], [0.0, 0.0, 0.0]]),
                      np.array([[1, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 1]], float), 0.01)
CAM = CameraModel(intrinsics(640, 480, np.radians(58)), 640, 480, look_at([0.05, 0.02, 0.0], [0, 0, -0.55]))


def _rot(a: float, b: float, g: float) -> np.ndarray:
    ca, sa, cb, sb, cg, sg = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(g), np.sin(g)
    return np.array([[ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg],
                     [sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg],
                     [-sb, cb * sg, cb * cg]])


def render_plate(T: np.ndarray, hide: tuple[int, ...] = (), noise_rel: float = 0.0, seed: int = 0
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Exact ray-cast of a grey plate plane (radius 0.1 m) with coloured discs, background at NaN."""
    rng = np.random.default_rng(seed)
    uu, vv = np.meshgrid(np.arange(640.0), np.arange(480.0))
    rays = CAM.ray(np.stack([uu, vv], -1))
    n = T[:3, 2]
    o = CAM.position
    s = ((T[:3, 3] - o) @ n) / (rays @ n)
    pts = o + rays * s[..., None]
    local = (pts - T[:3, 3]) @ T[:3, :3]
    on = (np.linalg.norm(local[..., :2], axis=-1) < 0.1) & (s > 0)
    rgb = np.full((480, 640, 3), 30, np.uint8)
    rgb[on] = (170, 170, 170)
    for k, (m, c) in enumerate(zip(LAYOUT.points, LAYOUT.rgb)):
        if k in hide:
            continue
        disc = on & (np.linalg.norm(local[..., :2] - m[:2], axis=-1) < LAYOUT.radius)
        rgb[disc] = (c * 220).astype(np.uint8)
    z = CAM.to_camera(pts)[..., 2]
    depth = np.where(on, z, np.nan)
    if noise_rel:
        depth = depth * (1 + noise_rel * rng.standard_normal(depth.shape))
        depth = np.round(depth * 1000) / 1000
    return rgb, depth.astype(np.float32)


def _pose_T(x, y, z, a, b, g) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _rot(a, b, g)
    T[:3, 3] = [x, y, z]
    return T


@pytest.mark.parametrize("seed", range(6))
def test_marker_pose_accuracy_on_noisy_depth(seed: int) -> None:
    rng = np.random.default_rng(seed)
    T = _pose_T(*rng.uniform(-0.08, 0.08, 2), -0.55, *np.radians(rng.uniform(-25, 25, 3)))
    rgb, depth = render_plate(T, noise_rel=0.01, seed=seed)
    det = MarkerDetector(LAYOUT, CAM)
    fit, _ = det.estimate(rgb, depth)
    assert fit.ok, fit.reason
    assert np.linalg.norm(fit.t - T[:3, 3]) < 0.002
    assert np.degrees(rotation_angle(fit.R, T[:3, :3])) < 1.0
    assert len(fit.used) == 4 and np.all(np.isfinite(fit.covariance))
    assert np.all(np.diag(fit.covariance) > 0)


@pytest.mark.parametrize("hidden", range(4))
def test_any_three_markers_suffice(hidden: int) -> None:
    T = _pose_T(0.03, -0.02, -0.55, 0.1, 0.2, -0.1)
    rgb, depth = render_plate(T, hide=(hidden,))
    fit, obs = MarkerDetector(LAYOUT, CAM).estimate(rgb, depth)
    assert obs[hidden] is None
    assert fit.ok and hidden not in fit.used and len(fit.used) == 3
    assert np.linalg.norm(fit.t - T[:3, 3]) < 0.001


def test_two_markers_are_not_enough_and_counted() -> None:
    T = _pose_T(0.0, 0.0, -0.55, 0, 0, 0)
    rgb, depth = render_plate(T, hide=(0, 1))
    det = MarkerDetector(LAYOUT, CAM)
    fit, _ = det.estimate(rgb, depth)
    assert not fit.ok and "2 marker" in fit.reason and det.rejected_fits == 1


def test_a_displaced_marker_is_rejected_and_the_rest_fit() -> None:
    R = _rot(0.3, -0.2, 0.1)
    meas = LAYOUT.points @ R.T + [0.0, 0.0, -0.5]
    meas[2] += [0.0, 0.03, 0.0]
    fit = fit_marker_set(LAYOUT.points, meas, tol=0.003)
    assert fit.ok and fit.rejected == (2,) and rotation_angle(fit.R, R) < 1e-9


def test_three_inconsistent_markers_are_rejected() -> None:
    meas = LAYOUT.points.copy()
    meas[3] = np.nan
    meas[0] += [0.02, 0.0, 0.0]
    fit = fit_marker_set(LAYOUT.points, meas, tol=0.003)
    assert not fit.ok and "no consistent subset" in fit.reason


def test_mocap_rigid_body_with_one_missing_marker() -> None:
    body = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.07, 0.03, 0.02]])
    R = _rot(0.5, 0.1, -0.3)
    meas = body @ R.T + [0.1, 0.2, 0.3]
    meas[1] = np.nan
    fit = fit_marker_set(body, meas)
    assert fit.ok and fit.used == (0, 2, 3) and np.allclose(fit.t, [0.1, 0.2, 0.3])


def test_bad_images_raise() -> None:
    det = MarkerDetector(LAYOUT, CAM)
    with pytest.raises(MarkerError, match="aligned"):
        det.detect(np.zeros((480, 640, 3), np.uint8), np.zeros((240, 320), np.float32))
    with pytest.raises(MarkerError, match="does not match camera"):
        det.detect(np.zeros((240, 320, 3), np.uint8), np.zeros((240, 320), np.float32))


def test_empty_depth_gives_no_fit_not_a_crash() -> None:
    T = _pose_T(0.0, 0.0, -0.55, 0, 0, 0)
    rgb, _ = render_plate(T)
    fit, obs = MarkerDetector(LAYOUT, CAM).estimate(rgb, np.full((480, 640), np.nan, np.float32))
    assert not fit.ok and all(o is not None and np.all(np.isnan(o.point)) for o in obs)


def test_pose_and_quaternion_conversions() -> None:
    T = _pose_T(0.1, 0.2, -0.5, 0.3, -0.2, 0.4)
    assert np.allclose(pose_from_transform(T), [0.1, 0.2, -0.5, 0.3, -0.2, 0.4])
    q = quaternion_from_matrix(T[:3, :3])
    x, y, z, w = q
    Rq = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                   [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                   [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    assert np.allclose(Rq, T[:3, :3])
