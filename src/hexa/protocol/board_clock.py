"""Which joint command was in effect when a current sample was measured.

The current board (Mega) stamps each sample with its own microsecond clock; the host knows only when the sample
*arrived*, and samples arrive in bursts — a USB-serial latency timer, a busy host, a driver thread that waited for the
GIL. Pairing each sample with the command sent by the time the driver *handles* the sample would pair a burst of
samples measured before a command went out with that command: the arm-angle estimator would place the set-point
step up to a burst early, and the collision observer's residual would spike (docs/driver_timing.md, "Which
command a sample carries").

Here the host keeps a map from its clock to the board's, built from the samples themselves. A sample with board time
b_k that arrived at host time t_k says that the board clock read *at least* b_k at t_k (it was measured before it
arrived). With the board clock's rate ρ (board seconds per host second: 1 up to a resonator's tolerance on the robot,
the real-time factor in simulation), the board time at host time t is the upper envelope of these bounds,

    b(t) = max_k [ b_k + ρ (t − t_k) ]      over the samples of the last `envelope_window` s,

which the least-delayed sample of a burst decides. Each command is stamped with b(t_send) when it is sent —
provisionally: the samples still waiting in the port at that moment are not in the map yet, and the next read of the
port raises the stamp to what they prove (`CommandTimeline.confirm`) — and each sample is paired with the latest
command whose board stamp is not after the sample's board time (`CommandTimeline.at`).

A hobby servo then takes the command only from its next pulse, once per 20 ms frame of the servo board (Uno). When
the Uno reports its frames (LATCH, docs/protocol.md) the driver maps them onto the same board clock and gives each
servo the set-point its last pulse carried (`ServoFrameTimeline`); without the reports that 0–20 ms is unknown. The
rest of the servo's delay is the estimator's `command_delay` (hexa.estimation.ServoModel).
"""
from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Iterable

import numpy as np

#: the board's microsecond clock wraps at 2³² µs (71.6 min), like Arduino's micros()
BOARD_CLOCK_WRAP_S = 2 ** 32 * 1e-6
#: a board clock that goes back by more than this (µs) was restarted (a board reset); less: a sample out of order
RESTART_STEP_US = 100_000
#: a board clock that runs ahead of the host's by more than this (s) beyond the fastest rate allowed, between two
#: samples, is one bad board time (rejected, `BoardClockMap.rejected`), unless ADOPT_AFTER samples agree on it
FORWARD_SLACK = 1.0
ADOPT_AFTER = 5
#: the rate is refitted every this many samples
RATE_EVERY = 10
#: a command's board time raised by more than this (s) by a later read is counted (`CommandTimeline.redated`): a
#: stalled driver. Small raises are routine: the read's bound is sharper than the map's by the samples' arrival
#: delay, and in simulation the board clock (sim time) runs in bursts between camera renders
REDATE_COUNTED = 0.01


