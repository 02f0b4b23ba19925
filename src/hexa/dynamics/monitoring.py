"""Whether the collision monitor is watching: OK, DEGRADED (settling) or LOST, with the input to blame — the
fail-safe contract of the observer node (docs/monitoring.md).

The monitor watches only while fresh current samples become residuals. `MonitoringWatch` wraps a CollisionMonitor:
it counts what arrives on each input stream, and `evaluate(now, wall)` (called on a timer) compares what arrived and
what became a residual since the last call, on the node's clock (`now`, sim time in simulation) and on a monotonic
wall clock (`wall`, which also runs when a simulator's /clock stalls):

- DEGRADED "settling" from the start (and after a reset or a LOST) until residuals have been fresh without a break
  for `settle_time`, with the detector out of collision;
- OK while the newest residual is at most `timeout` old (and, where ζ needs the camera, the newest usable plate pose
  at most `pose_timeout` old);
- LOST when either bound is still broken at an evaluation at least CONFIRM_GAP of wall time after the one that found
  it broken (a timer that runs before the samples already queued for the node does not count as a loss); the reason
  names the input (silent, or rejected by reason since the last fresh residual);
- DEGRADED "clock stalled" when no residual came for `wall_timeout` of wall time while the node's clock stood still
  (sim time not advancing: the simulated robot stands still too; with the clock, the residuals and OK come back).
"""
from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Sequence

    from numpy.typing import ArrayLike, NDArray

    from hexa.dynamics.monitor import CollisionMonitor, MonitorSample

OK, DEGRADED, LOST = "OK", "DEGRADED", "LOST"
LEVELS = (OK, DEGRADED, LOST)
#: wall s between the evaluation that finds a bound broken and the one that confirms it (LOST)
CONFIRM_GAP = 0.002


class MonitoringError(ValueError):
    """A bound of the monitoring contract out of range (named)."""


