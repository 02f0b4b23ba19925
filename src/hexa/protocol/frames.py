"""Binary frames of the hexa serial link: layout, CRC-16, message types, payload codecs and a streaming parser.

Frame (all multi-byte fields little-endian; spec in docs/protocol.md)::

    0xA5 0x5A | LEN (u8, payload bytes, 0..64) | TYPE (u8) | SEQ (u8) | PAYLOAD (LEN bytes) | CRC16 (u16)

CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor; check("123456789") = 0x29B1) over
LEN, TYPE, SEQ and PAYLOAD. The firmware computes the same with avr-libc's ``_crc_xmodem_update`` seeded 0xFFFF.
"""
from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass
from typing import NamedTuple, Sequence

PROTOCOL_VERSION = 1
SYNC1 = 0xA5
SYNC2 = 0x5A
SYNC = bytes((SYNC1, SYNC2))
HEADER_SIZE = 5          # sync(2) + len + type + seq
CRC_SIZE = 2
MAX_PAYLOAD = 64
MAX_FRAME = HEADER_SIZE + MAX_PAYLOAD + CRC_SIZE
N_CHANNELS = 6

# Message types. 0x0_: common to both boards; 0x1_: servo board (Uno); 0x2_: current board (Mega).
HELLO = 0x01         # host -> board: u8 host protocol version
HELLO_REPLY = 0x02   # board -> host: u8 protocol version, u8 board kind, u16 firmware version, u8 channels
PING = 0x03          # host -> board: u32 token
PONG = 0x04          # board -> host: u32 token, u32 board time (us)
GET_STATUS = 0x05    # host -> board: empty
STATUS = 0x06        # board -> host: common part + board-specific part (see ServoStatus / CurrentStatus)
ACK = 0x07           # board -> host: u8 acknowledged type, u8 acknowledged seq
ERROR = 0x08         # board -> host: u8 code, u8 offending type, u8 offending seq, u8 detail
SET_TARGETS = 0x10   # host -> Uno: 6 x u16 pulse widths (us); no reply (status reports clamping)
SET_LIMITS = 0x11    # host -> Uno: 6 x u16 min, 6 x u16 max (us) -> ACK or ERROR(BAD_VALUE)
SET_WATCHDOG = 0x12  # host -> Uno: u16 command timeout (ms) -> ACK
SET_LATCH_REPORT = 0x13  # host -> Uno: u8 enable (0/1) -> ACK or ERROR(BAD_VALUE); off after reset
LATCH = 0x14         # Uno -> host, once per 20 ms frame while enabled: see Latch
START_STREAM = 0x20  # host -> Mega: u16 rate (Hz, 1..1000) -> ACK or ERROR(BAD_VALUE)
STOP_STREAM = 0x21   # host -> Mega: empty -> ACK
SAMPLE = 0x22        # Mega -> host: u32 sample sequence, u32 board time (us), 6 x u16 ADC counts

TYPE_NAMES = {
    HELLO: "HELLO", HELLO_REPLY: "HELLO_REPLY", PING: "PING", PONG: "PONG", GET_STATUS: "GET_STATUS",
    STATUS: "STATUS", ACK: "ACK", ERROR: "ERROR", SET_TARGETS: "SET_TARGETS", SET_LIMITS: "SET_LIMITS",
    SET_WATCHDOG: "SET_WATCHDOG", SET_LATCH_REPORT: "SET_LATCH_REPORT", LATCH: "LATCH",
    START_STREAM: "START_STREAM", STOP_STREAM: "STOP_STREAM", SAMPLE: "SAMPLE",
}

# Board kinds (HELLO_REPLY).
BOARD_SERVO = 1
BOARD_CURRENT = 2
BOARD_NAMES = {BOARD_SERVO: "servo (Uno)", BOARD_CURRENT: "current (Mega 2560)"}