class BoardClockMap:
    """Host time → board time of one board, from its samples' (board time, arrival time) pairs.

    Args:
        envelope_window: samples that arrived within this many host seconds of the newest one bound the board clock
            (s); a longer window makes an error in the rate count more.
        rate_window: host seconds of samples over which the board clock's rate is fitted (s).
        rate_bounds: the fitted rate is kept within these (board s per host s); before `min_rate_span` s of samples
            the rate is `nominal_rate`.
        nominal_rate: rate used until the fit has enough span (1: the board runs on real time).
        min_rate_span: host seconds of samples needed before the rate is fitted (s).
        max_extrapolation: the estimate never runs more than this (board s) past the newest sample: a silence is a
            starved host thread on the robot (the board clock runs on) but mostly a paused simulator in simulation
            (the board clock stands still while a camera frame renders); unbounded, the estimate overshot the true
            set-point time by up to 30 ms there.
    """

    def __init__(self, envelope_window: float = 0.05, rate_window: float = 1.0,
                 rate_bounds: tuple[float, float] = (0.02, 5.0), nominal_rate: float = 1.0,
                 min_rate_span: float = 0.2, max_extrapolation: float = 0.01) -> None:
        if not (envelope_window > 0 and rate_window >= envelope_window and 0 < rate_bounds[0] <= rate_bounds[1]
                and rate_bounds[0] <= nominal_rate <= rate_bounds[1] and 0 < min_rate_span <= rate_window
                and max_extrapolation >= 0):
            raise ValueError(f"bad BoardClockMap windows/rates: envelope {envelope_window}, rate window {rate_window}"
                             f", bounds {rate_bounds}, nominal {nominal_rate}, min span {min_rate_span}, "
                             f"max extrapolation {max_extrapolation}")
        self.envelope_window = float(envelope_window)
        self.rate_window = float(rate_window)
        self.rate_bounds = (float(rate_bounds[0]), float(rate_bounds[1]))
        self.nominal_rate = float(nominal_rate)
        self.min_rate_span = float(min_rate_span)
        self.max_extrapolation = float(max_extrapolation)
        self.restarts = 0           # board clock went backwards (board reset): the map started over
        self.rejected = 0           # single board times far ahead of what the host's clock allows
        self.reset()

    def reset(self) -> None:
        """Forget every sample (a new connection: the board clock may have restarted)."""
        self._pairs: deque[tuple[float, float]] = deque()   # (host time, unwrapped board time), host time ascending
        self._last_raw: int | None = None
        self._wraps = 0
        self._count = 0
        self._ahead: list[tuple[int, float]] = []   # (raw, host time) of the board times rejected in a row
        self.rate = self.nominal_rate

    def update(self, board_time_us: int, t_host: float) -> float:
        """Record a sample measured at board time `board_time_us` (µs, wrapping at 2³²) that arrived at host time
        `t_host` (s, monotonic); returns its unwrapped board time (s).

        A board time further ahead of the last one than the host's clock allows (the fastest rate times the host
        time between, plus FORWARD_SLACK) is one bad sample: counted in `rejected`, the map left alone, and the
        map's estimate for `t_host` returned — unless ADOPT_AFTER such samples in a row agree with one another (the
        board clock really jumped): then the map starts over at them, as on a restart."""
        raw = int(board_time_us) & 0xFFFFFFFF
        if self._runs_ahead(raw, float(t_host)):
            self.rejected += 1
            est = self.board_time_at(float(t_host))
            return (self._last_raw or 0) * 1e-6 + self._wraps * BOARD_CLOCK_WRAP_S if est is None else est
        wraps = self._wraps
        if self._last_raw is not None and raw < self._last_raw:
            if self._last_raw - raw > 2 ** 31:      # the counter wrapped
                wraps = self._wraps = self._wraps + 1
            elif self._last_raw - raw > RESTART_STEP_US:   # the clock went back: the board restarted
                self.restarts += 1
                self.reset()
                wraps = 0
            else:                                   # a sample out of order (not from a serial link): keep the newest
                return raw * 1e-6 + wraps * BOARD_CLOCK_WRAP_S
        self._last_raw = raw
        b = raw * 1e-6 + wraps * BOARD_CLOCK_WRAP_S
        t_host = float(t_host)
        if self._pairs and t_host < self._pairs[-1][0]:  # arrival times never go back: keep the envelope's order
            t_host = self._pairs[-1][0]
        self._pairs.append((t_host, b))
        while self._pairs[0][0] < t_host - self.rate_window:
            self._pairs.popleft()
        self._count += 1
        if self._count % RATE_EVERY == 0 and t_host - self._pairs[0][0] >= self.min_rate_span:
            self._fit_rate()
        return b

    def _runs_ahead(self, raw: int, t_host: float) -> bool:
        """Whether board time `raw` (µs) is further ahead of the newest sample than the host's clock allows and not
        yet confirmed by ADOPT_AFTER samples that follow one another (then the map starts over)."""
        if self._last_raw is None or not self._pairs:
            return False
        step = ((raw - self._last_raw + (1 << 31)) & 0xFFFFFFFF) - (1 << 31)
        allowed = self.rate_bounds[1] * max(t_host - self._pairs[-1][0], 0.0) + FORWARD_SLACK
        if step * 1e-6 <= allowed:
            self._ahead.clear()
            return False
        if self._ahead:
            r0, t0 = self._ahead[-1]
            s0 = ((raw - r0 + (1 << 31)) & 0xFFFFFFFF) - (1 << 31)
            if not 0 < s0 * 1e-6 <= self.rate_bounds[1] * max(t_host - t0, 0.0) + FORWARD_SLACK:
                self._ahead.clear()
        self._ahead.append((raw, t_host))
        if len(self._ahead) < ADOPT_AFTER:
            return True
        self.restarts += 1           # the board clock jumped for good: start over at it
        self.reset()
        return False

    def _fit_rate(self) -> None:
        """Rate between the least-delayed samples at the two ends of the rate window (late samples of a burst
        would bias a fit through all of them low)."""
        t_first, t_last = self._pairs[0][0], self._pairs[-1][0]
        head = list(itertools.takewhile(lambda p: p[0] <= t_first + self.envelope_window, self._pairs))
        tail = list(itertools.takewhile(lambda p: p[0] >= t_last - self.envelope_window, reversed(self._pairs)))
        t_a, b_a = max(head, key=lambda p: p[1] - self.rate * p[0])
        t_b, b_b = max(tail, key=lambda p: p[1] - self.rate * p[0])
        if t_b - t_a >= self.min_rate_span and b_b > b_a:
            lo, hi = self.rate_bounds
            self.rate = min(max((b_b - b_a) / (t_b - t_a), lo), hi)

    def board_time_at(self, t_host: float) -> float | None:
        """Board time (s, unwrapped) at host time `t_host`: the upper envelope of the recent samples' bounds, at most
        `max_extrapolation` past the newest sample's board time; None before the first sample."""
        if not self._pairs:
            return None
        t_new, b_new = self._pairs[-1]
        best = -math.inf
        for t_k, b_k in reversed(self._pairs):
            if t_k < t_new - self.envelope_window:
                break
            best = max(best, b_k + self.rate * (t_host - t_k))
        return min(best, b_new + self.max_extrapolation)


