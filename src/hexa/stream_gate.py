"""Bounds on what one input stream may do from one message to the next, so that a single bad message costs only itself.

A stream of times (sample stamps, board clocks, image stamps) or of poses is checked against the last value it
accepted: a value that does not follow it — a time in the past, a time far in the future, a pose further away than
the robot can move in the time between — is rejected with a reason and leaves the reference where it was, so the
next good message is accepted as if the bad one had never come. A clock that really jumped (a board reset, a restarted
simulator, a bag played again, a plate that moved while the camera did not see it) sends values that all disagree with
the old reference but agree with one another: after `adopt_after` such values in a row the gate adopts the newest as
its reference, so a stream is never lost for good.
"""
from __future__ import annotations

import math
from collections import Counter
from typing import Callable, Generic, SupportsFloat, TypeVar

T = TypeVar("T")

#: check() results that mean "accepted"
ACCEPTED = ("ok", "adopted")


class StreamGate(Generic[T]):
    """Accepts values that follow the last accepted one, by a caller's rule, and re-adopts a consistent jump.

    Args:
        follows: follows(previous, value) is None when `value` may come after `previous`, else the reject reason.
        adopt_after: this many rejected values in a row, each following the one before it, are adopted (>= 1).

    Attributes:
        last: the last accepted value (None before the first).
        rejected: rejects by reason (collections.Counter).
        adopted: how many times the reference was re-adopted.
    """

    def __init__(self, follows: Callable[[T, T], str | None], adopt_after: int = 5) -> None:
        if int(adopt_after) < 1:
            raise ValueError(f"adopt_after must be >= 1, got {adopt_after!r}")
        self.follows = follows
        self.adopt_after = int(adopt_after)
        self.rejected: Counter[str] = Counter()
        self.adopted = 0
        self.reset()

    def reset(self) -> None:
        """Forget the reference: the next value is accepted whatever it is."""
        self.last: T | None = None
        self._run: list[T] = []

    def check(self, value: T) -> str:
        """"ok" (accepted), "adopted" (accepted as the new reference after a consistent jump) or the reject reason."""
        if self.last is None:
            self.last = value
            return "ok"
        reason = self.follows(self.last, value)
        if reason is None:
            self.last = value
            self._run.clear()
            return "ok"
        if self._run and self.follows(self._run[-1], value) is None:
            self._run.append(value)
        else:
            self._run = [value]
        if len(self._run) >= self.adopt_after:
            self.last = value
            self._run.clear()
            self.adopted += 1
            return "adopted"
        self.rejected[reason] += 1
        return reason

    def adopt(self, value: T) -> None:
        """Take `value` as the reference now (the caller has other evidence that the stream moved there)."""
        self.last = value
        self._run.clear()
        self.adopted += 1


def time_step_rule(max_step: float, repeats: bool = False) -> Callable[[float, float], str | None]:
    """The rule of a stream of times (s) that increase by at most `max_step` per message: "time_past" for a time before
    the previous one (or equal to it, unless `repeats`: host stamps quantized by /clock repeat), "time_future" for one
    more than max_step after it."""
    if not (math.isfinite(max_step) and max_step > 0):
        raise ValueError(f"max_step must be > 0 s, got {max_step!r}")

    def follows(prev: float, t: float) -> str | None:
        if t < prev or (t == prev and not repeats):
            return "time_past"
        if t - prev > max_step:
            return "time_future"
        return None

    return follows


class TimeGate(StreamGate[float]):
    """A StreamGate on a stream of times (s): each time later than the last accepted one (or equal, with `repeats`) by
    at most `max_step`; non-finite times are rejected as "non_finite" and never adopted."""

    def __init__(self, max_step: float, adopt_after: int = 5, repeats: bool = False) -> None:
        self.max_step = float(max_step)
        super().__init__(time_step_rule(self.max_step, repeats), adopt_after)

    def check(self, value: SupportsFloat | str) -> str:
        try:
            t = float(value)
        except (TypeError, ValueError):
            t = math.nan
        if not math.isfinite(t):
            self.rejected["non_finite"] += 1
            return "non_finite"
        return super().check(t)
