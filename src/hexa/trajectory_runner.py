"""A TrajectoryPlayer on a clock: when trajectory time starts (a set time, a delay after the first clock reading,
or the end of a slow approach from the first measured plate pose; never before the collision monitoring is first
OK), what is commanded each tick, the collision, monitoring and operator requests, and the state an operator
reads."""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.trajectory_player import Command, TrajectoryPlayer

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

#: s: the approach starts only from a plate pose whose stamp is this recent (limp servos let the plate sag; a
#: stalled camera lies)
APPROACH_POSE_MAX_AGE = 0.5
#: states in which the robot does not follow the trajectory for a reason an operator should see
WARN_STATES = ("held", "retracting", "waiting_for_pose", "waiting_for_monitoring")


@dataclass(frozen=True)
class TrajectorySettings:
    """The trajectory node's configuration (its parameters: same names, SI units; see hexa_dynamics.trajectory_node).

    Raises (check):
        ValueError: naming the setting out of range.
    """

    trajectory: str = "circle"
    file: str = ""
    rate_hz: float = 100.0
    start_delay: float = 1.0
    start_time: float = -1.0
    loop: bool = False
    loop_blend: float = 2.0
    collision_policy: str = "hold"
    retract_distance: float = 0.02
    retract_time: float = 0.5
    max_step: float = 0.03
    start_blend: float = 1.0
    approach_speed: float = 0.0
    approach_tolerance: float = 0.02
    require_monitoring: bool = True
    monitoring_timeout: float = 0.25

    def check(self) -> None:
        if not (math.isfinite(self.approach_speed) and self.approach_speed >= 0):
            raise ValueError(f"approach_speed must be >= 0 rad/s (0 = off), got {self.approach_speed}")
        if not (math.isfinite(self.approach_tolerance) and self.approach_tolerance >= 0):
            raise ValueError(f"approach_tolerance must be >= 0 rad, got {self.approach_tolerance}")
        if not self.rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {self.rate_hz}")
        if not (math.isfinite(self.monitoring_timeout) and self.monitoring_timeout > 0):
            raise ValueError(f"monitoring_timeout must be > 0 s, got {self.monitoring_timeout}")
        if not self.start_blend >= 0:
            raise ValueError(f"start_blend must be >= 0 s, got {self.start_blend}")
        m = self.max_step
        if not math.isfinite(m) or m < 0 or (0 < m < 1.0 / self.rate_hz):
            raise ValueError(f"max_step must be 0 (no limit) or >= 1/rate_hz = {1.0 / self.rate_hz:g} s, got {m}")


@dataclass(frozen=True)
class Tick:
    """What one tick gives: the state to report (None: nothing) and the arm angles ζ (rad) and rates ζ̇ (rad/s) to
    command (None: no command)."""

    state: str | None = None
    zeta: np.ndarray | None = None
    zeta_dot: np.ndarray | None = None


