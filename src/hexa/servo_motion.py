"""The servo motion a plate trajectory asks of the Hexa: arm angles by inverse kinematics all along (seed 000 eqs
14–18, with the serial-singularity margin and the joint range), their rates ζ̇ = J_ζ V and ζ̈ = J_ζ V̇ + J̇_ζ V, the
nominal model's free-motion servo torques (eqs 21–22), and the peaks of the three to hold against the servos'
limits. Shared by the calibration's excitation design and the random trajectories of the evaluation campaign.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from hexa.dynamics.lagrange import HexaDynamicParameters, MotionState
    from hexa.robots.hexa_description import HexaDescription


def twist_rate(pose: NDArray, vel: NDArray, acc: NDArray) -> NDArray:
    """V̇ = [p̈, ω̇] (…, 6) from the Z-Y-X pose (eq 38) and its first and second time derivatives."""
    from hexa.kinematics import hexa6rus as kin

    out = np.empty_like(acc)
    out[..., :3] = acc[..., :3]
    out[..., 3:] = kin.angular_acceleration_zyx(pose[..., 3:], vel[..., 3:], acc[..., 3:])
    return out


def servo_motion(desc: HexaDescription, pose: NDArray, vel: NDArray, acc: NDArray,
                 prm: HexaDynamicParameters | None = None) -> MotionState:
    """The arms' motion (ζ, ζ̇, ζ̈) and the plate's (p, R, V, V̇) along poses (N, 6) and their time derivatives.

    Raises:
        hexa.kinematics.hexa6rus.UnreachablePoseError: a pose without arm angles (naming it and the chain).
    """
    from hexa.dynamics.lagrange import HexaDynamicParameters, motion_from_plate
    from hexa.kinematics import hexa6rus as kin

    prm = prm or HexaDynamicParameters.from_description(desc)
    zeta = kin.inverse_kinematics_batch(desc, pose)
    return motion_from_plate(prm, zeta, pose, kin.twist_from_pose_rate(pose, vel), twist_rate(pose, vel, acc))


@dataclass(frozen=True)
class MotionPeaks:
    """Largest |ζ̇| (rad/s), |ζ̈| (rad/s²) and nominal-model free-motion |τ| (N·m) over every servo and sample;
    `unreachable` says why a pose has no arm angles ("" when all have)."""

    speed: float
    accel: float
    torque: float
    unreachable: str = ""

    @property
    def reachable(self) -> bool:
        return not self.unreachable

    def as_dict(self) -> dict[str, Any]:
        return {"peak_zeta_dot": self.speed, "peak_zeta_ddot": self.accel, "peak_torque": self.torque,
                "reachable": self.reachable}


def motion_peaks(desc: HexaDescription, pose: NDArray, vel: NDArray, acc: NDArray,
                 prm: HexaDynamicParameters | None = None) -> MotionPeaks:
    """The peaks of `servo_motion` along poses (N, 6); an unreachable pose gives infinite peaks and its reason.
    A pose near a type II singularity (J_ζᵀ singular) gives an infinite torque."""
    from hexa.calibration.regressor import free_motion_torques
    from hexa.dynamics.lagrange import HexaDynamicParameters

    prm = prm or HexaDynamicParameters.from_description(desc)
    try:
        state = servo_motion(desc, pose, vel, acc, prm)
    except ValueError as exc:    # UnreachablePoseError, KinematicsError
        return MotionPeaks(np.inf, np.inf, np.inf, str(exc))
    assert state.zeta_ddot is not None    # given V̇, motion_from_plate sets ζ̈
    try:
        torque = float(np.abs(free_motion_torques(prm, state)).max())
    except np.linalg.LinAlgError:
        torque = np.inf
    return MotionPeaks(float(np.abs(state.zeta_dot).max()), float(np.abs(state.zeta_ddot).max()),
                       torque if np.isfinite(torque) else np.inf)
