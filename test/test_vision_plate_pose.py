"""The pose node's pipeline without ROS: pairing, the detector only when its output is used, the box then the whole
frame, counters and rejects."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.vision.detector import Detection
from hexa.vision.images import numpy_to_image
from hexa.vision.plate_pose import PlatePoseEstimator
from test_vision_markers import CAM, LAYOUT, _pose_T, render_plate

T_PLATE = _pose_T(0.02, -0.01, -0.55, 0.1, -0.1, 0.05)


class FakeDetector:
    """Returns one fixed box; counts its calls."""

    def __init__(self, box: tuple[float, float, float, float]) -> None:
        self.box = np.asarray(box, float)
        self.calls = 0

    def detect(self, rgb: np.ndarray) -> list[Detection]:
        self.calls += 1
        return [Detection(self.box, 0.9)]


@pytest.fixture(scope="module")
def frame() -> tuple[tuple, tuple]:
    rgb, depth = render_plate(T_PLATE)
    depth_mm = np.nan_to_num(depth * 1000.0, nan=0.0).round().astype(np.uint16)
    c, d = numpy_to_image(rgb, "rgb8"), numpy_to_image(depth_mm, "16UC1")
    return ((c.height, c.width, c.encoding, c.is_bigendian, c.step, c.data),
            (d.height, d.width, d.encoding, d.is_bigendian, d.step, d.data))


def _plate_box() -> tuple[float, float, float, float]:
    uv, _ = CAM.project(T_PLATE[:3, 3][None])
    u, v = uv[0]
    return (u - 90, v - 90, u + 90, v + 90)


def _estimator(detector=None, roi: bool = True) -> PlatePoseEstimator:
    est = PlatePoseEstimator(LAYOUT, "cam_top", CAM.T_base_camera, detector, roi)
    est.set_camera_info(CAM.width, CAM.height, CAM.K.reshape(-1).tolist())
    return est


def test_a_colour_depth_pair_gives_the_plate_pose(frame) -> None:
    est = _estimator()
    color, depth = frame
    assert est.add_color(1.0, *color) is None
    out = est.add_depth(1.0, *depth)
    assert out is not None and out.stamp == 1.0 and out.detections == []
    assert out.fit is not None and np.linalg.norm(out.fit.t - T_PLATE[:3, 3]) < 0.002
    assert est.counters() == {"frames": 1, "poses": 1} and est.rejected() == 0


def test_the_detector_runs_only_when_its_box_or_its_boxes_are_used(frame) -> None:
    color, depth = frame
    det = FakeDetector(_plate_box())
    est = _estimator(det, roi=False)
    est.add_color(1.0, *color, detections_wanted=False)
    out = est.add_depth(1.0, *depth, detections_wanted=False)
    assert det.calls == 0 and out.fit is not None and out.detections == []
    est.add_color(2.0, *color, detections_wanted=True)
    out = est.add_depth(2.0, *depth, detections_wanted=True)
    assert det.calls == 1 and len(out.detections) == 1
    est = _estimator(det, roi=True)                      # the box is used: the detector runs unasked
    est.add_color(3.0, *color, detections_wanted=False)
    out = est.add_depth(3.0, *depth, detections_wanted=False)
    assert det.calls == 2 and out.fit is not None and est.counters()["detections"] == 1


def test_markers_are_searched_in_the_padded_box_then_in_the_whole_frame(frame) -> None:
    color, depth = frame
    est = _estimator(FakeDetector((0.0, 0.0, 40.0, 30.0)))      # a box far from the plate
    box = est.detector_box([Detection(np.array([100.0, 50.0, 200.0, 150.0]), 0.9)])
    assert box == pytest.approx((80.0, 30.0, 220.0, 170.0))      # 20 % of the size on each side
    est.add_color(1.0, *color)
    out = est.add_depth(1.0, *depth)
    assert out.fit is not None and np.linalg.norm(out.fit.t - T_PLATE[:3, 3]) < 0.002


def test_frames_without_camera_info_or_markers_are_counted_as_rejects(frame) -> None:
    color, depth = frame
    est = PlatePoseEstimator(LAYOUT, "cam_top", CAM.T_base_camera)
    est.add_color(1.0, *color)
    assert est.add_depth(1.0, *depth) is None                     # no camera_info yet: the pair is held
    first = est.set_camera_info(CAM.width, CAM.height, CAM.K.reshape(-1).tolist())
    assert first is not None and first.stamp == 1.0 and first.fit is not None   # ... and fitted with it
    blank = numpy_to_image(np.full((CAM.height, CAM.width, 3), 30, np.uint8), "rgb8")
    est.add_color(2.0, blank.height, blank.width, blank.encoding, blank.is_bigendian, blank.step, blank.data)
    out = est.add_depth(2.0, *depth)
    assert out is not None and out.fit is None
    assert est.counters() == {"frames": 2, "poses": 1, "marker fit rejected": 1}
    assert est.rejected() == 1


def _moving_frames(n: int) -> list[tuple[tuple, tuple]]:
    """A plate moving 3 mm and 0.6° per frame (0.09 m/s at 30 fps), with depth noise."""
    out = []
    for k in range(n):
        rgb, depth = render_plate(_pose_T(0.02 - 0.003 * k, -0.01 + 0.002 * k, -0.55, 0.1 + 0.01 * k, -0.1, 0.05),
                                  noise_rel=0.002, seed=k)
        depth_mm = np.nan_to_num(depth * 1000.0, nan=0.0).round().astype(np.uint16)
        c, d = numpy_to_image(rgb, "rgb8"), numpy_to_image(depth_mm, "16UC1")
        out.append(((c.height, c.width, c.encoding, c.is_bigendian, c.step, c.data),
                    (d.height, d.width, d.encoding, d.is_bigendian, d.step, d.data)))
    return out


def test_a_tracked_plate_is_searched_around_its_last_pose_with_the_detectors_poses() -> None:
    frames = _moving_frames(6)
    poses = {}
    for track_age in (0.0, 0.1):                    # 0: the detector's box every frame (the reference)
        det = FakeDetector(_plate_box())
        est = PlatePoseEstimator(LAYOUT, "cam_top", CAM.T_base_camera, det, track_age=track_age)
        est.set_camera_info(CAM.width, CAM.height, CAM.K.reshape(-1).tolist())
        fits = []
        for k, (color, depth) in enumerate(frames):
            est.add_color(k / 30.0, *color, detections_wanted=False)
            fits.append(est.add_depth(k / 30.0, *depth, detections_wanted=False).fit)
        assert all(f is not None for f in fits)
        poses[track_age] = np.array([f.T for f in fits])
        assert det.calls == (6 if track_age == 0.0 else 1)
        assert est.counters()["tracked boxes"] == (0 if track_age == 0.0 else 5) and est.rejected() == 0
    np.testing.assert_allclose(poses[0.1], poses[0.0], rtol=0, atol=1e-12)


def test_an_old_fit_or_wanted_boxes_bring_the_detector_back(frame) -> None:
    color, depth = frame
    det = FakeDetector(_plate_box())
    est = PlatePoseEstimator(LAYOUT, "cam_top", CAM.T_base_camera, det)
    est.set_camera_info(CAM.width, CAM.height, CAM.K.reshape(-1).tolist())
    for stamp, wanted in ((1.0, False), (1.05, False), (1.3, False), (1.33, True)):
        est.add_color(stamp, *color, detections_wanted=wanted)
        out = est.add_depth(stamp, *depth, detections_wanted=wanted)
        assert out.fit is not None
    assert det.calls == 3                             # 1.0 (first), 1.3 (last fit 0.25 s old), 1.33 (boxes wanted)
    assert est.counters()["tracked boxes"] == 2       # 1.05 and 1.33
    assert len(out.detections) == 1
