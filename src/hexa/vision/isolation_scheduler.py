"""Collision isolation in the live graph: which frame pairs to evaluate, when, and with which plate pose.

`IsolationScheduler` holds the bookkeeping of the isolation node, with the wall clock passed in:

- a ring buffer of frames per camera (any object with a `stamp`; `add_image` pairs undecoded colour and depth
  images into a `RawFrame`), and the background frames wanted (the first frames `background_delay` s of frame time
  after start-up, and again on request);
- on a collision START the buffered pair nearest the onset ("onset pair") and the buffered pairs after it, then each
  new complete pair while the collision lasts, spaced at least `eval_period` s of frame time apart;
- a queue of at most `max_pending` pairs waiting for the camera plate pose of their stamp (the pose node lags the
  cameras); the onset pair is never dropped for a newer one;
- the onset pair (the first contact, wanted at once) waits at most `onset_pose_wait` wall s for the camera pose of
  its stamp; then it takes the newest camera pose carried forward by the observer's estimate, or the nearest camera
  pose within `onset_pose_age` s, with the wider robot mask of a coarse pose (`Work.coarse`); with neither, it
  waits like the other pairs;
- the pose of a pair: interpolated at its stamp once a camera pose at or after the stamp has arrived; after
  `pose_wait` wall seconds, the newest camera pose before the stamp carried forward by the observer's tracked pose
  (`add_pose_estimate`): pose(t) = pose_cam(t0) + est(t) − est(t0) in x y z and Z-Y-X angles (the difference cancels
  the static offset between the model's and the camera's pose; `Work.coarse`) once the estimate of t has arrived,
  else the nearest camera pose within `max_pose_age`; a pair still without a pose after `pose_expiry` wall seconds
  is dropped;
- pairs stamped after their collision's END are skipped; frames stamped up to the END that reach the node after it
  (at 1× the END can overtake the last frames of its collision, taken from the readers every 0.05 s) still are.

`ContactLocator` does the work: decodes a pair (`FrameAssembler`), takes backgrounds and isolates the contact with
the robot drawn at the work's pose (a wider robot mask for a coarse pose).
"""
from __future__ import annotations

import dataclasses
import math
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.rotations import pose6_from_transform, transform_from_pose6
from hexa.vision.camera import CameraModel
from hexa.vision.isolation import (
    LINK_UNKNOWN,
    CollisionIsolator,
    ContactEstimate,
    IsolationError,
    RobotGeometry,
    debug_image,
)
from hexa.vision.sync import FrameAssembler, ImagePairer, PoseBuffer, RawFrame, RawImage, RGBDFrame

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

ISOLATE, BACKGROUND = "isolate", "background"


@dataclass(frozen=True)
class Work:
    """One thing for the locator to do: take a `BACKGROUND` from `frames` (one camera) or `ISOLATE` the pair.

    stamp: newest frame stamp (s); pose: 4x4 plate pose in base at `stamp` (None for a background); coarse: the
    pose is carried forward by the observer's estimate (good to a few mm); collision_id: the collision the pair
    belongs to; debug: the onset pair (the only one worth a debug image).
    """

    kind: str
    frames: dict[str, Any]
    stamp: float
    pose: np.ndarray | None = None
    coarse: bool = False
    collision_id: int = 0
    debug: bool = False


@dataclass
class _Pending:
    queued: float        # wall s
    frames: dict[str, Any]
    stamp: float
    onset: bool
    collision_id: int


