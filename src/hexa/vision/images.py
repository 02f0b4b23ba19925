"""numpy ↔ sensor_msgs/Image fields, written once (no cv_bridge here): step padding, endianness, encodings."""
from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

#: encoding → (numpy dtype without byte order, channels)
ENCODINGS: dict[str, tuple[str, int]] = {
    "rgb8": ("u1", 3),
    "bgr8": ("u1", 3),
    "rgba8": ("u1", 4),
    "bgra8": ("u1", 4),
    "mono8": ("u1", 1),
    "8UC1": ("u1", 1),
    "8UC3": ("u1", 3),
    "mono16": ("u2", 1),
    "16UC1": ("u2", 1),
    "32FC1": ("f4", 1),
}


#: a sensor_msgs/Image's `data` as `image_to_numpy` takes it: a buffer, a numpy array (any dtype: its bytes) or a list
#: of byte values
ImageData = bytes | bytearray | memoryview | np.ndarray | list


class ImageConversionError(ValueError):
    """Image fields are inconsistent (size, step, encoding) or the array does not fit the requested encoding."""


@dataclass(frozen=True)
class ImageFields:
    """The sensor_msgs/Image fields without the header."""

    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: bytes


def image_to_numpy(height: int, width: int, encoding: str, is_bigendian: int | bool, step: int,
                   data: ImageData) -> np.ndarray:
    """Array (H, W) or (H, W, C) in native byte order from sensor_msgs/Image fields.

    Rows may be padded (step > width·bytes per pixel); the padding is dropped. Big-endian multi-byte data is
    byte-swapped to native order. The channel order is kept as encoded (bgr8 stays BGR; see `to_rgb`).

    Raises:
        ImageConversionError: unknown encoding, zero size, step shorter than a row, or data shorter than height·step.
    """
    if encoding not in ENCODINGS:
        raise ImageConversionError(f"unsupported encoding {encoding!r}; supported: {sorted(ENCODINGS)}")
    height, width, step = int(height), int(width), int(step)
    if height <= 0 or width <= 0:
        raise ImageConversionError(f"empty image {width}x{height}")
    kind, channels = ENCODINGS[encoding]
    itemsize = np.dtype(kind).itemsize
    row_bytes = width * channels * itemsize
    if step < row_bytes:
        raise ImageConversionError(f"step {step} is shorter than one row of {width} {encoding} pixels ({row_bytes} B)")
    if isinstance(data, np.ndarray):
        buf = data.reshape(-1).view(np.uint8)
    elif isinstance(data, list):
        buf = np.asarray(data, dtype=np.uint8)
    else:
        buf = np.frombuffer(data, dtype=np.uint8)
    need = step * (height - 1) + row_bytes
    if buf.size < need:
        raise ImageConversionError(f"data has {buf.size} B but {width}x{height} {encoding} with step {step} "
                                   f"needs {need} B")
    if buf.size < step * height:
        buf = np.concatenate([buf, np.zeros(step * height - buf.size, np.uint8)])
    rows = buf[: step * height].reshape(height, step)[:, :row_bytes]
    order = ">" if is_bigendian else "<"
    dt = np.dtype(order + kind) if itemsize > 1 else np.dtype(kind)
    arr = np.ascontiguousarray(rows).view(dt).reshape(height, width, channels)
    if itemsize > 1:
        arr = arr.astype(np.dtype(kind), copy=False)  # to native byte order
    if channels == 1:
        arr = arr[:, :, 0]
    return arr


def check_image_array(array: np.ndarray, encoding: str, bigendian: bool = False) -> np.ndarray:
    """The array as (H, W, C) of the encoding's dtype in the byte order asked (little-endian by default; a view when
    it already is).

    Raises:
        ImageConversionError: unknown encoding, wrong dtype or channel count, empty array.
    """
    if encoding not in ENCODINGS:
        raise ImageConversionError(f"unsupported encoding {encoding!r}; supported: {sorted(ENCODINGS)}")
    a = np.asarray(array)
    kind, channels = ENCODINGS[encoding]
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] != channels:
        raise ImageConversionError(f"array of shape {np.asarray(array).shape} does not fit {encoding} "
                                   f"({channels} channel(s))")
    if a.dtype.kind + str(a.dtype.itemsize) != kind[0] + kind[1]:
        raise ImageConversionError(f"array dtype {a.dtype} does not fit {encoding} (needs {np.dtype(kind)})")
    h, w = a.shape[:2]
    if h == 0 or w == 0:
        raise ImageConversionError(f"empty image {w}x{h}")
    itemsize = np.dtype(kind).itemsize
    dt = np.dtype((">" if bigendian else "<") + kind) if itemsize > 1 else np.dtype(kind)
    return a.astype(dt, copy=False)


