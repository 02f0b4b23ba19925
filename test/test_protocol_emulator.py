"""The pty board emulators (hexa.protocol.emulator) answer the protocol like the firmware."""
from __future__ import annotations

import os
import time

import pytest
import serial

from hexa.protocol import frames as fr
from hexa.protocol.emulator import MegaEmulator, UnoEmulator
from hexa.protocol.sensor_model import DEFAULT_SENSOR


def _exchange(port: serial.Serial, parser: fr.FrameParser, data: bytes, want: int, timeout: float = 2.0):
    port.write(data)
    out: list[fr.Frame] = []
    t_end = time.monotonic() + timeout
    while len(out) < want and time.monotonic() < t_end:
        out += parser.feed(port.read(port.in_waiting or 1))
    return out


def test_uno_emulator_hello_targets_clamped_and_status():
    got = []
    with UnoEmulator(on_targets=got.append) as uno:
        with serial.Serial(uno.port, 500000, timeout=0.05) as s:
            p = fr.FrameParser()
            (hello,) = _exchange(s, p, fr.encode_frame(fr.HELLO, 0, fr.pack_hello()), 1)
            assert hello.type == fr.HELLO_REPLY
            assert fr.unpack_hello_reply(hello.payload).board_kind == fr.BOARD_SERVO
            s.write(fr.encode_frame(fr.SET_TARGETS, 1, fr.pack_targets([1500, 400, 2600, 1000, 2000, 1234])))
            (st,) = _exchange(s, p, fr.encode_frame(fr.GET_STATUS, 2), 1)
            status = fr.unpack_servo_status(st.payload)
            assert status.pulses_us == (1500, 500, 2500, 1000, 2000, 1234)
            assert status.flags & fr.FLAG_CLAMPED and status.flags & fr.FLAG_ACTIVE
            assert got == [(1500, 500, 2500, 1000, 2000, 1234)]


def test_uno_emulator_rejects_wrong_length_and_unknown_type():
    with UnoEmulator() as uno, serial.Serial(uno.port, 500000, timeout=0.05) as s:
        p = fr.FrameParser()
        (e1,) = _exchange(s, p, fr.encode_frame(fr.SET_TARGETS, 9, b"\x00" * 11), 1)
        assert fr.unpack_error(e1.payload) == fr.ErrorReport(fr.ERR_BAD_LENGTH, fr.SET_TARGETS, 9, 11)
        (e2,) = _exchange(s, p, fr.encode_frame(fr.START_STREAM, 3, fr.pack_start_stream(10)), 1)
        assert fr.unpack_error(e2.payload).code == fr.ERR_UNKNOWN_TYPE
        assert uno.targets == (0,) * 6


def test_mega_emulator_streams_counts_from_sensor_model():
    amps = [0.0, 0.5, -0.5, 1.0, 2.0, -2.0]
    with MegaEmulator(current_source=lambda t: amps) as mega, serial.Serial(mega.port, 500000, timeout=0.05) as s:
        p = fr.FrameParser()
        frames = _exchange(s, p, fr.encode_frame(fr.START_STREAM, 0, fr.pack_start_stream(200)), 12)
        assert frames[0].type == fr.ACK
        samples = [fr.unpack_sample(f.payload) for f in frames if f.type == fr.SAMPLE]
        assert len(samples) >= 10
        assert [x.sequence for x in samples] == list(range(samples[0].sequence, samples[0].sequence + len(samples)))
        assert samples[0].counts == tuple(int(c) for c in DEFAULT_SENSOR.counts_from_current(amps))
        dt = (samples[-1].board_time_us - samples[0].board_time_us) / (len(samples) - 1)
        assert dt == pytest.approx(5000, abs=2)


def test_mega_emulator_rejects_rate_above_1khz():
    with MegaEmulator() as mega, serial.Serial(mega.port, 500000, timeout=0.05) as s:
        (e,) = _exchange(s, fr.FrameParser(), fr.encode_frame(fr.START_STREAM, 4, fr.pack_start_stream(1001)), 1)
        assert fr.unpack_error(e.payload).code == fr.ERR_BAD_VALUE and not mega.streaming


def test_unplug_removes_link_and_replug_points_to_new_pty(tmp_path):
    link = tmp_path / "uno"
    with UnoEmulator(link=link) as uno:
        first = os.readlink(link)
        s = serial.Serial(uno.port, 500000, timeout=0.05)
        uno.unplug()
        assert not link.exists()
        with pytest.raises(serial.SerialException):
            for _ in range(20):
                s.read(1)
        s.close()
        uno.replug()
        assert link.is_symlink() and os.path.exists(os.readlink(link))
        with serial.Serial(uno.port, 500000, timeout=0.05) as s2:
            (h,) = _exchange(s2, fr.FrameParser(), fr.encode_frame(fr.HELLO, 0, fr.pack_hello()), 1)
            assert h.type == fr.HELLO_REPLY
        assert isinstance(first, str)


def test_emulator_survives_a_failing_consumer_callback():
    def boom(_):
        raise RuntimeError("simulator gone")

    with UnoEmulator(on_targets=boom) as uno, serial.Serial(uno.port, 500000, timeout=0.05) as s:
        p = fr.FrameParser()
        s.write(fr.encode_frame(fr.SET_TARGETS, 1, fr.pack_targets([1500] * 6)))
        (st,) = _exchange(s, p, fr.encode_frame(fr.GET_STATUS, 2), 1)
        assert fr.unpack_servo_status(st.payload).pulses_us == (1500,) * 6
        assert uno.callback_errors == 1 and "simulator gone" in uno.last_callback_error
