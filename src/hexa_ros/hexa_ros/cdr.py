"""Serialized (CDR) camera messages read in place: a raw subscription hands over the bytes DDS delivered, and the
image's pixels become a numpy view of them, with no per-byte conversion.

rclpy turns a sensor_msgs/Image's `uint8[] data` into an array.array (≈ 0.75 ms for a 640×480 RGB frame here); a
node that keeps every frame of two cameras at 30 fps and decodes few of them (isolation), or that only needs the
pixels (pose), subscribes with `raw=True` and reads the fields here instead (≈ 10 µs). The observer reads the
driver's two 1 kHz streams the same way: building the message objects costs more than the fields it needs.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np


class CdrError(ValueError):
    """The bytes are not a serialized message of the expected type (names what is wrong)."""


@dataclass(frozen=True)
class CdrImage:
    """The fields of a serialized sensor_msgs/Image; `data` is a read-only numpy view of the message's bytes."""

    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: np.ndarray

    @property
    def stamp(self) -> float:
        return self.stamp_sec + 1e-9 * self.stamp_nanosec

    def raw(self) -> Any:
        """The core's undecoded image (hexa.vision.sync.RawImage), its pixels still a view of the message's bytes."""
        from hexa.vision.sync import RawImage

        return RawImage(self.stamp, self.height, self.width, self.encoding, self.is_bigendian, self.step, self.data)


_U32 = {"<": struct.Struct("<I").unpack_from, ">": struct.Struct(">I").unpack_from}   # compiled once: 1 kHz streams
_CURRENTS = {o: struct.Struct(o + "6d6H3I").unpack_from for o in "<>"}   # MotorCurrents after its frame_id


class _Reader:
    """CDR (XCDR1, plain) reader: 4-byte encapsulation header, then fields aligned to their size from its end."""

    def __init__(self, buf: bytes | memoryview) -> None:
        if len(buf) < 4:
            raise CdrError(f"{len(buf)} bytes: shorter than the CDR encapsulation header")
        kind = buf[1]
        if kind not in (0, 1):
            raise CdrError(f"unsupported CDR representation {bytes(buf[:2]).hex()}")
        self.buf, self.pos = memoryview(buf), 4
        self.order = "<" if kind == 1 else ">"
        self._u32 = _U32[self.order]

    def _align(self, n: int) -> None:
        self.pos += (-(self.pos - 4)) % n

    def u32(self) -> int:
        self._align(4)
        if self.pos + 4 > len(self.buf):
            raise CdrError("message ends inside a 32-bit field")
        (v,) = self._u32(self.buf, self.pos)
        self.pos += 4
        return v

    def i32(self) -> int:
        v = self.u32()
        return v - (1 << 32) if v >= 1 << 31 else v

    def f64s(self, n: int | None = None) -> np.ndarray:
        """n float64 (a fixed array), or a sequence with its length first (n None)."""
        if n is None:
            n = self.u32()
        if n == 0:                               # an empty sequence aligns nothing (Fast CDR)
            return np.zeros(0)
        self._align(8)
        if self.pos + 8 * n > len(self.buf):
            raise CdrError(f"{n} doubles do not fit the {len(self.buf)}-byte message")
        out = np.frombuffer(self.buf, dtype=self.order + "f8", count=n, offset=self.pos)
        self.pos += 8 * n
        return out

    def skip_u16s(self, n: int) -> None:
        self._align(2)
        if self.pos + 2 * n > len(self.buf):
            raise CdrError(f"{n} uint16 do not fit the {len(self.buf)}-byte message")
        self.pos += 2 * n

    def u8(self) -> int:
        if self.pos + 1 > len(self.buf):
            raise CdrError("message ends inside an 8-bit field")
        v = self.buf[self.pos]
        self.pos += 1
        return v

    def string(self) -> str:
        n = self.u32()
        if n == 0 or self.pos + n > len(self.buf):
            raise CdrError(f"string of {n} bytes does not fit the message")
        s = bytes(self.buf[self.pos:self.pos + n - 1]).decode("utf-8", errors="replace")   # n counts the NUL
        self.pos += n
        return s

    def octets(self) -> np.ndarray:
        n = self.u32()
        if self.pos + n > len(self.buf):
            raise CdrError(f"byte sequence of {n} bytes does not fit the {len(self.buf)}-byte message")
        out = np.frombuffer(self.buf, dtype=np.uint8, count=n, offset=self.pos)
        self.pos += n
        return out