# Error codes (ERROR).
ERR_UNKNOWN_TYPE = 2
ERR_BAD_LENGTH = 3
ERR_BAD_VALUE = 4
ERR_BAD_VERSION = 5
ERROR_NAMES = {ERR_UNKNOWN_TYPE: "UNKNOWN_TYPE", ERR_BAD_LENGTH: "BAD_LENGTH", ERR_BAD_VALUE: "BAD_VALUE",
               ERR_BAD_VERSION: "BAD_VERSION"}

# STATUS flags.
FLAG_ACTIVE = 0x01         # servo: pulse outputs enabled (a target was received); current: streaming
FLAG_WATCHDOG_HOLD = 0x02  # servo: no command within the timeout, holding the last targets
FLAG_CLAMPED = 0x04        # servo: the last targets were clamped to the limits
FLAG_OVERRUN = 0x08        # current: a sample deadline was missed since the last status

MIN_RATE_HZ = 1
MAX_RATE_HZ = 1000
PULSE_MIN_US = 400    # SET_LIMITS bounds (six pulses of <= 3 ms fit the 20 ms servo frame)
PULSE_MAX_US = 3000


class ProtocolError(ValueError):
    """A payload that does not decode: wrong length for its type or a value out of range."""


def crc16(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE of `data` (poly 0x1021, init 0xFFFF); crc16(b"123456789") == 0x29B1."""
    return binascii.crc_hqx(data, crc)


class Frame(NamedTuple):
    """One decoded frame: message type, sender's sequence number (0..255) and raw payload."""

    type: int
    seq: int
    payload: bytes


def encode_frame(msg_type: int, seq: int, payload: bytes = b"") -> bytes:
    """Bytes on the wire for one frame.

    Raises:
        ProtocolError: the payload is longer than MAX_PAYLOAD or type/seq do not fit a byte.
    """
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(f"payload of {len(payload)} bytes exceeds MAX_PAYLOAD={MAX_PAYLOAD}")
    if not 0 <= msg_type <= 0xFF or not 0 <= seq <= 0xFF:
        raise ProtocolError(f"type {msg_type} or seq {seq} outside 0..255")
    body = bytes((len(payload), msg_type, seq)) + payload
    c = binascii.crc_hqx(body, 0xFFFF)
    return SYNC + body + bytes((c & 0xFF, c >> 8))


@dataclass
class ParserStats:
    """Counters of a FrameParser (monotonic)."""

    frames: int = 0        # frames accepted (good CRC)
    crc_errors: int = 0    # candidate frames whose CRC did not match
    bad_length: int = 0    # LEN field above MAX_PAYLOAD
    resyncs: int = 0       # times the parser had to discard bytes to find the next sync
    discarded: int = 0     # bytes discarded while searching for sync
    bytes_in: int = 0


class FrameParser:
    """Streaming frame parser: feed arbitrary chunks, get complete frames with a verified CRC.

    Never raises on input: noise, truncated frames, bad CRC and impossible lengths are counted in `stats`
    and the parser resynchronises on the next sync pair after the offending sync byte.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats = ParserStats()

    def reset(self) -> None:
        """Drop any partial frame (e.g. after a reconnect)."""
        self._buf.clear()

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        """Append `data` and return the frames completed by it, in order."""
        buf = self._buf
        buf += data
        st = self.stats
        st.bytes_in += len(data)
        out: list[Frame] = []
        pos = 0
        n = len(buf)
        crc = binascii.crc_hqx
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:
                # keep a trailing SYNC1 that may start the next frame
                keep = 1 if n and buf[n - 1] == SYNC1 else 0
                dropped = n - keep - pos
                if dropped > 0:
                    st.discarded += dropped
                    st.resyncs += 1
                pos = max(pos, n - keep)
                break
            if i > pos:
                st.discarded += i - pos
                st.resyncs += 1
            pos = i
            if n - pos < HEADER_SIZE:
                break
            length = buf[pos + 2]
            if length > MAX_PAYLOAD:
                st.bad_length += 1
                pos += 1
                continue
            end = pos + HEADER_SIZE + length + CRC_SIZE
            if end > n:
                break
            c = crc(buf[pos + 2:end - 2], 0xFFFF)
            if buf[end - 2] != (c & 0xFF) or buf[end - 1] != (c >> 8):
                st.crc_errors += 1
                pos += 1
                continue
            out.append(Frame(buf[pos + 3], buf[pos + 4], bytes(buf[pos + HEADER_SIZE:end - 2])))
            pos = end
        if pos:
            del buf[:pos]
        st.frames += len(out)
        return out


# ---------------------------------------------------------------------------------------------- payload codecs
_U8 = struct.Struct("<B")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_HELLO_REPLY = struct.Struct("<BBHB")
_PONG = struct.Struct("<II")
_ACK = struct.Struct("<BB")
_ERROR = struct.Struct("<BBBB")
_SIX_U16 = struct.Struct("<6H")
_LIMITS = struct.Struct("<12H")
_SAMPLE = struct.Struct("<II6H")
_LATCH = struct.Struct("<I6H6BB")
_STATUS_COMMON = struct.Struct("<BHHHI")
_STATUS_SERVO = struct.Struct("<6HH")
_STATUS_CURRENT = struct.Struct("<HHI")


def _expect(payload: bytes, size: int, msg_type: int) -> None:
    if len(payload) != size:
        raise ProtocolError(f"{TYPE_NAMES.get(msg_type, hex(msg_type))} payload has {len(payload)} bytes, "
                            f"expected {size}")


class HelloReply(NamedTuple):
    protocol_version: int
    board_kind: int
    firmware_version: int
    channels: int


class Pong(NamedTuple):
    token: int
    board_time_us: int


class Ack(NamedTuple):
    acked_type: int
    acked_seq: int


class ErrorReport(NamedTuple):
    code: int
    offending_type: int
    offending_seq: int
    detail: int


class Sample(NamedTuple):
    """One current-board sample: its sequence number, board time (us, wraps at 2^32) and six ADC counts."""

    sequence: int
    board_time_us: int
    counts: tuple[int, int, int, int, int, int]


@dataclass(frozen=True)
class Latch:
    """One 20 ms pulse frame of the servo board (LATCH): when each channel's pulse started and which command it carried.

    A hobby servo takes a new set-point only from a pulse, so `seqs[i]` names the SET_TARGETS (its frame header SEQ)
    whose width channel i's pulse carried, and its set-point changed at that pulse (edge at
    ``frame_start_us + offsets_us[i]``, falling edge one pulse width later).

    Attributes:
        frame_start_us: board time (µs, the micros() clock of PONG/STATUS, wraps at 2^32) of channel 1's rising edge;
            4 µs resolution on the 16 MHz Uno.
        offsets_us: start of each channel's slot (its rising edge) in µs after `frame_start_us` (offsets_us[0] = 0).
        seqs: SEQ of the SET_TARGETS frame whose target each channel's pulse carried.
        mask: bit i set when channel i's output was on (a pulse was sent) in this frame.
    """

    frame_start_us: int
    offsets_us: tuple[int, ...]
    seqs: tuple[int, ...]
    mask: int

    def pulse_start_us(self, channel: int) -> int:
        """Board time (µs, wrapped to 32 bits) at which `channel`'s pulse (0-based) started."""
        return (self.frame_start_us + self.offsets_us[channel]) & 0xFFFFFFFF


