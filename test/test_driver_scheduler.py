"""The driver's command scheduling and sample pairing without ROS (hexa.protocol.driver_scheduler): the rate limit and
coalescing, commands dated after their write and confirmed by the next read, the slew limit on the Mega's clock, the
Uno's frames moved onto the Mega's clock, the calibration's averaging, diagnostics and concurrent callers."""
from __future__ import annotations

import math
import threading
from types import SimpleNamespace

import numpy as np
import pytest

from hexa.protocol import frames as fr
from hexa.protocol.driver_core import DriverConfigError, driver_core_from_config, load_driver_config
from hexa.protocol.driver_scheduler import CalibrationRefused, DriverScheduler, driver_reports
from hexa.protocol.stream_watch import StreamWatch
from hexa.robots.hexa_description import load_hexa

MEGA = 5.0      # the Mega's board clock reads host time · rate + MEGA (s)
UNO = 2.0       # the Uno's reads host time + UNO (s)
COUNTS = (512, 520, 500, 530, 490, 512)


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


@pytest.fixture
def core(desc):
    c = driver_core_from_config(load_driver_config(), desc.zeta_min, desc.zeta_max, desc.K_t)
    c.max_speed = 0.0
    return c


class World:
    """A host clock, a Mega that measures a sample every ms (arriving at once, one read each) and a servo board
    that takes SET_TARGETS (their SEQs count from 1)."""

    def __init__(self, sched: DriverScheduler, rate: float = 1.0) -> None:
        self.sched, self.rate, self.t, self.seq = sched, rate, 0.0, 0
        self.sent: list[list[int]] = []
        self.write_time = 0.0          # host seconds a write takes (the command is dated after it)

    def mega_time(self, t: float) -> float:
        return MEGA + self.rate * t

    def run_to(self, t_end: float) -> list:
        readings = []
        while self.t + 0.001 <= t_end + 1e-9:
            self.t += 0.001
            self.seq += 1
            sample = fr.Sample(self.seq, int(round(self.mega_time(self.t) * 1e6)), COUNTS)
            readings += [(self.mega_time(self.t), r) for r in self.sched.on_samples([sample], self.t, self.t)]
        return readings

    def send(self, pulses: list[int]) -> int:
        self.sent.append(list(pulses))
        return len(self.sent) & 0xFF

    def command(self, zeta: np.ndarray) -> None:
        """Submit and flush at the current host time."""
        self.sched.submit(zeta, self.t)
        self.flush()

    def flush(self) -> None:
        self.sched.flush(self.t, self.send, clock=lambda: self.t + self.write_time)


def test_commands_coalesce_and_go_out_at_most_at_command_rate(core, desc):
    sched = DriverScheduler(core, command_rate_hz=100.0)
    sent: list[list[int]] = []
    z = np.full(6, desc.zeta_center)
    assert sched.submit(z, 1.0)                          # the first goes at once
    sched.flush(1.0, lambda p: sent.append(p) or 1)
    assert len(sent) == 1
    assert not sched.submit(z + 0.01, 1.004)             # 4 ms later: waits for the rate limit
    assert not sched.submit(z + 0.02, 1.006)             # replaces the waiting one
    assert core.counters.coalesced == 1 and np.allclose(sched.pending, z + 0.02)
    sched.flush(1.010, lambda p: sent.append(p) or 2)
    assert len(sent) == 2 and sent[1] == core.pulses_from_angles(z + 0.02) and sched.pending is None
    sched.flush(1.020, lambda p: sent.append(p) or 3)    # nothing waiting: nothing sent
    assert len(sent) == 2 and core.counters.accepted == 2
    sched.submit(z, 1.03)
    sched.flush(1.03, lambda p: None)                    # the port did not take it
    assert sched.tx_failures == 1 and core.counters.accepted == 3


def test_each_sample_carries_the_command_sent_before_it_was_measured_dated_after_the_write(core, desc):
    sched = DriverScheduler(core, command_rate_hz=100.0, latch_report=False)
    w = World(sched)
    a, b = np.full(6, desc.zeta_center), np.full(6, desc.zeta_center) + 0.05
    before = w.run_to(0.2)
    assert all(np.isnan(r.setpoints).all() for _, r in before)       # nothing commanded yet
    w.command(a)
    w.run_to(0.3)
    w.write_time = 0.004                                  # a slow write: the Uno cannot have it before it ends
    w.command(b)
    t_b = w.mega_time(0.304)
    readings = w.run_to(0.4)
    for board, r in readings:
        if abs(board - t_b) > 0.0015:
            assert np.allclose(r.setpoints, a if board < t_b else b), (board - t_b, r.setpoints)
        assert np.allclose(r.currents, core.currents_from_counts(COUNTS))
        assert np.allclose(r.efforts, desc.K_t * r.currents)
    _, r = readings[-1]
    assert np.isnan(sched.on_samples([r.sample._replace(sequence=0)], 0.4, 0.4, servos_driven=False)[0].setpoints).all()


