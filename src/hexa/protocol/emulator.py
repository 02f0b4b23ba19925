"""Python emulators of the two Arduino boards on pseudo-terminals, speaking the same protocol as the firmware.

`UnoEmulator` (servo board) and `MegaEmulator` (current board) each open a pty; `.port` is the path the driver
opens (the pty slave, or a stable symlink to it when `link=` is given, like a /dev/serial/by-id path). Each runs
in a thread; `start()/stop()` or use them as context managers. `unplug()` closes the pty (the driver's reads fail
like on a real USB unplug) and removes the symlink; `replug()` opens a fresh pty and points the symlink at it.

    with UnoEmulator(on_targets=print) as uno, MegaEmulator(current_source=lambda t: [0.1] * 6) as mega:
        driver.open(uno.port, mega.port)
"""
from __future__ import annotations

import errno
import os
import select
import threading
import time
import tty
from pathlib import Path
from typing import Callable, Self, Sequence

import numpy as np

from hexa.protocol import frames as fr
from hexa.protocol.sensor_model import DEFAULT_SENSOR, CurrentSensorModel

FIRMWARE_VERSION = 0x0100
DEFAULT_MIN_US = 500
DEFAULT_MAX_US = 2500
DEFAULT_WATCHDOG_MS = 500
FRAME_US = 20000        # the Uno's pulse frame (uno_servo.ino FRAME_TICKS)
OFF_SLOT_US = 100       # slot of a channel whose output is off (OFF_SLOT_TICKS)
PREP_US = 50            # channel 1's width is read this long before its frame starts (PREP_TICKS)


#: shortest wait (s) of an emulator thread for a board event that is not due yet
MIN_POLL = 0.0005


class EmulatorError(RuntimeError):
    """Emulator misuse (e.g. a symlink path that exists and is not ours)."""


