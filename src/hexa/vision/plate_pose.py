"""Plate pose from one camera's RGB-D stream: colour/depth pairing, the plate detector's box, the marker fit, and the
counters a node reports (what the pose node does per frame, without ROS)."""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from hexa.vision.markers import MarkerDetector, MarkerError, MarkerFit, MarkerLayout
from hexa.vision.sync import FrameAssembler, RGBDFrame

if TYPE_CHECKING:
    from collections.abc import Sequence

    from hexa.vision.detector import Detection, PlateDetector
    from hexa.vision.images import ImageData

#: counters that count work done, not rejected input
_WORK_COUNTERS = ("frames", "detections", "poses", "tracked boxes")


@dataclass
class PlatePose:
    """The outcome of one RGB-D frame: its stamp (s), the detector's boxes (empty when it did not run or found
    nothing) and the accepted marker fit (None when the frame gave no pose; the reason is counted)."""

    stamp: float
    detections: list[Detection] = field(default_factory=list)
    fit: MarkerFit | None = None


class PlatePoseEstimator:
    """Pairs a camera's colour and depth images, finds the plate (detector box, then coloured markers) per frame.

    Bad input is counted by reason in `counters()` and skipped, never raised. The detector runs when its box is
    used (`roi_from_detector`) or its boxes are wanted (`detections_wanted` of `add_color` / `add_depth`): no
    detector work for a frame whose boxes nobody uses. While the plate is tracked (an accepted fit at most `track_age`
    s before the frame), the markers are searched around that fit's markers projected into the image instead of in
    the detector's box, and the detector runs only when its boxes are wanted: the box it would give holds the same
    markers, so the pose is the same.

    Args:
        layout: the plate's marker layout.
        camera: camera name ("cam_top").
        T_base_camera: extrinsics of the colour optical frame (4x4).
        detector: the plate detector, or None (markers searched in the whole frame).
        roi_from_detector: search the markers in a box — the tracked box or the detector's best box, padded by
            `roi_pad` of its size on each side; the whole frame again when no fit is found there.
        track_age: largest age (s) of the last accepted fit that gives the tracked box (0: never tracked).
        track_margin: pixels added around the projected marker discs for the motion between frames.
    """

    def __init__(self, layout: MarkerLayout, camera: str, T_base_camera: np.ndarray,
                 detector: PlateDetector | None = None, roi_from_detector: bool = True, roi_pad: float = 0.2,
                 track_age: float = 0.1, track_margin: float = 24.0) -> None:
        self.layout = layout
        self.detector = detector
        self.roi_from_detector = roi_from_detector
        self.roi_pad = roi_pad
        self.track_age, self.track_margin = float(track_age), float(track_margin)
        self._last_fit: tuple[float, np.ndarray] | None = None   # (stamp, T_base_plate) of the newest accepted fit
        self.assembler = FrameAssembler(camera, T_base_camera)
        self.markers: MarkerDetector | None = None
        self._counters: Counter[str] = Counter()

    def set_camera_info(self, width: int, height: int, k: Sequence[float] | np.ndarray,
                        d: Sequence[float] | np.ndarray | None = None, detections_wanted: bool = True
                        ) -> PlatePose | None:
        """Update the intrinsics from CameraInfo fields (a new marker detector when they change); the pose of the
        frame that was paired before the first camera_info, else None."""
        frame = self.assembler.set_camera_info(width, height, k, d)
        cam = self.assembler.camera
        if cam is not None and not cam.same_as(self.markers.camera if self.markers else None):
            self.markers = MarkerDetector(self.layout, cam)
        return None if frame is None else self.process(frame, detections_wanted)

    def add_color(self, stamp: float, height: int, width: int, encoding: str, is_bigendian: int, step: int,
                  data: ImageData, detections_wanted: bool = True) -> PlatePose | None:
        """Add a colour image (sensor_msgs/Image fields); the pose of the frame it completes, or None."""
        frame = self.assembler.add_color(stamp, height, width, encoding, is_bigendian, step, data)
        return None if frame is None else self.process(frame, detections_wanted)

    def add_depth(self, stamp: float, height: int, width: int, encoding: str, is_bigendian: int, step: int,
                  data: ImageData, detections_wanted: bool = True) -> PlatePose | None:
        """Add a depth image (sensor_msgs/Image fields); the pose of the frame it completes, or None."""
        frame = self.assembler.add_depth(stamp, height, width, encoding, is_bigendian, step, data)
        return None if frame is None else self.process(frame, detections_wanted)

    def detector_box(self, detections: list[Detection]) -> tuple[float, float, float, float] | None:
        """The marker search box: the best detection padded by `roi_pad` of its size, or None."""
        if not detections or not self.roi_from_detector:
            return None
        b = detections[0].box
        pw, ph = self.roi_pad * (b[2] - b[0]), self.roi_pad * (b[3] - b[1])
        return (b[0] - pw, b[1] - ph, b[2] + pw, b[3] + ph)

    def tracked_box(self, stamp: float) -> tuple[float, float, float, float] | None:
        """The marker search box from the newest accepted fit when it is at most `track_age` s before `stamp`: the
        layout's markers at that pose projected into the image, padded by two disc radii and `track_margin` px; None
        when there is no such fit or a marker projects behind the camera."""
        if self._last_fit is None or self.markers is None or not self.roi_from_detector:
            return None
        t_fit, T = self._last_fit
        if not 0.0 <= stamp - t_fit <= self.track_age:
            return None
        cam = self.markers.camera
        uv, z = cam.project(self.layout.points @ T[:3, :3].T + T[:3, 3])
        if not (np.all(z > 0) and np.all(np.isfinite(uv))):
            return None
        pad = 2.0 * float(cam.K[0, 0]) * self.layout.radius / float(z.min()) + self.track_margin
        (u0, v0), (u1, v1) = uv.min(axis=0) - pad, uv.max(axis=0) + pad
        return (float(u0), float(v0), float(u1), float(v1))

    def process(self, frame: RGBDFrame, detections_wanted: bool = True) -> PlatePose:
        """Detector (when its output is used) and marker fit of one RGB-D frame."""
        c = self._counters
        c["frames"] += 1
        out = PlatePose(frame.stamp)
        roi = self.tracked_box(frame.stamp)
        if roi is not None:
            c["tracked boxes"] += 1
        if self.detector is not None and (detections_wanted or (self.roi_from_detector and roi is None)):
            out.detections = self.detector.detect(frame.rgb)
            c["detections"] += len(out.detections)
        if self.markers is None:
            c["no camera_info"] += 1
            return out
        if roi is None:
            roi = self.detector_box(out.detections)
        try:
            fit, _ = self.markers.estimate(frame.rgb, frame.depth, roi)
            if not fit.ok and roi is not None:
                fit, _ = self.markers.estimate(frame.rgb, frame.depth, None)
        except MarkerError:
            c["reject: marker input"] += 1
            return out
        if not fit.ok:
            c["marker fit rejected"] += 1
            return out
        c["poses"] += 1
        self._last_fit = (frame.stamp, fit.T)
        if fit.rejected:
            c["markers rejected as outliers"] += len(fit.rejected)
        out.fit = fit
        return out

    def count_reject(self, reason: str) -> None:
        """Count an input rejected before it reached the estimator (e.g. a malformed message)."""
        self._counters[f"reject: {reason}"] += 1

    def counters(self) -> Counter[str]:
        """Frames, detections, poses and every reject by reason (the pairing's included)."""
        merged = Counter(self._counters)
        merged.update(self.assembler.rejects)
        return merged

    def rejected(self) -> int:
        """How many inputs were rejected (frames without a pose, unusable images, outlier markers)."""
        return int(sum(v for k, v in self.counters().items() if k not in _WORK_COUNTERS))
