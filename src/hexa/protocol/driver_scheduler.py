"""When each joint command goes out to the servo board, and which set-points each current sample carries.

`DriverScheduler` is the driver's timing state between the two boards (docs/driver_timing.md):

- commands: the newest command waits while the previous one went out less than 1/`command_rate_hz` ago (faster
  ones coalesce, the latest wins);
- samples: the Mega's board clock mapped from the host's (`BoardClockMap`), each command dated on it when sent and
  confirmed by the next read of the port (`CommandTimeline`), each sample paired with the set-points the servos acted
  on when it was measured — from the Uno's reported pulse frames (`ServoFrameTimeline`) when it reports them;
- LATCH reports: the Uno's frames moved onto the Mega's clock by the median offset between the two board clocks;
- the zero-current calibration's averaging.

Times are arguments (host monotonic seconds): nothing here reads a clock except `flush`, which dates a command after
its bytes are written (`clock`). The serial link threads (`on_samples`, `on_latch`, `on_connected`) and the ROS
callbacks (`submit`, `flush`, the calibration) may call in concurrently: every method that touches the shared state
takes one lock.
"""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from hexa.protocol import frames as fr
from hexa.protocol.board_clock import BoardClockMap, CommandTimeline, ServoFrameTimeline
from hexa.protocol.driver_core import N_JOINTS, DriverConfigError, DriverCore

if TYPE_CHECKING:
    from hexa.protocol.link import BoardLink, CurrentLink, ServoLink
    from hexa.protocol.stream_watch import StreamWatch

#: LATCH reports whose clock offsets (Uno board time − Mega board time) the median runs over: 1 s of 20 ms frames
OFFSET_WINDOW = 50
#: fewest samples a zero-current calibration averages
MIN_CALIBRATION_SAMPLES = 5
#: longest zero-current averaging a request may ask for (s): the robot stays at rest throughout
MAX_CALIBRATION_DURATION = 60.0


class CalibrationRefused(RuntimeError):
    """A zero-current calibration that cannot be done now; the message says why."""


def calibration_duration(requested: float, default: float) -> float:
    """The averaging time (s) of a zero-current calibration request: `requested`, or `default` when it is 0 or less.

    Raises:
        CalibrationRefused: `requested` is not finite or longer than MAX_CALIBRATION_DURATION.
    """
    if not math.isfinite(requested) or requested > MAX_CALIBRATION_DURATION:
        raise CalibrationRefused(f"duration must be a finite number of seconds up to {MAX_CALIBRATION_DURATION:g} "
                                 f"(0 = {default:g} s), got {requested!r}")
    return float(requested) if requested > 0 else float(default)


class SampleReading(NamedTuple):
    """One current sample converted: motor currents I − I₀ (A), efforts τ = K_t (I − I₀) (N·m) and the six
    set-points the servos acted on when it was measured (rad; NaN where unknown)."""

    sample: fr.Sample
    currents: np.ndarray
    efforts: np.ndarray
    setpoints: np.ndarray


