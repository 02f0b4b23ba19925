"""Image field conversion (step padding, endianness, encodings) and the pinhole camera model."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexa.vision.camera import CameraModel, CameraModelError, intrinsics, look_at
from hexa.vision.images import (
    ENCODINGS,
    ImageConversionError,
    depth_to_meters,
    image_to_numpy,
    numpy_to_image,
    to_rgb,
)


def _array_for(encoding: str, h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    kind, c = ENCODINGS[encoding]
    shape = (h, w) if c == 1 else (h, w, c)
    if kind == "f4":
        return rng.normal(size=shape).astype(np.float32)
    return rng.integers(0, 2 ** (8 * np.dtype(kind).itemsize), size=shape).astype(kind)


@settings(max_examples=80, deadline=None)
@given(encoding=st.sampled_from(sorted(ENCODINGS)), h=st.integers(1, 7), w=st.integers(1, 9),
       pad=st.integers(0, 7), big=st.booleans(), seed=st.integers(0, 1000))
def test_round_trip_any_encoding_step_and_endianness(encoding, h, w, pad, big, seed) -> None:
    a = _array_for(encoding, h, w, np.random.default_rng(seed))
    row = a[0].nbytes
    f = numpy_to_image(a, encoding, step=row + pad, bigendian=big)
    assert f.step == row + pad and len(f.data) == f.step * h
    b = image_to_numpy(f.height, f.width, f.encoding, f.is_bigendian, f.step, f.data)
    assert b.dtype.isnative and b.shape == a.shape
    np.testing.assert_array_equal(a, b)


def test_big_endian_depth_bytes_are_swapped() -> None:
    data = bytes([0x01, 0x02, 0x00, 0x10])  # 2 pixels, big-endian 0x0102 = 258, 0x0010 = 16
    a = image_to_numpy(1, 2, "16UC1", 1, 4, data)
    assert a.tolist() == [[258, 16]]
    a_le = image_to_numpy(1, 2, "16UC1", 0, 4, data)
    assert a_le.tolist() == [[0x0201, 0x1000]]


def test_bgr_and_rgba_to_rgb() -> None:
    px = np.array([[[10, 20, 30]]], np.uint8)
    assert to_rgb(px, "bgr8").tolist() == [[[30, 20, 10]]]
    assert to_rgb(np.array([[[1, 2, 3, 4]]], np.uint8), "rgba8").tolist() == [[[1, 2, 3]]]
    assert to_rgb(np.array([[[1, 2, 3, 4]]], np.uint8), "bgra8").tolist() == [[[3, 2, 1]]]
    with pytest.raises(ImageConversionError, match="16UC1"):
        to_rgb(np.zeros((1, 1), np.uint16), "16UC1")


def test_depth_zero_is_invalid_and_mm_become_metres() -> None:
    d = depth_to_meters(np.array([[0, 1500]], np.uint16), "16UC1")
    assert np.isnan(d[0, 0]) and d[0, 1] == pytest.approx(1.5)
    f = depth_to_meters(np.array([[0.0, np.inf, 0.7]], np.float32), "32FC1")
    assert np.isnan(f[0, 0]) and np.isnan(f[0, 1]) and f[0, 2] == pytest.approx(0.7)


@pytest.mark.parametrize("args, fragment", [
    ((2, 2, "yuv422", 0, 4, b"\0" * 8), "unsupported encoding 'yuv422'"),
    ((2, 2, "rgb8", 0, 5, b"\0" * 12), "step 5 is shorter"),
    ((2, 2, "rgb8", 0, 6, b"\0" * 7), "data has 7 B"),
    ((0, 2, "mono8", 0, 2, b""), "empty image"),
])
def test_bad_fields_raise_naming_the_value(args, fragment) -> None:
    with pytest.raises(ImageConversionError, match=fragment):
        image_to_numpy(*args)


def test_array_encoding_mismatch_is_rejected() -> None:
    with pytest.raises(ImageConversionError, match="uint8"):
        numpy_to_image(np.zeros((2, 2), np.uint8), "16UC1")
    with pytest.raises(ImageConversionError, match="3 channel"):
        numpy_to_image(np.zeros((2, 2), np.uint8), "rgb8")
    with pytest.raises(ImageConversionError, match="dtype"):
        numpy_to_image(np.zeros((2, 2), np.float64), "32FC1")


@settings(max_examples=60, deadline=None)
@given(u=st.floats(0, 639), v=st.floats(0, 479), z=st.floats(0.1, 3.0), seed=st.integers(0, 1000))
def test_project_back_project_round_trip(u, v, z, seed) -> None:
    rng = np.random.default_rng(seed)
    T = look_at(rng.uniform(-1, 1, 3) + [0, 0, 1.0], rng.uniform(-0.2, 0.2, 3))
    cam = CameraModel(intrinsics(640, 480, np.radians(58)), 640, 480, T)
    p = cam.back_project(np.array([u, v]), z)
    uv, depth = cam.project(p)
    assert np.allclose(uv, [u, v], atol=1e-6) and depth == pytest.approx(z)
    assert np.allclose(cam.ray(np.array([u, v])), (p - cam.position) / np.linalg.norm(p - cam.position))


def test_look_at_points_the_optical_axis_at_the_target() -> None:
    T = look_at([0.0, 0.0, 0.3], [0.0, 0.0, -0.5])
    cam = CameraModel(intrinsics(640, 480, 1.0), 640, 480, T)
    uv, z = cam.project(np.array([0.0, 0.0, -0.5]))
    assert np.allclose(uv, [319.5, 239.5]) and z == pytest.approx(0.8)


def test_camera_info_round_trip_and_rejections() -> None:
    cam = CameraModel(intrinsics(640, 480, 1.0), 640, 480)
    f = cam.camera_info_fields()
    back = CameraModel.from_camera_info(f["width"], f["height"], f["k"], f["d"])
    assert np.allclose(back.K, cam.K)
    with pytest.raises(CameraModelError, match="9 values"):
        CameraModel.from_camera_info(640, 480, [0.0] * 9)
    with pytest.raises(CameraModelError, match="distortion"):
        CameraModel.from_camera_info(640, 480, f["k"], [0.1, 0, 0, 0, 0])
    with pytest.raises(CameraModelError, match="size"):
        CameraModel(cam.K, 0, 480)