def image_from_cdr(buf: bytes | memoryview) -> CdrImage:
    """The fields of a serialized sensor_msgs/Image (what a `raw=True` subscription delivers), pixels not copied.

    Raises:
        CdrError: the bytes are too short, of another representation, or their lengths do not fit.
    """
    r = _Reader(buf)
    sec, nanosec = r.i32(), r.u32()
    frame_id = r.string()
    height, width = r.u32(), r.u32()
    encoding = r.string()
    is_bigendian = r.u8()
    step = r.u32()
    data = r.octets()
    return CdrImage(sec, nanosec, frame_id, height, width, encoding, is_bigendian, step, data)


def joint_state_from_cdr(buf: bytes | memoryview) -> tuple[float, list[str], np.ndarray, np.ndarray, np.ndarray]:
    """(stamp s, names, position, velocity, effort) of a serialized sensor_msgs/JointState.

    Raises:
        CdrError: the bytes do not hold a JointState.
    """
    r = _Reader(buf)
    sec, nanosec = r.i32(), r.u32()
    r.string()                                  # frame_id
    names = [r.string() for _ in range(r.u32())]
    return sec + 1e-9 * nanosec, names, r.f64s(), r.f64s(), r.f64s()


def motor_currents_from_cdr(buf: bytes | memoryview) -> tuple[float, np.ndarray, int, np.ndarray]:
    """(stamp s, currents A (6), board time µs, set-points rad) of a serialized hexa_msgs/MotorCurrents; the
    set-points are empty when the message has none, or ends before the field (a bag recorded without it).

    Raises:
        CdrError: the bytes do not hold a MotorCurrents.
    """
    r = _Reader(buf)
    sec, nanosec = r.i32(), r.u32()
    r.string()                                  # frame_id
    r._align(8)
    if r.pos + 72 > len(r.buf):
        raise CdrError(f"{len(r.buf)} bytes: too short for a MotorCurrents")
    # currents, raw ADC counts, sequence, board time, gaps: one unpack (no padding between them from here)
    fields = _CURRENTS[r.order](r.buf, r.pos)
    r.pos += 72
    setpoint = r.f64s() if r.pos + 4 <= len(r.buf) else np.zeros(0)
    return sec + 1e-9 * nanosec, np.array(fields[:6]), fields[13], setpoint


def motor_currents_with_setpoint_field(buf: bytes) -> bytes:
    """A serialized hexa_msgs/MotorCurrents as the current definition has it: one recorded before the `setpoint`
    field existed gets an empty sequence appended (`hexa play` sends old bags so; a message object subscriber could
    not deserialize them otherwise). Others are returned as they are.

    Raises:
        CdrError: the bytes do not hold a MotorCurrents.
    """
    r = _Reader(buf)
    r.i32(), r.u32()
    r.string()
    r.f64s(6)
    r.skip_u16s(6)
    r.u32(), r.u32(), r.u32()                   # sequence, board time, gaps
    return bytes(buf) + b"\x00\x00\x00\x00" if r.pos + 4 > len(r.buf) else buf


