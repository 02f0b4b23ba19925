"""Host side of the serial link: one `BoardLink` per board (open, handshake, reader thread, stats, reconnect).

`ServoLink` talks to the Uno (targets, limits, watchdog, periodic status), `CurrentLink` to the Mega (streaming
samples with sequence-gap counting). Both reconnect on their own when the port disappears (USB unplug) or the
board stops answering, and count everything a diagnostics page needs (`LinkStats`). No ROS here: the driver node
(hexa_driver) wraps these.

    link = CurrentLink("/dev/serial/by-id/usb-Arduino_Mega...", rate_hz=1000, on_sample=print)
    link.start(); ...; link.stop()
"""
from __future__ import annotations

import errno
import os
import select
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Self, Sequence

import serial

from hexa.protocol import frames as fr
from hexa.protocol.stream_watch import RECONNECT, REREQUEST, StreamWatch

DISCONNECTED = "DISCONNECTED"
CONNECTING = "CONNECTING"
CONNECTED = "CONNECTED"
STALE = "STALE"


class LinkError(RuntimeError):
    """A request that could not be completed: port closed, no reply in time, or the board reported an error."""


@dataclass
class LinkStats:
    """Counters and timings of one link (all monotonic except `state`, times from time.monotonic())."""

    state: str = DISCONNECTED
    connects: int = 0            # successful handshakes
    disconnects: int = 0         # port lost (unplug, I/O error) or dropped after staleness
    open_failures: int = 0
    frames_rx: int = 0
    frames_tx: int = 0
    bytes_rx: int = 0
    crc_errors: int = 0
    bad_length: int = 0
    resyncs: int = 0
    discarded_bytes: int = 0
    dropped_frames: int = 0      # gaps in the board's frame sequence numbers
    board_errors: int = 0        # ERROR frames received
    decode_errors: int = 0       # frames with a good CRC but an undecodable payload
    callback_errors: int = 0     # exceptions raised by on_sample / on_frame consumers
    tx_failures: int = 0         # writes attempted while disconnected or failing
    last_rx: float = 0.0
    connected_since: float = 0.0
    lost_at: float = 0.0
    last_reconnect_s: float = float("nan")   # time from loss to the next successful handshake
    rtt_s: float = float("nan")              # last PING round trip
    firmware_version: int = 0
    last_error: str = ""
    extra: dict = field(default_factory=dict)


