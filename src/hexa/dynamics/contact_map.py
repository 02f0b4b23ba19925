"""The plate-equivalent wrench of a contact force anywhere on the Hexa — what the residual observer estimates.

The observer works on the reduced model in plate twist coordinates V = (v_P, ω) (seed 000 eq 23; moment about the
plate centre P, all in `base`), so an external force F at a material point D of any link enters it as the generalized
force W = J_Dᵀ F, with J_D = ∂v_D/∂V the velocity of that point per plate twist (principle of virtual work). A force
on the plate gives W = (F, (D − P) × F); a force on an arm or a rod gives only what the mechanism passes to the plate
coordinates, which is why those contacts reach the residual thresholds later than the force itself does.

J_D is formed by central differences of the point's position over the six twist directions, the arm angles following
by inverse kinematics (eq 17). The point is carried as a material point of its link: plate frame for the plate, arm
frame (eq 10) for an arm, rod frame (eq 13) for a rod.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from hexa.dynamics._kernel import exp_rotate
from hexa.kinematics import hexa6rus

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from hexa.robots.hexa_description import HexaDescription

LINK_CODES = {0: "plate", 1: "arm", 2: "rod"}


def _link_frame(desc: "HexaDescription", pose: NDArray, zeta: NDArray, link: str, chain: int
                ) -> tuple[NDArray, NDArray]:
    """Origin (3,) and rotation (3, 3) of the link's body frame in `base`."""
    if link == "plate":
        return pose[:3], hexa6rus.rotation_zyx(*pose[3:])
    i = chain - 1
    if link == "arm":
        return desc.A[i], hexa6rus.arm_rotations(desc, zeta)[i]
    R_rod, _, _ = hexa6rus.rod_rotations(desc, pose, zeta)
    return hexa6rus.elbows(desc, zeta)[i], R_rod[i]


def _perturbed_pose(pose: NDArray, k: int, h: float) -> NDArray:
    """The pose moved by h along twist direction k (0..2: v_P along base x, y, z; 3..5: ω about base x, y, z)."""
    out = pose.copy()
    if k < 3:
        out[k] += h
        return out
    w = [0.0, 0.0, 0.0]
    w[k - 3] = h
    R0 = hexa6rus.rotation_zyx(*pose[3:]).ravel().tolist()
    R = np.array(exp_rotate(w[0], w[1], w[2], R0)).reshape(3, 3)   # exp([w]×)·R
    out[3:] = np.array(hexa6rus.rotation_to_zyx(R), dtype=float)
    return out


def contact_point_jacobian(desc: "HexaDescription", pose: NDArray, link: str, chain: int, point: NDArray,
                           h: float = 1e-6) -> NDArray:
    """J_D (3, 6): velocity of the material point at `point` (base, m) of `link` (chain 1..6; any for the plate) per
    plate twist (v_P, ω).

    Raises:
        ValueError: unknown link or chain; hexa6rus.UnreachablePoseError: the pose (or a neighbour) has no IK.
    """
    if link not in ("plate", "arm", "rod"):
        raise ValueError(f"link must be plate, arm or rod, got {link!r}")
    if link != "plate" and not 1 <= int(chain) <= 6:
        raise ValueError(f"chain must be 1..6 for link {link!r}, got {chain!r}")
    pose = np.asarray(pose, dtype=float).reshape(6)
    o, R = _link_frame(desc, pose, hexa6rus.inverse_kinematics(desc, pose), link, int(chain))
    local = R.T @ (np.asarray(point, dtype=float).reshape(3) - o)
    J = np.zeros((3, 6))
    for k in range(6):
        ends = []
        for sgn in (1.0, -1.0):
            pk = _perturbed_pose(pose, k, sgn * h)
            ok, Rk = _link_frame(desc, pk, hexa6rus.inverse_kinematics(desc, pk), link, int(chain))
            ends.append(ok + Rk @ local)
        J[:, k] = (ends[0] - ends[1]) / (2.0 * h)
    return J


def plate_equivalent_wrench(desc: "HexaDescription", pose: NDArray, link: str, chain: int, point: NDArray,
                            force: NDArray) -> NDArray:
    """W = J_Dᵀ F (6,): the wrench [F, N_P] (N, N·m; base, moment about P) on the plate that does the same virtual
    work as the contact force `force` at `point` on `link` — the quantity the residual r converges to (seed 000
    eq 25 with eq 23's twist coordinates)."""
    return contact_point_jacobian(desc, pose, link, chain, point).T @ np.asarray(force, dtype=float).reshape(3)