@dataclass(frozen=True)
class ServoStatus:
    flags: int
    rx_frames: int
    rx_crc_errors: int
    rx_bad_frames: int
    board_time_us: int
    pulses_us: tuple[int, ...]
    ms_since_command: int


@dataclass(frozen=True)
class CurrentStatus:
    flags: int
    rx_frames: int
    rx_crc_errors: int
    rx_bad_frames: int
    board_time_us: int
    rate_hz: int
    overruns: int
    samples_sent: int


def pack_hello(version: int = PROTOCOL_VERSION) -> bytes:
    return _U8.pack(version)


def unpack_hello(payload: bytes) -> int:
    _expect(payload, 1, HELLO)
    return payload[0]


def pack_hello_reply(kind: int, firmware_version: int, channels: int = N_CHANNELS,
                     version: int = PROTOCOL_VERSION) -> bytes:
    return _HELLO_REPLY.pack(version, kind, firmware_version, channels)


def unpack_hello_reply(payload: bytes) -> HelloReply:
    _expect(payload, _HELLO_REPLY.size, HELLO_REPLY)
    return HelloReply(*_HELLO_REPLY.unpack(payload))


def pack_ping(token: int) -> bytes:
    return _U32.pack(token & 0xFFFFFFFF)


def unpack_ping(payload: bytes) -> int:
    _expect(payload, 4, PING)
    return _U32.unpack(payload)[0]