def test_a_command_sent_before_a_late_burst_was_read_keeps_off_the_samples_measured_before_it(core, desc):
    """The Mega's samples of 40 ms wait in the port (the link thread stalled) while a command goes out; the map
    then extrapolates at most 10 ms past the newest sample it knows, so the send is dated early. The read of the
    burst, started after the send, proves when the board clock was at least: the burst's samples keep the old one."""
    sched = DriverScheduler(core, command_rate_hz=100.0, latch_report=False)
    w = World(sched)
    a, b = np.full(6, desc.zeta_center), np.full(6, desc.zeta_center) + 0.05
    w.run_to(0.3)
    w.command(a)
    w.run_to(0.5)
    held = [fr.Sample(w.seq + k, int(round(w.mega_time(0.5 + 0.001 * k) * 1e6)), COUNTS) for k in range(1, 41)]
    w.t = 0.541
    w.command(b)                                          # dated at most 10 ms after the last sample read: early
    readings = sched.on_samples(held, t_read=0.542, t_rx=0.542)
    # the read proves the board clock read ≥ 0.540 at 0.542, hence ≥ 0.539 at the send: up to then, the old one
    measured = [(s.board_time_us * 1e-6 - MEGA, r.setpoints[0]) for s, r in zip(held, readings)]
    assert all(np.isclose(z, a[0]) for t, z in measured if t < 0.539 - 1e-6), measured
    assert sched.timeline.redated == 1
    w.t, w.seq = 0.541, w.seq + 40
    assert all(np.allclose(r.setpoints, b) for _, r in w.run_to(0.6)[2:])


def test_the_slew_limit_runs_on_the_megas_clock(core, desc):
    """In simulation at real-time factor 0.3 the Mega's clock (sim time) runs 0.3 s per host second: 100 ms of host
    time between two commands allow 30 ms of motion."""
    core.max_speed, core.slew_period = 1.0, 0.0
    sched = DriverScheduler(core, command_rate_hz=100.0, latch_report=False)
    w = World(sched, rate=0.3)
    a = np.full(6, desc.zeta_center)
    w.run_to(0.5)
    assert sched.board_clock.rate == pytest.approx(0.3, abs=1e-3)
    w.command(a)
    w.run_to(0.6)
    w.command(a + 1.0)
    assert np.allclose(core.commanded - a, 0.03, atol=1e-3), core.commanded - a
    assert core.counters.slew_limited == 1


def _frame_offsets(pulses: list[int]) -> tuple[int, ...]:
    """Each channel's slot start (µs after the frame's start): the pulses one after the other."""
    return tuple(int(v) for v in np.concatenate([[0], np.cumsum(pulses)[:-1]]))


def _report_frames(w: World, starts: list[float], seq_of, late: dict[int, float] | None = None) -> None:
    """Uno frames starting at host times `starts`, each reported after its last pulse (`late[k]` s later)."""
    for k, start in enumerate(starts):
        seq = seq_of(start)
        pulses = w.sent[seq - 1]
        offsets = _frame_offsets(pulses)
        arrival = start + (offsets[5] + pulses[5]) * 1e-6 + (late or {}).get(k, 0.0)
        w.run_to(arrival)
        latch = fr.Latch(int(round((start + UNO) * 1e6)), offsets, (seq,) * 6, 0b111111)
        w.sched.on_latch(latch, arrival)


