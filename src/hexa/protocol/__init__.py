"""Serial link between the host and the two Arduino boards: frames, CRC-16, streaming parser, message codecs.

Submodules: `frames` (wire format, codecs, FrameParser), `sensor_model` (ACS712 + 10-bit ADC), `emulator`
(pty board emulators), `link` (host-side board clients with handshake, stats and reconnect), `servo_calibration`
(angle <-> pulse width). Spec: docs/protocol.md.
"""
from __future__ import annotations

from hexa.protocol.frames import (
    MAX_PAYLOAD,
    PROTOCOL_VERSION,
    Frame,
    FrameParser,
    ParserStats,
    ProtocolError,
    crc16,
    encode_frame,
)

__all__ = ["MAX_PAYLOAD", "PROTOCOL_VERSION", "Frame", "FrameParser", "ParserStats", "ProtocolError", "crc16",
           "encode_frame"]