def pack_pong(token: int, board_time_us: int) -> bytes:
    return _PONG.pack(token & 0xFFFFFFFF, board_time_us & 0xFFFFFFFF)


def unpack_pong(payload: bytes) -> Pong:
    _expect(payload, _PONG.size, PONG)
    return Pong(*_PONG.unpack(payload))


def pack_ack(acked_type: int, acked_seq: int) -> bytes:
    return _ACK.pack(acked_type, acked_seq)


def unpack_ack(payload: bytes) -> Ack:
    _expect(payload, _ACK.size, ACK)
    return Ack(*_ACK.unpack(payload))


def pack_error(code: int, offending_type: int, offending_seq: int, detail: int = 0) -> bytes:
    return _ERROR.pack(code, offending_type, offending_seq, detail & 0xFF)


def unpack_error(payload: bytes) -> ErrorReport:
    _expect(payload, _ERROR.size, ERROR)
    return ErrorReport(*_ERROR.unpack(payload))


def _six(values: Sequence[int], what: str) -> tuple[int, ...]:
    vals = tuple(int(v) for v in values)
    if len(vals) != N_CHANNELS:
        raise ProtocolError(f"{what} needs {N_CHANNELS} values, got {len(vals)}")
    for v in vals:
        if not 0 <= v <= 0xFFFF:
            raise ProtocolError(f"{what} value {v} outside 0..65535")
    return vals


def pack_targets(pulses_us: Sequence[int]) -> bytes:
    return _SIX_U16.pack(*_six(pulses_us, "SET_TARGETS"))


def unpack_targets(payload: bytes) -> tuple[int, ...]:
    _expect(payload, _SIX_U16.size, SET_TARGETS)
    return _SIX_U16.unpack(payload)


def pack_limits(min_us: Sequence[int], max_us: Sequence[int]) -> bytes:
    return _LIMITS.pack(*_six(min_us, "SET_LIMITS min"), *_six(max_us, "SET_LIMITS max"))


def unpack_limits(payload: bytes) -> tuple[tuple[int, ...], tuple[int, ...]]:
    _expect(payload, _LIMITS.size, SET_LIMITS)
    v = _LIMITS.unpack(payload)
    return v[:6], v[6:]


def pack_watchdog(timeout_ms: int) -> bytes:
    return _U16.pack(timeout_ms)


def unpack_watchdog(payload: bytes) -> int:
    _expect(payload, 2, SET_WATCHDOG)
    return _U16.unpack(payload)[0]


def pack_latch_report(enable: bool | int) -> bytes:
    return _U8.pack(int(enable))


def unpack_latch_report(payload: bytes) -> int:
    """The enable byte of SET_LATCH_REPORT (the board answers ERROR(BAD_VALUE) to anything but 0 or 1)."""
    _expect(payload, 1, SET_LATCH_REPORT)
    return payload[0]


def pack_latch(latch: Latch) -> bytes:
    """LATCH payload (23 bytes): u32 frame start (µs), 6 x u16 pulse start offsets (µs), 6 x u8 seq, u8 mask.

    Raises:
        ProtocolError: not six offsets or seqs, or a value that does not fit its field.
    """
    offsets = _six(latch.offsets_us, "LATCH offsets")
    seqs = tuple(int(v) for v in latch.seqs)
    if len(seqs) != N_CHANNELS or not all(0 <= v <= 0xFF for v in seqs) or not 0 <= latch.mask <= 0x3F:
        raise ProtocolError(f"LATCH needs {N_CHANNELS} seqs in 0..255 and a mask in 0..0x3F, got {seqs}, "
                            f"{latch.mask}")
    return _LATCH.pack(latch.frame_start_us & 0xFFFFFFFF, *offsets, *seqs, latch.mask)