class DriverScheduler:
    """Command scheduling and sample pairing of the serial driver (one per Uno + Mega pair).

    Args:
        core: the driver's conversions and command limits; `flush` records each command sent in it.
        command_rate_hz: most SET_TARGETS per second.
        max_extrapolation: `BoardClockMap.max_extrapolation` of both board clocks (s, ≥ 0).
        latch_report: the Uno reports its pulse frames (`on_latch` is called).

    Raises:
        DriverConfigError: a value out of range (named by its driver.yaml key).
    """

    def __init__(self, core: DriverCore, command_rate_hz: float, max_extrapolation: float = 0.01,
                 latch_report: bool = True) -> None:
        rate, max_extrapolation = float(command_rate_hz), float(max_extrapolation)
        if not (math.isfinite(rate) and rate > 0):
            raise DriverConfigError(f"parameter command_rate_hz must be > 0, got {command_rate_hz}")
        if not (math.isfinite(max_extrapolation) and max_extrapolation >= 0.0):
            raise DriverConfigError(f"parameter board_clock_max_extrapolation must be >= 0 s, got {max_extrapolation}")
        self.core = core
        self.min_interval = 1.0 / rate
        self.latch_report = bool(latch_report)
        self.board_clock = BoardClockMap(max_extrapolation=max_extrapolation)   # the Mega's
        self.uno_clock = BoardClockMap(max_extrapolation=max_extrapolation)     # stops as the Mega's does
        self.timeline = CommandTimeline()
        self.frames = ServoFrameTimeline()
        self._lock = threading.Lock()
        self._pending: np.ndarray | None = None
        self._last_sent = -math.inf
        self._pulses_by_seq: dict[int, list[int]] = {}
        self._uno_offsets: deque[float] = deque(maxlen=OFFSET_WINDOW)
        self._board_restarts = 0
        self._calib: list[tuple[int, ...]] | None = None
        self._calib_submitted = 0
        self._rate_mark: tuple[float, int] | None = None
        self.sample_rate_hz = 0.0
        self.submitted = 0              # commands handed to `submit`
        self.tx_failures = 0            # commands the Uno's port did not take
        self.latches_unmapped = 0       # LATCH reports before the Mega's clock was known
        self.last_sample_time = 0.0     # host time of the newest sample (0: none yet)

    @classmethod
    def from_config(cls, core: DriverCore, cfg: Mapping[str, Any]) -> DriverScheduler:
        """The scheduler of a driver configuration (driver.yaml keys)."""
        return cls(core, float(cfg["command_rate_hz"]), float(cfg["board_clock_max_extrapolation"]),
                   bool(cfg["latch_report"]))

    # ------------------------------------------------------------------------------------------ links
    def on_connected(self, board: str) -> None:
        """The link to `board` ("uno" or "mega") connected: the board may have restarted, its clock with it."""
        with self._lock:
            if board == "mega":
                self.board_clock.reset()
                self.timeline.rebase()
            else:
                self.uno_clock.reset()
            self._uno_offsets.clear()
            self.frames.reset()

    # ------------------------------------------------------------------------------------------ commands
    def submit(self, zeta: np.ndarray, now: float) -> bool:
        """A checked command (six angles, rad) arrived at host time `now`: it replaces any command still waiting
        (counted as coalesced). True when the rate limit lets it go at once (call `flush`)."""
        with self._lock:
            if self._pending is not None:
                self.core.counters.coalesced += 1
            self._pending = np.array(zeta, dtype=float)
            self.submitted += 1
            return now - self._last_sent >= self.min_interval

    @property
    def pending(self) -> np.ndarray | None:
        """The command waiting to go out (None: none)."""
        return self._pending

    def flush(self, now: float, send: Callable[[list[int]], int | None],
              clock: Callable[[], float] = time.monotonic) -> None:
        """Send the waiting command, if any, at host time `now`.

        The command is clamped and slew-limited on the robot's time (the Mega's clock; before any sample the host's),
        recorded in the core, written with `send` and dated on the Mega's clock at `clock()` read after the write
        (the Uno cannot have it earlier), provisionally until the next read of the Mega's port.

        Args:
            now: host time (s).
            send: writes six pulse widths (µs) to the Uno; the SEQ of the SET_TARGETS frame, None when not written.
            clock: host clock read after the write.
        """
        with self._lock:
            if self._pending is None:
                return
            zeta, self._pending = self._pending, None
            board_now = self.board_clock.board_time_at(now)
            robot_now = now if board_now is None else board_now
            zeta = self.core.limit_command(zeta, robot_now)
            pulses = self.core.accept(zeta, now, slew_now=robot_now)
            seq = send(pulses)
            t_sent = clock()
            b_sent = self.timeline.add(self.board_clock.board_time_at(t_sent), self.core.commanded, sent_at=t_sent)
            if seq is not None:
                self.frames.add_command(seq, self.core.commanded, b_sent)
                self._pulses_by_seq[int(seq) & 0xFF] = list(pulses)
            else:
                self.tx_failures += 1
            self._last_sent = now

    # ------------------------------------------------------------------------------------------ telemetry
    def on_samples(self, samples: Sequence[fr.Sample], t_read: float, t_rx: float,
                   servos_driven: bool = True) -> list[SampleReading]:
        """One read of the Mega's port: its samples in order; the read started at host time `t_read` and returned at
        `t_rx` (s). Each sample converted and paired with the set-points in effect when it was measured (all NaN
        while `servos_driven` is False: no servo board, the arms' angle is unknown)."""
        if not samples:
            return []
        with self._lock:
            board_times = []
            for sample in samples:
                board_times.append(self.board_clock.update(sample.board_time_us, t_rx))
                if self.board_clock.restarts != self._board_restarts:
                    self._board_restarts = self.board_clock.restarts
                    self.timeline.rebase()
            # a command sent before this read is dated no earlier than its samples prove (CommandTimeline.confirm)
            self.timeline.confirm(t_read, max(board_times), self.board_clock.rate)
            setpoints = [self._setpoints_at(b) if servos_driven else None for b in board_times]
            if self._calib is not None:
                self._calib.extend(s.counts for s in samples)
            self.last_sample_time = t_rx
        return [self.reading(s, z) for s, z in zip(samples, setpoints)]

    def reading(self, sample: fr.Sample, setpoints: np.ndarray | None) -> SampleReading:
        """`sample` converted: currents, efforts and `setpoints` (None: unknown, NaN)."""
        currents = self.core.currents_from_counts(sample.counts)
        z = np.full(N_JOINTS, np.nan) if setpoints is None else np.asarray(setpoints, dtype=float)
        return SampleReading(sample, currents, self.core.torques_from_currents(currents), z)

    def setpoints_at(self, board_time: float) -> np.ndarray | None:
        """The set-points the servos acted on at Mega board time `board_time` (s): from the Uno's pulse frames when
        it reports them, else the command in effect (sent) then; None before any command."""
        with self._lock:
            return self._setpoints_at(board_time)

    def _setpoints_at(self, board_time: float) -> np.ndarray | None:
        z = self.frames.setpoints_at(board_time, self.timeline)
        return self.timeline.at(board_time) if z is None else z

    def on_latch(self, latch: fr.Latch, t_rx: float) -> None:
        """A LATCH report from the Uno, arrived at host time `t_rx` (s): the frame's pulses onto the Mega's clock,
        into the frame timeline.

        The Uno sends it right after the frame's last pulse, so that pulse's end is what the Uno's clock read, at the
        latest, when the report arrived, as the Mega's clock map says what the Mega's read then. Their difference is
        the offset between the two board clocks plus the difference of the two delays; its median over the last
        `OFFSET_WINDOW` frames (1 s) is the offset: crystals drift by ppm, constant over a second, and in simulation
        both clocks are sim time and stop together while a camera frame renders, which a single mapping through the
        host's clock would read as a jump."""
        with self._lock:
            widths = np.array([(self._pulses_by_seq.get(s) or [1500] * N_JOINTS)[i] for i, s in enumerate(latch.seqs)],
                              dtype=float) * 1e-6
            starts = np.asarray(latch.offsets_us, dtype=float) * 1e-6
            end_us = (latch.frame_start_us + int(latch.offsets_us[-1]) + int(round(widths[-1] * 1e6))) & 0xFFFFFFFF
            restarts = self.uno_clock.restarts
            b_end = self.uno_clock.update(end_us, t_rx)     # unwrapped (the µs counter wraps, the board restarts)
            if self.uno_clock.restarts != restarts:
                self._uno_offsets.clear()
                self.frames.reset()
            mega_now = self.board_clock.board_time_at(t_rx)
            if mega_now is None:
                self.latches_unmapped += 1
                return
            self._uno_offsets.append(b_end - mega_now)
            offset = float(np.median(self._uno_offsets))
            frame_start = b_end - starts[-1] - widths[-1] - offset     # on the Mega's clock
            self.frames.add_frame(frame_start, starts, starts + widths, np.asarray(latch.seqs), int(latch.mask),
                                  commands=self.timeline)

    @property
    def clock_offset(self) -> float | None:
        """Uno board time − Mega board time (s) as the LATCH reports measure it; None before any mapped report."""
        with self._lock:
            return float(np.median(self._uno_offsets)) if self._uno_offsets else None

    # ------------------------------------------------------------------------------------------ calibration
    def start_calibration(self, now: float, rest_quiet_time: float, link_state: str = "CONNECTED") -> None:
        """Start averaging the samples for the zero-current offsets I₀ at host time `now` (s).

        Args:
            now: host time (s).
            rest_quiet_time: the servos are at rest this long (s) after a command went out.
            link_state: the current board link's state (hexa.protocol.link): samples come only when CONNECTED.

        Raises:
            CalibrationRefused: the link is not connected, a calibration runs already, or a command went out less
                than `rest_quiet_time` s ago.
        """
        if link_state != "CONNECTED":
            raise CalibrationRefused(f"current board link is {link_state}")
        with self._lock:
            if self._calib is not None:
                raise CalibrationRefused("a calibration is running already")
            t_cmd = self.core.last_command_time
            if t_cmd is not None and now - t_cmd < rest_quiet_time:
                raise CalibrationRefused(f"not at rest: a joint command arrived less than {rest_quiet_time} s ago")
            self._calib = []
            self._calib_submitted = self.submitted

    def finish_calibration(self, duration: float) -> tuple[np.ndarray, int]:
        """End the averaging started by `start_calibration` `duration` s ago; the offsets I₀ (A, now in effect) and
        the number of samples averaged.

        Raises:
            CalibrationRefused: none was started, a command arrived meanwhile, or fewer than
                MIN_CALIBRATION_SAMPLES samples came.
        """
        with self._lock:
            samples, self._calib = self._calib, None
            moved = self.submitted != self._calib_submitted
        if samples is None:
            raise CalibrationRefused("no calibration was started")
        if moved:
            raise CalibrationRefused("not at rest: joint commands arrived during the calibration")
        if len(samples) < MIN_CALIBRATION_SAMPLES:
            raise CalibrationRefused(f"only {len(samples)} samples in {duration} s")
        return self.core.calibrate_offsets(np.asarray(samples)), len(samples)

    # ------------------------------------------------------------------------------------------ diagnostics
    def measure_sample_rate(self, now: float, samples: int) -> float:
        """The sample rate (Hz) since the previous call, from the link's sample count `samples` at host time `now`."""
        if self._rate_mark is not None and now > self._rate_mark[0]:
            self.sample_rate_hz = (samples - self._rate_mark[1]) / (now - self._rate_mark[0])
        self._rate_mark = (now, samples)
        return self.sample_rate_hz