def numpy_to_image(array: np.ndarray, encoding: str, step: int | None = None, bigendian: bool = False
                   ) -> ImageFields:
    """sensor_msgs/Image fields (little-endian unless asked) for an (H, W) or (H, W, C) array.

    Args:
        array: the pixels; dtype must match the encoding (uint8, uint16 or float32).
        encoding: one of ENCODINGS.
        step: row length in bytes (≥ width·bytes per pixel; rows are zero-padded); default no padding.
        bigendian: write multi-byte pixels big-endian.

    Raises:
        ImageConversionError: unknown encoding, wrong dtype or channel count, empty array, step too short.
    """
    a = check_image_array(array, encoding, bigendian)
    h, w, channels = a.shape
    itemsize = a.dtype.itemsize
    row_bytes = w * channels * itemsize
    step = row_bytes if step is None else int(step)
    if step < row_bytes:
        raise ImageConversionError(f"step {step} is shorter than one row ({row_bytes} B)")
    raw = np.ascontiguousarray(a).view(np.uint8).reshape(h, row_bytes)
    if step > row_bytes:
        raw = np.concatenate([raw, np.zeros((h, step - row_bytes), np.uint8)], axis=1)
    return ImageFields(h, w, encoding, int(bool(bigendian) and itemsize > 1), step, raw.tobytes())


def to_rgb(array: np.ndarray, encoding: str) -> np.ndarray:
    """uint8 RGB (H, W, 3) from any colour or mono8 encoding (drops alpha, swaps BGR, replicates mono).

    Raises:
        ImageConversionError: the encoding is not an 8-bit colour/mono encoding.
    """
    a = np.asarray(array)
    if encoding in ("rgb8", "8UC3"):
        return a
    if encoding == "bgr8":
        return a[:, :, ::-1]
    if encoding == "rgba8":
        return a[:, :, :3]
    if encoding == "bgra8":
        return a[:, :, 2::-1]
    if encoding in ("mono8", "8UC1"):
        return np.repeat(a[:, :, None], 3, axis=2)
    raise ImageConversionError(f"encoding {encoding!r} is not a colour image")


def depth_to_meters(array: np.ndarray, encoding: str) -> np.ndarray:
    """Depth in metres (float32, NaN where invalid) from 16UC1/mono16 (mm, 0 = invalid) or 32FC1 (m).

    Raises:
        ImageConversionError: the encoding is not a depth encoding.
    """
    a = np.asarray(array)
    if encoding in ("16UC1", "mono16"):
        d = a.astype(np.float32)
        d *= np.float32(1e-3)          # in place: one new array per frame
        d[a == 0] = np.nan
        return d
    if encoding == "32FC1":
        d = a.astype(np.float32, copy=True)
        d[~np.isfinite(d) | (d <= 0)] = np.nan
        return d
    raise ImageConversionError(f"encoding {encoding!r} is not a depth image (use 16UC1 mm or 32FC1 m)")


def from_message(msg) -> np.ndarray:
    """Array from a sensor_msgs/msg/Image (or any object with its fields)."""
    return image_to_numpy(msg.height, msg.width, msg.encoding, msg.is_bigendian, msg.step, bytes(msg.data))


def fill_message(msg, array: np.ndarray, encoding: str):
    """Fill a sensor_msgs/msg/Image's fields from an array; returns the message."""
    f = numpy_to_image(array, encoding)
    msg.height, msg.width, msg.encoding = f.height, f.width, f.encoding
    msg.is_bigendian, msg.step, msg.data = f.is_bigendian, f.step, f.data
    return msg


NATIVE_BIGENDIAN = sys.byteorder == "big"
