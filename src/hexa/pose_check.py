"""Plate pose validation, shared by every node that takes a measured plate pose (observer, rnea, isolation,
singularity): a pose is used only if it is a pose at all, one the robot can take, and one it can have reached from the
last accepted pose in the time between.

Checks, in order, each counted by its reason in `PoseCheck.rejected`:
- `bad_shape`, `non_finite`: three position and four quaternion components (or six pose values), all finite;
- `non_unit_quaternion`: |q| differs from 1 by more than `quaternion_tolerance` — a quaternion such as (0, 0, 0, 2)
  is not a rotation; normalising it would silently turn a corrupt message into a pose;
- `off_workspace`: outside the robot's workspace (for the Hexa: inverse kinematics, seed 000 eqs 14-18, finds no
  reachable arm angles — a plate 10 m away, or one past a joint limit);
- `time_past`, `time_future`, `jump`: against the last accepted pose (hexa.stream_gate.StreamGate): a stamp before
  it (an equal one passes), more than `max_step` s after it, or a move farther than the robot can go in the time between
  (|Δp| ≤ position_noise + max_speed·Δt, rotation angle ≤ angle_noise + max_angular_speed·Δt). A plate that really
  moved while it was not seen sends poses that agree with one another: after `adopt_after` of them the check adopts
  them.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from hexa.rotations import matrix_from_quaternion, transform_from_pose6
from hexa.stream_gate import ACCEPTED, StreamGate, time_step_rule

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from hexa.robots.hexa_description import HexaDescription


@dataclass(frozen=True)
class PoseLimits:
    """Bounds of PoseCheck (module docstring). Speeds in m/s and rad/s, noise in m and rad, times in s."""

    max_speed: float = 2.5
    max_angular_speed: float = 25.0
    position_noise: float = 0.01
    angle_noise: float = 0.05
    quaternion_tolerance: float = 0.01
    max_step: float = 2.0
    adopt_after: int = 3

    def __post_init__(self) -> None:
        for name in ("max_speed", "max_angular_speed", "position_noise", "angle_noise", "quaternion_tolerance",
                     "max_step"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"pose check {name} must be > 0, got {v!r}")
        if self.adopt_after < 1:
            raise ValueError(f"pose check adopt_after must be >= 1, got {self.adopt_after!r}")

    @classmethod
    def for_hexa(cls, desc: HexaDescription) -> "PoseLimits":
        """Speeds from the Hexa's servos: the plate moves no faster than twice an arm tip at full servo speed
        (2·l_a·ω_max, 2.5 m/s for the default description), and turns no faster than that over the plate radius."""
        v = 2.0 * float(desc.l_a) * float(desc.speed_max)
        return cls(max_speed=v, max_angular_speed=v / float(desc.plate_radius))


def rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """The angle (rad) of the rotation from Ra to Rb."""
    c = (float(np.trace(Ra.T @ Rb)) - 1.0) / 2.0
    return math.acos(min(1.0, max(-1.0, c)))


def hexa_reachable(desc: HexaDescription) -> Callable[[np.ndarray], bool]:
    """Whether the Hexa reaches a plate transform (4x4): its inverse kinematics has a solution within the limits."""
    from hexa.kinematics.hexa6rus import UnreachablePoseError, inverse_kinematics
    from hexa.rotations import pose6_from_transform

    def reachable(T: np.ndarray) -> bool:
        try:
            inverse_kinematics(desc, pose6_from_transform(T))
        except (UnreachablePoseError, ValueError):
            return False
        return True

    return reachable


class PoseCheck:
    """Accepts plate poses (stamp s, position m, unit quaternion x y z w or Z-Y-X angles rad) that pass the module's
    checks; returns them as 4x4 transforms, or None (counted in `rejected` by reason).

    Args:
        limits: the bounds (PoseLimits.for_hexa for the Hexa).
        reachable: reachable(T) is False for a pose off the workspace (hexa_reachable); None: no workspace check.
    """

    def __init__(self, limits: PoseLimits | None = None, reachable: Callable[[np.ndarray], bool] | None = None) -> None:
        self.limits = limits or PoseLimits()
        self.reachable = reachable
        self.rejected: Counter[str] = Counter()
        self.accepted = 0
        # equal stamps pass (a publisher that leaves the stamp 0): the move bound then allows only the noise
        self._time_rule = time_step_rule(self.limits.max_step, repeats=True)
        self.gate: StreamGate[tuple[float, np.ndarray]] = StreamGate(self._follows, self.limits.adopt_after)

    @classmethod
    def for_hexa(cls, desc: HexaDescription) -> "PoseCheck":
        """The Hexa's check: its speed bounds and inverse kinematics."""
        return cls(PoseLimits.for_hexa(desc), hexa_reachable(desc))

    def _follows(self, prev: tuple[float, np.ndarray], new: tuple[float, np.ndarray]) -> str | None:
        why = self._time_rule(prev[0], new[0])
        if why is not None:
            return why
        lim, dt = self.limits, new[0] - prev[0]
        Tp, Tn = prev[1], new[1]
        if float(np.linalg.norm(Tn[:3, 3] - Tp[:3, 3])) > lim.position_noise + lim.max_speed * dt:
            return "jump"
        if rotation_angle(Tp[:3, :3], Tn[:3, :3]) > lim.angle_noise + lim.max_angular_speed * dt:
            return "jump"
        return None

    def _reject(self, reason: str) -> None:
        self.rejected[reason] += 1

    def check(self, stamp: float, position: ArrayLike, quaternion: ArrayLike) -> np.ndarray | None:
        """A pose from a message: position (3,) and quaternion (x, y, z, w); its transform, or None when rejected."""
        try:
            p = np.asarray(position, dtype=float).reshape(-1)
            q = np.asarray(quaternion, dtype=float).reshape(-1)
            t = float(stamp)
        except (TypeError, ValueError):
            self._reject("bad_shape")
            return None
        if p.shape != (3,) or q.shape != (4,):
            self._reject("bad_shape")
            return None
        if not (math.isfinite(t) and np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
            self._reject("non_finite")
            return None
        if abs(float(np.linalg.norm(q)) - 1.0) > self.limits.quaternion_tolerance:
            self._reject("non_unit_quaternion")
            return None
        T = np.eye(4)
        T[:3, :3] = matrix_from_quaternion(*q.tolist())
        T[:3, 3] = p
        return self._check_transform(t, T)

    def check_pose6(self, stamp: float, pose: ArrayLike) -> np.ndarray | None:
        """A pose as [x y z α β γ] (m, rad; Z-Y-X, seed 000 eq 38); its transform, or None when rejected."""
        try:
            x = np.asarray(pose, dtype=float).reshape(-1)
            t = float(stamp)
        except (TypeError, ValueError):
            self._reject("bad_shape")
            return None
        if x.shape != (6,):
            self._reject("bad_shape")
            return None
        if not (math.isfinite(t) and np.all(np.isfinite(x))):
            self._reject("non_finite")
            return None
        return self._check_transform(t, transform_from_pose6(x))

    def _check_transform(self, t: float, T: np.ndarray) -> np.ndarray | None:
        if self.reachable is not None and not self.reachable(T):
            self._reject("off_workspace")
            return None
        verdict = self.gate.check((t, T))
        if verdict not in ACCEPTED:
            self._reject(verdict)
            return None
        self.accepted += 1
        return T

    def counters(self, prefix: str = "reject_pose_") -> dict[str, int]:
        """Rejects by reason, keyed for /diagnostics."""
        return {f"{prefix}{k}": v for k, v in self.rejected.items()}
