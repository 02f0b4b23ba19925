"""The isolation node's bookkeeping without ROS: which frame pairs are evaluated, when, with which pose
(hexa.vision.isolation_scheduler), and the raw image pairing it relies on (hexa.vision.sync)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from hexa.rotations import pose6_from_transform, transform_from_pose6
from hexa.vision.camera import intrinsics
from hexa.vision.images import numpy_to_image
from hexa.vision.isolation_scheduler import BACKGROUND, ISOLATE, IsolationScheduler
from hexa.vision.sync import FrameAssembler, ImagePairer, RawImage

CAMS = ("cam_top", "cam_side")


@dataclass(frozen=True)
class F:
    stamp: float


def _pose(x: float = 0.0, alpha: float = 0.0, z: float = -0.55) -> np.ndarray:
    return transform_from_pose6(np.array([x, 0.0, z, alpha, 0.0, 0.0]))


def _frames(s: IsolationScheduler, t0: float, n: int, now: float = 0.0, period: float = 1 / 30) -> None:
    for k in range(n):
        t = round(t0 + k * period, 6)
        for c in CAMS:
            s.add_frame(c, F(t), now)


def _sched(**kw) -> IsolationScheduler:
    kw.setdefault("background_delay", 1e9)        # no background work unless a test asks for it
    return IsolationScheduler(CAMS, **kw)


def test_onset_pair_waits_for_the_pose_of_its_stamp_and_is_the_debug_pair() -> None:
    s = _sched(max_pose_age=0.6)
    _frames(s, 10.0, 10)
    s.add_pose(9.9, _pose(0.0))
    s.collision_start(3, onset=10.1, now=100.0)
    assert s.due(100.1) == []                             # the pose of the onset frame has not arrived
    s.add_pose(10.4, _pose(0.03))
    work = s.due(100.2)
    first = work[0]
    assert first.kind == ISOLATE and first.debug and first.collision_id == 3 and not first.coarse
    assert first.stamp == pytest.approx(10.1, abs=1 / 60)
    assert set(first.frames) == set(CAMS)
    # interpolated at the frame's stamp between the poses around it
    x = 0.03 * (first.stamp - 9.9) / 0.5
    assert first.pose[0, 3] == pytest.approx(x, abs=1e-9)
    assert not any(w.debug for w in work[1:])


def test_buffered_pairs_after_the_onset_are_queued_every_eval_period() -> None:
    s = _sched(eval_period=0.1, max_pending=50)
    _frames(s, 10.0, 30)                                   # 1 s of frames at 30 fps
    s.collision_start(1, onset=10.0, now=0.0)
    stamps = [p.stamp for p in s.pending]
    assert stamps[0] == 10.0
    gaps = np.diff(stamps)
    assert np.all(gaps >= 0.1 - 1e-6) and np.all(gaps < 0.1 + 1 / 30)
    assert stamps == pytest.approx([10.0 + 0.1 * k for k in range(10)])


def test_new_frames_during_a_collision_are_queued_every_eval_period_and_stop_after_end() -> None:
    s = _sched(eval_period=0.1, max_pending=50)
    _frames(s, 10.0, 1)
    s.collision_start(1, onset=10.0, now=0.0)
    _frames(s, 10.0 + 1 / 30, 20)                          # live frames up to 10.67 s
    stamps = [p.stamp for p in s.pending]
    assert len(stamps) == 7 and np.all(np.diff(stamps) >= 0.1 - 1e-6)
    s.collision_end(1, 10.7)
    _frames(s, 10.7 + 1 / 30, 10)
    assert len(s.pending) == 7                              # no collision: nothing new queued


def test_frames_of_a_collision_that_arrive_after_its_end_are_still_queued() -> None:
    # at 1× the END (stamped at its sample) can reach the node before the last frames of its collision
    s = _sched(eval_period=0.1, max_pending=50, max_pose_age=5.0)
    _frames(s, 10.0, 1)
    s.collision_start(4, onset=10.0, now=0.0)
    _frames(s, 10.0 + 1 / 30, 11)                          # up to 10.367 s: pairs 10.0, 10.1, 10.2, 10.3
    s.collision_end(4, 10.449)
    _frames(s, 10.0 + 12 / 30, 6)                          # 10.4 (before the END) ... 10.567 (after it)
    s.add_pose(9.0, _pose())
    s.add_pose(11.0, _pose())
    work = s.due(0.1)
    assert [w.stamp for w in work] == pytest.approx([10.0, 10.1, 10.2, 10.3, 10.4])
    assert {w.collision_id for w in work} == {4}
    s.collision_start(5, onset=10.6, now=0.2)              # the onset pair (10.567 s) of the next collision
    s.collision_end(5, 10.65)
    _frames(s, 10.6, 1)                                   # within eval_period of it: not queued
    _frames(s, 10.7, 2)                                   # after its END: not queued
    assert [(p.collision_id, p.stamp) for p in s.pending] == [(5, pytest.approx(10.567, abs=1e-3))]


def test_pairs_stamped_after_the_end_are_skipped() -> None:
    s = _sched(eval_period=0.1, max_pending=50, max_pose_age=5.0)
    _frames(s, 10.0, 30)
    s.collision_start(5, onset=10.0, now=0.0)
    s.collision_end(5, 10.45)                              # the END reaches the node after the frames
    s.add_pose(11.0, _pose())
    s.add_pose(9.0, _pose())
    work = s.due(0.1)
    assert [w.stamp for w in work] == pytest.approx([10.0, 10.1, 10.2, 10.3, 10.4])
    assert s.counters["skipped: frame after END"] == 5 and not s.pending


def test_a_full_queue_drops_the_oldest_later_pair_never_the_onset_pair() -> None:
    s = _sched(eval_period=0.1, max_pending=3)
    _frames(s, 10.0, 30)
    s.collision_start(2, onset=10.0, now=0.0)
    assert [p.onset for p in s.pending] == [True, False, False]
    assert s.pending[0].stamp == 10.0
    assert [p.stamp for p in s.pending[1:]] == pytest.approx([10.8, 10.9])     # the newest ones stay
    assert s.counters["reject: pair dropped, queue full"] == 7


def test_a_pair_without_a_pose_expires_and_is_counted() -> None:
    s = _sched(pose_wait=0.5, pose_expiry=3.0)
    _frames(s, 10.0, 3)
    s.add_pose(5.0, _pose())                               # far older than max_pose_age, no estimates
    s.collision_start(1, onset=10.0, now=0.0)
    assert s.due(1.0) == [] and len(s.pending) == 1        # waits on past pose_wait
    assert s.due(3.1) == [] and not s.pending
    assert s.counters["reject: no plate pose for the frame pair"] == 1


def test_after_pose_wait_the_nearest_camera_pose_within_max_pose_age_is_used() -> None:
    s = _sched(pose_wait=0.5, max_pose_age=0.2)
    _frames(s, 10.0, 3)
    s.add_pose(9.9, _pose(0.01))
    s.collision_start(1, onset=10.0, now=0.0)
    assert s.due(0.4) == []
    (w,) = s.due(0.6)
    assert not w.coarse and w.pose[0, 3] == pytest.approx(0.01)
    assert s.counters["pose wait expired"] == 1


def test_the_last_camera_pose_is_carried_forward_by_the_estimate_difference() -> None:
    s = _sched(pose_wait=0.5, onset_pose_wait=1.0)        # the onset pair waits like the others
    _frames(s, 10.0, 3)
    T0 = transform_from_pose6(np.array([0.01, -0.02, -0.55, 0.05, 0.1, -0.02]))
    s.add_pose(9.8, T0)                                    # markers hidden from then on
    # the observer's estimate: offset from the camera by a static error, moving linearly
    est = lambda t: np.array([0.013 + 0.05 * (t - 9.8), -0.02, -0.552 + 0.02 * (t - 9.8),   # noqa: E731
                              0.05 + 0.1 * (t - 9.8), 0.1, -0.02 - 0.05 * (t - 9.8)])
    for t in np.arange(9.5, 10.2, 0.01):
        s.add_pose_estimate(float(t), transform_from_pose6(est(float(t))))
    s.collision_start(1, onset=10.0, now=0.0)
    assert s.due(0.4) == []
    (w,) = s.due(0.6)
    assert w.coarse and w.debug
    expected = pose6_from_transform(T0) + est(10.0) - est(9.8)
    assert np.allclose(pose6_from_transform(w.pose), expected, atol=1e-6)
    assert s.counters["pose carried forward"] == 1


def test_the_onset_pair_takes_a_recent_camera_pose_at_once_and_later_pairs_wait() -> None:
    s = _sched(pose_wait=0.5, onset_pose_age=0.05, eval_period=0.1)
    _frames(s, 10.0, 10)                                   # 10.0 … 10.3 s
    s.add_pose(10.0, _pose(0.01))                          # the pose node is one frame behind
    s.add_pose(10.0 + 1 / 30, _pose(0.012))
    s.collision_start(2, onset=10.07, now=0.0)             # onset pair at 10.067 s, queued pairs after it
    work = s.due(0.0)
    assert len(work) == 1 and len(s.pending) >= 2          # the onset pair only: the later ones wait for poses
    (w,) = work
    assert w.debug and w.coarse and w.collision_id == 2
    assert w.stamp == pytest.approx(10.0 + 2 / 30, abs=1e-6)
    assert w.pose[0, 3] == pytest.approx(0.012)            # the nearest pose received, not extrapolated
    assert s.counters["onset pair: pose already received"] == 1
    assert s.due(0.4) == []


def test_the_onset_pair_takes_the_estimate_carried_pose_at_once_and_waits_for_a_stale_one() -> None:
    s = _sched(onset_pose_age=0.05)
    _frames(s, 10.0, 3)
    s.add_pose(9.8, _pose(0.0))                            # 0.2 s before the onset: too old on its own
    s.collision_start(1, onset=10.0, now=0.0)
    assert s.due(0.0) == []                                # no estimate: waits for a camera pose of its stamp
    for t in np.arange(9.7, 10.05, 0.01):
        s.add_pose_estimate(float(t), _pose(0.1 * (t - 9.8)))
    (w,) = s.due(0.01)
    assert w.debug and w.coarse and w.pose[0, 3] == pytest.approx(0.02, abs=1e-6)
    # with onset_pose_wait the onset pair first waits for the camera pose of its stamp
    s = _sched(onset_pose_wait=0.03)
    _frames(s, 10.0, 3)
    s.add_pose(10.0 - 1 / 30, _pose(0.0))
    s.collision_start(1, onset=10.0, now=0.0)
    assert s.due(0.02) == []
    (w,) = s.due(0.04)
    assert w.coarse


def test_a_carried_pose_waits_for_the_estimate_of_the_stamp() -> None:
    s = _sched(pose_wait=0.5, pose_expiry=3.0)
    _frames(s, 10.0, 3)
    s.add_pose(9.9, _pose(0.0))
    for t in np.arange(9.5, 9.95, 0.01):                   # the estimate lags: not at 10.0 s yet
        s.add_pose_estimate(float(t), _pose(0.0))
    s.collision_start(1, onset=10.0, now=0.0)
    assert s.due(0.6) == []                                # not the nearest camera pose: the estimate is coming
    for t in np.arange(9.95, 10.1, 0.01):
        s.add_pose_estimate(float(t), _pose(0.02 * (t - 9.9)))
    (w,) = s.due(0.7)
    assert w.coarse and w.pose[0, 3] == pytest.approx(0.002, abs=1e-6)


def test_backgrounds_come_after_the_delay_and_again_on_request() -> None:
    s = IsolationScheduler(CAMS, background_delay=0.5)
    _frames(s, 1.0, 10)                                    # 0.3 s of frames: too early
    assert s.due(0.0) == []
    _frames(s, 1.5, 2)
    work = s.due(0.0)
    assert sorted(next(iter(w.frames)) for w in work) == sorted(CAMS)
    assert all(w.kind == BACKGROUND and w.stamp == pytest.approx(1.5 + 1 / 30) for w in work)
    s.background_taken("cam_top")                          # cam_side's frame was not usable: offered again
    _frames(s, 1.6, 1)
    assert [next(iter(w.frames)) for w in s.due(0.0)] == ["cam_side"]
    s.background_taken("cam_side")
    _frames(s, 1.7, 1)
    assert s.due(0.0) == []
    s.capture_background()
    _frames(s, 1.8, 1)
    assert len(s.due(0.0)) == 2


def test_image_pairer_pairs_raw_images_by_stamp_and_the_assembler_decodes_them_on_demand() -> None:
    rgb = np.full((6, 8, 3), 9, np.uint8)
    depth = np.full((6, 8), 700, np.uint16)

    def raw(stamp: float, a: np.ndarray, enc: str) -> RawImage:
        f = numpy_to_image(a, enc)
        return RawImage(stamp, f.height, f.width, f.encoding, f.is_bigendian, f.step, np.frombuffer(f.data, np.uint8))

    pr = ImagePairer()
    assert pr.add(raw(1.0, depth, "16UC1"), color=False) is None
    assert pr.add(raw(2.0, rgb, "rgb8"), color=True) is None
    pair = pr.add(raw(1.0, rgb, "rgb8"), color=True)
    assert pair is not None and pair.stamp == 1.0 and pair.color.encoding == "rgb8" and pr.frames == 1
    fa = FrameAssembler("cam_top", np.eye(4))
    assert fa.assemble(pair) is None and fa.rejects["no camera_info"] == 1
    fa.set_camera_info(8, 6, intrinsics(8, 6, 1.0).reshape(-1).tolist())
    frame = fa.assemble(pair)
    assert frame is not None and frame.rgb[0, 0].tolist() == [9, 9, 9] and frame.depth[0, 0] == pytest.approx(0.7)
    bad = pr.add(raw(3.0, depth[:, :4].copy(), "16UC1"), color=False)
    assert bad is None
    assert fa.assemble(pr.add(raw(3.0, rgb, "rgb8"), color=True)) is None
    assert fa.rejects["colour/depth size mismatch"] == 1


def test_a_batch_of_images_taken_per_topic_pairs_into_every_frame() -> None:
    """Ten colour images, then ten depth images of each camera (as the readers hand them over): every frame pairs
    (the pairer alone keeps five unpaired images), and a collision queues pairs of both cameras."""
    def raw(stamp: float) -> RawImage:
        return RawImage(stamp, 2, 2, "rgb8", 0, 6, b"\0" * 12)

    s = _sched(eval_period=0.1, max_pending=50)
    s.collision_start(1, onset=10.0, now=0.0)             # nothing buffered yet: no onset pair
    stamps = [round(10.0 + k / 30, 6) for k in range(10)]
    batch = [(c, raw(t), color) for c in CAMS for color in (True, False) for t in stamps]
    s.add_images(batch, now=0.0)
    assert all(s.counters[f"{c}: frames paired"] == 10 for c in CAMS)
    assert [f.stamp for f in s.frames["cam_side"]] == stamps
    assert s.pending and all(set(p.frames) == set(CAMS) for p in s.pending)