class IsolationScheduler:
    """The isolation node's frames, poses, collisions and queue (module docstring); `due(now)` hands out the work.

    Args:
        cameras: camera names; a pair holds one frame of each.
        keep: frames kept per camera.
        max_pending: pairs queued at most while waiting for their pose.
        pose_wait: wall s a pair waits for a camera pose at or after its stamp.
        pose_expiry: wall s after which a pair without any pose is dropped.
        max_pose_age: s; the largest gap between camera poses to interpolate across, or to the nearest pose.
        eval_period: s of frame time between evaluated pairs during a collision.
        background_delay: s of frame time after the first frame before the backgrounds are taken.
        pair_tolerance: s; the largest stamp difference between the frames of a pair.
        estimate_gap: s; the largest gap between pose estimates to interpolate across, or to the nearest one.
        onset_pose_wait: wall s the onset pair waits for the camera pose of its stamp before it takes a pose
            already received (`onset_pose_age`).
        onset_pose_age: s; the oldest camera pose the onset pair takes (nearest to its stamp) without an estimate.
    """

    def __init__(self, cameras: Sequence[str] = ("cam_top", "cam_side"), *, keep: int = 30, max_pending: int = 8,
                 pose_wait: float = 0.5, pose_expiry: float = 3.0, max_pose_age: float = 0.2,
                 eval_period: float = 0.1, background_delay: float = 1.0, pair_tolerance: float = 0.02,
                 estimate_gap: float = 0.05, onset_pose_wait: float = 0.0, onset_pose_age: float = 0.05) -> None:
        if not cameras:
            raise ValueError("IsolationScheduler needs at least one camera")
        if max_pending < 1:
            raise ValueError(f"max_pending must be at least 1, got {max_pending}")
        self.cameras = tuple(cameras)
        self.max_pending, self.pose_wait, self.pose_expiry = int(max_pending), pose_wait, pose_expiry
        self.max_pose_age, self.eval_period, self.background_delay = max_pose_age, eval_period, background_delay
        self.pair_tolerance, self.estimate_gap = pair_tolerance, estimate_gap
        self.onset_pose_wait, self.onset_pose_age = onset_pose_wait, onset_pose_age
        self.frames: dict[str, deque[Any]] = {c: deque(maxlen=keep) for c in self.cameras}
        self.poses = PoseBuffer(keep=400)
        self.estimates = PoseBuffer(keep=1000)
        self.pending: list[_Pending] = []
        self.ended: dict[int, float] = {}      # collision id → END stamp
        self.active: int | None = None
        self._last_end: tuple[int, float] | None = None     # the last collision that ended: (id, END stamp)
        self.counters: Counter[str] = Counter()
        self._last_eval = -math.inf
        self._t_first: float | None = None
        self._want_background = set(self.cameras)
        self._background: dict[str, Any] = {}
        self._pairers = {c: ImagePairer() for c in self.cameras}

    # ------------------------------------------------------------------ inputs
    def add_image(self, cam: str, image: RawImage, color: bool, now: float) -> None:
        """An undecoded colour (`color` True) or depth image of `cam`; the frame it completes goes to `add_frame`."""
        frame = self._pairers[cam].add(image, color)
        if frame is not None:
            self.counters[f"{cam}: frames paired"] += 1
            self.add_frame(cam, frame, now)

    def add_images(self, images: Sequence[tuple[str, RawImage, bool]], now: float) -> None:
        """Images taken in a batch, (camera, image, colour?) in any order: added in stamp order, colour before depth,
        so that each camera's colour and depth pair up and the cameras' frames pair up."""
        for cam, image, color in sorted(images, key=lambda i: (i[1].stamp, i[0], not i[2])):
            self.add_image(cam, image, color, now)

    def add_frame(self, cam: str, frame: Any, now: float) -> None:
        """Buffer a frame of `cam` (anything with `stamp`); during a collision, queue the pair it completes."""
        self.frames[cam].append(frame)
        if self._t_first is None:
            self._t_first = frame.stamp
        if cam in self._want_background and frame.stamp - self._t_first >= self.background_delay:
            self._background[cam] = frame
        collision = self.active
        if collision is None and self._last_end is not None and frame.stamp <= self._last_end[1] + 1e-3:
            collision = self._last_end[0]                  # a frame of the collision that came after its END
        if collision is not None and frame.stamp - self._last_eval >= self.eval_period - 1e-6:
            pair = self._pair(cam, frame)
            if pair is not None:
                self._last_eval = frame.stamp
                self._submit(pair, now, onset=False, collision_id=collision)

    def add_pose(self, t: float, T: np.ndarray) -> None:
        """A camera plate pose (4x4 in base) of stamp `t`."""
        self.poses.add(t, T)
        self.counters["plate poses"] += 1

    def add_pose_estimate(self, t: float, T: np.ndarray) -> None:
        """The observer's tracked plate pose (4x4 in base) at sample time `t`."""
        self.estimates.add(t, T)

    def collision_start(self, collision_id: int, onset: float, now: float) -> None:
        """Queue the buffered pair nearest `onset` and the buffered pairs after it (every `eval_period`)."""
        self.active = int(collision_id)
        self._last_end = None
        self.counters["collisions"] += 1
        onset_pair = {c: min(fs, key=lambda f: abs(f.stamp - onset)) for c, fs in self.frames.items() if fs}
        if not onset_pair:
            return
        self._last_eval = max(f.stamp for f in onset_pair.values())
        self._submit(onset_pair, now, onset=True)
        # the START comes late under load: the frames after the onset are already here
        for f in sorted(self.frames[self.cameras[0]], key=lambda f: f.stamp):
            if f.stamp - self._last_eval >= self.eval_period - 1e-6:
                pair = self._pair(self.cameras[0], f)
                if pair is not None:
                    self._last_eval = f.stamp
                    self._submit(pair, now, onset=False)

    def collision_end(self, collision_id: int, stamp: float) -> None:
        """The collision ended at `stamp`: its pairs stamped later are skipped."""
        self.ended[int(collision_id)] = stamp
        while len(self.ended) > 100:
            del self.ended[next(iter(self.ended))]
        if self.active == int(collision_id):
            self.active = None
            self._last_end = (int(collision_id), float(stamp))

    def capture_background(self) -> None:
        """Take the next frame of every camera as its background."""
        self._want_background = set(self.cameras)

    def background_taken(self, cam: str) -> None:
        """The locator took `cam`'s background (until then every new frame is offered)."""
        self._want_background.discard(cam)

    # ------------------------------------------------------------------ work
    def due(self, now: float) -> list[Work]:
        """The work to do now, backgrounds first, then the pairs whose pose is known, oldest first."""
        out = [Work(BACKGROUND, {c: f}, f.stamp) for c, f in self._background.items()]
        self._background.clear()
        keep = []
        for p in self.pending:
            waited = now - p.queued
            coarse = False
            if p.collision_id in self.ended and p.stamp > self.ended[p.collision_id] + 1e-3:
                self.counters["skipped: frame after END"] += 1
                continue
            if self.poses.covers(p.stamp):
                T = self.poses.at(p.stamp, self.max_pose_age)
                if T is None:                  # the camera lost the plate around the stamp
                    T = self.carried_pose(p.stamp)
                    coarse = T is not None
            elif p.onset and waited >= self.onset_pose_wait and (T := self.received_pose(p.stamp)) is not None:
                coarse = True
                self.counters["onset pair: pose already received"] += 1
            elif waited > self.pose_wait:
                T = self.carried_pose(p.stamp)
                coarse = T is not None
                if T is None and waited <= self.pose_expiry and self.estimates.latest is not None \
                        and not self.estimates.covers(p.stamp):
                    keep.append(p)             # the estimate of the stamp is on its way
                    continue
                if T is None:
                    T = self.poses.at(p.stamp, self.max_pose_age)
                if T is None and waited <= self.pose_expiry:
                    keep.append(p)
                    continue
                self.counters["pose wait expired"] += 1
            else:
                keep.append(p)
                continue
            if T is None:
                self.counters["reject: no plate pose for the frame pair"] += 1
                continue
            self.counters["pose carried forward"] += int(coarse)
            out.append(Work(ISOLATE, p.frames, p.stamp, T, coarse, p.collision_id, p.onset))
        self.pending = keep
        return out

    def carried_pose(self, stamp: float) -> np.ndarray | None:
        """pose_cam(t0) + est(stamp) − est(t0) (x y z, Z-Y-X angles) with t0 the newest camera pose at or before
        `stamp`; None without such a pose or without estimates at t0 and at `stamp`."""
        before = self.poses.before(stamp)
        if before is None:
            return None
        t0, T0 = before
        e0, e1 = self.estimates.at(t0, self.estimate_gap), self.estimates.at(stamp, self.estimate_gap)
        if e0 is None or e1 is None:
            return None
        d = pose6_from_transform(e1) - pose6_from_transform(e0)
        d[3:] = (d[3:] + np.pi) % (2 * np.pi) - np.pi
        return transform_from_pose6(pose6_from_transform(T0) + d)

    def received_pose(self, stamp: float) -> np.ndarray | None:
        """A pose for `stamp` from what has arrived: the camera pose carried forward by the estimate
        (`carried_pose`), else the nearest camera pose within `onset_pose_age` s, else None."""
        T = self.carried_pose(stamp)
        return T if T is not None else self.poses.at(stamp, self.onset_pose_age)

    def _pair(self, cam: str, frame: Any) -> dict[str, Any] | None:
        """`frame` with the nearest frame of every other camera within `pair_tolerance`, or None."""
        pair = {cam: frame}
        for c in self.cameras:
            if c != cam:
                near = min(self.frames[c], key=lambda f: abs(f.stamp - frame.stamp), default=None)
                if near is None or abs(near.stamp - frame.stamp) > self.pair_tolerance:
                    return None
                pair[c] = near
        return pair

    def _submit(self, frames: dict[str, Any], now: float, onset: bool, collision_id: int | None = None) -> None:
        stamp = max(f.stamp for f in frames.values())
        if collision_id is None:
            collision_id = self.active if self.active is not None else 0
        self.pending.append(_Pending(now, frames, stamp, onset, collision_id))
        while len(self.pending) > self.max_pending:
            drop = next((i for i, p in enumerate(self.pending) if not p.onset), 0)
            self.pending.pop(drop)
            self.counters["reject: pair dropped, queue full"] += 1


