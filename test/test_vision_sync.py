"""Frame assembly from message fields: stamp pairing, and bad input counted and skipped (never raised)."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.vision.camera import intrinsics
from hexa.vision.images import numpy_to_image
from hexa.vision.sync import FrameAssembler

K = intrinsics(8, 6, 1.0).reshape(-1).tolist()


def _fields(a: np.ndarray, enc: str):
    f = numpy_to_image(a, enc)
    return f.height, f.width, f.encoding, f.is_bigendian, f.step, f.data


def _assembler() -> FrameAssembler:
    fa = FrameAssembler("cam_top", np.eye(4))
    fa.set_camera_info(8, 6, K)
    return fa


def test_colour_and_depth_with_equal_stamps_make_a_frame() -> None:
    fa = _assembler()
    rgb = np.full((6, 8, 3), 7, np.uint8)
    depth = np.full((6, 8), 500, np.uint16)
    depth[0, 0] = 0
    assert fa.add_color(1.0, *_fields(rgb, "rgb8")) is None
    assert fa.add_depth(2.0, *_fields(depth, "16UC1")) is None       # no partner yet
    f = fa.add_depth(1.0, *_fields(depth, "16UC1"))
    assert f is not None and f.stamp == 1.0 and f.rgb.shape == (6, 8, 3)
    assert np.isnan(f.depth[0, 0]) and f.depth[1, 1] == np.float32(0.5)
    assert fa.frames == 1 and not fa.rejects


def test_bgr_input_is_converted_to_rgb() -> None:
    fa = _assembler()
    bgr = np.zeros((6, 8, 3), np.uint8)
    bgr[..., 0] = 255
    fa.add_color(1.0, *_fields(bgr, "bgr8"))
    f = fa.add_depth(1.0, *_fields(np.full((6, 8), 1.0, np.float32), "32FC1"))
    assert f is not None and f.rgb[0, 0].tolist() == [0, 0, 255]


def test_bad_input_is_counted_and_skipped() -> None:
    fa = FrameAssembler("cam_top", np.eye(4))
    rgb = np.zeros((6, 8, 3), np.uint8)
    depth = np.full((6, 8), 500, np.uint16)
    fa.add_color(1.0, *_fields(rgb, "rgb8"))
    assert fa.add_depth(1.0, *_fields(depth, "16UC1")) is None           # no camera_info yet: held
    assert fa.set_camera_info(8, 6, [0.0] * 9) is None                   # empty camera_info
    first = fa.set_camera_info(8, 6, K)                                  # the held pair, now usable
    assert first is not None and first.stamp == 1.0 and first.depth[0, 0] == pytest.approx(0.5)
    assert fa.set_camera_info(8, 6, K) is None                           # given once
    h, w, _, be, step, data = _fields(rgb, "rgb8")
    assert fa.add_color(2.0, h, w, "yuv422", be, step, data) is None     # unknown encoding
    assert fa.add_color(3.0, h, w, "rgb8", be, step, data[:10]) is None  # truncated data
    assert fa.add_depth(4.0, *_fields(np.zeros((6, 8), np.uint16), "16UC1")) is None   # empty depth
    fa.add_color(5.0, *_fields(np.zeros((4, 8, 3), np.uint8), "rgb8"))
    assert fa.add_depth(5.0, *_fields(depth[:4], "16UC1")) is None      # frame smaller than camera_info
    fa.add_color(6.0, *_fields(np.zeros((6, 8, 3), np.uint8), "rgb8"))
    assert fa.add_depth(6.0, *_fields(np.full((4, 8), 500, np.uint16), "16UC1")) is None  # colour/depth differ
    assert fa.rejects == {"bad camera_info": 1, "bad colour image": 2, "empty depth": 1,
                          "frame/camera_info size mismatch": 1, "colour/depth size mismatch": 1}
    assert fa.frames == 1


def test_of_the_pairs_before_the_first_camera_info_the_newest_is_held_the_older_counted() -> None:
    fa = FrameAssembler("cam_top", np.eye(4))
    for t in (1.0, 2.0):
        fa.add_color(t, *_fields(np.zeros((6, 8, 3), np.uint8), "rgb8"))
        assert fa.add_depth(t, *_fields(np.full((6, 8), 500, np.uint16), "16UC1")) is None
    frame = fa.set_camera_info(8, 6, K)
    assert frame is not None and frame.stamp == 2.0
    assert fa.rejects == {"no camera_info": 1} and fa.frames == 1


def test_an_image_whose_partner_never_comes_is_dropped_and_counted_once_the_queue_is_full() -> None:
    fa = _assembler()                                   # keeps 5 unpaired images of each kind
    rgb = np.zeros((6, 8, 3), np.uint8)
    for k in range(7):                                  # colour only: the depth topic lost these
        assert fa.add_color(float(k), *_fields(rgb, "rgb8")) is None
    assert fa.rejects == {"unpaired colour image": 2}
    assert fa.add_depth(1.0, *_fields(np.full((6, 8), 500, np.uint16), "16UC1")) is None   # its colour was dropped
    f = fa.add_depth(6.0, *_fields(np.full((6, 8), 500, np.uint16), "16UC1"))
    assert f is not None and f.stamp == 6.0 and fa.frames == 1
    assert fa.rejects == {"unpaired colour image": 2}