def unpack_latch(payload: bytes) -> Latch:
    _expect(payload, _LATCH.size, LATCH)
    v = _LATCH.unpack(payload)
    return Latch(v[0], tuple(v[1:7]), tuple(v[7:13]), v[13])


def pack_start_stream(rate_hz: int) -> bytes:
    return _U16.pack(rate_hz)


def unpack_start_stream(payload: bytes) -> int:
    _expect(payload, 2, START_STREAM)
    return _U16.unpack(payload)[0]


def pack_sample(sequence: int, board_time_us: int, counts: Sequence[int]) -> bytes:
    return _SAMPLE.pack(sequence & 0xFFFFFFFF, board_time_us & 0xFFFFFFFF, *_six(counts, "SAMPLE"))


def unpack_sample(payload: bytes) -> Sample:
    _expect(payload, _SAMPLE.size, SAMPLE)
    v = _SAMPLE.unpack(payload)
    return Sample(v[0], v[1], tuple(v[2:]))


def pack_servo_status(s: ServoStatus) -> bytes:
    return (_STATUS_COMMON.pack(s.flags, s.rx_frames & 0xFFFF, s.rx_crc_errors & 0xFFFF, s.rx_bad_frames & 0xFFFF,
                                s.board_time_us & 0xFFFFFFFF)
            + _STATUS_SERVO.pack(*s.pulses_us, min(s.ms_since_command, 0xFFFF)))


def unpack_servo_status(payload: bytes) -> ServoStatus:
    _expect(payload, _STATUS_COMMON.size + _STATUS_SERVO.size, STATUS)
    c = _STATUS_COMMON.unpack_from(payload, 0)
    s = _STATUS_SERVO.unpack_from(payload, _STATUS_COMMON.size)
    return ServoStatus(c[0], c[1], c[2], c[3], c[4], pulses_us=tuple(s[:6]), ms_since_command=s[6])


def pack_current_status(s: CurrentStatus) -> bytes:
    return (_STATUS_COMMON.pack(s.flags, s.rx_frames & 0xFFFF, s.rx_crc_errors & 0xFFFF, s.rx_bad_frames & 0xFFFF,
                                s.board_time_us & 0xFFFFFFFF)
            + _STATUS_CURRENT.pack(s.rate_hz, s.overruns & 0xFFFF, s.samples_sent & 0xFFFFFFFF))


def unpack_current_status(payload: bytes) -> CurrentStatus:
    _expect(payload, _STATUS_COMMON.size + _STATUS_CURRENT.size, STATUS)
    c = _STATUS_COMMON.unpack_from(payload, 0)
    s = _STATUS_CURRENT.unpack_from(payload, _STATUS_COMMON.size)
    return CurrentStatus(*c, *s)


# Fixed payload sizes of host -> board messages (the boards reject others with ERROR(BAD_LENGTH)).
REQUEST_SIZES = {HELLO: 1, PING: 4, GET_STATUS: 0, SET_TARGETS: 12, SET_LIMITS: 24, SET_WATCHDOG: 2,
                 SET_LATCH_REPORT: 1, START_STREAM: 2, STOP_STREAM: 0}
SERVO_STATUS_SIZE = _STATUS_COMMON.size + _STATUS_SERVO.size
CURRENT_STATUS_SIZE = _STATUS_COMMON.size + _STATUS_CURRENT.size
SAMPLE_SIZE = _SAMPLE.size
LATCH_SIZE = _LATCH.size   # 23 bytes: a LATCH frame is 30 bytes on the wire, 600 µs of the link every 20 ms
