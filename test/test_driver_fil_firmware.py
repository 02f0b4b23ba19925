"""Firmware-in-the-loop: the real Uno/Mega .elf files in simavr, driven by the host links (hexa.protocol.link).

These tests fail (never skip) when the toolchain or the build is missing: `make test` builds the firmware first.
"""
from __future__ import annotations

import time

import pytest

from hexa.protocol import frames as fr
from hexa.protocol.link import CurrentLink, LinkError, ServoLink
from hexa.protocol.simavr import SERVO_PINS, SimavrBoard, simavr_counts


def _wait(cond, timeout=3.0):
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def test_uno_firmware_outputs_commanded_pulse_widths_on_the_right_pins(tmp_path):
    with SimavrBoard("uno", link=tmp_path / "uno") as uno:
        with ServoLink(uno.port, min_us=[600] * 6, max_us=[2400] * 6, watchdog_ms=200) as link:
            assert link.wait_connected(5.0), link.stats.last_error
            assert link.stats.firmware_version == 0x0100
            targets = [1000, 1100, 1500, 1900, 2000, 2300]
            t_cmd = time.monotonic()
            assert link.set_targets(targets)
            for pin, width in zip(SERVO_PINS, targets):
                p = uno.wait_pulse(pin, width, tol_us=1.0, after=t_cmd, timeout=3.0)
                assert p is not None, (pin, width, uno.latest_widths())
            # outside the limits set at connect time -> clamped by the firmware, flagged in STATUS
            t_cmd = time.monotonic()
            assert link.set_targets([500, 2500, 1500, 1500, 1500, 1500])
            assert uno.wait_pulse(2, 600, tol_us=1.0, after=t_cmd) is not None
            assert uno.wait_pulse(3, 2400, tol_us=1.0, after=t_cmd) is not None
            assert _wait(lambda: link.status is not None and link.status.pulses_us[:2] == (600, 2400))
            assert link.status.flags & fr.FLAG_CLAMPED
            # no command for > 200 ms: the board holds the last pulses and says so
            time.sleep(0.4)
            assert _wait(lambda: link.status.flags & fr.FLAG_WATCHDOG_HOLD)
            t_hold = time.monotonic()
            assert uno.wait_pulse(3, 2400, tol_us=1.0, after=t_hold) is not None
            assert link.stats.crc_errors == 0


def test_uno_firmware_counts_bad_crc_and_rejects_wrong_length(tmp_path):
    with SimavrBoard("uno", link=tmp_path / "uno") as uno:
        with ServoLink(uno.port) as link:
            assert link.wait_connected(5.0), link.stats.last_error
            bad = bytearray(fr.encode_frame(fr.SET_TARGETS, 1, fr.pack_targets([2000] * 6)))
            bad[-1] ^= 0xFF
            link._ser.write(bytes(bad))  # a corrupted command must never move a servo
            with pytest.raises(LinkError, match="BAD_LENGTH"):
                link.request(fr.SET_WATCHDOG, b"\x01")
            with pytest.raises(LinkError, match="BAD_VALUE"):   # six 3.5 ms pulses would not fit 20 ms
                link.request(fr.SET_LIMITS, fr.pack_limits([500] * 6, [3500] * 6))
            status = fr.unpack_servo_status(link.request(fr.GET_STATUS, reply_types=(fr.STATUS,)).payload)
            assert status.rx_crc_errors == 1
            assert status.rx_bad_frames >= 1
            assert not status.flags & fr.FLAG_ACTIVE and status.pulses_us == (0,) * 6
            assert not any(p.width_us > 1900 for p in uno.pulses)


def test_mega_firmware_streams_injected_adc_voltages_at_1khz(tmp_path):
    volts = [2.5, 2.6, 2.4, 3.0, 1.0, 4.5]
    samples = []
    with SimavrBoard("mega", link=tmp_path / "mega") as mega:
        for ch, v in enumerate(volts):
            mega.set_adc(ch, v)
        with CurrentLink(mega.port, rate_hz=1000, on_sample=lambda s, t, g: samples.append(s)) as link:
            assert link.wait_connected(5.0), link.stats.last_error
            assert _wait(lambda: len(samples) >= 300, 5.0)
            expected = tuple(simavr_counts(v) for v in volts)
            assert samples[-1].counts == expected
            dts = {b.board_time_us - a.board_time_us for a, b in zip(samples[-200:], samples[-199:])}
            assert dts == {1000}   # the board's 1 kHz sampling instants, exactly
            assert link.sample_gaps == 0 and link.stats.crc_errors == 0
            mega.set_adc(0, 3.5)
            t_set = time.monotonic()
            assert _wait(lambda: samples[-1].counts[0] == simavr_counts(3.5), 2.0)
            assert time.monotonic() - t_set < 1.0
            status = fr.unpack_current_status(link.request(fr.GET_STATUS, reply_types=(fr.STATUS,)).payload)
            assert status.rate_hz == 1000 and status.overruns == 0 and status.flags & fr.FLAG_ACTIVE
            link.stop_stream()
            n = len(samples)
            time.sleep(0.2)
            assert len(samples) <= n + 2   # STOP_STREAM stops the stream