@dataclass(frozen=True)
class WatchConfig:
    """Bounds of the contract (s).

    timeout: node-clock time without a fresh residual before LOST; wall_timeout: wall time without one before LOST,
    whatever the node's clock does; pose_timeout: node-clock time without a usable plate pose before LOST, where ζ
    needs the camera; settle_time: node-clock time of fresh residuals without a break (and no collision in progress)
    before OK, after the start, a reset or a LOST."""

    timeout: float = 0.05
    wall_timeout: float = 1.0
    pose_timeout: float = 1.5
    settle_time: float = 0.5

    @classmethod
    def from_values(cls, values: dict[str, Any], prefix: str = "monitoring_") -> WatchConfig:
        """The bounds from parameter values named prefix + field (the observer node's `monitoring_timeout`, …)."""
        return cls(**{f.name: float(values[prefix + f.name]) for f in dataclasses.fields(cls)})

    def __post_init__(self) -> None:
        for name in ("timeout", "wall_timeout", "pose_timeout"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise MonitoringError(f"{name} must be > 0 s, got {v!r}")
        if not (math.isfinite(self.settle_time) and self.settle_time >= 0):
            raise MonitoringError(f"settle_time must be >= 0 s, got {self.settle_time!r}")


@dataclass(frozen=True)
class MonitoringStatus:
    """The contract's state: level (OK | DEGRADED | LOST), reason (empty when OK), the node-clock age (s) of the
    newest fresh residual (inf before the first) and the node-clock time the level was entered."""

    level: str
    reason: str
    residual_age: float
    since: float


class MonitoringWatch:
    """A CollisionMonitor's inputs and outputs against the contract (module docstring).

    Usage:
        watch = MonitoringWatch(monitor, WatchConfig(timeout=0.05), now)
        samples = watch.push_currents(stamp, board_us, currents)      # likewise push_states, push_pose
        status = watch.evaluate(now, wall)   # a new MonitoringStatus when the level or its cause changed, else None

    Args:
        monitor: the monitor whose inputs pass through this watch.
        config: the bounds.
        now: the node's clock at the start (s).
    """

    def __init__(self, monitor: CollisionMonitor, config: WatchConfig | None = None, now: float = 0.0) -> None:
        self.monitor = monitor
        self.config = config or WatchConfig()
        #: ζ from the estimator with camera updates: without usable plate poses the servo-model bias goes unchecked
        self.pose_needed = monitor.config.zeta_source == "estimator" and monitor.estimator.config.camera_sigma > 0
        self.received = {s: 0 for s in ("joint_states", "motor_currents", "plate_pose")}
        self._seen = dict(self.received)
        self._arrived = {s: -math.inf for s in self.received}
        self._residuals = monitor.observer.accepted
        self._poses = monitor.estimator.camera_accepted
        self._pose_at = -math.inf
        self._fresh = -math.inf          # node-clock time of the evaluation that saw the newest residual
        self._fresh_wall = math.inf      # wall time of it (inf: none yet, the wall bound does not apply)
        self._window: float | None = None   # start of the current run of fresh residuals
        self._rejects = self._reject_counts()
        self._phase = "starting"         # starting | watching | lost | settling
        self._grace = now                # LOST is not raised for a residual age counted from before this
        self._now = now                  # the node's clock at the previous evaluation
        self._cause: frozenset[str] = frozenset()
        self._suspect: float | None = None   # wall time of the first evaluation that found a bound broken
        self.status = MonitoringStatus(DEGRADED, "settling: no joint_states received yet", math.inf, now)
        self.lost_count = 0

    @property
    def streams(self) -> tuple[str, ...]:
        """The sample streams residuals come from: joint_states, and motor_currents when the sample times come
        from the current board's clock (time_source "board", or "auto" once board samples have been seen); only
        motor_currents while its messages carry their set-points."""
        tsrc = self.monitor.config.time_source
        if self.monitor.carries_setpoint:
            return ("motor_currents",)
        board = tsrc == "board" or (tsrc == "auto" and self.monitor.board_seen)
        return ("joint_states", "motor_currents") if board else ("joint_states",)

    # ------------------------------------------------------------------ inputs (counted, then to the monitor)
    def push_currents(self, stamp: float, board_us: int, currents: ArrayLike,
                      setpoint: Sequence[float] | NDArray | None = None) -> list[MonitorSample]:
        self.received["motor_currents"] += 1
        return self.monitor.push_currents(stamp, board_us, currents, setpoint)

    def push_states(self, stamp: float, position: NDArray | None, velocity: NDArray | None,
                    effort: NDArray | None) -> list[MonitorSample]:
        self.received["joint_states"] += 1
        return self.monitor.push_states(stamp, position, velocity, effort)

    def push_pose(self, stamp: float, pose: NDArray) -> list[MonitorSample]:
        self.received["plate_pose"] += 1
        return self.monitor.push_pose(stamp, pose)

    def restart(self, now: float) -> None:
        """After the monitor's reset: settle again (DEGRADED); LOST if no residual comes within the bounds, counted
        from now plus the estimator's settle time."""
        self._window = None
        self._grace = now + self.monitor.estimator.config.settle_time
        if self._phase != "starting":
            self._phase = "settling"
        self._set(DEGRADED, "settling: restarted by a reset", now)

    # ------------------------------------------------------------------ the state machine
    @property
    def ever_ok(self) -> bool:
        return self._phase != "starting"

    def health(self) -> tuple[str, str]:
        """("OK" | "WARN" | "ERROR", message) for diagnostics: ERROR naming the input while LOST, WARN while
        DEGRADED, else the monitor's own (WARN in collision)."""
        st = self.status
        if st.level == LOST:
            return "ERROR", f"monitoring LOST: {st.reason}"
        if st.level == DEGRADED:
            return "WARN", f"monitoring DEGRADED: {st.reason}"
        return self.monitor.health()

    def values(self) -> dict[str, Any]:
        """The monitor's counters and the contract's state for diagnostics."""
        st = self.status
        return {**self.monitor.counters(), "monitoring": st.level, "monitoring_reason": st.reason,
                "monitoring_lost_count": self.lost_count, **{f"received_{k}": v for k, v in self.received.items()}}

    def evaluate(self, now: float, wall: float) -> MonitoringStatus | None:
        """Apply the contract at node-clock time `now` and monotonic wall time `wall` (s). Returns the new status
        when the level or the blamed input changed, else None (`status` holds the current one)."""
        self._observe(now, wall)
        cfg = self.config
        age = now - self._fresh
        fresh = age <= cfg.timeout
        if not fresh:
            self._window = None
        pose_ok = not self.pose_needed or now - self._pose_at <= cfg.pose_timeout
        if self._phase == "starting":
            if self._settled(now, fresh, pose_ok):
                return self._watch(now, age)
            return self._set(DEGRADED, "settling: " + self._missing(now, age, pose_ok), now, age)
        lost = self._lost_cause(now, age, pose_ok)
        # confirmed by a later evaluation (not by the other timer in the same executor wake-up)
        confirmed = lost is not None and self._suspect is not None and wall - self._suspect >= CONFIRM_GAP
        if lost is None or self._suspect is None:
            self._suspect = None if lost is None else wall
        if lost is not None and (confirmed or self._phase == "lost"):
            if self._phase != "lost":
                self._phase = "lost"
                self.lost_count += 1
            return self._set(LOST, lost, now, age)
        if self._phase == "watching":
            if wall - self._fresh_wall > cfg.wall_timeout:
                return self._set(DEGRADED, f"clock stalled: no fresh residual for {wall - self._fresh_wall:.2f} s "
                                           f"of wall time while the node's clock stood at {now:.3f} s", now, age)
            return self._set(OK, "", now, age)
        if self._settled(now, fresh, pose_ok):
            return self._watch(now, age)
        self._phase = "settling"
        return self._set(DEGRADED, "settling: " + self._missing(now, age, pose_ok), now, age)

    # ------------------------------------------------------------------ helpers
    def _observe(self, now: float, wall: float) -> None:
        if now < self._now:   # the node's clock went back (a restarted simulator): ages run on across the jump
            shift = now - self._now
            self._fresh, self._pose_at, self._grace = self._fresh + shift, self._pose_at + shift, self._grace + shift
            self._arrived = {k: v + shift for k, v in self._arrived.items()}
            self._window = None if self._window is None else self._window + shift
        self._now = now
        for s, n in self.received.items():
            if n != self._seen[s]:
                self._seen[s], self._arrived[s] = n, now
        m = self.monitor
        if m.observer.accepted != self._residuals:
            self._residuals = m.observer.accepted
            self._fresh, self._fresh_wall = now, wall
            if self._window is None:
                self._window = now
            self._rejects = self._reject_counts()
        if m.estimator.camera_accepted != self._poses:
            self._poses, self._pose_at = m.estimator.camera_accepted, now

    def _settled(self, now: float, fresh: bool, pose_ok: bool) -> bool:
        return (fresh and pose_ok and self._window is not None and now - self._window >= self.config.settle_time
                and not self.monitor.observer.detector.active)

    def _watch(self, now: float, age: float) -> MonitoringStatus | None:
        self._phase = "watching"
        return self._set(OK, "", now, age)

    def _lost_cause(self, now: float, age: float, pose_ok: bool) -> str | None:
        cfg = self.config
        if now - max(self._fresh, self._grace) > cfg.timeout:
            return f"no fresh residual for {_ms(age)}: {self._blame(now)}"
        if not pose_ok:
            return f"plate_pose unusable for {now - self._pose_at:.2f} s: {self._pose_blame(now)}"
        return None

    def _blame(self, now: float) -> str:
        """The input that stopped the residuals: a silent stream, else the rejects since the last fresh residual."""
        silent = [f"{s} silent for {_ms(now - self._arrived[s])}" for s in self.streams
                  if now - self._arrived[s] > self.config.timeout]
        if silent:
            return ", ".join(silent)
        grown = self._grown_rejects()
        if grown:
            return "input rejected: " + ", ".join(f"{k} +{v}" for k, v in grown)
        if self.monitor.settling:
            return "samples arrive, the estimator is settling"
        return "samples arrive but none became a residual"

    def _pose_blame(self, now: float) -> str:
        if now - self._arrived["plate_pose"] > self.config.pose_timeout:
            return f"none received for {now - self._arrived['plate_pose']:.2f} s"
        grown = [(k, v) for k, v in self._grown_rejects() if "pose" in k or "camera" in k]
        return ("received but rejected: " + ", ".join(f"{k} +{v}" for k, v in grown)) if grown else \
            "received but none used by the estimator"

    def _missing(self, now: float, age: float, pose_ok: bool) -> str:
        """What start-up (or a recovery) still waits for."""
        for s in self.streams:
            if self._arrived[s] == -math.inf:
                return f"no {s} received yet"
        if self._fresh == -math.inf and self._arrived["plate_pose"] == -math.inf:
            return "no plate_pose received yet (the observer starts from a camera pose)"
        if age > self.config.timeout:
            return self._blame(now)
        if not pose_ok:
            return f"no usable plate_pose for {now - self._pose_at:.2f} s"
        if self.monitor.observer.detector.active:
            return "a collision is in progress"
        run = 0.0 if self._window is None else now - self._window
        return f"residuals fresh for {run:.2f} of {self.config.settle_time:g} s"

    def _set(self, level: str, reason: str, now: float, age: float = math.inf) -> MonitoringStatus | None:
        cause = frozenset(re.sub(r"[-+]?\d[\d.]*", " ", reason).replace(",", " ").split())   # names, not counts
        if level == self.status.level and cause == self._cause:
            return None
        self._cause = cause
        self.status = MonitoringStatus(level, reason, age, now if level != self.status.level else self.status.since)
        return self.status

    def _reject_counts(self) -> dict[str, int]:
        return {k: int(v) for k, v in self.monitor.counters().items() if k.startswith("reject_")}

    def _grown_rejects(self) -> list[tuple[str, int]]:
        now = self._reject_counts()
        grown = [(k.removeprefix("reject_"), v - self._rejects.get(k, 0)) for k, v in now.items()
                 if v > self._rejects.get(k, 0)]
        return sorted(grown, key=lambda kv: -kv[1])[:3]


def _ms(s: float) -> str:
    return "ever" if not math.isfinite(s) else f"{s * 1e3:.0f} ms"