class CommandTimeline:
    """Commanded angles, each with the board time from which it was in effect.

    A command's board time is first estimated when it is sent (`add` with `sent_at`, from the clock map), and is
    *provisional* until a read of the board's port that started after the send (`confirm`): samples that were
    already waiting in the port when the command went out — a driver that was stopped or starved while the board
    went on measuring — are not in the map yet, so the estimate can be early by the whole wait, and every sample of
    that wait would carry a command the servos did not have yet (after a 45 ms driver stall this makes a false collision
    START, docs/driver_timing.md). Each such read raises the estimate to what its samples prove: they had all been
    measured when the read started.

    Args:
        horizon: board seconds of superseded commands kept for samples that arrive late (s).
    """

    def __init__(self, horizon: float = 2.0) -> None:
        self.horizon = float(horizon)
        self._items: deque[list] = deque()   # [board time, zeta, host send time (None: confirmed)], in send order
        self.redated = 0                     # board times raised by more than REDATE_COUNTED (diagnostics)

    def rebase(self) -> None:
        """The board clock started over (a board reset or a new connection): keep only the newest command, in
        effect from now on whatever the new clock reads."""
        if self._items:
            self._items = deque([[-math.inf, self._items[-1][1], None]])

    def add(self, board_time: float | None, zeta: np.ndarray, sent_at: float | None = None) -> float:
        """Record `zeta` as sent at `board_time` (None: before any sample, in effect for every sample); returns the
        board time used (never before the previous command's). With `sent_at` (host time of the send, s) the board
        time is provisional until `confirm`."""
        b = -math.inf if board_time is None else float(board_time)
        if self._items and b < self._items[-1][0]:
            b = self._items[-1][0]
        self._items.append([b, np.array(zeta, dtype=float), None if sent_at is None else float(sent_at)])
        return b

    def confirm(self, read_started: float, newest_board_time: float, rate: float) -> int:
        """A read of the board's port that started at host time `read_started` (s) returned samples measured up to
        board time `newest_board_time` (s): the board clock read at least that when the read started. A command sent
        at host time t_s before the read was therefore sent no earlier than newest − rate·(read_started − t_s) (rate:
        board s per host s, the clock map's; a clock that paused in between only makes the bound looser), and is
        confirmed; one sent after the read started — the samples are handled after it went out — no earlier than
        just after `newest`, and stays provisional for the next read. Each provisional command gets the later of its
        estimate and its bound; commands keep their send order. Returns how many board times were raised by more
        than REDATE_COUNTED."""
        items = self._items
        first = len(items)                  # provisional commands are the newest ones (confirmed in send order)
        while first > 0 and items[first - 1][2] is not None:
            first -= 1
        raised = 0
        floor = items[first - 1][0] if first > 0 else -math.inf
        for k in range(first, len(items)):
            item = items[k]
            sent_at = item[2]
            if sent_at is not None:
                if sent_at <= read_started:
                    bound = newest_board_time - rate * (read_started - sent_at)
                    item[2] = None
                else:
                    bound = newest_board_time + 1e-6
                if bound > item[0]:
                    raised += bound - item[0] > REDATE_COUNTED
                    item[0] = bound
            if item[0] < floor:      # a command is never in effect before one sent earlier
                item[0] = floor
            floor = item[0]
        self.redated += raised
        return raised

    def at(self, board_time: float) -> np.ndarray | None:
        """The command in effect at `board_time` (s): the latest one sent at or before it; None if none was."""
        found = None
        for b, zeta, _ in reversed(self._items):
            if b <= board_time:
                found = zeta
                break
        # commands superseded more than `horizon` before this sample are not needed any more
        while len(self._items) > 1 and self._items[1][0] <= board_time - self.horizon:
            self._items.popleft()
        return found