def test_the_unos_frames_land_on_the_megas_clock_by_the_median_offset(core, desc):
    """Each servo switches to a command at the end of the first pulse that carried it, on the Mega's clock — also
    when that frame's report (and another) came 6 ms late: the offset between the clocks is the median over the
    reports, not the latest."""
    sched = DriverScheduler(core, command_rate_hz=100.0)
    w = World(sched)
    sched.on_latch(fr.Latch(0, (0,) * 6, (0,) * 6, 0), 0.0)           # before any sample: cannot be mapped
    assert sched.latches_unmapped == 1 and sched.frames.frames == 0
    a = np.full(6, desc.zeta_center)
    b = a + 0.02 * np.arange(1, 7)
    w.run_to(0.3)
    w.command(a)
    starts = [0.3105 + 0.02 * k for k in range(12)]
    _report_frames(w, starts[:7], lambda s: 1)
    w.run_to(0.45)
    w.command(b)
    switch_frame = 7                                      # the first frame after the command carries it
    _report_frames(w, starts[7:], lambda s: 2, late={0: 0.006, 2: 0.006})
    assert sched.frames.frames == 12
    assert sched.clock_offset == pytest.approx(UNO - MEGA, abs=2e-6)
    pulses_b = w.sent[1]
    offsets = _frame_offsets(pulses_b)
    for i in range(6):
        switch = w.mega_time(starts[switch_frame]) + (offsets[i] + pulses_b[i]) * 1e-6
        assert sched.setpoints_at(switch - 2e-4)[i] == pytest.approx(a[i])
        assert sched.setpoints_at(switch + 2e-4)[i] == pytest.approx(b[i])


def test_the_calibration_averages_the_samples_at_rest_and_refuses_otherwise(core, desc):
    sched = DriverScheduler(core, command_rate_hz=100.0, latch_report=False)
    w = World(sched)
    with pytest.raises(CalibrationRefused, match="current board link is DISCONNECTED"):
        sched.start_calibration(0.0, 0.5, link_state="DISCONNECTED")
    w.command(np.full(6, desc.zeta_center))
    w.run_to(0.2)
    with pytest.raises(CalibrationRefused, match="less than 0.5 s ago"):
        sched.start_calibration(w.t, 0.5)
    w.run_to(0.6)
    sched.start_calibration(w.t, 0.5)
    with pytest.raises(CalibrationRefused, match="running already"):
        sched.start_calibration(w.t, 0.5)
    w.run_to(0.603)
    with pytest.raises(CalibrationRefused, match="only 3 samples in 0.003 s"):
        sched.finish_calibration(0.003)
    sched.start_calibration(w.t, 0.5)
    w.run_to(0.7)
    sched.submit(np.full(6, desc.zeta_center), w.t)       # a command during the averaging
    with pytest.raises(CalibrationRefused, match="arrived during the calibration"):
        sched.finish_calibration(0.1)
    w.flush()
    w.run_to(1.3)
    sched.start_calibration(w.t, 0.5)
    w.run_to(1.4)
    offsets, n = sched.finish_calibration(0.1)
    assert n == 100 and np.allclose(offsets, core.sensor.current_from_counts(COUNTS))
    assert np.allclose(w.run_to(1.41)[-1][1].currents, 0.0)
    with pytest.raises(CalibrationRefused, match="no calibration"):
        sched.finish_calibration(0.1)


def test_a_new_mega_connection_keeps_only_the_newest_command_whatever_its_clock_reads(core, desc):
    sched = DriverScheduler(core, command_rate_hz=100.0, latch_report=False)
    w = World(sched)
    a = np.full(6, desc.zeta_center)
    w.run_to(0.2)
    w.command(a)
    w.run_to(0.3)
    sched.on_connected("mega")
    assert sched.board_clock.board_time_at(w.t) is None
    restarted = fr.Sample(1, 1000, COUNTS)                # the board restarted: its clock reads 1 ms
    assert np.allclose(sched.on_samples([restarted], 0.31, 0.31)[0].setpoints, a)


@pytest.mark.parametrize("key, value", [("board_clock_max_extrapolation", -1.0),
                                        ("board_clock_max_extrapolation", float("nan")),
                                        ("command_rate_hz", 0.0)])
def test_a_bad_timing_parameter_is_refused_naming_it(core, key, value):
    cfg = dict(load_driver_config(), **{key: value})
    with pytest.raises(DriverConfigError, match=key):
        DriverScheduler.from_config(core, cfg)