class LinkReport(NamedTuple):
    """One board's diagnostic status: level "OK", "WARN" or "ERROR", message, hardware id and key/values."""

    name: str
    level: str
    message: str
    hardware_id: str
    values: dict[str, Any]


def link_report(name: str, link: BoardLink, now: float, extra: Mapping[str, Any]) -> LinkReport:
    """The status of a `hexa.protocol.link.BoardLink` at host time `now`: OK when connected, ERROR when stale,
    connecting or disconnected (the last error), with its stats and `extra` as values."""
    from hexa.protocol.link import CONNECTED, STALE

    st = link.stats
    if st.state == CONNECTED:
        level, message = "OK", "connected"
    elif st.state == STALE:
        level, message = "ERROR", f"telemetry stale (no data for {now - st.last_rx:.2f} s)"
    else:
        level = "ERROR"
        message = f"{st.state.lower()}: {st.last_error}" if st.last_error else st.state.lower()
    rtt = st.rtt_s * 1e3 if st.rtt_s == st.rtt_s else float("nan")
    values = {"state": st.state, "port": link.port, "connects": st.connects, "disconnects": st.disconnects,
              "last_reconnect_s": f"{st.last_reconnect_s:.3f}", "frames_rx": st.frames_rx, "frames_tx": st.frames_tx,
              "crc_errors": st.crc_errors, "bad_length": st.bad_length, "resyncs": st.resyncs,
              "discarded_bytes": st.discarded_bytes, "dropped_frames": st.dropped_frames,
              "board_errors": st.board_errors, "decode_errors": st.decode_errors, "latency_rtt_ms": f"{rtt:.3f}",
              "firmware_version": hex(st.firmware_version), "last_error": st.last_error}
    return LinkReport(name, level, message, str(link.port), {**values, **extra})