@dataclass
class Located:
    """An isolated pair: the work, the answer and the robot geometry it was drawn with."""

    work: Work
    estimate: ContactEstimate
    geometry: RobotGeometry
    frames: dict[str, RGBDFrame] = field(repr=False, default_factory=dict)

    def summary(self) -> str:
        """One log line: stamp, link, chain, camera, point (mm) and each camera's reason."""
        e = self.estimate
        point = np.round(1e3 * np.asarray(e.point), 1).tolist()
        per = "; ".join(f"{c}: {r.link} {r.chain} {r.reason}" for c, r in e.per_camera.items())
        return (f"isolation at {self.work.stamp:.3f} s ({'carried' if self.work.coarse else 'camera'} pose, cameras "
                f"{sorted(self.frames)}): {e.link_name} {e.chain} from {e.camera}, point {point} mm; {per}")


class ContactLocator:
    """Decodes the scheduler's frames on demand, takes backgrounds and isolates contacts.

    Args:
        desc: the Hexa description (robot geometry from a plate pose through IK).
        cameras: camera models by name (intrinsics and extrinsics of the description).
        coarse_margin: m added around the drawn robot when the pose is carried forward.
    """

    def __init__(self, desc: HexaDescription, cameras: dict[str, CameraModel], coarse_margin: float = 0.008) -> None:
        self.desc = desc
        self.isolator = CollisionIsolator(cameras)
        self.assemblers = {c: FrameAssembler(c, m.T_base_camera) for c, m in cameras.items()}
        self.coarse_margin = coarse_margin
        self.counters: Counter[str] = Counter()

    def all_counters(self) -> Counter[str]:
        """The locator's counters with the assemblers' rejects ("reject: <camera> <reason>") and frame counts."""
        out = Counter(self.counters)
        for name, a in self.assemblers.items():
            out.update({f"reject: {name} {k}": v for k, v in a.rejects.items()})
            out[f"{name}: frames decoded"] = a.frames
        return out

    def take_background(self, work: Work) -> bool:
        """Make the work's frame its camera's background; False when it cannot be decoded or used (counted)."""
        (cam, raw), = work.frames.items()
        frame = self._decode(cam, raw)
        if frame is None:
            return False
        try:
            self.isolator.set_background(cam, frame.rgb, frame.depth)
        except IsolationError:
            self.counters["reject: background frame"] += 1
            return False
        self.counters[f"background {cam}"] += 1
        return True

    def locate(self, work: Work, debug: bool = False) -> Located | None:
        """Isolate the work's pair; None when nothing could be evaluated (the reason counted)."""
        frames = {}
        for cam, raw in work.frames.items():
            if cam not in self.isolator.backgrounds:
                self.counters["reject: no background"] += 1
                continue
            frame = self._decode(cam, raw)
            if frame is not None:
                frames[cam] = frame
        if not frames or work.pose is None:
            return None
        try:
            geom = RobotGeometry.from_state(self.desc, pose6_from_transform(work.pose))
        except Exception:  # noqa: BLE001 - IK fails for an unreachable pose (a bad fit): nothing to draw
            self.counters["reject: plate pose unreachable"] += 1
            return None
        config = self.isolator.config
        if work.coarse:
            self.isolator.config = dataclasses.replace(config, robot_margin_m=self.coarse_margin)
        try:
            est = self.isolator.isolate({c: (f.rgb, f.depth) for c, f in frames.items()}, geom, debug=debug)
        except IsolationError:
            self.counters["reject: isolation error"] += 1
            return None
        finally:
            self.isolator.config = config
        self.counters["evaluations"] += 1
        self.counters["contacts" if est.link != LINK_UNKNOWN else "no contact found"] += 1
        return Located(work, est, geom, frames)

    def debug_mosaic(self, located: Located) -> np.ndarray:
        """The debug mosaic (RGB uint8) of the answering camera; `locate` must have run with debug=True."""
        per = located.estimate.per_camera
        res = per.get(located.estimate.camera) or next(iter(per.values()))
        return debug_image(res, self.isolator, located.geometry)

    def _decode(self, cam: str, frame: RawFrame | RGBDFrame) -> RGBDFrame | None:
        return self.assemblers[cam].assemble(frame) if isinstance(frame, RawFrame) else frame
