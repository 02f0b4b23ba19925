"""When a connected board's periodic telemetry has gone quiet: ask for it again, then reconnect.

A board can stop its stream while its port stays open and it still answers requests: the Mega after a reset (or one
STOP_STREAM frame) no longer samples, the Uno after a reset no longer sends its LATCH reports and has forgotten its
limits, watchdog and targets. Other frames (STATUS, PONG) keep the link alive, so the link's own staleness check never
fires. `StreamWatch` watches one stream by its data frames alone:

    quiet > timeout           -> REREQUEST (the board's stream request again), then every `rerequest_period`
    quiet > reconnect_after   -> RECONNECT (close the port; the link reopens it and configures the board anew)

Times are arguments (host monotonic seconds): the link thread calls `data` per frame of the stream and `step`
periodically, and performs the action `step` returns.
"""
from __future__ import annotations

import math

NONE = "NONE"
REREQUEST = "REREQUEST"
RECONNECT = "RECONNECT"


class StreamWatchError(ValueError):
    """Invalid stream-watch timing (the message names the parameter and value)."""


class StreamWatch:
    """The recovery of one board stream (the Mega's samples, the Uno's LATCH reports).

    Args:
        timeout: no data frame for this long (s) -> the stream is stale and is re-requested.
        rerequest_period: a stale stream is re-requested again this often (s).
        reconnect_after: no data frame for this long (s, > timeout) -> reconnect.

    Raises:
        StreamWatchError: a time that is not finite and positive, or reconnect_after <= timeout.
    """

    def __init__(self, timeout: float, rerequest_period: float, reconnect_after: float) -> None:
        for name, value in (("stale_timeout", timeout), ("stream_rerequest_period", rerequest_period),
                            ("stream_reconnect_after", reconnect_after)):
            if not (math.isfinite(float(value)) and float(value) > 0):
                raise StreamWatchError(f"parameter {name} must be a finite time > 0 s, got {value}")
        if reconnect_after <= timeout:
            raise StreamWatchError(f"parameter stream_reconnect_after ({reconnect_after} s) must exceed "
                                   f"stale_timeout ({timeout} s)")
        self.timeout = float(timeout)
        self.rerequest_period = float(rerequest_period)
        self.reconnect_after = float(reconnect_after)
        self.rerequests = 0          # stream requests sent for a stale stream
        self.reconnects = 0          # ports closed because the stream stayed quiet
        self.recoveries = 0          # stale episodes that ended with data again
        self.last_recovery_s = math.nan   # last stale episode: from the last data frame before it to the first after
        self._active = False
        self._last = 0.0             # last data frame, or when watching started
        self._stale_since: float | None = None   # the last data frame before the current stale episode
        self._next_rerequest = 0.0

    @property
    def active(self) -> bool:
        """The stream is expected (watching started and not stopped)."""
        return self._active

    def start(self, now: float) -> None:
        """The stream was requested at host time `now` (on connect): quiet time counts from here."""
        self._active = True
        self._last = now
        self._next_rerequest = now

    def stop(self) -> None:
        """The stream is not expected (the host stopped it, or the port is closed): nothing to recover."""
        self._active = False

    def data(self, now: float) -> None:
        """A data frame of the stream arrived at host time `now`."""
        if self._stale_since is not None:
            self.recoveries += 1
            self.last_recovery_s = now - self._stale_since
            self._stale_since = None
        self._last = now

    def quiet(self, now: float) -> float:
        """Seconds since the last data frame (or the start) at host time `now`."""
        return now - self._last

    def stale(self, now: float) -> bool:
        """The stream is expected and has been quiet for longer than `timeout` at host time `now`."""
        return self._active and self.quiet(now) > self.timeout

    def step(self, now: float) -> str:
        """What the link does at host time `now`: NONE, REREQUEST or RECONNECT (counted here)."""
        if not self.stale(now):
            return NONE
        if self._stale_since is None:
            self._stale_since = self._last
            self._next_rerequest = now
        if self.quiet(now) > self.reconnect_after:
            self.reconnects += 1
            self._active = False          # until the link has reconnected and calls `start`
            return RECONNECT
        if now >= self._next_rerequest:
            self.rerequests += 1
            self._next_rerequest = now + self.rerequest_period
            return REREQUEST
        return NONE
