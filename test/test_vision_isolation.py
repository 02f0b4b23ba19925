"""Collision isolation: geometry helpers, bad input, and accuracy against simulator ground truth (seeded)."""
from __future__ import annotations

import os

import numpy as np
import pytest

from hexa.vision.camera import CameraModel, intrinsics, look_at
from hexa.robots.plate import hexagon_border_point, plate_outline
from hexa.vision.isolation import (
    LINK_UNKNOWN,
    CollisionIsolator,
    IsolationError,
    RobotGeometry,
    hexagon_line_entry,
    plate_distance,
    segment_distance,
    segment_distances,
)

HEX = np.array([[np.cos(a), np.sin(a)] for a in np.radians([0, 60, 120, 180, 240, 300])]) * 0.1


def _geometry() -> RobotGeometry:
    arms = np.zeros((6, 2, 3))
    rods = np.zeros((6, 2, 3))
    for i in range(6):
        a = np.radians(60 * i)
        A = np.array([0.15 * np.cos(a), 0.15 * np.sin(a), 0.0])
        B = A + [0.1 * np.cos(a), 0.1 * np.sin(a), -0.1]
        C = np.array([0.1 * np.cos(a), 0.1 * np.sin(a), -0.55])
        arms[i], rods[i] = (A, B), (B, C)
    T = np.eye(4)
    T[2, 3] = -0.55
    return RobotGeometry(arms, rods, T, HEX, 0.008, 0.005, 0.004)


