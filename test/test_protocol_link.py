"""Host-side links (hexa.protocol.link) against the pty emulators: handshake, streaming, gaps, reconnect."""
from __future__ import annotations

import threading
import time

import pytest

from hexa.protocol import frames as fr
from hexa.protocol.emulator import MegaEmulator, UnoEmulator
from hexa.protocol.link import CONNECTED, DISCONNECTED, CurrentLink, LinkError, ServoLink


def _wait(cond, timeout=3.0):
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


def test_servo_link_configures_limits_and_commands_reach_board(tmp_path):
    got = []
    with UnoEmulator(on_targets=got.append, link=tmp_path / "uno") as uno:
        with ServoLink(uno.port, min_us=[600] * 6, max_us=[2400] * 6, watchdog_ms=300) as link:
            assert link.wait_connected(3.0)
            assert uno.min_us == [600] * 6 and uno.max_us == [2400] * 6 and uno.watchdog_ms == 300
            assert link.set_targets([500, 1000, 1500, 2000, 2500, 1234])
            assert _wait(lambda: got)
            assert got[0] == (600, 1000, 1500, 2000, 2400, 1234)
            assert _wait(lambda: link.status is not None and link.status.pulses_us == got[0])
            assert link.status.flags & fr.FLAG_CLAMPED
            assert _wait(lambda: link.stats.rtt_s == link.stats.rtt_s)  # a PONG measured the round trip
            assert link.stats.crc_errors == 0 and link.stats.dropped_frames == 0


def test_servo_link_refuses_a_current_board(tmp_path):
    with MegaEmulator(link=tmp_path / "mega") as mega:
        link = ServoLink(mega.port, hello_timeout=0.3, reconnect_period=0.05).start()
        try:
            time.sleep(0.5)
            assert link.stats.state != CONNECTED
            assert "expected a servo (Uno) board" in link.stats.last_error
        finally:
            link.stop()


def test_request_reports_board_error_naming_it(tmp_path):
    with UnoEmulator(link=tmp_path / "uno") as uno, ServoLink(uno.port) as link:
        assert link.wait_connected(3.0)
        with pytest.raises(LinkError, match="BAD_VALUE"):
            link.request(fr.SET_LIMITS, fr.pack_limits([2000] * 6, [1000] * 6))


def test_current_link_streams_without_gaps_and_counts_injected_drops(tmp_path):
    drop = threading.Event()
    dropped = []

    def tx_filter(data: bytes) -> bytes:
        if drop.is_set() and data[3] == fr.SAMPLE and len(dropped) < 5:
            dropped.append(data)
            return b""
        return data

    samples = []
    with MegaEmulator(current_source=lambda t: [0.25] * 6, link=tmp_path / "mega", tx_filter=tx_filter) as mega:
        with CurrentLink(mega.port, rate_hz=500, on_sample=lambda s, t, g: samples.append((s, g))) as link:
            assert link.wait_connected(3.0)
            assert _wait(lambda: len(samples) >= 100)
            assert link.sample_gaps == 0
            drop.set()
            assert _wait(lambda: len(dropped) == 5 and len(samples) >= 200)
            assert link.sample_gaps == 5
            assert link.stats.dropped_frames == 5
            assert sum(g for _, g in samples) == 5


def test_unplug_replug_recovers_under_two_seconds(tmp_path):
    samples = []
    with MegaEmulator(link=tmp_path / "mega") as mega:
        with CurrentLink(mega.port, rate_hz=200, on_sample=lambda s, t, g: samples.append(t)) as link:
            assert link.wait_connected(3.0)
            assert _wait(lambda: len(samples) > 10)
            mega.unplug()
            assert _wait(lambda: link.stats.state == DISCONNECTED, 1.0)
            time.sleep(0.3)
            n_before = len(samples)
            t_replug = time.monotonic()
            mega.replug()
            assert _wait(lambda: len(samples) > n_before, 2.0)
            recovery = samples[n_before] - t_replug
            assert recovery < 2.0
            assert link.stats.disconnects == 1 and link.stats.connects == 2
            assert link.stats.last_reconnect_s < 2.5


