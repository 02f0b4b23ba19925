"""Firmware-in-the-loop: the real Uno/Mega .elf files in simavr, driven by the host links (hexa.protocol.link).

These tests fail (never skip) when the toolchain or the build is missing: `make test` builds the firmware first.
"""
from __future__ import annotations

import time

import pytest

from hexa.protocol import frames as fr
from hexa.protocol.link import CurrentLink, LinkError, ServoLink
from hexa.protocol.simavr import SERVO_PINS, SimavrBoard, simavr_counts

pytestmark = pytest.mark.slow   # the firmware in simavr: left out of `make check`


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


def _rising_edges(uno, pin):
    """Simulated times (µs) of the rising edges on `pin` with the widths of their pulses."""
    return [(p.sim_time_us - p.width_us, p.width_us) for p in list(uno.pulses) if p.pin == pin]


def _nearest(edges, t_us):
    return min(edges, key=lambda e: abs(e[0] - t_us))


LATCH_CLOCK_TOL_US = 4.0    # micros() counts in 4 µs steps (Timer0, prescaler 64 at 16 MHz)
LATCH_EDGE_JITTER_US = 9.0  # an edge is late by however long another ISR (Timer0 overflow, UART) holds the CPU:
# ≤ 6 µs in most runs, 7.1 µs at most seen (two back to back); under half the test commands' 20 µs spacing


def test_uno_firmware_latch_report_times_each_pulse_and_names_its_command(tmp_path):
    latches: list[fr.Latch] = []
    with SimavrBoard("uno", link=tmp_path / "uno") as uno:
        with ServoLink(uno.port) as link:
            assert link.wait_connected(5.0), link.stats.last_error
            assert link.set_targets([1500] * 6)
            time.sleep(0.3)
            assert link.latches == 0                      # off after reset: no LATCH without the enable
            with pytest.raises(LinkError, match="BAD_LENGTH"):
                link.request(fr.SET_LATCH_REPORT, b"\x01\x00")
            with pytest.raises(LinkError, match="BAD_VALUE"):
                link.request(fr.SET_LATCH_REPORT, b"\x02")
            link.on_latch = lambda latch, t_rx: latches.append(latch)
            link.request(fr.SET_LATCH_REPORT, fr.pack_latch_report(True))
            widths: dict[int, tuple[int, ...]] = {link.last_targets_seq: (1500,) * 6}
            for k in range(1, 21):   # 20 commands, each with its own widths, the next once a frame latched this one
                w = tuple(1000 + 100 * i + 20 * k for i in range(6))
                assert link.set_targets(w)
                seq = link.last_targets_seq
                widths[seq] = w
                # paced by the board's frames, not by wall time: simavr runs at 0.2-1x of real time with the host's
                # load, and a command superseded within one 20 ms frame is never latched (as on the robot)
                t_end = time.monotonic() + 5.0
                while not any(x.seqs[5] == seq for x in list(latches)) and time.monotonic() < t_end:
                    time.sleep(0.005)
            time.sleep(0.1)
            link.request(fr.SET_LATCH_REPORT, fr.pack_latch_report(False))
            n_off = len(latches)
            time.sleep(0.2)
            assert len(latches) <= n_off + 1              # disabled: the stream stops (one may be in flight)
            assert link.stats.crc_errors == 0 and link.stats.decode_errors == 0
        del latches[n_off:]
        # at least one 20 ms frame per command: enough for the spacing check below, which proves none is missing in
        # between
        assert len(latches) >= 8
        starts = [x.frame_start_us for x in latches]
        spacing = [b - a for a, b in zip(starts, starts[1:])]
        # one LATCH per 20 ms frame of simulated time, none missing: 50 per simulated second
        assert all(abs(d - 20000) <= LATCH_CLOCK_TOL_US for d in spacing), sorted(set(spacing))
        edges = {i: _rising_edges(uno, pin) for i, pin in enumerate(SERVO_PINS)}
        # the board's micros() clock and the simulated time differ by a constant: estimate it, then check each edge
        offset = sorted(_nearest(edges[0], s)[0] - s for s in starts)[len(starts) // 2]
        start_err, slot_err, width_err, seen = [], [], [], set()
        for x in latches:
            assert x.mask == 0x3F and x.offsets_us[0] == 0
            rise0, _ = _nearest(edges[0], x.frame_start_us + offset)
            start_err.append(rise0 - offset - x.frame_start_us)
            for i in range(6):
                rise, width = _nearest(edges[i], rise0 + x.offsets_us[i])
                slot_err.append(rise - rise0 - x.offsets_us[i])
                assert x.seqs[i] in widths, (x, i)
                width_err.append(width - widths[x.seqs[i]][i])   # the pulse carried that command (20 µs apart)
                assert abs(width_err[-1]) <= LATCH_EDGE_JITTER_US, (x, i, width)
                seen.add(x.seqs[i])
        assert max(map(abs, start_err)) <= LATCH_CLOCK_TOL_US + LATCH_EDGE_JITTER_US, start_err
        assert max(map(abs, slot_err)) <= LATCH_EDGE_JITTER_US, slot_err
        # every command reached every servo, in order: per channel, seqs step through the commands without going back
        order = list(widths)
        for i in range(6):
            idx = [order.index(x.seqs[i]) for x in latches]
            assert idx == sorted(idx)
        assert set(order[1:]) <= seen
        print(f"LATCH frames {len(latches)}, spacing {min(spacing)}..{max(spacing)} us, frame start vs edge "
              f"{min(start_err):+.2f}..{max(start_err):+.2f} us (clock offset {offset:.2f} us), "
              f"slot offsets vs edges {min(slot_err):+.2f}..{max(slot_err):+.2f} us, "
              f"widths {min(width_err):+.2f}..{max(width_err):+.2f} us")