def test_segment_distance_and_parameter() -> None:
    d, s = segment_distance(np.array([[0.5, 1.0, 0.0], [2.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]), np.zeros(3),
                            np.array([1.0, 0.0, 0.0]))
    assert np.allclose(d, [1.0, 1.0, 1.0]) and np.allclose(s, [0.5, 1.0, 0.0])


def test_plate_distance_inside_outside_above() -> None:
    g = _geometry()
    pts = np.array([[0.0, 0.0, -0.55], [0.2, 0.0, -0.55], [0.0, 0.0, -0.50]])
    d = plate_distance(pts, g)
    assert d[0] == 0.0 and d[1] == pytest.approx(0.1) and d[2] == pytest.approx(0.05 - 0.004)


def test_batched_segment_and_plate_distances_equal_the_per_segment_forms() -> None:
    """The isolation's distances of every object point to the 12 links (one matrix product) and to the plate
    (edges at once) against segment_distance per segment and a point-in-hexagon test per edge."""
    g = _geometry()
    rng = np.random.default_rng(4)
    pts = rng.normal([0.0, 0.0, -0.45], 0.15, (3000, 3))
    segs = np.array([seg for *_, seg, _ in g.link_segments(0.01)])
    D, S = segment_distances(pts, segs[:, 0], segs[:, 1])
    for k, seg in enumerate(segs):
        d, s = segment_distance(pts, seg[0], seg[1])
        np.testing.assert_allclose(D[k], d, rtol=0, atol=1e-12)
        np.testing.assert_allclose(S[k], s, rtol=0, atol=1e-12)
    q = pts - g.T_plate[:3, 3]
    inside = np.ones(len(q), bool)
    d_edge = np.full(len(q), np.inf)
    for k in range(6):
        a, b = HEX[k], HEX[(k + 1) % 6]
        inside &= (b[0] - a[0]) * (q[:, 1] - a[1]) - (b[1] - a[1]) * (q[:, 0] - a[0]) >= 0
        flat = np.column_stack([q[:, :2], np.zeros(len(q))])
        d_edge = np.minimum(d_edge, segment_distance(flat, np.append(a, 0.0), np.append(b, 0.0))[0])
    ref = np.hypot(np.where(inside, 0.0, d_edge), np.maximum(np.abs(q[:, 2]) - 0.004, 0.0))
    assert 0 < inside.sum() < len(q)
    np.testing.assert_allclose(plate_distance(pts, g), ref, rtol=0, atol=1e-12)


def test_hexagon_border_point_and_line_entry() -> None:
    p = hexagon_border_point(HEX, np.array([1.0, 0.0]))
    assert np.allclose(p, [0.1, 0.0])
    q = hexagon_line_entry(HEX, np.array([0.15, 0.01]), np.array([-1.0, 0.0]))
    assert q is not None and q[1] == pytest.approx(0.01) and np.hypot(*q) <= 0.1 + 1e-9
    assert hexagon_line_entry(HEX, np.array([0.3, 0.3]), np.array([1.0, 0.0])) is None
    with pytest.raises(ValueError, match="no hexagon border point"):
        hexagon_border_point(HEX + 1.0, np.array([-1.0, 0.0]))      # the centre outside the polygon


def test_the_plate_outline_runs_through_every_plate_joint_by_angle() -> None:
    from hexa.robots.hexa_description import load_hexa

    desc = load_hexa()
    hexagon = plate_outline(desc)
    angles = np.arctan2(hexagon[:, 1], hexagon[:, 0])
    assert hexagon.shape == (6, 2) and np.all(np.diff(angles) > 0)
    assert sorted(map(tuple, hexagon.round(12))) == sorted(map(tuple, np.asarray(desc.C)[:, :2].round(12)))
    for k in range(6):          # the ray towards a vertex meets the border at that vertex
        np.testing.assert_allclose(hexagon_border_point(hexagon, hexagon[k]), hexagon[k], atol=1e-12)


def _isolator() -> tuple[CollisionIsolator, CameraModel]:
    cam = CameraModel(intrinsics(64, 48, 1.0), 64, 48, look_at([0, 0, 0], [0, 0, -0.5]), "cam_top")
    return CollisionIsolator({"cam_top": cam}), cam


def test_no_background_and_bad_frames_raise_naming_the_problem() -> None:
    iso, _ = _isolator()
    g = _geometry()
    rgb = np.zeros((48, 64, 3), np.uint8)
    depth = np.full((48, 64), 0.5, np.float32)
    with pytest.raises(IsolationError, match="no background"):
        iso.isolate_camera("cam_top", rgb, depth, g)
    with pytest.raises(IsolationError, match="sizes differ"):
        iso.set_background("cam_top", rgb, depth[:10])
    with pytest.raises(IsolationError, match="does not match camera_info"):
        iso.set_background("cam_top", rgb[:10, :10], depth[:10, :10])
    with pytest.raises(IsolationError, match="RGB uint8"):
        iso.set_background("cam_top", depth, depth)
    iso.set_background("cam_top", rgb, depth)
    with pytest.raises(IsolationError, match="no valid pixel"):
        iso.isolate_camera("cam_top", rgb, np.full((48, 64), np.nan, np.float32), g)
    with pytest.raises(IsolationError, match="no usable camera frame"):
        iso.isolate({"cam_top": (rgb, np.zeros((48, 64), np.float32) * np.nan)}, g)


def test_unchanged_scene_gives_no_contact() -> None:
    iso, _ = _isolator()
    rgb = np.full((48, 64, 3), 100, np.uint8)
    depth = np.full((48, 64), 0.5, np.float32)
    iso.set_background("cam_top", rgb, depth)
    est = iso.isolate({"cam_top": (rgb, depth)}, _geometry())
    assert est.link == LINK_UNKNOWN and est.confidence == 0.0


needs_sim = pytest.mark.skipif(os.environ.get("HEXA_SKIP_SIM") == "1", reason="simulator tests disabled")


@pytest.fixture(scope="module")
def desc():
    pytest.importorskip("mujoco")
    from hexa.robots.hexa_description import load_hexa

    return load_hexa()


@pytest.mark.slow
@needs_sim
def test_isolation_accuracy_against_simulator_truth(desc) -> None:
    """24 feasible randomised contacts (8 per link, chains 1..6): median error ≤ 10 mm and link+chain ≥ 90 %.

    The 95 % target is checked over the larger run in docs/vision.md (`python -m hexa.vision.evaluation`);
    on 24 contacts one miss is already 4 %, so this test allows two (a regression still fails it)."""
    from hexa.vision.evaluation import contact_samples, evaluate_isolation

    rep = evaluate_isolation(contact_samples(24, seed=7, desc=desc), desc)
    table = rep.confusion_markdown()
    assert rep.n == 24
    assert rep.link_chain_correct >= 0.90, table
    assert rep.median_error <= 0.010, rep.per_case
    assert rep.p90_error <= 0.020
    assert table.count("\n") == len(rep.labels) + 1
    # step 6: the pushing object's axis is the push direction (the simulator pushes along it)
    push = np.array([c["push_direction_error_deg"] for c in rep.per_case if c["truth"] == c["estimate"]])
    assert np.isfinite(push).mean() >= 0.8, push
    assert np.nanmedian(push) <= 5.0 and np.nanmax(push) <= 20.0, push


@needs_sim
def test_debug_image_shows_every_step(desc) -> None:
    from hexa.vision.evaluation import contact_samples, isolate_sample
    from hexa.vision.isolation import debug_image

    sample = next(contact_samples(1, seed=3, desc=desc))
    est, geom, iso = isolate_sample(sample, desc, debug=True)
    img = debug_image(est.per_camera[est.camera], iso, geom)
    assert img.shape == (480, 1280, 3) and img.dtype == np.uint8
    assert img[240:, 960:].max() > 0   # the result tile has text


@needs_sim
def test_marker_pose_accuracy_against_simulator_truth() -> None:
    """Top camera, random plate poses, rendered with noise: median ≤ 2 mm and ≤ 0.5 deg."""
    from hexa.vision.evaluation import evaluate_markers

    rep = evaluate_markers(8, seed=11)
    assert rep.ok == rep.n >= 6
    assert rep.median_position_error <= 0.002
    assert np.degrees(rep.median_rotation_error) <= 0.5


def test_filters_on_the_box_around_their_pixels_equal_the_whole_frame_ones_also_at_the_border() -> None:
    """The isolation runs its median and box filters on `_box` crops: at the pixels they serve, the values equal
    those of the filter over the whole frame, for pixels inside the frame and on its edges."""
    import cv2

    from hexa.vision.isolation import _box

    rng = np.random.default_rng(3)
    depth = rng.integers(0, 3000, (48, 64)).astype(np.uint16)
    values = rng.random((48, 64)).astype(np.float32)
    for corner in ((10, 20), (0, 0), (40, 57)):           # inside, top-left and bottom-right edges
        vv = rng.integers(corner[0], corner[0] + 8, 30).clip(0, 47)
        uu = rng.integers(corner[1], corner[1] + 7, 30).clip(0, 63)
        rows, cols = _box(vv, uu, 2, depth.shape)
        assert np.array_equal(cv2.medianBlur(depth[rows, cols], 5)[vv - rows.start, uu - cols.start],
                              cv2.medianBlur(depth, 5)[vv, uu])
        rows, cols = _box(vv, uu, 7 // 2 + 1, values.shape)
        assert np.array_equal(cv2.boxFilter(values[rows, cols], -1, (7, 7), normalize=False)[
            vv - rows.start, uu - cols.start], cv2.boxFilter(values, -1, (7, 7), normalize=False)[vv, uu])


# ----------------------------------------------------------------------------------------------------------------
# a pushing stick, ray-cast: a camera above the plate (looking down), the floor, the plate's top face, the stick
_W, _H = 320, 240
_STICK_RADIUS = 0.015


def _stick_scene(geom: RobotGeometry, cam: CameraModel, stick: tuple[np.ndarray, np.ndarray] | None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Colour and depth (m) of the scene; the stick (a capsule between two points) is found by sphere tracing."""
    uu, vv = np.meshgrid(np.arange(_W), np.arange(_H))
    ray = np.stack([(uu - cam.K[0, 2]) / cam.K[0, 0], (vv - cam.K[1, 2]) / cam.K[1, 1], np.ones((_H, _W))], -1)
    o, w = cam.T_base_camera[:3, 3], ray.reshape(-1, 3) @ cam.T_base_camera[:3, :3].T   # depth t: o + t w
    floor = (-0.8 - o[2]) / w[:, 2]
    z_top = geom.T_plate[2, 3] + geom.plate_half_thickness
    t_top = (z_top - o[2]) / w[:, 2]
    on_plate = plate_distance(o + t_top[:, None] * w, geom) <= 1e-9
    depth = np.where(on_plate, t_top, floor)
    rgb = np.where(on_plate[:, None], 30, 150).astype(np.uint8).repeat(3, axis=1)
    if stick is not None:
        t = np.full(len(w), 0.3)
        for _ in range(60):
            d, _ = segment_distance(o + t[:, None] * w, *stick)
            t += d - _STICK_RADIUS
        hit = (d - _STICK_RADIUS < 1e-4) & (t < depth)
        depth[hit] = t[hit]
        rgb[hit] = (255, 140, 0)
    return rgb.reshape(_H, _W, 3), depth.reshape(_H, _W).astype(np.float32)


def _isolate_stick(geom: RobotGeometry, stick: tuple[np.ndarray, np.ndarray], **config: float):
    from hexa.vision.isolation import IsolationConfig

    cam = CameraModel(intrinsics(_W, _H, np.radians(40)), _W, _H, look_at([0, 0, 0], [0, 0, -0.5]), "cam_top")
    iso = CollisionIsolator({"cam_top": cam}, IsolationConfig(**config))
    iso.set_background("cam_top", *_stick_scene(geom, cam, None))
    return iso.isolate_camera("cam_top", *_stick_scene(geom, cam, stick), geom)


def test_a_stick_along_a_rod_pushing_the_plate_behind_it_is_a_plate_contact() -> None:
    """The stick's end pushes the plate's far face near an edge, hidden behind the plate; its body runs beside a
    rod, nearer to the rod over its length than its visible part is to the plate. The nearest points alone say
    "rod"; the stick's axis, followed out of its end, meets the plate first."""
    from hexa.vision.isolation import LINK_PLATE, LINK_ROD

    g = _geometry()
    edge_mid, normal = np.array([0.075, 0.0433]), np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    push = np.array([*(-normal * np.cos(np.radians(60))), np.sin(np.radians(60))])       # up, into the plate
    apex = np.array([*(edge_mid - 0.02 * normal), g.T_plate[2, 3] - g.plate_half_thickness])
    near = apex - _STICK_RADIUS * push
    stick = (near, near - 0.25 * push)
    beside = near + 0.026 * np.array([-normal[1], normal[0], 0.0])                       # rod 1, parallel
    rods = g.rods.copy()
    rods[0] = (beside - 0.3 * push, beside + 0.01 * push)
    g = RobotGeometry(g.arms, rods, g.T_plate, g.hexagon, g.arm_radius, g.rod_radius, g.plate_half_thickness)

    nearest_only = _isolate_stick(g, stick, tip_gap=0.0)
    assert (nearest_only.link, nearest_only.chain) == (LINK_ROD, 1), nearest_only.reason
    res = _isolate_stick(g, stick)
    assert (res.link, res.chain) == (LINK_PLATE, 0), res.reason
    assert np.linalg.norm(res.point[:2] - edge_mid) <= 0.005


def test_a_stick_pushing_a_rod_with_its_end_stays_a_rod_contact() -> None:
    """The axis rule does not move a plain rod contact: the stick's visible end touches rod 1 from the side."""
    from hexa.vision.isolation import LINK_ROD

    g = _geometry()
    on_rod = g.rods[0, 0] + 0.7 * (g.rods[0, 1] - g.rods[0, 0])
    push = np.array([0.0, -1.0, 0.0])
    near = on_rod - (g.rod_radius + _STICK_RADIUS) * push
    res = _isolate_stick(g, (near, near - 0.25 * push))
    assert (res.link, res.chain) == (LINK_ROD, 1), res.reason
    assert np.linalg.norm(res.point - (on_rod - g.rod_radius * push)) <= 0.008
