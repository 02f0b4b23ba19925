"""The outer loop of the hybrid controller (seed 003 sec 2.5): Algorithm 1 once per sample t_s against the measured
pose X_c, with the reference it follows and the enable pin."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexa.srm.algorithm import SingularityReleaseModule

if TYPE_CHECKING:
    from hexa.robots.upsrpu_description import UpsrpuDescription


@dataclass(frozen=True)
class LoopStep:
    """One sample: the commanded lengths q_ind^d, the reference q_ind^r (m), and whether the enable pin was set
    automatically at this sample."""

    q_d: np.ndarray
    q_r: np.ndarray
    auto_enabled: bool = False


class ReleaseLoop:
    """Algorithm 1 per sample against the newest measured pose X_c.

    The reference is a Cartesian path at t_s (`reference_path`), played from the first measured pose on, one point
    per sample and then held at its end; without one, the first measured pose is held. A pose older than
    `pose_timeout` clears the pin for the sample, so Δ freezes instead of being updated from a stale X_c.

    Args:
        desc: the 3UPS+RPU description.
        variant: SRM variant, 1 or 2.
        reference: (N, 4) Cartesian reference at t_s, or None (hold the first measured pose).
        enabled: the initial enable pin.
        auto_enable_after: set the pin this many seconds after the reference ends (< 0: only through `enable`).
        pose_timeout: largest age (s) of X_c that still counts as fresh.

    Raises:
        hexa.srm.SrmError: a variant other than 1 or 2.
    """

    def __init__(self, desc: UpsrpuDescription, variant: int = 1, reference: np.ndarray | None = None,
                 enabled: bool = False, auto_enable_after: float = -1.0, pose_timeout: float = 0.1) -> None:
        self.desc = desc
        self.srm = SingularityReleaseModule(desc, variant)
        self.reference = None if reference is None else np.asarray(reference, dtype=float)
        self._hold_first = reference is None
        self.enabled = enabled
        self.auto_enable_after = auto_enable_after
        self.pose_timeout = pose_timeout
        self.X_c: np.ndarray | None = None
        self.X_c_time = 0.0
        self.index = 0
        self.ticks_at_end = 0
        self.rejected = 0
        self.steps_active = 0

    def set_pose(self, X: np.ndarray, now: float) -> bool:
        """Take a measured pose X_c at time `now` (s, any monotonic clock); False (counted) when not finite."""
        X = np.asarray(X, dtype=float)
        if not np.all(np.isfinite(X)):
            self.rejected += 1
            return False
        self.X_c, self.X_c_time = X, now
        if self.reference is None and self._hold_first:
            self.reference = X[None].copy()
        return True

    def fresh(self, now: float) -> bool:
        """True when a pose at most `pose_timeout` old has arrived."""
        return self.X_c is not None and now - self.X_c_time <= self.pose_timeout

    def enable(self, enable: bool, variant: int = 0) -> tuple[bool, str]:
        """Set the enable pin and (1 or 2; 0 keeps it) the variant; (success, message)."""
        if variant not in (0, 1, 2):
            return False, f"variant must be 0 (keep), 1 or 2, got {variant}"
        if variant:
            self.srm.variant = int(variant)
        self.enabled = bool(enable)
        return True, f"SRM-V{self.srm.variant} {'enabled' if self.enabled else 'disabled'}"

    def step(self, now: float) -> LoopStep | None:
        """One sample at time `now`: the next reference point, its IK, Algorithm 1 at X_c; None before the first
        measured pose."""
        from hexa.kinematics.upsrpu import inverse_kinematics
        from hexa.singularity import upsrpu_indices

        if self.X_c is None or self.reference is None:
            return None
        X_r = self.reference[min(self.index, len(self.reference) - 1)]
        auto = False
        if self.index < len(self.reference) - 1:
            self.index += 1
        else:
            self.ticks_at_end += 1
            if 0 <= self.auto_enable_after <= self.ticks_at_end * self.desc.t_s and not self.enabled:
                self.enabled = auto = True
        q_r = inverse_kinematics(self.desc, X_r)
        q_d = self.srm.step(q_r, self.X_c, self.enabled and self.fresh(now), upsrpu_indices(self.desc, self.X_c))
        if self.srm.last.active:
            self.steps_active += 1
        return LoopStep(q_d, q_r, auto)