class BoardLink:
    """One serial port to one board, run by a background thread.

    Args:
        port: device path (a /dev/serial/by-id/... path survives re-enumeration after an unplug).
        kind: expected board kind (frames.BOARD_SERVO or frames.BOARD_CURRENT); another kind fails the handshake.
        baud: serial baud rate (500000 for both boards; ignored by ptys).
        stale_timeout: no frame for this long while connected -> state STALE.
        drop_after: STALE for this long -> close and reconnect (board reset or hung).
        reconnect_period: delay between attempts to reopen a missing port.
        hello_timeout: how long to keep sending HELLO after opening (a real Uno resets on open, ~1.5 s).
        boot_delay: wait this long after opening a real serial device before the first HELLO (the DTR reset
            starts the bootloader, which must not see our bytes); skipped for pseudo-terminals (/dev/pts/*).
        poll_period: send GET_STATUS this often when connected (0 = never).
        ping_period: send PING this often to measure the round trip (0 = never).
        stream_rerequest_period: a board stream quiet for `stale_timeout` while the port is open (the Mega's
            samples, the Uno's LATCH reports) is requested again this often (s; hexa.protocol.stream_watch).
        stream_reconnect_after: the stream quiet this long (s, > stale_timeout; None: stale_timeout + drop_after)
            -> close the port and reconnect.
    """

    kind = 0

    def __init__(self, port: str, baud: int = 500000, stale_timeout: float = 0.5, drop_after: float = 1.0,
                 reconnect_period: float = 0.1, hello_timeout: float = 3.0, poll_period: float = 0.2,
                 ping_period: float = 1.0, on_state: Callable[[str], None] | None = None,
                 boot_delay: float = 0.0, stream_rerequest_period: float = 0.2,
                 stream_reconnect_after: float | None = None) -> None:
        self.port = port
        self.baud = baud
        self.stale_timeout = stale_timeout
        self.drop_after = drop_after
        self.reconnect_period = reconnect_period
        self.hello_timeout = hello_timeout
        self.boot_delay = boot_delay
        self.poll_period = poll_period
        self.ping_period = ping_period
        self.on_state = on_state
        self.stats = LinkStats()
        self.watch = StreamWatch(stale_timeout, stream_rerequest_period,
                                 stale_timeout + drop_after if stream_reconnect_after is None
                                 else stream_reconnect_after)
        self._ser: serial.Serial | None = None
        self._parser = fr.FrameParser()
        self._parser_base = fr.ParserStats()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._wlock = threading.Lock()
        self._seq = 0
        self._last_rx_seq: int | None = None
        self._waiters: list[tuple[Callable[[fr.Frame], bool], list, threading.Event]] = []
        self._wait_lock = threading.Lock()
        self._next_poll = 0.0
        self.status_asked = 0.0   # host time of the last periodic GET_STATUS
        self._next_ping = 0.0
        self._ping_sent: dict[int, float] = {}
        self._token = 0

    # --------------------------------------------------------------------------------------------- lifecycle
    def start(self) -> Self:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=f"{type(self).__name__}({self.port})",
                                            daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=3.0)
            self._thread = None
        self._close(count=False)
        self._set_state(DISCONNECTED)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def connected(self) -> bool:
        return self.stats.state in (CONNECTED, STALE)

    def wait_connected(self, timeout: float) -> bool:
        """Block until the handshake has succeeded (state CONNECTED) or `timeout` s passed."""
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            if self.stats.state == CONNECTED:
                return True
            time.sleep(0.005)
        return self.stats.state == CONNECTED

    # --------------------------------------------------------------------------------------------- sending
    def send(self, msg_type: int, payload: bytes = b"", on_seq: Callable[[int], None] | None = None) -> int | None:
        """Write one frame; returns its sequence number, or None if the port is not open (counted).

        `on_seq(seq)` is called before the bytes are written (so a reply cannot overtake its registration).
        """
        with self._wlock:
            ser = self._ser
            if ser is None:
                self.stats.tx_failures += 1
                return None
            seq = self._seq
            self._seq = (seq + 1) & 0xFF
            if on_seq is not None:
                on_seq(seq)
            try:
                ser.write(fr.encode_frame(msg_type, seq, payload))
            except (serial.SerialException, OSError) as exc:
                self.stats.tx_failures += 1
                self.stats.last_error = f"write failed: {exc}"
                return None
            self.stats.frames_tx += 1
            return seq

    def request(self, msg_type: int, payload: bytes = b"", reply_types: Sequence[int] = (fr.ACK,),
                timeout: float = 0.5) -> fr.Frame:
        """Send a request and wait for its reply (an ACK/ERROR naming its sequence, or one of `reply_types`).

        Raises:
            LinkError: not connected, no reply within `timeout`, or the board answered ERROR.
        """
        box: list[fr.Frame] = []
        event = threading.Event()
        seq_holder: list[int] = []

        def match(f: fr.Frame) -> bool:
            if not seq_holder:
                return False
            if f.type == fr.ERROR:
                return len(f.payload) == 4 and f.payload[1] == msg_type and f.payload[2] == seq_holder[0]
            if f.type == fr.ACK:
                return fr.ACK in reply_types and len(f.payload) == 2 and f.payload[1] == seq_holder[0]
            return f.type in reply_types

        waiter = (match, box, event)
        with self._wait_lock:
            self._waiters.append(waiter)
        try:
            seq = self.send(msg_type, payload, on_seq=seq_holder.append)
            if seq is None:
                raise LinkError(f"{self.port}: not connected, cannot send {fr.TYPE_NAMES.get(msg_type, msg_type)}")
            t_end = time.monotonic() + timeout
            in_thread = threading.current_thread() is self._thread
            while not event.is_set():
                remaining = t_end - time.monotonic()
                if remaining <= 0:
                    raise LinkError(f"{self.port}: no reply to {fr.TYPE_NAMES.get(msg_type, msg_type)} "
                                    f"within {timeout} s")
                if in_thread:
                    self._read_once(min(remaining, 0.02))
                else:
                    event.wait(min(remaining, 0.05))
        finally:
            with self._wait_lock:
                if waiter in self._waiters:
                    self._waiters.remove(waiter)
        reply = box[0]
        if reply.type == fr.ERROR:
            err = fr.unpack_error(reply.payload)
            raise LinkError(f"{self.port}: board rejected {fr.TYPE_NAMES.get(msg_type, msg_type)}: "
                            f"{fr.ERROR_NAMES.get(err.code, err.code)} (detail {err.detail})")
        return reply

    # --------------------------------------------------------------------------------------------- hooks
    def on_connected(self) -> None:
        """Configure the board after the handshake (runs in the link thread; may call request())."""

    def on_frame(self, frame: fr.Frame, t_rx: float) -> None:
        """Handle a board frame that is not a reply (runs in the link thread)."""

    def on_disconnected(self) -> None:
        """Called when the port was lost."""

    def periodic(self, now: float) -> None:
        """Called about every 20 ms while connected."""

    def request_stream(self) -> None:
        """Ask the board for its watched stream again (`watch` found it quiet; runs in the link thread)."""

    def _watch_stream(self, now: float) -> bool:
        """Recover a quiet stream (`watch`): re-request it, or close the port to reconnect (True)."""
        action = self.watch.step(now)
        if action == REREQUEST:
            self.request_stream()
        elif action == RECONNECT:
            self.stats.last_error = (f"stream quiet for {self.watch.quiet(now):.2f} s after "
                                     f"{self.watch.rerequests} re-requests: reconnecting")
            self._close()
            return True
        return False

    # --------------------------------------------------------------------------------------------- thread
    def _set_state(self, state: str) -> None:
        if state != self.stats.state:
            self.stats.state = state
            if self.on_state is not None:
                try:
                    self.on_state(state)
                except Exception:  # a callback must not kill the link
                    pass

    def _open(self) -> bool:
        try:
            ser = serial.Serial(self.port, self.baud, timeout=0, write_timeout=0.5, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            self.stats.open_failures += 1
            self.stats.last_error = f"open failed: {exc}"
            return False
        if self.boot_delay > 0 and not os.path.realpath(self.port).startswith("/dev/pts/"):
            self._set_state(CONNECTING)
            self._stop.wait(self.boot_delay)
        ser.reset_input_buffer()
        self._parser.reset()
        self._parser.stats = fr.ParserStats()  # counters accumulate in self.stats across reconnects
        self._parser_base = fr.ParserStats(crc_errors=self.stats.crc_errors, bad_length=self.stats.bad_length,
                                           resyncs=self.stats.resyncs, discarded=self.stats.discarded_bytes)
        self._last_rx_seq = None
        with self._wlock:
            self._ser = ser
        return True

    def _close(self, count: bool = True) -> None:
        with self._wlock:
            ser, self._ser = self._ser, None
        self.watch.stop()
        if ser is not None:
            try:
                ser.close()
            except Exception:
                pass
            if count:
                self.stats.disconnects += 1
                self.stats.lost_at = time.monotonic()
                self.on_disconnected()

    def _handshake(self) -> bool:
        self._set_state(CONNECTING)
        t_end = time.monotonic() + self.hello_timeout
        while time.monotonic() < t_end and not self._stop.is_set():
            try:
                reply = self.request(fr.HELLO, fr.pack_hello(), reply_types=(fr.HELLO_REPLY,), timeout=0.1)
            except LinkError as exc:
                if self._ser is None:
                    return False
                self.stats.last_error = str(exc)
                continue
            try:
                hello = fr.unpack_hello_reply(reply.payload)
            except fr.ProtocolError as exc:
                self.stats.last_error = f"bad HELLO_REPLY: {exc}"
                continue
            if hello.board_kind != self.kind or hello.protocol_version != fr.PROTOCOL_VERSION:
                self.stats.last_error = (f"{self.port}: expected a {fr.BOARD_NAMES.get(self.kind)} board with protocol "
                                         f"{fr.PROTOCOL_VERSION}, found kind {hello.board_kind} protocol "
                                         f"{hello.protocol_version}")
                return False
            self.stats.firmware_version = hello.firmware_version
            try:
                self.on_connected()
            except LinkError as exc:
                self.stats.last_error = f"configuration failed: {exc}"
                return False
            now = time.monotonic()
            self.stats.connects += 1
            self.stats.connected_since = now
            self.stats.last_rx = now
            if self.stats.lost_at:
                self.stats.last_reconnect_s = now - self.stats.lost_at
            self._next_poll = now
            self._next_ping = now
            self._set_state(CONNECTED)
            return True
        self.stats.last_error = self.stats.last_error or f"{self.port}: no HELLO_REPLY"
        return False

    def _read_once(self, timeout: float) -> None:
        ser = self._ser
        if ser is None:
            time.sleep(timeout)
            return
        try:
            fd = ser.fileno()
            readable, _, _ = select.select([fd], [], [], timeout)
            if not readable:
                return
            t_read = time.monotonic()   # every byte that had arrived by now is in this read
            data = os.read(fd, 65536)
            if not data:
                raise OSError(errno.EIO, "port readable but returned no data (device disconnected?)")
        except (serial.SerialException, OSError, ValueError, TypeError) as exc:
            self.stats.last_error = f"read failed: {exc}"
            self._close()
            self._set_state(DISCONNECTED)
            return
        t_rx = time.monotonic()
        self.stats.bytes_rx += len(data)
        for frame in self._parser.feed(data):
            self._dispatch(frame, t_rx)
        self.end_of_read(t_read, t_rx)
        ps, base = self._parser.stats, self._parser_base
        self.stats.crc_errors = base.crc_errors + ps.crc_errors
        self.stats.bad_length = base.bad_length + ps.bad_length
        self.stats.resyncs = base.resyncs + ps.resyncs
        self.stats.discarded_bytes = base.discarded + ps.discarded

    def end_of_read(self, t_read: float, t_rx: float) -> None:
        """Called after the frames of one read of the port were dispatched: the read started at host time `t_read`
        and returned at `t_rx` (s, monotonic). Subclasses that batch frames per read override it."""

    def _dispatch(self, frame: fr.Frame, t_rx: float) -> None:
        st = self.stats
        st.frames_rx += 1
        st.last_rx = t_rx
        if self._last_rx_seq is not None:
            st.dropped_frames += (frame.seq - self._last_rx_seq - 1) & 0xFF
        self._last_rx_seq = frame.seq
        if st.state == STALE:
            self._set_state(CONNECTED)
        with self._wait_lock:
            for waiter in self._waiters:
                match, box, event = waiter
                if not event.is_set() and match(frame):
                    box.append(frame)
                    event.set()
                    if frame.type in (fr.ACK, fr.ERROR, fr.HELLO_REPLY):
                        return
                    break  # a STATUS/PONG/SAMPLE reply is also handled as usual below
        try:
            if frame.type == fr.PONG:
                pong = fr.unpack_pong(frame.payload)
                sent = self._ping_sent.pop(pong.token, None)
                if sent is not None:
                    st.rtt_s = t_rx - sent
            elif frame.type == fr.ERROR:
                st.board_errors += 1
                err = fr.unpack_error(frame.payload)
                st.last_error = (f"board error {fr.ERROR_NAMES.get(err.code, err.code)} for "
                                 f"{fr.TYPE_NAMES.get(err.offending_type, err.offending_type)}")
            else:
                self.on_frame(frame, t_rx)
        except fr.ProtocolError as exc:
            st.decode_errors += 1
            st.last_error = str(exc)
        except Exception as exc:  # a consumer callback failed: keep the link alive, say so
            st.callback_errors += 1
            st.last_error = f"callback failed: {type(exc).__name__}: {exc}"

    def _run(self) -> None:
        while not self._stop.is_set():
            if self._ser is None:
                self._set_state(DISCONNECTED)
                if not self._open():
                    self._stop.wait(self.reconnect_period)
                    continue
                if not self._handshake():
                    self._close(count=False)
                    self._set_state(DISCONNECTED)
                    self._stop.wait(self.reconnect_period)
                    continue
            self._read_once(0.01)
            if self._ser is None:
                continue
            now = time.monotonic()
            quiet = now - self.stats.last_rx
            if quiet > self.stale_timeout:
                if self.stats.state == CONNECTED:
                    self._set_state(STALE)
                if quiet > self.stale_timeout + self.drop_after:
                    self.stats.last_error = f"no data for {quiet:.2f} s: reconnecting"
                    self._close()
                    continue
            if self._watch_stream(now):
                continue
            if self.poll_period and now >= self._next_poll:
                self._next_poll = now + self.poll_period
                self.status_asked = time.monotonic()
                self.send(fr.GET_STATUS)
            if self.ping_period and now >= self._next_ping:
                self._next_ping = now + self.ping_period
                self._token = (self._token + 1) & 0xFFFFFFFF
                self._ping_sent = {self._token: time.monotonic()}
                self.send(fr.PING, fr.pack_ping(self._token))
            self.periodic(now)


class ServoLink(BoardLink):
    """The Uno servo board: pulse targets (us), limits and command watchdog set on every (re)connect.

    With `on_latch`, the board's latch report is enabled on every (re)connect (SET_LATCH_REPORT) and
    `on_latch(latch, t_rx)` is called with each LATCH (frames.Latch: when each servo's pulse started, board clock,
    and the SET_TARGETS seq it carried; `set_targets` records the seq it used in `last_targets_seq`). Firmware
    without the report answers UNKNOWN_TYPE: the link connects anyway, with `latch_supported` False.

    A board that reset with its port open (its hardware watchdog, a brown-out) forgets its configuration: the link
    configures it again, counted by reason in `reconfigures`, when its LATCH reports go quiet after targets were sent
    (`watch`: then, still quiet, it reconnects), when its STATUS shows the outputs off although targets were sent
    ("outputs_off"), and when its STATUS shows the command watchdog holding although a command went out well within
    `watchdog_ms` ("watchdog_hold"). A board without targets sends no LATCH, and none is expected of it."""

    kind = fr.BOARD_SERVO

    def __init__(self, port: str, min_us: Sequence[int] = (500,) * 6, max_us: Sequence[int] = (2500,) * 6,
                 watchdog_ms: int = 500, on_latch: Callable[[fr.Latch, float], None] | None = None, **kw) -> None:
        super().__init__(port, **kw)
        self.min_us = tuple(int(v) for v in min_us)
        self.max_us = tuple(int(v) for v in max_us)
        self.watchdog_ms = int(watchdog_ms)
        self.on_latch = on_latch
        self.last_targets_seq: int | None = None
        self.latches = 0
        self.latch_supported: bool | None = None   # None: not asked (no on_latch) or not connected yet
        self.status: fr.ServoStatus | None = None
        self.status_time = 0.0
        self.targets_sent = 0
        self.last_targets: tuple[int, ...] | None = None
        self.restored = 0
        self.reconfigures = {"latch_quiet": 0, "outputs_off": 0, "watchdog_hold": 0}
        self._targets_since: float | None = None   # the board has had targets since (host time), this connection
        self._targets_tx = 0.0                     # last SET_TARGETS written (host time)

    def on_connected(self) -> None:
        self._targets_since = None
        self.request(fr.SET_LIMITS, fr.pack_limits(self.min_us, self.max_us))
        self.request(fr.SET_WATCHDOG, fr.pack_watchdog(self.watchdog_ms))
        if self.on_latch is not None:
            try:
                self.request(fr.SET_LATCH_REPORT, fr.pack_latch_report(True))
                self.latch_supported = True
            except LinkError as exc:   # firmware before the latch report: the link works without it
                if "UNKNOWN_TYPE" not in str(exc):
                    raise
                self.latch_supported = False
                self.stats.last_error = str(exc)
        if self.last_targets is not None:  # after a board reset: restore what the host believes is commanded
            self._restore_targets()
            self._watch_latches()

    def _watch_latches(self) -> None:
        """Expect LATCH reports from now on: the board reports a pulse frame only when some output is on, that is
        once it has targets, so a board that has none is not taken for a quiet one."""
        if self.latch_supported and not self.watch.active:
            self.watch.start(time.monotonic())

    def _restore_targets(self) -> None:
        if self.last_targets is not None and self.send(fr.SET_TARGETS, fr.pack_targets(self.last_targets)) is not None:
            self.restored += 1
            self._targets_since = self._targets_tx = time.monotonic()

    def _reconfigure(self, reason: str, targets: bool) -> None:
        """Configure the board again without waiting for its ACKs (the link thread keeps reading)."""
        self.reconfigures[reason] += 1
        self.stats.last_error = f"servo board reconfigured: {reason.replace('_', ' ')}"
        self.send(fr.SET_LIMITS, fr.pack_limits(self.min_us, self.max_us))
        self.send(fr.SET_WATCHDOG, fr.pack_watchdog(self.watchdog_ms))
        if self.latch_supported:
            self.send(fr.SET_LATCH_REPORT, fr.pack_latch_report(True))
        if targets and self.last_targets is not None:
            self._restore_targets()

    def request_stream(self) -> None:
        self._reconfigure("latch_quiet", targets=False)

    def set_targets(self, pulses_us: Sequence[int]) -> bool:
        """Command six pulse widths (us); False if the port is not open (the command is dropped).

        The last targets are re-sent after every reconnect (the board starts with its outputs off).
        """
        self.last_targets = tuple(int(p) for p in pulses_us)
        seq = self.send(fr.SET_TARGETS, fr.pack_targets(self.last_targets))
        ok = seq is not None
        if ok:
            self.last_targets_seq = seq
            self._targets_tx = time.monotonic()
            if self._targets_since is None:
                self._targets_since = self._targets_tx
            self._watch_latches()
        self.targets_sent += ok
        return ok

    def on_frame(self, frame: fr.Frame, t_rx: float) -> None:
        if frame.type == fr.STATUS:
            self.status = status = fr.unpack_servo_status(frame.payload)
            self.status_time = t_rx
            # the board answers in order: targets written before the poll had reached it when it answered
            asked = self.status_asked
            if self._targets_since is not None and self._targets_since < asked:
                if not status.flags & fr.FLAG_ACTIVE:
                    self._reconfigure("outputs_off", targets=True)
                elif status.flags & fr.FLAG_WATCHDOG_HOLD and asked - self._targets_tx < 0.5e-3 * self.watchdog_ms:
                    self._reconfigure("watchdog_hold", targets=True)
        elif frame.type == fr.LATCH:
            latch = fr.unpack_latch(frame.payload)
            self.latches += 1
            self.watch.data(t_rx)
            if self.on_latch is not None:
                self.on_latch(latch, t_rx)


class CurrentLink(BoardLink):
    """The Mega current board: streams samples at `rate_hz`; `on_sample(sample, t_rx, gap)` per sample, or, with
    `on_samples`, `on_samples([(sample, gap), ...], t_read, t_rx)` once per read of the port with its samples in
    order (t_read: when the read started — every sample in it had been measured by then).

    `gap` is the number of samples missing before this one (sequence gap); `stats.extra["sample_gaps"]` sums them.
    """

    kind = fr.BOARD_CURRENT

    def __init__(self, port: str, rate_hz: int = 1000,
                 on_sample: Callable[[fr.Sample, float, int], None] | None = None,
                 on_samples: Callable[[list[tuple[fr.Sample, int]], float, float], None] | None = None,
                 **kw) -> None:
        kw.setdefault("poll_period", 1.0)
        super().__init__(port, **kw)
        if not fr.MIN_RATE_HZ <= rate_hz <= fr.MAX_RATE_HZ:
            raise LinkError(f"rate_hz {rate_hz} outside {fr.MIN_RATE_HZ}..{fr.MAX_RATE_HZ}")
        self.rate_hz = int(rate_hz)
        self.on_sample = on_sample
        self.on_samples = on_samples
        self._batch: list[tuple[fr.Sample, int]] = []
        self.status: fr.CurrentStatus | None = None
        self.samples = 0
        self.sample_gaps = 0
        self._last_sample_seq: int | None = None

    def on_connected(self) -> None:
        self._last_sample_seq = None
        self.request(fr.START_STREAM, fr.pack_start_stream(self.rate_hz))
        self.watch.start(time.monotonic())

    def request_stream(self) -> None:
        self.send(fr.START_STREAM, fr.pack_start_stream(self.rate_hz))

    def end_of_read(self, t_read: float, t_rx: float) -> None:
        if self._batch and self.on_samples is not None:
            batch, self._batch = self._batch, []
            try:
                self.on_samples(batch, t_read, t_rx)
            except Exception as exc:  # a consumer callback failed: keep the link alive, say so
                self.stats.callback_errors += 1
                self.stats.last_error = f"callback failed: {type(exc).__name__}: {exc}"

    def stop_stream(self) -> None:
        """Stop the board's stream (not re-requested until the next connect)."""
        self.watch.stop()
        self.request(fr.STOP_STREAM, b"")

    def on_frame(self, frame: fr.Frame, t_rx: float) -> None:
        if frame.type == fr.SAMPLE:
            sample = fr.unpack_sample(frame.payload)
            gap = 0
            if self._last_sample_seq is not None:
                gap = (sample.sequence - self._last_sample_seq - 1) & 0xFFFFFFFF
                if gap >= 0x80000000:  # went backwards (board restarted): not a gap
                    gap = 0
            self._last_sample_seq = sample.sequence
            self.watch.data(t_rx)
            self.samples += 1
            self.sample_gaps += gap
            self.stats.extra["sample_gaps"] = self.sample_gaps
            if self.on_samples is not None:
                self._batch.append((sample, gap))
            elif self.on_sample is not None:
                self.on_sample(sample, t_rx, gap)
        elif frame.type == fr.STATUS:
            self.status = fr.unpack_current_status(frame.payload)