class _BoardEmulator:
    """Common pty + thread + frame handling of both boards."""

    kind = 0

    def __init__(self, link: str | os.PathLike | None = None, tx_filter: Callable[[bytes], bytes] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._link = Path(link) if link is not None else None
        self.tx_filter = tx_filter
        self._clock = clock
        self._t0 = clock()
        self._master: int | None = None
        self._slave: int | None = None
        self._slave_name = ""
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.RLock()
        self._parser = fr.FrameParser()
        self._seq = 0
        self.rx_frames = 0
        self.rx_bad_frames = 0
        self.tx_frames = 0
        self.tx_dropped_bytes = 0
        self.callback_errors = 0
        self.last_callback_error = ""
        self.plugged = False

    # ------------------------------------------------------------------ lifecycle
    @property
    def port(self) -> str:
        """Path for the driver: the symlink if one was requested, else the pty slave device."""
        return str(self._link) if self._link is not None else self._slave_name

    @property
    def rx_crc_errors(self) -> int:
        return self._parser.stats.crc_errors

    def start(self) -> Self:
        """Open the pty and start the board thread (idempotent)."""
        if self._thread is not None:
            return self
        self._open_pty()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=type(self).__name__, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the pty; removes the symlink."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close_pty()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def unplug(self) -> None:
        """Simulate a USB unplug: the pty disappears (driver reads fail), the symlink is removed."""
        with self._lock:
            self._close_pty()

    def reset(self) -> None:
        """Simulate a board reset with the port open (hardware watchdog, brown-out): the board's state is as after
        power-up (no stream, outputs off, default limits and watchdog, no latch report); the pty stays."""
        with self._lock:
            self._reset_board()

    def replug(self) -> None:
        """Simulate plugging the board back in: new pty, symlink updated, board state reset (like a reset)."""
        with self._lock:
            if self.plugged:
                return
            self._reset_board()
            self._open_pty()

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        tty.setraw(master)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self._slave_name = os.ttyname(slave)
        self._parser.reset()
        if self._link is not None:
            if self._link.is_symlink():
                self._link.unlink()
            elif self._link.exists():
                raise EmulatorError(f"link path {self._link} exists and is not a symlink")
            tmp = self._link.with_name(self._link.name + ".tmp")
            if tmp.is_symlink():
                tmp.unlink()
            os.symlink(self._slave_name, tmp)
            os.replace(tmp, self._link)
        self.plugged = True

    def _close_pty(self) -> None:
        self.plugged = False
        if self._link is not None and self._link.is_symlink():
            try:
                self._link.unlink()
            except FileNotFoundError:
                pass
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None

    # ------------------------------------------------------------------ I/O
    def board_time_us(self) -> int:
        """Board clock (us since the emulator was created, wraps at 2^32 like micros())."""
        return int((self._clock() - self._t0) * 1e6) & 0xFFFFFFFF

    @property
    def clock_zero(self) -> float:
        """The emulator's clock reading at which its board clock read 0 (s)."""
        return self._t0

    def board_time_us_at(self, t: float) -> int:
        """The board clock (µs, wrapping at 2³²) when the emulator's clock read `t` (s)."""
        return int(round((t - self._t0) * 1e6)) & 0xFFFFFFFF

    def _send(self, msg_type: int, payload: bytes = b"") -> None:
        data = fr.encode_frame(msg_type, self._seq, payload)
        self._seq = (self._seq + 1) & 0xFF
        self._write(data)
        self.tx_frames += 1

    def _write(self, data: bytes) -> None:
        if self.tx_filter is not None:
            data = self.tx_filter(data)
        fd = self._master
        if fd is None:
            return
        view = memoryview(data)
        while view:
            try:
                n = os.write(fd, view)
            except BlockingIOError:
                self.tx_dropped_bytes += len(view)  # nobody reads: bytes are lost, like a UART
                return
            except OSError:
                return
            view = view[n:]

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                fd = self._master
            if fd is None:
                time.sleep(0.005)
                continue
            timeout = self._poll_timeout()
            try:
                r, _, _ = select.select([fd], [], [], timeout)
            except (OSError, ValueError):
                continue
            with self._lock:
                if fd != self._master:
                    continue
                if r:
                    try:
                        data = os.read(fd, 4096)
                    except BlockingIOError:
                        data = b""
                    except OSError as e:
                        if e.errno == errno.EIO:  # no slave open: nothing to read
                            data = b""
                            time.sleep(0.002)
                        else:
                            raise
                    for frame in self._parser.feed(data):
                        self.rx_frames += 1
                        self._handle_frame(frame)
                self._tick()

    def _handle_frame(self, frame: fr.Frame) -> None:
        size = fr.REQUEST_SIZES.get(frame.type)
        if size is None or not self._accepts(frame.type):
            self.rx_bad_frames += 1
            self._send(fr.ERROR, fr.pack_error(fr.ERR_UNKNOWN_TYPE, frame.type, frame.seq))
            return
        if len(frame.payload) != size:
            self.rx_bad_frames += 1
            self._send(fr.ERROR, fr.pack_error(fr.ERR_BAD_LENGTH, frame.type, frame.seq, len(frame.payload)))
            return
        if frame.type == fr.HELLO:
            version = fr.unpack_hello(frame.payload)
            if version != fr.PROTOCOL_VERSION:
                self._send(fr.ERROR, fr.pack_error(fr.ERR_BAD_VERSION, frame.type, frame.seq, version))
            self._send(fr.HELLO_REPLY, fr.pack_hello_reply(self.kind, FIRMWARE_VERSION))
        elif frame.type == fr.PING:
            self._send(fr.PONG, fr.pack_pong(fr.unpack_ping(frame.payload), self.board_time_us()))
        elif frame.type == fr.GET_STATUS:
            self._send(fr.STATUS, self._status_payload())
        else:
            self._handle_board_frame(frame)

    # ------------------------------------------------------------------ board-specific hooks
    def _accepts(self, msg_type: int) -> bool:
        return msg_type in (fr.HELLO, fr.PING, fr.GET_STATUS)

    def _poll_timeout(self) -> float:
        return 0.01

    def _tick(self) -> None:
        pass

    def _reset_board(self) -> None:
        self._seq = 0

    def _status_payload(self) -> bytes:
        raise NotImplementedError

    def _handle_board_frame(self, frame: fr.Frame) -> None:
        raise NotImplementedError


class UnoEmulator(_BoardEmulator):
    """The servo board (Arduino Uno): six pulse-width targets with limits and a hold-last-command watchdog.

    Latch report (SET_LATCH_REPORT, off after reset): like the firmware, one LATCH per 20 ms pulse frame on the
    board clock. Frames start at board times k·20 ms; the six slots follow one another (a channel's slot is its
    pulse width, or 100 µs when its output is off); channel 1's width is the command handled up to 50 µs before the
    frame, channel i's the command handled up to the start of channel i-1's slot (as the firmware's ISR reads them).
    A frame is reported once its last slot has ended; frames more than 0.1 s behind are skipped (`latch_skipped`).

    Args:
        on_targets: called with the six pulse widths (us, after clamping to the limits) of every SET_TARGETS,
            from the emulator thread.
        on_command: like `on_targets`, called with the widths and the SET_TARGETS frame's SEQ (the tag a simulator
            can attach to the targets, so that its own pulse frames can name the command each servo latched).
        latch_source: when given, the LATCH frames come from it instead of the emulator's own frame model: called
            every tick while the report is enabled, it returns the frames (frames.Latch, board clock µs) completed
            since the last call. Mapping from hexa.sim's `Simulator.pop_latch_frames()` (LatchFrame): frame_start_us
            = board time of `start` in µs, offsets_us = `pulse_offsets` in µs, seqs = `tags` & 0xFF (the seq passed
            via `on_command`), mask = 0x3F (servos without a tag yet carry tag -1: leave their bit clear).
        latch_capable: False = firmware without the latch report (SET_LATCH_REPORT answered UNKNOWN_TYPE), e.g.
            for a simulator whose servos take set-points at once: there is no frame to report.
        link: optional stable symlink path for `.port`.
        tx_filter: optional function applied to every chunk the board sends (fault injection in tests).
    """

    kind = fr.BOARD_SERVO

    def __init__(self, on_targets: Callable[[tuple[int, ...]], None] | None = None,
                 link: str | os.PathLike | None = None, tx_filter: Callable[[bytes], bytes] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 on_command: Callable[[tuple[int, ...], int], None] | None = None,
                 latch_source: Callable[[], Sequence[fr.Latch]] | None = None, latch_capable: bool = True) -> None:
        super().__init__(link=link, tx_filter=tx_filter, clock=clock)
        self.on_targets = on_targets
        self.on_command = on_command
        self.latch_source = latch_source
        self.latch_capable = bool(latch_capable)
        self.latches_sent = 0
        self.latch_skipped = 0
        self._reset_board()

    def _reset_board(self) -> None:
        super()._reset_board()
        self.min_us = [DEFAULT_MIN_US] * fr.N_CHANNELS
        self.max_us = [DEFAULT_MAX_US] * fr.N_CHANNELS
        self.watchdog_ms = DEFAULT_WATCHDOG_MS
        self.pulses_us: tuple[int, ...] = (0,) * fr.N_CHANNELS  # 0 = output off (no command yet)
        self.outputs_enabled = False
        self.clamped = False
        self.last_command_time: float | None = None
        self.commands = 0
        self.targets_seq = 0
        self.latch_report = False
        self._next_frame = 0      # index of the next pulse frame to report
        self._history: list[tuple[float, int, tuple[int, ...]]] = []   # (board µs handled, seq, widths), in order

    @property
    def targets(self) -> tuple[int, ...]:
        """Pulse widths (us) currently output on the six channels (0 = off, before the first command)."""
        return self.pulses_us

    def _accepts(self, msg_type: int) -> bool:
        return super()._accepts(msg_type) or msg_type in (fr.SET_TARGETS, fr.SET_LIMITS, fr.SET_WATCHDOG) or (
            msg_type == fr.SET_LATCH_REPORT and self.latch_capable)

    def _now_us(self) -> float:
        return (self._clock() - self._t0) * 1e6

    def _record(self) -> None:
        self._history.append((self._now_us(), self.targets_seq, self.pulses_us))

    def _handle_board_frame(self, frame: fr.Frame) -> None:
        if frame.type == fr.SET_TARGETS:
            req = fr.unpack_targets(frame.payload)
            out = tuple(min(max(p, lo), hi) for p, lo, hi in zip(req, self.min_us, self.max_us))
            self.clamped = out != req
            self.pulses_us = out
            self.outputs_enabled = True
            self.last_command_time = self._clock()
            self.commands += 1
            self.targets_seq = frame.seq
            self._record()
            for callback, args in ((self.on_targets, (out,)), (self.on_command, (out, frame.seq))):
                if callback is None:
                    continue
                try:
                    callback(*args)
                except Exception as exc:  # the consumer failed: the board keeps running, like the real one
                    self.callback_errors += 1
                    self.last_callback_error = f"{type(exc).__name__}: {exc}"
        elif frame.type == fr.SET_LIMITS:
            lo, hi = fr.unpack_limits(frame.payload)
            if any(a > b or a < fr.PULSE_MIN_US or b > fr.PULSE_MAX_US for a, b in zip(lo, hi)):
                self._send(fr.ERROR, fr.pack_error(fr.ERR_BAD_VALUE, frame.type, frame.seq))
                return
            self.min_us, self.max_us = list(lo), list(hi)
            if self.outputs_enabled:
                self.pulses_us = tuple(min(max(p, a), b) for p, a, b in zip(self.pulses_us, lo, hi))
                self._record()
            self._send(fr.ACK, fr.pack_ack(frame.type, frame.seq))
        elif frame.type == fr.SET_WATCHDOG:
            self.watchdog_ms = fr.unpack_watchdog(frame.payload)
            self._send(fr.ACK, fr.pack_ack(frame.type, frame.seq))
        elif frame.type == fr.SET_LATCH_REPORT:
            enable = fr.unpack_latch_report(frame.payload)
            if enable > 1:
                self._send(fr.ERROR, fr.pack_error(fr.ERR_BAD_VALUE, frame.type, frame.seq, enable))
                return
            if enable and not self.latch_report:   # whole frames only: the first one starting from now
                self._next_frame = int(self._now_us() // FRAME_US) + 1
            self.latch_report = bool(enable)
            self._send(fr.ACK, fr.pack_ack(frame.type, frame.seq))

    # ------------------------------------------------------------------ latch report
    def _widths_at(self, t_us: float) -> tuple[int, tuple[int, ...]]:
        """(seq, widths) of the newest command handled at or before board time `t_us` ((0, all off) if none)."""
        for t, seq, widths in reversed(self._history):
            if t <= t_us:
                return seq, widths
        return 0, (0,) * fr.N_CHANNELS

    def latch_frame(self, k: int) -> tuple[fr.Latch, float]:
        """The LATCH of pulse frame `k` (starting at board time k·20 ms) and the board time (µs) its last slot ends."""
        start = k * FRAME_US
        offsets, seqs, mask = [], [], 0
        t, read_at = 0, start - PREP_US
        for i in range(fr.N_CHANNELS):
            seq, widths = self._widths_at(read_at)
            offsets.append(t)
            seqs.append(seq)
            if widths[i]:
                mask |= 1 << i
            read_at = start + t
            t += widths[i] or OFF_SLOT_US
        return fr.Latch(start & 0xFFFFFFFF, tuple(offsets), tuple(seqs), mask), float(start + t)

    def _send_latches(self) -> None:
        if self.latch_source is not None:
            for latch in self.latch_source():
                self._send(fr.LATCH, fr.pack_latch(latch))
                self.latches_sent += 1
            if len(self._history) > 1:      # the emulator's own frame model is not used: no history needed
                del self._history[:-1]
            return
        now = self._now_us()
        behind = int(now // FRAME_US) - self._next_frame
        if behind > 0.1 * 1e6 / FRAME_US:   # fell far behind (host stalled): skip to the newest frames, counted
            self.latch_skipped += behind - 1
            self._next_frame += behind - 1
        while True:
            latch, end = self.latch_frame(self._next_frame)
            if end > now:
                break
            self._next_frame += 1
            if latch.mask:
                self._send(fr.LATCH, fr.pack_latch(latch))
                self.latches_sent += 1
        # keep the newest command handled before the frame still to be reported, and everything after it
        first = self._next_frame * FRAME_US - PREP_US
        while len(self._history) > 1 and self._history[1][0] <= first:
            del self._history[0]

    def _poll_timeout(self) -> float:
        if not self.latch_report:
            return 0.01
        if self.latch_source is not None:   # the source's frames are polled: its clock may not be this thread's
            return 0.002
        wait = (self.latch_frame(self._next_frame)[1] - self._now_us()) * 1e-6
        return 0.0 if wait <= 0.0 else max(MIN_POLL, min(0.01, wait))

    def _tick(self) -> None:
        if not self.latch_report:
            if len(self._history) > 1:
                del self._history[:-1]
            return
        if self._master is not None:
            self._send_latches()

    def _status_payload(self) -> bytes:
        since = (0xFFFF if self.last_command_time is None
                 else int((self._clock() - self.last_command_time) * 1000))
        flags = 0
        if self.outputs_enabled:
            flags |= fr.FLAG_ACTIVE
            if self.watchdog_ms and since > self.watchdog_ms:
                flags |= fr.FLAG_WATCHDOG_HOLD
        if self.clamped:
            flags |= fr.FLAG_CLAMPED
        return fr.pack_servo_status(fr.ServoStatus(
            flags, self.rx_frames, self.rx_crc_errors, self.rx_bad_frames, self.board_time_us(),
            self.pulses_us, min(since, 0xFFFF)))


class MegaEmulator(_BoardEmulator):
    """The current board (Arduino Mega 2560): six ADC channels streamed at the commanded rate.

    Args:
        current_source: called at each sample time with the board time (s) and returning six values: amps
            (converted to counts by `sensor`, the default) or ADC counts when `units="counts"`. None: 0 A.
        units: "amps" or "counts".
        sensor: the current-sensor/ADC model (hexa.protocol.sensor_model).
        noise_counts: standard deviation of Gaussian ADC noise (counts) added before rounding; 0 = none.
        seed: noise RNG seed.
        link, tx_filter, clock: as for UnoEmulator.
    """

    kind = fr.BOARD_CURRENT

    def __init__(self, current_source: Callable[[float], Sequence[float] | np.ndarray] | None = None,
                 units: str = "amps",
                 sensor: CurrentSensorModel = DEFAULT_SENSOR, noise_counts: float = 0.0, seed: int = 0,
                 link: str | os.PathLike | None = None, tx_filter: Callable[[bytes], bytes] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if units not in ("amps", "counts"):
            raise EmulatorError(f"units {units!r} must be 'amps' or 'counts'")
        super().__init__(link=link, tx_filter=tx_filter, clock=clock)
        self.current_source = current_source
        self.units = units
        self.sensor = sensor
        self.noise_counts = float(noise_counts)
        self._rng = np.random.default_rng(seed)
        self._reset_board()

    def _reset_board(self) -> None:
        super()._reset_board()
        self.rate_hz = 0
        self.streaming = False
        self.sample_seq = 0
        self.overruns = 0
        self._overrun_flag = False
        self._next_t = 0.0
        self._k = 0

    def _accepts(self, msg_type: int) -> bool:
        return super()._accepts(msg_type) or msg_type in (fr.START_STREAM, fr.STOP_STREAM)

    def _handle_board_frame(self, frame: fr.Frame) -> None:
        if frame.type == fr.START_STREAM:
            rate = fr.unpack_start_stream(frame.payload)
            if not fr.MIN_RATE_HZ <= rate <= fr.MAX_RATE_HZ:
                self._send(fr.ERROR, fr.pack_error(fr.ERR_BAD_VALUE, frame.type, frame.seq))
                return
            self.rate_hz = rate
            self.streaming = True
            self._t_stream = self._clock()
            self._k = 0
            self._next_t = self._t_stream
            self._send(fr.ACK, fr.pack_ack(frame.type, frame.seq))
        elif frame.type == fr.STOP_STREAM:
            self.streaming = False
            self._send(fr.ACK, fr.pack_ack(frame.type, frame.seq))

    def _poll_timeout(self) -> float:
        if not self.streaming:
            return 0.01
        wait = self._next_t - self._clock()
        # a sample due: no wait; else at least MIN_POLL, even when the board clock is a simulator's that stands
        # still during a camera render (a zero timeout would spin on the interpreter lock the renderer needs)
        return 0.0 if wait <= 0.0 else max(MIN_POLL, min(0.01, wait))

    def sample_counts(self, t: float) -> tuple[int, ...]:
        """The six ADC counts the board would read at board time `t` (s)."""
        values = np.zeros(fr.N_CHANNELS)
        if self.current_source is not None:
            try:
                values = np.asarray(self.current_source(t), dtype=float).reshape(fr.N_CHANNELS)
            except Exception as exc:  # the source failed: sample 0 A (counted), keep streaming
                self.callback_errors += 1
                self.last_callback_error = f"{type(exc).__name__}: {exc}"
                values = np.zeros(fr.N_CHANNELS)
                if self.units == "counts":
                    values = self.sensor.counts_from_current(values).astype(float)
        if self.units == "amps":
            volts = self.sensor.zero_voltage + self.sensor.sensitivity * values
            if self.noise_counts:
                volts = volts + self._rng.normal(0.0, self.noise_counts, fr.N_CHANNELS) * (
                    self.sensor.vref / self.sensor.full_scale)
            counts = self.sensor.counts_from_voltage(volts)
        else:
            if self.noise_counts:
                values = values + self._rng.normal(0.0, self.noise_counts, fr.N_CHANNELS)
            counts = np.clip(np.rint(values), 0, self.sensor.full_scale - 1).astype(np.int64)
        return tuple(int(c) for c in counts)

    def _tick(self) -> None:
        if not self.streaming or self._master is None:
            return
        now = self._clock()
        period = 1.0 / self.rate_hz
        if now - self._next_t > 0.1:  # fell far behind (host machine stalled): skip, count an overrun
            missed = int((now - self._next_t) / period)
            self._k += missed
            self._next_t = self._t_stream + self._k * period
            self.overruns += 1
            self._overrun_flag = True
        while self._next_t <= now:
            t_board = self._next_t - self._t0
            counts = self.sample_counts(t_board)
            self._send(fr.SAMPLE, fr.pack_sample(self.sample_seq, int(t_board * 1e6), counts))
            self.sample_seq = (self.sample_seq + 1) & 0xFFFFFFFF
            self._k += 1
            self._next_t = self._t_stream + self._k * period

    def _status_payload(self) -> bytes:
        flags = (fr.FLAG_ACTIVE if self.streaming else 0) | (fr.FLAG_OVERRUN if self._overrun_flag else 0)
        self._overrun_flag = False
        return fr.pack_current_status(fr.CurrentStatus(
            flags, self.rx_frames, self.rx_crc_errors, self.rx_bad_frames, self.board_time_us(),
            self.rate_hz if self.streaming else 0, self.overruns, self.sample_seq))
