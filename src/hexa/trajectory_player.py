"""Plays a plate trajectory through inverse kinematics as arm-angle commands, with the collision reaction
an operator expects of a safety stack: hold (default), retract along the residual force, or ignore."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from hexa.trajectories import cross_fade, smoothstep, smoothstep_rate

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

POLICIES = ("hold", "retract", "ignore")


class TrajectoryPlayerError(ValueError):
    """Bad player configuration (unknown policy or trajectory, non-positive durations)."""


@dataclass
class Command:
    """One command: arm angles ζ (rad), their rates (rad/s), the plate pose commanded, and the player state."""

    zeta: np.ndarray
    zeta_dot: np.ndarray
    pose: np.ndarray
    state: str  # "approaching" | "running" | "held" | "retracting" | "resuming" | "finished"
    trajectory_time: float


class TrajectoryPlayer:
    """Samples `trajectory(t) -> (pose, pose_dot, pose_ddot)` and converts poses to ζ by IK.

    Args:
        desc: the Hexa description.
        trajectory: callable of trajectory time (s) returning pose (6,) [x y z α β γ] and its derivatives.
        duration: trajectory length (s); after it the last pose is held ("finished") unless `loop`.
        policy: reaction to a collision START: "hold", "retract" or "ignore".
        retract_distance: how far (m) the plate backs off along the external force in "retract".
        retract_time: seconds the retraction and the return blend take.
        loop: restart the trajectory after `duration`. A trajectory that does not end where it starts (the helix
            rises 5 cm in its 10 s) would jump there; instead the first `loop_blend` seconds of each new cycle
            cross-fade from the old cycle continued (the trajectory function evaluated past `duration`) onto the new
            one with a smoothstep: position and velocity stay continuous, the offset is taken up at ≤ 1.5·offset /
            loop_blend extra speed. A periodic trajectory (circle, ellipse) is unchanged by it.
        loop_blend: seconds of that cross-fade (> 0).
        max_step: the most (s) trajectory time may advance between two successive commands, or None (no limit).
            When the caller is late (a stalled host, a clock delivered in bursts) the trajectory pauses for the
            surplus instead of jumping: the servos never receive a step of more than `max_step` of motion, which
            they could not follow and which the collision observer would see as an unmodelled transient. The
            surplus is added to the hold offset and counted in `lag_events` / `lag_time`. Trajectory time starts
            at 0, so a first command at t > max_step also starts from the beginning of the trajectory.
        start_blend: seconds (0 = none) over which the command blends from rest at the start pose onto the
            trajectory, which (as in the paper) starts with non-zero velocity: pose = p0 + s(t)·(p(t) − p0) with a
            smoothstep s, so the commanded velocity rises from 0 and the trajectory is exact after `start_blend`
            (no time shift; catching up costs up to 1.69x the trajectory's rate midway, with accelerations
            ≈ 3.4 v / start_blend). Without it the servos see a velocity step at t = 0.
    """

    def __init__(self, desc: "HexaDescription", trajectory: Callable[[float], tuple], duration: float,
                 policy: str = "hold", retract_distance: float = 0.02, retract_time: float = 0.5,
                 loop: bool = False, max_step: float | None = None, start_blend: float = 0.0,
                 loop_blend: float = 2.0) -> None:
        if policy not in POLICIES:
            raise TrajectoryPlayerError(f"unknown collision policy {policy!r}; use one of {POLICIES}")
        if not (start_blend >= 0 and np.isfinite(start_blend)):
            raise TrajectoryPlayerError(f"start_blend must be >= 0, got {start_blend}")
        if not (loop_blend > 0 and np.isfinite(loop_blend)):
            raise TrajectoryPlayerError(f"loop_blend must be > 0 s, got {loop_blend}")
        if max_step is not None and not max_step > 0:
            raise TrajectoryPlayerError(f"max_step must be > 0 or None, got {max_step}")
        if not duration > 0 or not retract_time > 0 or retract_distance < 0:
            raise TrajectoryPlayerError(f"durations must be > 0 and distance >= 0, got duration={duration}, "
                                        f"retract_time={retract_time}, retract_distance={retract_distance}")
        from hexa.kinematics import hexa6rus

        self._ik = hexa6rus.inverse_kinematics
        self._ik_rates = hexa6rus.inverse_kinematics_derivatives
        self.desc = desc
        self.trajectory = trajectory
        self.duration = float(duration)
        self.policy = policy
        self.retract_distance = float(retract_distance)
        self.retract_time = float(retract_time)
        self.loop = loop
        self.loop_blend = float(loop_blend)
        self.max_step = None if max_step is None else float(max_step)
        self._last_t = 0.0          # time of the previous command (for max_step)
        self.lag_events = 0
        self.lag_time = 0.0
        self._offset = 0.0          # wall/sim time spent held, subtracted from trajectory time
        self._held_since: float | None = None
        self._hold_pose: np.ndarray | None = None
        self._retract_dir = np.zeros(3)
        # a blend from `_resume_from` onto the trajectory, progressing in trajectory (played) time from
        # `_resume_at`, so that max_step also limits its steps; the start is a resume from rest at trajectory time 0
        self._resume_at: float | None = None
        self._resume_from: np.ndarray | None = None
        self._blend_time = self.retract_time
        self._starting = start_blend > 0
        if start_blend > 0:
            self._resume_at, self._blend_time = 0.0, float(start_blend)
            self._resume_from = self._trajectory_pose(0.0)[0]
        self._approach_from: np.ndarray | None = None   # pose the approach starts at (trajectory time −T)
        self._approach_delta = np.zeros(6)               # start pose − _approach_from
        self.approach_time = 0.0
        self._last: Command | None = None
        self.ik_failures = 0

    # -- approach ------------------------------------------------------------------------------------------------
    def approach_from(self, pose_now: np.ndarray, speed: float, tolerance: float = 0.02) -> float:
        """Start with a slow move from the measured pose `pose_now` to the trajectory's start pose; returns its
        duration T (s), 0 when the largest arm-angle difference is below `tolerance` (rad).

        The plate pose follows p_now + s(u)·(p_0 − p_now) with a smoothstep s over T = 1.5·max|dζ/ds| / speed (the
        smoothstep's peak rate is 1.5/T; the slope dζ/ds of every arm along the line is taken from 64 chords, as IK
        is not linear), so no arm exceeds `speed` (rad/s), and the move starts and ends at rest. Trajectory time 0
        is shifted by T: the trajectory (and its `start_blend`) starts when the approach ends. Call it before the
        first command.

        Raises:
            TrajectoryPlayerError: called after the first command, or speed not > 0.
            hexa.kinematics.hexa6rus.UnreachablePoseError: `pose_now` has no IK solution.
        """
        if self._last is not None:
            raise TrajectoryPlayerError("approach_from must come before the first command")
        if not (speed > 0 and np.isfinite(speed)):
            raise TrajectoryPlayerError(f"approach speed must be > 0 rad/s, got {speed}")
        pose_now = np.asarray(pose_now, dtype=float).reshape(6)
        delta = self._trajectory_pose(0.0)[0] - pose_now
        # the arms along the straight pose line, 64 chords (IK is not linear): their largest rate per unit of path
        s = np.linspace(0.0, 1.0, 65)
        zs = np.array([self._ik(self.desc, pose_now + v * delta) for v in s])
        if float(np.max(np.abs(zs[-1] - zs[0]))) < tolerance:
            return 0.0
        slope = float(np.max(np.abs(np.diff(zs, axis=0)))) * (len(s) - 1)
        self.approach_time = 1.5 * slope / float(speed)
        self._approach_from, self._approach_delta = pose_now, delta
        self._offset += self.approach_time
        return self.approach_time

    # -- events --------------------------------------------------------------------------------------------------
    def on_collision(self, t: float, external_force: np.ndarray | None = None) -> str:
        """React to a collision START at time t; returns the new state."""
        if self.policy == "ignore" or self._held_since is not None:
            return self.state_at(t)
        self._held_since = t
        self._hold_pose = None if self._last is None else self._last.pose.copy()
        f = np.zeros(3) if external_force is None else np.asarray(external_force, dtype=float)[:3]
        norm = float(np.linalg.norm(f))
        self._retract_dir = f / norm if (self.policy == "retract" and norm > 1e-9) else np.zeros(3)
        return "retracting" if self._retract_dir.any() else "held"

    def resume(self, t: float) -> bool:
        """Resume after a hold: blend back onto the trajectory over `retract_time`. False if not held."""
        if self._held_since is None:
            return False
        self._offset += t - self._held_since
        self._resume_from = None if self._last is None else self._last.pose.copy()
        self._resume_at = t - self._offset  # trajectory time at which the blend starts
        self._blend_time, self._starting = self.retract_time, False
        self._held_since = None
        return True

    def state_at(self, t: float) -> str:
        return self._last.state if self._last is not None else "running"

    # -- sampling ------------------------------------------------------------------------------------------------
    def _trajectory_pose(self, tt: float) -> tuple[np.ndarray, np.ndarray]:
        if self.loop and tt >= self.duration:
            x = tt % self.duration
            pose, pose_dot = self._raw_pose(x)
            if x < self.loop_blend:  # cross-fade from the previous cycle continued past its end
                pose, pose_dot = cross_fade(self._raw_pose(x + self.duration), (pose, pose_dot), x, self.loop_blend)
            return pose, pose_dot
        pose, pose_dot = self._raw_pose(min(max(tt, 0.0), self.duration))
        return pose, (pose_dot if tt <= self.duration else np.zeros(6))   # finished: held at rest

    def _raw_pose(self, tt: float) -> tuple[np.ndarray, np.ndarray]:
        pose, pose_dot, _ = self.trajectory(tt)
        return np.asarray(pose, dtype=float), np.asarray(pose_dot, dtype=float)

    def _approach_pose(self, tt: float) -> tuple[np.ndarray, np.ndarray]:
        u = (tt + self.approach_time) / self.approach_time
        start = self._approach_from
        assert start is not None, "an approach is planned before its poses are asked for"
        return (start + smoothstep(u) * self._approach_delta,
                smoothstep_rate(u, self.approach_time) * self._approach_delta)

    def command(self, t: float) -> Command:
        """The command at time t (s, sim or wall clock, monotonic).

        Raises:
            hexa.kinematics.hexa6rus.UnreachablePoseError: the pose cannot be reached (counted in ik_failures;
                the previous command is then the caller's to keep).
        """
        gap = t - self._last_t
        self._last_t = max(self._last_t, t)
        if self.max_step is not None and gap > self.max_step and self._held_since is None:
            self._offset += gap - self.max_step   # pause the trajectory for the time the caller was late
            self.lag_events += 1
            self.lag_time += gap - self.max_step
        if self._held_since is not None:
            base = self._hold_pose if self._hold_pose is not None else self._trajectory_pose(self._held_since
                                                                                            - self._offset)[0]
            s = smoothstep((t - self._held_since) / self.retract_time)
            pose = base.copy()
            pose[:3] += self._retract_dir * self.retract_distance * s
            state = "retracting" if self._retract_dir.any() and s < 1.0 else "held"
            pose_dot = np.zeros(6)
            tt = self._held_since - self._offset
        else:
            tt = t - self._offset
            if self._approach_from is not None and tt < 0.0:   # approach: trajectory time −T..0
                pose, pose_dot = self._approach_pose(tt)
                state = "approaching"
            else:
                pose, pose_dot = self._trajectory_pose(tt)
                state = "finished" if (not self.loop and tt >= self.duration) else "running"
            if self._resume_at is not None and self._resume_from is not None and tt >= self._resume_at:
                u = (tt - self._resume_at) / self._blend_time
                s = smoothstep(u)
                if s < 1.0:
                    ds = smoothstep_rate(u, self._blend_time)
                    pose_dot = ds * (pose - self._resume_from) + s * pose_dot
                    pose = self._resume_from + (pose - self._resume_from) * s
                    state = state if self._starting else "resuming"
                else:
                    self._resume_at, self._starting = None, False
        try:
            zeta = np.asarray(self._ik(self.desc, pose), dtype=float)
            zeta_dot = self._ik_rates(self.desc, pose, pose_dot, np.zeros(6), check=False)[1]
        except Exception:
            self.ik_failures += 1
            raise
        self._last = Command(zeta, zeta_dot, pose, state, tt)
        return self._last