#: the servo board picks up channel 1's width this long (s) before the frame starts (firmware PREP_TICKS)
FRAME_PREP = 50e-6


def percentile_linear(values: Iterable[float], q: float) -> float:
    """The q-th percentile of finite `values` as numpy's default (linear) method computes it, to the last bit, on
    plain floats: np.percentile's machinery costs ≈ 25 µs a call, and the driver asks for two per servo pulse report."""
    a = sorted(values)
    n = len(a)
    v = (n - 1) * (q / 100)
    if v >= n - 1:
        return a[-1]
    i = math.floor(v)
    g = v - i
    lo, hi = a[i], a[i + 1]
    d = hi - lo
    return hi - d * (1 - g) if g >= 0.5 else lo + d * g   # numpy's _lerp, exact from either end


def read_points(pulse_offsets: np.ndarray) -> np.ndarray:
    """When (s after the frame's start) the servo board reads each channel's width from its newest command: channel 1
    `FRAME_PREP` before the frame, channel i at the start of channel i−1's slot (uno_servo.ino's compare ISR)."""
    return np.concatenate([[-FRAME_PREP], np.asarray(pulse_offsets, dtype=float)[:-1]])


class ServoFrameTimeline:
    """The set-point each servo acts on, from the servo board's pulse frames (LATCH reports).

    A hobby servo takes a new set-point only from its pulse, one per `period` (20 ms) frame, the six pulses one after
    the other: servo i acts on the command its latest pulse carried from that pulse's end on. The servo board reports
    each frame — its start, each pulse's start and the SEQ of the SET_TARGETS each pulse carried (docs/protocol.md,
    LATCH) — after the frame's last pulse, so the frames of the last ≈ 20 ms are not reported yet when their current
    samples arrive. Those are predicted: the frames are periodic, each pulse starts where it started in the newest
    reported frame (its width changes little from one frame to the next), and it carries the newest command the board
    had at its read point (`read_points`: the start of the previous channel's slot), which `commands` (the
    CommandTimeline of send times) approximates. A reported frame
    replaces the prediction (`mismatches` counts the servos whose reported command differed from the predicted one).

    All times here are on one clock — the current board's (the driver maps the servo board's clock through the host's
    onto it, or the caller's clock in tests).

    Args:
        period: the frame period (s).
        horizon: seconds of reported frames kept for samples that arrive late.
    """

    def __init__(self, period: float = 0.02, horizon: float = 1.0) -> None:
        if not (period > 0 and horizon > period):
            raise ValueError(f"bad ServoFrameTimeline period {period} / horizon {horizon}")
        self.period = float(period)
        self.horizon = float(horizon)
        self._by_seq: dict[int, np.ndarray] = {}            # SEQ -> the angles that SET_TARGETS carried
        self._sent_at: dict[int, float] = {}                # SEQ -> its send time on this clock
        self._seq_order: deque[int] = deque(maxlen=256)     # SEQs in send order
        # bounds on the delay from a command's send time to the board having it, from the reported frames: the SEQ
        # a pulse carried was there at its read point (upper bound), the next one was not (lower bound)
        self._delay_lo: deque[float] = deque(maxlen=200)
        self._delay_hi: deque[float] = deque(maxlen=200)
        self.delivery_delay = 0.0
        # (start, latch offsets, angles | nan, read points)
        self._frames: deque[tuple[float, np.ndarray, np.ndarray, np.ndarray]] = deque()
        self.frames = 0
        self.unknown_seq = 0
        self.mismatches = 0

    def reset(self) -> None:
        """Forget the frames (the servo board or a clock restarted); the commands by SEQ stay valid."""
        self._frames.clear()

    def add_command(self, seq: int, zeta: np.ndarray, sent_at: float | None = None) -> None:
        """A SET_TARGETS frame with header SEQ `seq` (0..255) carried the angles `zeta` (rad), sent at `sent_at` (s,
        this timeline's clock; None: unknown) — the send times let the reported frames measure the delivery delay."""
        seq = int(seq) & 0xFF
        self._by_seq[seq] = np.array(zeta, dtype=float)
        if sent_at is not None and math.isfinite(sent_at):
            self._sent_at[seq] = float(sent_at)
            if seq in self._seq_order:
                self._seq_order.remove(seq)
            self._seq_order.append(seq)

    def add_frame(self, start: float, pulse_offsets: np.ndarray, latch_offsets: np.ndarray, seqs: np.ndarray,
                  mask: int, commands: CommandTimeline | None = None) -> None:
        """A reported frame: its start (s, on this timeline's clock), each servo's pulse start and latch (pulse end)
        offsets from the start (s), the SEQ each pulse carried and the bit mask of servos pulsed (others keep their
        set-point). With `commands`, counts the servos whose reported command differs from the one predicted."""
        offsets = np.asarray(latch_offsets, dtype=float).reshape(6)
        starts = read_points(np.asarray(pulse_offsets, dtype=float).reshape(6))
        angles = np.full(6, np.nan)
        for i in range(6):
            if not (int(mask) >> i) & 1:
                continue
            zeta = self._by_seq.get(int(seqs[i]) & 0xFF)
            if zeta is None:
                self.unknown_seq += 1
                continue
            angles[i] = zeta[i]
            self._delay_bounds(int(seqs[i]) & 0xFF, start + starts[i])
            if commands is not None:   # what the board had at the pulse's read point, as predicted
                predicted = commands.at(start + starts[i] - self.delivery_delay)
                if predicted is not None and abs(predicted[i] - zeta[i]) > 1e-9:
                    self.mismatches += 1
        if self._frames and start <= self._frames[-1][0] + 0.5 * self.period:
            if start < self._frames[-1][0] - 0.5 * self.period:   # the clock went back: start over
                self._frames.clear()
            else:
                return                                             # a repeated report of a known frame
        self._frames.append((float(start), offsets, angles, starts))
        self.frames += 1
        while len(self._frames) > 1 and self._frames[0][0] < start - self.horizon:
            self._frames.popleft()

    def _delay_bounds(self, seq: int, read_at: float) -> None:
        """SEQ `seq` was the newest command on the board at `read_at`: the delivery delay is at most read_at − its
        send time, and more than read_at − the next command's send time. The estimate is the 98th percentile of the
        recent lower bounds (a late delivery happens), kept below the 10th percentile of the upper bounds."""
        sent = self._sent_at.get(seq)
        if sent is None:
            return
        self._delay_hi.append(read_at - sent)
        order = list(self._seq_order)
        k = order.index(seq) if seq in order else -1
        if 0 <= k < len(order) - 1:
            nxt = self._sent_at.get(order[k + 1])
            if nxt is not None and nxt < read_at:
                self._delay_lo.append(read_at - nxt)
        if len(self._delay_lo) >= 10:
            d = percentile_linear(self._delay_lo, 98)
            if len(self._delay_hi) >= 10:
                d = min(d, percentile_linear(self._delay_hi, 10))
            self.delivery_delay = min(max(d, 0.0), self.period)

    def setpoints_at(self, t: float, commands: CommandTimeline) -> np.ndarray | None:
        """The six set-points the servos act on at time `t` (s); None before any reported frame (the caller falls
        back to `commands.at`). A servo's set-point comes from the latest pulse that ended at or before t: a
        reported frame's, or for a frame not reported yet, the command `commands` had when that pulse started."""
        if not self._frames:
            return None
        out = np.full(6, np.nan)
        last_start, last_off, _, last_pulse = self._frames[-1]
        for i in range(6):
            # the latest pulse end of servo i at or before t, on the frame grid of the newest report
            k = math.floor((t - last_start - last_off[i]) / self.period + 1e-9)
            if k > 0:     # a frame after the newest report: its pulse carries the command the board had at its
                # read point, i.e. sent a delivery delay earlier
                z = commands.at(last_start + k * self.period + last_pulse[i] - self.delivery_delay)
                if z is not None:
                    out[i] = z[i]
                    continue
            for start, off, ang, _ in reversed(self._frames):
                if start + off[i] <= t and np.isfinite(ang[i]):
                    out[i] = ang[i]
                    break
        if np.isnan(out).any():
            fallback = commands.at(t)
            if fallback is None:
                return None
            out = np.where(np.isnan(out), fallback, out)
        return out