def test_a_board_that_stops_streaming_is_asked_again_and_streams_within_a_second(tmp_path):
    samples = []
    with MegaEmulator(link=tmp_path / "mega") as mega, \
            CurrentLink(mega.port, rate_hz=200, stale_timeout=0.25, stream_reconnect_after=0.75,
                        on_sample=lambda s, t, g: samples.append(t)) as link:
        assert link.wait_connected(3.0) and _wait(lambda: len(samples) > 20)
        mega.reset()                        # the board restarts with its port open: no stream, answers requests
        t_stop = time.monotonic()
        assert _wait(lambda: samples[-1] > t_stop + 0.05, 2.0)
        back = next(t for t in samples if t > t_stop) - t_stop
        print(f"stopped stream -> streaming again: {back * 1e3:.0f} ms")
        assert back < 1.0 and link.watch.rerequests >= 1 and link.watch.recoveries == 1
        assert link.stats.connects == 1 and link.watch.reconnects == 0   # re-requested, not reconnected
        link.stop_stream()                  # stopped by the host: not re-requested
        time.sleep(0.5)
        assert not mega.streaming and link.watch.rerequests == 1


def test_a_hung_board_is_reconnected_when_rerequests_do_not_help(tmp_path):
    hung = threading.Event()
    with MegaEmulator(link=tmp_path / "mega", tx_filter=lambda b: b"" if hung.is_set() else b) as mega:
        states = []
        with CurrentLink(mega.port, rate_hz=100, stale_timeout=0.2, drop_after=5.0, stream_reconnect_after=0.5,
                         poll_period=0, ping_period=0, on_state=states.append) as link:
            assert link.wait_connected(3.0)
            hung.set()                      # the board sends nothing at all
            assert _wait(lambda: "STALE" in states, 1.0)
            assert _wait(lambda: link.stats.disconnects == 1, 1.0)    # after 0.5 s quiet, not drop_after's 5 s
            assert link.watch.reconnects == 1 and link.watch.rerequests >= 1
            hung.clear()
            assert _wait(lambda: link.stats.connects >= 2, 3.0)       # reopened, stream restarted
            assert mega.streaming


def test_a_servo_board_reset_with_the_port_open_is_configured_again(tmp_path):
    got, latches = [], []
    with UnoEmulator(on_targets=got.append, link=tmp_path / "uno") as uno, \
            ServoLink(uno.port, watchdog_ms=300, min_us=[700] * 6, on_latch=lambda x, t: latches.append(t),
                      stale_timeout=0.25) as link:
        assert link.wait_connected(3.0)
        link.set_targets([1100, 1200, 1300, 1400, 1500, 1600])
        assert _wait(lambda: len(got) == 1 and len(latches) > 5)
        uno.reset()                         # outputs off, default limits and watchdog, no latch report
        t_reset = time.monotonic()
        assert _wait(lambda: latches[-1] > t_reset + 0.05 and len(got) >= 2, 2.0)
        back = next(t for t in latches if t > t_reset) - t_reset
        print(f"servo board reset -> latch report again: {back * 1e3:.0f} ms")
        assert back < 1.0 and got[-1] == got[0] and uno.outputs_enabled
        assert (uno.watchdog_ms, uno.min_us, uno.latch_report) == (300, [700] * 6, True)
        assert link.reconfigures["outputs_off"] + link.reconfigures["latch_quiet"] >= 1
        assert link.stats.connects == 1


def test_a_servo_board_without_targets_is_not_taken_for_a_quiet_one(tmp_path):
    # the board reports a pulse frame only while some output is on: before the first targets no LATCH is due
    latches = []
    with UnoEmulator(link=tmp_path / "uno") as uno, \
            ServoLink(uno.port, on_latch=lambda x, t: latches.append(t), stale_timeout=0.2,
                      stream_reconnect_after=0.5) as link:
        assert link.wait_connected(3.0) and link.latch_supported
        time.sleep(1.5)                     # three times the stream's reconnect time, without targets
        assert (link.stats.connects, link.stats.disconnects, link.watch.reconnects) == (1, 0, 0)
        assert latches == [] and link.reconfigures["latch_quiet"] == 0
        link.set_targets([1500] * 6)
        assert _wait(lambda: len(latches) > 5, 2.0) and link.watch.active
        uno.reset()                         # outputs off, no latch report: now the quiet stream is recovered
        assert _wait(lambda: link.reconfigures["latch_quiet"] + link.reconfigures["outputs_off"] >= 1, 2.0)


def test_servo_link_restores_last_targets_after_the_board_comes_back(tmp_path):
    got = []
    with UnoEmulator(on_targets=got.append, link=tmp_path / "uno") as uno, ServoLink(uno.port) as link:
        assert link.wait_connected(3.0)
        link.set_targets([1100, 1200, 1300, 1400, 1500, 1600])
        assert _wait(lambda: len(got) == 1)
        uno.unplug()
        assert _wait(lambda: link.stats.state == DISCONNECTED, 1.0)
        uno.replug()   # the board restarts with its outputs off
        assert _wait(lambda: len(got) == 2, 3.0)
        assert got[1] == got[0] and uno.outputs_enabled and link.restored == 1
