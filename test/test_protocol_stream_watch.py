"""StreamWatch (hexa.protocol.stream_watch): when a quiet board stream is re-requested, when the port is reconnected,
and what is counted."""
from __future__ import annotations

import math

import pytest

from hexa.protocol.stream_watch import NONE, RECONNECT, REREQUEST, StreamWatch, StreamWatchError


def _actions(watch: StreamWatch, t0: float, t1: float, dt: float = 0.01) -> list[tuple[float, str]]:
    """The actions `step` returns when called every `dt` s from `t0` to `t1` (times rounded to 1 µs)."""
    out = []
    for k in range(int(round((t1 - t0) / dt)) + 1):
        t = round(t0 + k * dt, 6)
        a = watch.step(t)
        if a != NONE:
            out.append((t, a))
    return out


def _streaming(watch: StreamWatch, t0: float, t1: float, dt: float = 0.01) -> None:
    for k in range(int(round((t1 - t0) / dt)) + 1):
        watch.data(round(t0 + k * dt, 6))
        assert watch.step(round(t0 + k * dt, 6)) == NONE


def test_a_quiet_stream_is_rerequested_after_the_timeout_every_period_then_reconnected():
    w = StreamWatch(timeout=0.25, rerequest_period=0.2, reconnect_after=0.75)
    w.start(0.0)
    _streaming(w, 0.01, 0.1)
    assert _actions(w, 0.11, 1.5) == [(0.36, REREQUEST), (0.56, REREQUEST), (0.76, REREQUEST), (0.86, RECONNECT)]
    assert (w.rerequests, w.reconnects, w.active) == (3, 1, False)   # nothing more until the link reconnected
    assert not w.stale(1.5)
    w.start(1.6)                                                     # reconnected: quiet counts from the connect
    assert _actions(w, 1.6, 1.85) == []
    w.data(1.9)
    assert w.recoveries == 1 and w.last_recovery_s == pytest.approx(1.8)   # from the last sample at 0.1 s


def test_data_after_a_rerequest_ends_the_episode_and_times_it():
    w = StreamWatch(timeout=0.25, rerequest_period=0.2, reconnect_after=0.75)
    w.start(0.0)
    _streaming(w, 0.0, 1.0)
    assert not w.stale(1.2) and w.stale(1.26)
    assert _actions(w, 1.01, 1.3) == [(1.26, REREQUEST)]
    w.data(1.31)
    assert (w.recoveries, w.rerequests, w.reconnects) == (1, 1, 0)
    assert w.last_recovery_s == pytest.approx(0.31)
    assert _actions(w, 1.32, 1.5) == []                              # streaming again: quiet counts anew
    assert _actions(w, 1.51, 1.6) == [(1.57, REREQUEST)]             # a second episode re-requests at once


def test_a_stopped_watch_never_acts():
    w = StreamWatch(timeout=0.1, rerequest_period=0.1, reconnect_after=0.3)
    assert _actions(w, 0.0, 2.0) == []                               # never started (no stream asked for)
    w.start(0.0)
    w.stop()                                                         # the host stopped the stream itself
    assert _actions(w, 0.0, 2.0) == [] and math.isnan(w.last_recovery_s)


@pytest.mark.parametrize("kwargs, name", [
    (dict(timeout=0.0, rerequest_period=0.2, reconnect_after=0.75), "stale_timeout"),
    (dict(timeout=0.25, rerequest_period=math.nan, reconnect_after=0.75), "stream_rerequest_period"),
    (dict(timeout=0.25, rerequest_period=0.2, reconnect_after=math.inf), "stream_reconnect_after"),
    (dict(timeout=0.25, rerequest_period=0.2, reconnect_after=0.25), "must exceed stale_timeout"),
])
def test_bad_timing_is_refused_naming_the_parameter(kwargs, name):
    with pytest.raises(StreamWatchError, match=name):
        StreamWatch(**kwargs)