def zeta_estimates_from_cdr(buf: bytes | memoryview) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(times (N), ζ̂, ζ̂̇, τ (N×6 each)) of a serialized hexa_msgs/ZetaEstimates.

    Raises:
        CdrError: the bytes do not hold a ZetaEstimates, or its arrays disagree in size.
    """
    r = _Reader(buf)
    r.i32(), r.u32()
    r.string()                                  # frame_id
    t, zeta, zeta_dot, tau = r.f64s(), r.f64s(), r.f64s(), r.f64s()
    if not zeta.size == zeta_dot.size == tau.size == 6 * t.size:
        raise CdrError(f"ZetaEstimates with {t.size} times and {zeta.size}, {zeta_dot.size}, {tau.size} values "
                       f"(6 per time)")
    return t, zeta.reshape(-1, 6), zeta_dot.reshape(-1, 6), tau.reshape(-1, 6)


# ---------------------------------------------------------------------- writing (the driver's and the observer's
# per-sample messages)
_LE_HEADER = b"\x00\x01\x00\x00"               # CDR, little endian, as rmw_fastrtps writes it


def _header_cdr(sec: int, nanosec: int, frame_id: str) -> bytearray:
    """Encapsulation + std_msgs/Header; fields after it align from offset 4."""
    name = frame_id.encode("utf-8") + b"\x00"
    out = bytearray(_LE_HEADER)
    out += struct.pack("<iII", sec, nanosec, len(name))
    out += name
    return out


def _pad(out: bytearray, n: int) -> None:
    out += b"\x00" * ((-(len(out) - 4)) % n)


_RESIDUAL_BODY = struct.Struct("<6d3d3d6d6?2x6d6d6??")


def residual_to_cdr(sec: int, nanosec: int, frame_id: str, r, force, torque, threshold, over, servo_torque,
                    servo_threshold, servo_over, in_collision: bool) -> bytes:
    """A serialized hexa_msgs/Residual (the bytes rclpy would publish for the same fields; `publish(bytes)` sends
    them as they are): building the message object costs more than the sample's whole observer update."""
    out = _header_cdr(sec, nanosec, frame_id)
    _pad(out, 8)
    out += _RESIDUAL_BODY.pack(*r, *force, *torque, *threshold, *over, *servo_torque, *servo_threshold,
                               *servo_over, in_collision)
    return bytes(out)


def _f64_seq(out: bytearray, values) -> None:
    _pad(out, 4)
    out += struct.pack("<I", len(values))
    if len(values):
        _pad(out, 8)
        out += struct.pack(f"<{len(values)}d", *values)


_CURRENTS_BODY = struct.Struct("<6d6H3I")


def motor_currents_to_cdr(sec: int, nanosec: int, frame_id: str, current, raw, sequence: int, board_time_us: int,
                          gaps: int, setpoint) -> bytes:
    """A serialized hexa_msgs/MotorCurrents (the bytes rclpy would publish for the same fields): the driver's 1 kHz
    stream, whose message objects cost more to build and convert than the sample's whole handling."""
    out = _header_cdr(sec, nanosec, frame_id)
    _pad(out, 8)
    out += _CURRENTS_BODY.pack(*current, *raw, sequence, board_time_us, gaps)
    _f64_seq(out, setpoint)
    return bytes(out)


def zeta_estimates_to_cdr(sec: int, nanosec: int, times, zeta, zeta_dot, tau) -> bytes:
    """A serialized hexa_msgs/ZetaEstimates (frame_id empty): `times` N floats, the others N×6 flattened."""
    out = _header_cdr(sec, nanosec, "")
    for seq in (times, zeta, zeta_dot, tau):
        _f64_seq(out, seq)
    return bytes(out)


def joint_state_to_cdr(sec: int, nanosec: int, frame_id: str, names, position, velocity, effort) -> bytes:
    """A serialized sensor_msgs/JointState (the bytes rclpy would publish for the same fields)."""
    out = _header_cdr(sec, nanosec, frame_id)
    _pad(out, 4)
    out += struct.pack("<I", len(names))
    for n in names:
        b = n.encode("utf-8") + b"\x00"
        _pad(out, 4)
        out += struct.pack("<I", len(b))
        out += b
    for seq in (position, velocity, effort):
        _f64_seq(out, seq)
    return bytes(out)


def image_to_cdr(sec: int, nanosec: int, frame_id: str, array: np.ndarray, encoding: str) -> bytes:
    """A serialized sensor_msgs/Image of an (H, W) or (H, W, C) array (little-endian, no row padding): the bytes
    rclpy publishes for `hexa.vision.images.fill_message`'s message, with one copy of the pixels where the message
    object takes three (array → bytes → array.array → C struct) before rclpy serializes it. `publish(bytes)` sends
    them as they are.

    Raises:
        hexa.vision.images.ImageConversionError: the array does not fit the encoding.
    """
    from hexa.vision.images import check_image_array

    a = np.ascontiguousarray(check_image_array(array, encoding))
    h, w, channels = a.shape
    enc = encoding.encode("ascii") + b"\x00"
    out = _header_cdr(sec, nanosec, frame_id)
    _pad(out, 4)
    out += struct.pack("<III", h, w, len(enc))
    out += enc
    out += b"\x00"                               # is_bigendian
    _pad(out, 4)
    out += struct.pack("<II", w * channels * a.itemsize, a.nbytes)
    return b"".join((out, memoryview(a.reshape(-1).view(np.uint8))))