def test_link_threads_and_callbacks_may_call_in_concurrently(core, desc):
    """Samples from one thread, commands and flushes from another, LATCH reports from a third: no torn state (an
    unlocked timeline raises 'deque mutated during iteration' here), every set-point one of the commands sent."""
    sched = DriverScheduler(core, command_rate_hz=1e6)
    a = np.full(6, desc.zeta_center)
    errors: list[BaseException] = []
    stop = threading.Event()
    seen: list[float] = []

    def samples():
        k = 0
        while not stop.is_set():
            k += 1
            t = 1e-4 * k
            for r in sched.on_samples([fr.Sample(k, int(t * 1e6) + 1000, COUNTS)], t, t):
                if np.isfinite(r.setpoints[0]):
                    seen.append(float(r.setpoints[0]))

    def commands():
        for k in range(2000):
            sched.submit(a + 1e-4 * k, 1e-3 * k)
            sched.flush(1e-3 * k, lambda p: k & 0xFF, clock=lambda: 1e-3 * k)

    def latches():
        while not stop.is_set():
            sched.on_latch(fr.Latch(1000, _frame_offsets([1500] * 6), (1,) * 6, 0b111111), 0.5)

    def guard(fn):
        def run():
            try:
                fn()
            except BaseException as exc:     # noqa: BLE001 - reported by the test
                errors.append(exc)
        return run

    threads = [threading.Thread(target=guard(f)) for f in (samples, latches)]
    for th in threads:
        th.start()
    guard(commands)()
    stop.set()
    for th in threads:
        th.join()
    assert not errors, errors
    steps = (np.asarray(seen) - a[0]) / 1e-4              # every set-point one of the commands sent, whole
    assert core.counters.accepted == 2000 and seen and np.allclose(steps, np.round(steps), atol=1e-6)


def test_diagnostics_name_a_stale_board_and_the_watchdog_hold(core):
    sched = DriverScheduler(core, command_rate_hz=100.0)
    stats = dict(connects=1, disconnects=0, last_reconnect_s=float("nan"), frames_rx=10, frames_tx=5, crc_errors=0,
                 bad_length=0, resyncs=0, discarded_bytes=0, dropped_frames=0, board_errors=0, decode_errors=0,
                 rtt_s=0.001, firmware_version=1, last_error="")
    uno = SimpleNamespace(port="/dev/uno", restored=0, stats=SimpleNamespace(state="CONNECTED", last_rx=9.9, **stats),
                          status=fr.ServoStatus(fr.FLAG_WATCHDOG_HOLD, 0, 0, 0, 0, (1500,) * 6, 600),
                          watch=StreamWatch(0.25, 0.2, 0.75), reconfigures={"outputs_off": 0})
    mega = SimpleNamespace(port="/dev/mega", samples=100, sample_gaps=0, rate_hz=200, status=None,
                           stats=SimpleNamespace(state="STALE", last_rx=9.5, **stats),
                           watch=StreamWatch(0.25, 0.2, 0.75))
    uno_r, mega_r = driver_reports(sched, uno, mega, now=10.0, stale_timeout=0.25)
    assert (mega_r.level, mega_r.message) == ("ERROR", "telemetry stale (no data for 0.50 s)")
    assert uno_r.level == "OK" and uno_r.values["board_watchdog_hold"] is True   # nothing commanded yet: no WARN
    sched.submit(np.zeros(6), 10.0)
    sched.flush(10.0, lambda p: 1)
    sched.on_samples([fr.Sample(1, 1000, COUNTS)], 10.0, 10.0)
    mega.stats.state = "CONNECTED"
    uno_r, mega_r = driver_reports(sched, uno, mega, now=10.5, stale_timeout=0.25)
    assert uno_r.level == "WARN" and "holding last command" in uno_r.message
    assert (mega_r.level, mega_r.message) == ("ERROR", "telemetry stale (no sample for 0.50 s)")
    assert mega_r.values["sample_rate_hz"] == "0.0" and uno_r.values["commands_accepted"] == 1
    assert uno_r.hardware_id == "/dev/uno" and mega_r.values["state"] == "CONNECTED"
    uno.watch.start(10.5)          # the latch report asked for and quiet since: ERROR naming it, counted recoveries
    uno_r, _ = driver_reports(sched, uno, mega, now=10.8, stale_timeout=0.25)
    assert (uno_r.level, uno_r.message) == ("ERROR", "latch report stale (no LATCH for 0.30 s)")
    assert uno_r.values["latch_rerequests"] == 0 and uno_r.values["board_reconfigures_outputs_off"] == 0


def test_a_calibration_duration_that_is_not_finite_or_too_long_is_refused_naming_it():
    from hexa.protocol.driver_scheduler import MAX_CALIBRATION_DURATION, calibration_duration

    assert calibration_duration(0.4, 1.0) == 0.4
    assert calibration_duration(0.0, 1.0) == 1.0 and calibration_duration(-2.0, 1.0) == 1.0
    for bad in (math.nan, math.inf, MAX_CALIBRATION_DURATION + 1.0, 1e300):
        with pytest.raises(CalibrationRefused, match="duration must be a finite number of seconds"):
            calibration_duration(bad, 1.0)