class TrajectoryRunner:
    """Trajectory time from a clock for a TrajectoryPlayer.

    Trajectory time 0 is `start_time` on the clock, or `start_delay` after the first clock reading when
    `start_time` < 0; before it the start pose is commanded at rest ("waiting"). With `approach_speed` > 0 nothing
    is commanded until a plate pose at most APPROACH_POSE_MAX_AGE old has arrived (`on_pose`): from it the player
    plans a slow approach to the start pose, and trajectory time 0 becomes that moment. A clock at 0 (sim time not
    started) commands nothing. With `require_monitoring`, trajectory time stays at 0 (the start pose, or the
    approach's first pose, commanded at rest: "waiting_for_monitoring") until the collision monitoring is first OK
    (`on_monitoring`); a LOST then holds the robot as a collision START does, and `resume` is refused until it is
    OK again. The observer re-publishes its state every 50 ms: no state for `monitoring_timeout` (the observer
    killed or hung) counts as LOST.

    Args:
        player: the trajectory player.
        start_time, start_delay: see above (s).
        approach_speed: rad/s, 0 = no approach.
        approach_tolerance: rad; no approach when every arm is this close to its start angle.
        log: called with ("info" | "warn" | "error", message) for what an operator should read.
        require_monitoring: wait for the monitoring's first OK, hold on LOST (False: no collision monitoring).
        monitoring_timeout: s of clock time without a monitoring state that count as LOST.
    """

    def __init__(self, player: TrajectoryPlayer, start_time: float = -1.0, start_delay: float = 1.0,
                 approach_speed: float = 0.0, approach_tolerance: float = 0.02,
                 log: Callable[[str, str], Any] | None = None, require_monitoring: bool = True,
                 monitoring_timeout: float = 0.25) -> None:
        self.player = player
        self.start_time, self.start_delay = start_time, start_delay
        self.approach_speed, self.approach_tolerance = approach_speed, approach_tolerance
        self.approach_pending = approach_speed > 0
        self._log = log or (lambda _level, _text: None)
        self._t0: float | None = None
        self._pose: np.ndarray | None = None
        self._pose_time = -math.inf
        self._last: Command | None = None
        self.state = "waiting"
        self.collisions = 0
        self.bad_poses = 0
        self.require_monitoring = require_monitoring
        self.monitoring, self.monitoring_reason = ("unknown", "no monitoring state received yet")
        self._watched = not require_monitoring      # monitoring has been OK at least once
        self.monitoring_holds = 0
        self.monitoring_timeout = monitoring_timeout
        self._monitoring_at = -math.inf             # clock time of the newest monitoring state
        self.refusal = ""                           # why the last resume was refused

    @classmethod
    def from_settings(cls, desc: HexaDescription, s: TrajectorySettings,
                      log: Callable[[str, str], Any] | None = None) -> TrajectoryRunner:
        """The runner of checked settings, with its player.

        Raises:
            ValueError: a setting out of range, an unknown trajectory or policy, a bad pose file.
            OSError: the pose file cannot be read.
        """
        from hexa.trajectories import trajectory_named

        s.check()
        traj, duration = trajectory_named(s.trajectory, s.file)
        player = TrajectoryPlayer(desc, traj, duration, policy=s.collision_policy,
                                  retract_distance=s.retract_distance, retract_time=s.retract_time, loop=s.loop,
                                  max_step=s.max_step or None, start_blend=s.start_blend, loop_blend=s.loop_blend)
        return cls(player, s.start_time, s.start_delay, s.approach_speed, s.approach_tolerance, log,
                   s.require_monitoring, s.monitoring_timeout)

    # -- inputs --------------------------------------------------------------------------------------------------
    def reject_pose(self, why: str) -> None:
        """Count a plate pose that cannot be used (and say why)."""
        self.bad_poses += 1
        self._log("warn", f"plate_pose rejected: {why}")

    def on_pose(self, pose: np.ndarray, stamp: float, now: float) -> None:
        """A measured plate pose [x y z α β γ] taken at `stamp` (s; ≤ 0: unknown, `now` is used)."""
        pose = np.asarray(pose, dtype=float)
        if not np.all(np.isfinite(pose)):
            self.reject_pose(f"non-finite pose {pose.tolist()}")
            return
        self._pose, self._pose_time = pose, (stamp if stamp > 0 else now)

    @property
    def start(self) -> float | None:
        """Clock time (s) of trajectory time 0 once it is fixed, else None: after the monitoring's first OK (or
        at the first tick without required monitoring) and once any approach is planned. It may lie ahead of the
        clock (a `start_time` not reached yet) and never moves afterwards: a scenario timed in trajectory time (the
        simulator's scripted collision) starts its clock from it."""
        if self._t0 is None or not self._watched or self.approach_pending:
            return None
        return self._t0

    def _fresh(self, now: float) -> bool:
        return self._pose is not None and now - self._pose_time <= APPROACH_POSE_MAX_AGE

    # -- time ----------------------------------------------------------------------------------------------------
    def time(self, now: float) -> float | None:
        """Trajectory time at clock time `now` (negative before the start), or None while nothing may be
        commanded. Plans the approach at the first call with a fresh measured pose."""
        if now <= 0.0:
            return None
        if self._t0 is None:
            self._t0 = self.start_time if self.start_time >= 0 else now + self.start_delay
        if self.approach_pending:
            if now < self._t0 or not self._fresh(now) or not self._plan_approach(now):
                return None
        if not self._watched and now > self._t0:
            self._t0 = now   # not watched yet: trajectory time stays at 0
        return now - self._t0

    def _plan_approach(self, now: float) -> bool:
        pose = self._pose
        if pose is None:    # _fresh() holds only with a pose
            return False
        try:
            T = self.player.approach_from(pose, self.approach_speed, self.approach_tolerance)
        except ValueError as exc:  # unreachable measured pose: wait for the next one
            self.bad_poses += 1
            self._pose = None
            self._log("error", f"cannot approach from the measured plate pose: {exc}")
            return False
        self.approach_pending = False
        self._t0 = now
        p = pose
        self._log("info", f"approach from plate pose ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m: {T:.2f} s"
                  if T > 0 else "at the start pose: no approach needed")
        return True

    # -- per tick and on request ---------------------------------------------------------------------------------
    def tick(self, now: float) -> Tick:
        """The command and state at clock time `now`; after an IK failure the previous command again."""
        self._monitoring_at = min(self._monitoring_at, now)   # a clock that went back restarts the count
        if (self._watched and self.require_monitoring and self.monitoring != "LOST"
                and now - self._monitoring_at > self.monitoring_timeout):
            text = self.on_monitoring("LOST", f"no monitoring state from the observer for "
                                      f"{now - self._monitoring_at:.2f} s (observer down or hung)", now)
            self._log("error", text or "monitoring silent")
        t = self.time(now)
        if t is None:
            if not self.approach_pending:
                return Tick()
            self.state = "waiting" if self._fresh(now) else "waiting_for_pose"
            return Tick(self.state)
        try:
            self._last = self.player.command(max(0.0, t))
        except ValueError as exc:
            self._log("error", f"IK failed, holding the last command: {exc}")
            if self._last is None:
                return Tick()
        cmd = self._last
        self.state = "waiting_for_monitoring" if not self._watched else "waiting" if t < 0 else cmd.state
        return Tick(self.state, cmd.zeta, np.zeros(6) if t < 0 or not self._watched else cmd.zeta_dot)

    def collision(self, now: float, external_force: np.ndarray | None = None) -> str | None:
        """A collision START: the player's new state, or None before the trajectory clock runs."""
        self.collisions += 1
        t = self.time(now)
        return None if t is None else self.player.on_collision(max(0.0, t), external_force)

    def on_monitoring(self, level: str, reason: str, now: float) -> str | None:
        """The observer's monitoring state ("OK" | "DEGRADED" | "LOST"): the first OK lets trajectory time start; a
        LOST after it holds as a collision START does. Returns what to log, or None."""
        if not self.require_monitoring:
            return None
        was = self.monitoring
        self.monitoring, self.monitoring_reason = level, reason
        if not (level == "LOST" and reason.startswith("no monitoring state")):
            self._monitoring_at = now
        if level == "OK" and not self._watched:
            self._watched = True
            if self._t0 is not None and not self.approach_pending:
                self._t0 = max(self._t0, now)   # trajectory time 0 is now at the latest
            return "monitoring OK: the trajectory may start"
        if level != "LOST" or not self._watched or was == "LOST":
            return None
        t = self.time(now)
        if t is None:
            return f"monitoring LOST ({reason}); nothing commanded yet"
        self.monitoring_holds += 1
        state = self.player.on_collision(max(0.0, t))
        return f"monitoring LOST ({reason}): {state}; resume with ~/resume once it is OK"

    def resume(self, now: float) -> bool:
        """Resume after a hold; False when not held, or while the monitoring is not OK (`refusal` says why)."""
        if self.require_monitoring and self.monitoring != "OK":
            self.refusal = f"monitoring {self.monitoring}: {self.monitoring_reason}; resume once it is OK"
            return False
        t = self.time(now)
        ok = t is not None and self.player.resume(max(0.0, t))
        self.refusal = "" if ok else "not held"
        return ok

    def hold(self, now: float) -> bool:
        """Hold as on a collision; False with the policy "ignore" or before the trajectory clock runs."""
        t = self.time(now)
        return t is not None and self.player.on_collision(max(0.0, t)) in ("held", "retracting")

    def diagnostic_values(self) -> dict[str, str]:
        """State and counters for /diagnostics."""
        p = self.player
        return {"state": self.state, "collisions": str(self.collisions), "ik_failures": str(p.ik_failures),
                "lag_events": str(p.lag_events), "lag_time_s": f"{p.lag_time:.3f}",
                "approach_time_s": f"{p.approach_time:.3f}", "rejected_poses": str(self.bad_poses),
                "monitoring": self.monitoring, "monitoring_reason": self.monitoring_reason,
                "monitoring_holds": str(self.monitoring_holds)}
