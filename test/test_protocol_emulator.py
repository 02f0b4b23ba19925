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


def _frames_for(port: serial.Serial, parser: fr.FrameParser, seconds: float) -> list[fr.Frame]:
    out: list[fr.Frame] = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        out += parser.feed(port.read(port.in_waiting or 1))
    return out


def test_uno_emulator_latch_report_follows_commands_on_its_20ms_frames():
    now = [0.0]   # the board clock (s), moved by the test: frames are deterministic
    w1, w2 = (1000, 1100, 1200, 1300, 1400, 1500), (1600, 1700, 1800, 1900, 2000, 2100)
    with UnoEmulator(clock=lambda: now[0]) as uno, serial.Serial(uno.port, 500000, timeout=0.05) as s:
        p = fr.FrameParser()
        s.write(fr.encode_frame(fr.SET_TARGETS, 4, fr.pack_targets(w1)))
        now[0] = 0.1
        (st,) = _exchange(s, p, fr.encode_frame(fr.GET_STATUS, 1), 1)
        assert st.type == fr.STATUS
        assert not [f for f in _frames_for(s, p, 0.05) if f.type == fr.LATCH]   # off after reset
        (e1,) = _exchange(s, p, fr.encode_frame(fr.SET_LATCH_REPORT, 2, b"\x02"), 1)
        assert fr.unpack_error(e1.payload) == fr.ErrorReport(fr.ERR_BAD_VALUE, fr.SET_LATCH_REPORT, 2, 2)
        (e2,) = _exchange(s, p, fr.encode_frame(fr.SET_LATCH_REPORT, 3, b"\x01\x00"), 1)
        assert fr.unpack_error(e2.payload).code == fr.ERR_BAD_LENGTH
        now[0] = 0.1105
        (ack,) = _exchange(s, p, fr.encode_frame(fr.SET_LATCH_REPORT, 5, fr.pack_latch_report(True)), 1)
        assert fr.unpack_ack(ack.payload) == fr.Ack(fr.SET_LATCH_REPORT, 5) and uno.latch_report
        s.write(fr.encode_frame(fr.SET_TARGETS, 6, fr.pack_targets(w1)))
        _exchange(s, p, fr.encode_frame(fr.GET_STATUS, 7), 1)
        now[0] = 0.1408   # during frame 7 (starts 140 ms): channel 1's slot (1000 us) is running
        s.write(fr.encode_frame(fr.SET_TARGETS, 8, fr.pack_targets(w2)))
        # frame 6's LATCH (ended at 127.5 ms) may come before the STATUS: wait for the STATUS, so that the board
        # has handled command 8 before its clock moves on
        got = _exchange(s, p, fr.encode_frame(fr.GET_STATUS, 9), 1)
        while not any(f.type == fr.STATUS for f in got):
            more = _exchange(s, p, b"", 1)
            assert more, "no STATUS reply"
            got += more
        now[0] = 0.2
        got += _frames_for(s, p, 0.1)
        latches = [fr.unpack_latch(f.payload) for f in got if f.type == fr.LATCH]
    # frames 6..9 (120..180 ms) ended by 200 ms; the one starting at 100 ms began before the enable: not reported
    assert [x.frame_start_us for x in latches] == [120000, 140000, 160000, 180000]
    assert [x.seqs for x in latches] == [(6,) * 6, (6, 6, 8, 8, 8, 8), (8,) * 6, (8,) * 6]
    assert latches[0].offsets_us == (0, 1000, 2100, 3300, 4600, 6000)
    # channel 3 was scheduled when channel 2's slot started, after the command: it carries the new width
    assert latches[1].offsets_us == (0, 1000, 2100, 3900, 5800, 7800)
    assert all(x.mask == 0x3F for x in latches)


def test_uno_emulator_streams_latches_to_a_servo_link_naming_its_commands():
    from hexa.protocol.link import ServoLink

    latches: list[fr.Latch] = []
    seqs: list[int] = []
    with UnoEmulator() as uno, ServoLink(uno.port, on_latch=lambda x, t: latches.append(x)) as link:
        assert link.wait_connected(3.0), link.stats.last_error
        assert uno.latch_report and not latches            # enabled at connect; outputs off: nothing latched yet
        for k in range(6):
            assert link.set_targets([1200 + 50 * k] * 6)
            seqs.append(link.last_targets_seq)
            time.sleep(0.06)
        time.sleep(0.05)
    assert len(latches) >= 10
    starts = [x.frame_start_us for x in latches]
    assert all(b - a == 20000 for a, b in zip(starts, starts[1:]))   # every frame, 20 ms apart
    got = [x.seqs[0] for x in latches]
    assert set(got) == set(seqs) and got == sorted(got, key=seqs.index)
    assert all(x.offsets_us[1] == 1200 + 50 * seqs.index(x.seqs[0]) for x in latches)


def test_servo_link_connects_to_firmware_without_latch_report():
    from hexa.protocol.link import ServoLink

    class OldUno(UnoEmulator):
        def _accepts(self, msg_type: int) -> bool:
            return msg_type != fr.SET_LATCH_REPORT and super()._accepts(msg_type)

    with OldUno() as uno, ServoLink(uno.port, on_latch=lambda x, t: None) as link:
        assert link.wait_connected(3.0), link.stats.last_error
        assert link.latch_supported is False and "UNKNOWN_TYPE" in link.stats.last_error
        assert link.set_targets([1500] * 6)


def test_uno_emulator_hooks_pass_the_seq_and_forward_a_simulators_frames():
    commands, pending = [], []
    sim_frame = fr.Latch(123456, (0, 1500, 3000, 4500, 6000, 7500), (9,) * 6, 0x3F)

    def source():
        out = list(pending)
        pending.clear()
        return out

    with UnoEmulator(on_command=lambda w, seq: commands.append((w, seq)), latch_source=source) as uno, \
            serial.Serial(uno.port, 500000, timeout=0.05) as s:
        p = fr.FrameParser()
        s.write(fr.encode_frame(fr.SET_TARGETS, 9, fr.pack_targets([1500] * 6)))
        pending.append(sim_frame)
        got = _exchange(s, p, fr.encode_frame(fr.GET_STATUS, 10), 1) + _frames_for(s, p, 0.05)
        assert commands == [((1500,) * 6, 9)]
        assert not [f for f in got if f.type == fr.LATCH] and pending   # report off: the source is not asked
        got = _exchange(s, p, fr.encode_frame(fr.SET_LATCH_REPORT, 11, fr.pack_latch_report(True)), 1)
        got += _frames_for(s, p, 0.1)
        assert [fr.unpack_latch(f.payload) for f in got if f.type == fr.LATCH] == [sim_frame]
        assert uno.latches_sent == 1