def driver_reports(sched: DriverScheduler, uno: ServoLink, mega: CurrentLink, now: float, stale_timeout: float
                   ) -> tuple[LinkReport, LinkReport]:
    """The diagnostics of the servo board (a ServoLink) and the current board (a CurrentLink) at host time `now`:
    each link's status and counters, the Mega's ERROR when no sample came for `stale_timeout` s, the Uno's ERROR
    while its LATCH reports are quiet, its WARN while it holds the last command because commands stopped (its
    watchdog), and how often each link recovered a quiet stream (hexa.protocol.stream_watch)."""
    age = now - sched.last_sample_time if sched.last_sample_time else float("inf")
    rate = sched.measure_sample_rate(now, mega.samples)
    c = sched.core.counters
    us = uno.status
    hold = bool(us.flags & fr.FLAG_WATCHDOG_HOLD) if us is not None else None
    mega_r = link_report("hexa_driver: current board (Mega)", mega, now, {
        "sample_rate_hz": f"{rate:.1f}", "sample_rate_commanded_hz": mega.rate_hz, "samples": mega.samples,
        "sample_gaps": mega.sample_gaps, "data_age_s": f"{age:.3f}",
        "board_clock_rate": f"{sched.board_clock.rate:.4f}", "board_clock_restarts": sched.board_clock.restarts,
        "board_clock_rejected": sched.board_clock.rejected, "commands_redated": sched.timeline.redated,
        "board_overruns": mega.status.overruns if mega.status else "?", **_recovery_values("stream", mega.watch)})
    if mega_r.level == "OK" and age > stale_timeout:
        mega_r = mega_r._replace(level="ERROR", message=f"telemetry stale (no sample for {age:.2f} s)")
    uno_r = link_report("hexa_driver: servo board (Uno)", uno, now, {
        "commands_accepted": c.accepted, "commands_rejected_nan": c.rejected_nan,
        "commands_rejected_names": c.rejected_names, "commands_rejected_size": c.rejected_size,
        "commands_rejected_range": c.rejected_range, "commands_clamped": c.clamped,
        "commands_slew_limited": c.slew_limited, "commands_coalesced": c.coalesced,
        "commands_unsent": sched.tx_failures, "targets_restored_after_reconnect": uno.restored,
        "board_pulses_us": list(us.pulses_us) if us is not None else "?",
        "latch_report": sched.latch_report, "latch_frames": sched.frames.frames,
        "latch_unknown_seq": sched.frames.unknown_seq, "latch_predicted_wrong": sched.frames.mismatches,
        "latch_delivery_delay_ms": f"{1e3 * sched.frames.delivery_delay:.2f}",
        "latch_unmapped": sched.latches_unmapped, "uno_clock_rate": f"{sched.uno_clock.rate:.4f}",
        "board_watchdog_hold": "?" if hold is None else hold, **_recovery_values("latch", uno.watch),
        **{f"board_reconfigures_{k}": v for k, v in uno.reconfigures.items()}})
    if uno_r.level == "OK" and uno.watch.stale(now):
        uno_r = uno_r._replace(level="ERROR", message=f"latch report stale (no LATCH for {uno.watch.quiet(now):.2f} s)")
    elif uno_r.level == "OK" and hold and sched.core.last_command_time is not None:
        uno_r = uno_r._replace(level="WARN", message="holding last command (no joint_commands within the watchdog)")
    return uno_r, mega_r


def _recovery_values(stream: str, watch: StreamWatch) -> dict[str, Any]:
    """Diagnostic values of a link's StreamWatch, keys prefixed with the stream's name."""
    return {f"{stream}_rerequests": watch.rerequests, f"{stream}_reconnects": watch.reconnects,
            f"{stream}_recoveries": watch.recoveries, f"{stream}_last_recovery_s": f"{watch.last_recovery_s:.3f}"}
