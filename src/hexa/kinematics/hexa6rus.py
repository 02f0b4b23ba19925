"""Hexa (6-RUS) kinematics after seed 000 §2.1–2.2: rotations, closed-form IK, Newton–Raphson FK, Jacobians.

Conventions (SI units, frames of the paper):
- Pose = [x, y, z, alpha, beta, gamma]: position of P in {O} and Z-Y-X Tait–Bryan angles of eq 38,
  R = Rz(alpha)·Ry(beta)·Rx(gamma). The paper's Z-Y-Z Euler angles (phi, theta, psi) of eq 1 are available through
  `zyx_to_zyz` / `zyz_to_zyx` (robust at theta = 0, the home orientation).
- Arm direction (first column of eq 10): u_i(ζ) = (−cos α_i cos ζ, −sin α_i cos ζ, sin ζ); B_i = A_i + l_a·u_i.
  ζ = 0 is the arm horizontal pointing towards the base axis; in the default geometry the arms hang outward and down
  (ζ ≈ −148.5° at home).
- IK (eqs 14–18, eq 15 as restored in DESIGN.md): b_i cos ζ_i + c_i sin ζ_i = a_i with a_i, b_i, c_i of eq 17, solved
  by ζ_i = atan2(c_i, b_i) + branch·acos(a_i / √(b_i² + c_i²)) and reported in [ζ_c − π, ζ_c + π), ζ_c the middle of
  the joint range.
- Twist t = (v_P, ω) in {O} (velocity of the plate centre P and angular velocity). Constraint Jacobians:
  J_D·t = J_I·ζ̇ with J_D rows [n_i, r_i × n_i] (n_i unit rod direction B_i→C_i, r_i = R·c_i) and
  J_I = diag(l_a n_i·∂u_i/∂ζ_i). Type II (parallel) singularity: det J_D = 0; type I (serial): a J_I entry = 0.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

TWO_PI = 2.0 * math.pi


class KinematicsError(ValueError):
    """Base error of the Hexa kinematics."""


class UnreachablePoseError(KinematicsError):
    """A pose has no inverse-kinematics solution: the chain, the reason and (batch) the pose index are named."""

    def __init__(self, message: str, chain: int, reason: str, pose_index: int | None = None) -> None:
        super().__init__(message)
        self.chain = chain
        self.reason = reason
        self.pose_index = pose_index


class ForwardKinematicsError(KinematicsError):
    """Newton–Raphson did not converge (singular Jacobian or no assembly near the guess)."""


# --------------------------------------------------------------------------------------------------- rotations
def rotation_zyx(alpha: float | np.ndarray, beta: float | np.ndarray, gamma: float | np.ndarray) -> np.ndarray:
    """Rotation Rz(α)·Ry(β)·Rx(γ) of the Z-Y-X Tait–Bryan angles (seed 000, eq 38); broadcasts to (…, 3, 3).

    The seed's printed entry R23 has a sign slip ("+ cos α sin γ"); this is the proper rotation, R23 = sα sβ cγ − cα sγ.

    >>> np.round(rotation_zyx(np.pi / 2, 0.0, 0.0) @ [1.0, 0.0, 0.0], 12)
    array([0., 1., 0.])
    """
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    cg, sg = np.cos(gamma), np.sin(gamma)
    return np.stack([
        np.stack([ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg], -1),
        np.stack([sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg], -1),
        np.stack([-sb, cb * sg, cb * cg], -1),
    ], -2)


def rotation_zyz(phi: float | np.ndarray, theta: float | np.ndarray, psi: float | np.ndarray) -> np.ndarray:
    """Rotation R_P^O = Rz(φ)·Ry(θ)·Rz(ψ) of the intrinsic Z-Y-Z Euler angles (seed 000, eq 1); (…, 3, 3)."""
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    return np.stack([
        np.stack([cf * ct * cp - sf * sp, -cf * ct * sp - sf * cp, cf * st], -1),
        np.stack([sf * ct * cp + cf * sp, -sf * ct * sp + cf * cp, sf * st], -1),
        np.stack([-st * cp, st * sp, ct], -1),
    ], -2)


def rotation_to_zyz(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z-Y-Z angles (φ, θ ∈ [0, π], ψ) of rotation(s) R (…, 3, 3), inverse of eq 1.

    Robust at θ = 0: φ + ψ comes from (R21 − R12, R11 + R22) = (1 + cos θ)(sin, cos)(φ + ψ) and φ − ψ from
    (−(R21 + R12), R22 − R11) = (1 − cos θ)(sin, cos)(φ − ψ); at θ = 0 exactly the split is φ = ψ.
    """
    R = np.asarray(R, dtype=float)
    theta = np.arctan2(np.hypot(R[..., 0, 2], R[..., 1, 2]), R[..., 2, 2])
    s = np.arctan2(R[..., 1, 0] - R[..., 0, 1], R[..., 0, 0] + R[..., 1, 1])
    d = np.arctan2(-(R[..., 1, 0] + R[..., 0, 1]), R[..., 1, 1] - R[..., 0, 0])
    # Where θ ≈ π the sum is undefined; use the difference-only formulas there (R13, R23, R31, R32 are then ~0 too).
    phi = 0.5 * (s + d)
    psi = 0.5 * (s - d)
    # The half-angle split is defined modulo π; pick the representative consistent with R13, R23 when θ is not ~0.
    st = np.sin(theta)
    big = st > 1e-6
    phi_direct = np.arctan2(R[..., 1, 2], R[..., 0, 2])
    psi_direct = np.arctan2(R[..., 2, 1], -R[..., 2, 0])
    phi = np.where(big, phi_direct, _wrap_pi(phi))
    psi = np.where(big, psi_direct, _wrap_pi(psi))
    return phi, theta, psi


def rotation_to_zyx(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z-Y-X Tait–Bryan angles (α, β ∈ [−π/2, π/2], γ) of rotation(s) R (…, 3, 3), inverse of eq 38.

    Gimbal lock (β = ±π/2) is far outside the Hexa's workspace; there γ is set to 0.
    """
    R = np.asarray(R, dtype=float)
    beta = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 0, 0], R[..., 1, 0]))
    lock = np.hypot(R[..., 0, 0], R[..., 1, 0]) < 1e-12
    alpha = np.where(lock, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), np.arctan2(R[..., 1, 0], R[..., 0, 0]))
    gamma = np.where(lock, 0.0, np.arctan2(R[..., 2, 1], R[..., 2, 2]))
    return alpha, beta, gamma


def zyx_to_zyz(alpha: float | np.ndarray, beta: float | np.ndarray,
               gamma: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(α, β, γ) of eq 38 → (φ, θ, ψ) of eq 1 describing the same rotation (robust at θ = 0)."""
    return rotation_to_zyz(rotation_zyx(alpha, beta, gamma))


def zyz_to_zyx(phi: float | np.ndarray, theta: float | np.ndarray,
               psi: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(φ, θ, ψ) of eq 1 → (α, β, γ) of eq 38 describing the same rotation (any θ, including 0)."""
    return rotation_to_zyx(rotation_zyz(phi, theta, psi))


def _wrap_pi(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + math.pi) % TWO_PI - math.pi


# ------------------------------------------------------------------------------------------- angular velocity
def angular_velocity_zyz(angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """Plate angular velocity ω_P in {O} from Z-Y-Z angles (φ, θ, ψ) and their rates (seed 000, eq 3); (…, 3)."""
    angles, rates = np.asarray(angles, dtype=float), np.asarray(rates, dtype=float)
    phi, theta = angles[..., 0], angles[..., 1]
    dphi, dtheta, dpsi = rates[..., 0], rates[..., 1], rates[..., 2]
    return np.stack([dpsi * np.cos(phi) * np.sin(theta) - dtheta * np.sin(phi),
                     dpsi * np.sin(phi) * np.sin(theta) + dtheta * np.cos(phi),
                     dpsi * np.cos(theta) + dphi], -1)


def zyx_rate_matrix(alpha: float | np.ndarray, beta: float | np.ndarray) -> np.ndarray:
    """E(α, β) with ω = E·(α̇, β̇, γ̇) for R = Rz(α)Ry(β)Rx(γ) (eq 38); columns e_z, Rz(α)e_y, Rz(α)Ry(β)e_x."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    z, o = np.zeros_like(ca), np.ones_like(ca)
    return np.stack([np.stack([z, -sa, ca * cb], -1),
                     np.stack([z, ca, sa * cb], -1),
                     np.stack([o, z, -sb], -1)], -2)


def angular_velocity_zyx(angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """ω in {O} from Z-Y-X angles (α, β, γ) and rates (the eq 3 counterpart for eq 38, regular at home); (…, 3)."""
    angles, rates = np.asarray(angles, dtype=float), np.asarray(rates, dtype=float)
    return np.einsum("...ij,...j->...i", zyx_rate_matrix(angles[..., 0], angles[..., 1]), rates)


def angular_acceleration_zyx(angles: np.ndarray, rates: np.ndarray, accels: np.ndarray) -> np.ndarray:
    """ω̇ = E·(α̈, β̈, γ̈) + Ė·(α̇, β̇, γ̇) for Z-Y-X angles; (…, 3)."""
    angles, rates, accels = (np.asarray(v, dtype=float) for v in (angles, rates, accels))
    a, b = angles[..., 0], angles[..., 1]
    da, db, dg = rates[..., 0], rates[..., 1], rates[..., 2]
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    e_dot_r = np.stack([-ca * da * db + (-sa * da * cb - ca * sb * db) * dg,
                        -sa * da * db + (ca * da * cb - sa * sb * db) * dg,
                        -cb * db * dg], -1)
    return angular_velocity_zyx(angles, accels) + e_dot_r


def twist_from_pose_rate(pose: np.ndarray, pose_dot: np.ndarray) -> np.ndarray:
    """Plate twist (v_P, ω) in {O} from the pose (x y z α β γ) and its time derivative; (…, 6)."""
    pose, pose_dot = np.asarray(pose, dtype=float), np.asarray(pose_dot, dtype=float)
    return np.concatenate([pose_dot[..., :3], angular_velocity_zyx(pose[..., 3:], pose_dot[..., 3:])], -1)


def pose_rate_from_twist(pose: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """Pose derivative (ẋ ẏ ż α̇ β̇ γ̇) from the twist (v_P, ω) (singular only at β = ±π/2); (…, 6)."""
    pose, twist = np.asarray(pose, dtype=float), np.asarray(twist, dtype=float)
    E = zyx_rate_matrix(pose[..., 3], pose[..., 4])
    return np.concatenate([twist[..., :3], np.linalg.solve(E, twist[..., 3:, None])[..., 0]], -1)


# ------------------------------------------------------------------------------------------------ geometry
_CACHE: dict[int, tuple] = {}


def _consts(desc: "HexaDescription") -> tuple:
    """Per-description constants (cached by identity; the description is immutable)."""
    hit = _CACHE.get(id(desc))
    if hit is not None and hit[0] is desc:
        return hit
    ca, sa = np.cos(desc.alpha), np.sin(desc.alpha)
    Cp = np.ascontiguousarray(desc.C.T)  # (3, 6)
    entry = (desc, ca, sa, desc.A[:, 0].copy(), desc.A[:, 1].copy(), desc.A[:, 2].copy(), Cp[0].copy(),
             Cp[1].copy(), Cp[2].copy(), desc.l_d ** 2 - desc.l_a ** 2, 2.0 * desc.l_a, desc.zeta_center)
    if len(_CACHE) > 64:
        _CACHE.clear()
    _CACHE[id(desc)] = entry
    return entry


def plate_joints(desc: "HexaDescription", pose: np.ndarray) -> np.ndarray:
    """Spherical-joint centres C_i in {O}: r_P + R·c_i (seed 000, eq 14); pose (…, 6) → (…, 6, 3)."""
    pose = np.asarray(pose, dtype=float)
    R = rotation_zyx(pose[..., 3], pose[..., 4], pose[..., 5])
    return pose[..., None, :3] + np.einsum("...ij,kj->...ki", R, desc.C)


def arm_directions(desc: "HexaDescription", zeta: np.ndarray) -> np.ndarray:
    """Unit arm vectors u_i = (−cos α_i cos ζ_i, −sin α_i cos ζ_i, sin ζ_i), first column of eq 10; (…, 6, 3)."""
    zeta = np.asarray(zeta, dtype=float)
    cz, sz = np.cos(zeta), np.sin(zeta)
    return np.stack([-np.cos(desc.alpha) * cz, -np.sin(desc.alpha) * cz, sz], -1)


def elbows(desc: "HexaDescription", zeta: np.ndarray) -> np.ndarray:
    """Universal-joint centres B_i = A_i + l_a·u_i(ζ_i) in {O} (seed 000, eqs 10 and 14); (…, 6) → (…, 6, 3)."""
    return desc.A + desc.l_a * arm_directions(desc, zeta)


# ------------------------------------------------------------------------------------------ inverse kinematics
def ik_coefficients(desc: "HexaDescription", pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """a_i, b_i, c_i of seed 000 eq 17 (b_i cos ζ_i + c_i sin ζ_i = a_i, eq 15 restored); pose (…, 6) → 3 × (…, 6)."""
    d = desc.A - plate_joints(desc, pose)
    a = desc.l_d ** 2 - desc.l_a ** 2 - np.einsum("...k,...k->...", d, d)
    b = -2.0 * desc.l_a * (np.cos(desc.alpha) * d[..., 0] + np.sin(desc.alpha) * d[..., 1])
    c = 2.0 * desc.l_a * d[..., 2]
    return a, b, c


def _solve_eq18(desc: "HexaDescription", a: np.ndarray, b: np.ndarray, c: np.ndarray,
                zc: float) -> tuple[np.ndarray, np.ndarray]:
    r = np.hypot(b, c)
    ratio = a / r
    with np.errstate(invalid="ignore"):
        zeta = np.arctan2(c, b) + desc.branch * np.arccos(ratio)
    zeta = zc + (zeta - zc + math.pi) % TWO_PI - math.pi
    return zeta, ratio


def _check_ik(desc: "HexaDescription", zeta: np.ndarray, ratio: np.ndarray, index: int | None) -> None:
    """Raise UnreachablePoseError for the first chain out of reach / alignment margin / joint range."""
    where = "" if index is None else f" (pose {index})"
    for i in range(6):
        q = float(ratio[i])
        if not abs(q) <= 1.0:
            raise UnreachablePoseError(
                f"chain {i + 1} cannot close{where}: |a_{i + 1}| / sqrt(b² + c²) = {abs(q):.4f} > 1 "
                f"(rod too {'short' if q > 0 else 'long'} for the arm)", i + 1, "out_of_reach", index)
        if abs(q) > desc.max_alignment:
            raise UnreachablePoseError(
                f"chain {i + 1} near its serial singularity{where}: |a_{i + 1}| / sqrt(b² + c²) = {abs(q):.4f} "
                f"> max_alignment {desc.max_alignment}", i + 1, "alignment", index)
        z = float(zeta[i])
        if not desc.zeta_min <= z <= desc.zeta_max:
            raise UnreachablePoseError(
                f"chain {i + 1} outside its joint range{where}: zeta_{i + 1} = {math.degrees(z):.2f}° not in "
                f"[{math.degrees(desc.zeta_min):.2f}°, {math.degrees(desc.zeta_max):.2f}°]", i + 1, "joint_limit",
                index)


def inverse_kinematics(desc: "HexaDescription", pose: np.ndarray, check: bool = True) -> np.ndarray:
    """Arm angles ζ (6,) for pose [x, y, z, α, β, γ] (m, rad) in closed form (seed 000, eqs 14–18).

    Args:
        desc: the Hexa description.
        pose: position of P in {O} and Z-Y-X angles of eq 38.
        check: raise on unreachable poses (otherwise NaN / out-of-range angles are returned as computed).
    Returns:
        ζ_i = atan2(c_i, b_i) + branch·acos(a_i/√(b_i²+c_i²)), in [ζ_c − π, ζ_c + π).
    Raises:
        UnreachablePoseError: naming the chain and why (|a_i| > √(b_i²+c_i²), alignment margin, joint limit).
    """
    k = _consts(desc)
    x, y, z, al, be, ga = (float(v) for v in pose)
    ca, sa, cb, sb, cg, sg = math.cos(al), math.sin(al), math.cos(be), math.sin(be), math.cos(ga), math.sin(ga)
    cpx, cpy, cpz = k[6], k[7], k[8]
    # d = A − C, C = p + R c (eq 14)
    dx = k[3] - (x + ca * cb * cpx + (ca * sb * sg - sa * cg) * cpy + (ca * sb * cg + sa * sg) * cpz)
    dy = k[4] - (y + sa * cb * cpx + (sa * sb * sg + ca * cg) * cpy + (sa * sb * cg - ca * sg) * cpz)
    dz = k[5] - (z - sb * cpx + cb * sg * cpy + cb * cg * cpz)
    a = k[9] - (dx * dx + dy * dy + dz * dz)
    b = -k[10] * (k[1] * dx + k[2] * dy)
    c = k[10] * dz
    zeta, ratio = _solve_eq18(desc, a, b, c, k[11])
    if check:
        if not (np.all(np.abs(ratio) <= desc.max_alignment) and np.all(zeta >= desc.zeta_min)
                and np.all(zeta <= desc.zeta_max)):
            _check_ik(desc, zeta, ratio, None)
    return zeta


def inverse_kinematics_batch(desc: "HexaDescription", poses: np.ndarray, check: bool = True) -> np.ndarray:
    """ζ (N, 6) for poses (N, 6), vectorised eqs 14–18 (same branch and range as `inverse_kinematics`).

    Raises:
        UnreachablePoseError: naming the first bad pose index and chain when `check`; otherwise that row is NaN
            where |a_i| > √(b_i²+c_i²) and the other rows are returned unchecked.
    """
    k = _consts(desc)
    P = np.asarray(poses, dtype=float)
    if P.ndim != 2 or P.shape[1] != 6:
        raise KinematicsError(f"poses must have shape (N, 6), got {P.shape}")
    x, y, z = P[:, 0:1], P[:, 1:2], P[:, 2:3]
    ca, sa = np.cos(P[:, 3:4]), np.sin(P[:, 3:4])
    cb, sb = np.cos(P[:, 4:5]), np.sin(P[:, 4:5])
    cg, sg = np.cos(P[:, 5:6]), np.sin(P[:, 5:6])
    cpx, cpy, cpz = k[6], k[7], k[8]
    sbsg, sbcg = sb * sg, sb * cg
    dx = k[3] - x - (ca * cb) * cpx - (ca * sbsg - sa * cg) * cpy
    dy = k[4] - y - (sa * cb) * cpx - (sa * sbsg + ca * cg) * cpy
    dz = k[5] - z + sb * cpx - (cb * sg) * cpy
    if np.any(cpz):
        dx -= (ca * sbcg + sa * sg) * cpz
        dy -= (sa * sbcg - ca * sg) * cpz
        dz -= (cb * cg) * cpz
    a = k[9] - (dx * dx + dy * dy + dz * dz)
    b = -k[10] * (k[1] * dx + k[2] * dy)
    c = k[10] * dz
    zeta, ratio = _solve_eq18(desc, a, b, c, k[11])
    if check:
        bad = ~((np.abs(ratio) <= desc.max_alignment) & (zeta >= desc.zeta_min) & (zeta <= desc.zeta_max))
        if np.any(bad):
            n = int(np.argmax(bad.any(axis=1)))
            _check_ik(desc, zeta[n], ratio[n], n)
    return zeta


def inverse_kinematics_derivatives(desc: "HexaDescription", pose: np.ndarray, pose_dot: np.ndarray,
                                   pose_ddot: np.ndarray, check: bool = True
                                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ζ, ζ̇, ζ̈ (…, 6) along a trajectory from pose, pose rate and pose acceleration (…, 6) (eqs 15–18 differentiated).

    With f = b cos ζ + c sin ζ − a = 0: ζ̇ = (ȧ − ḃ cos ζ − ċ sin ζ)/(c cos ζ − b sin ζ) and
    ζ̈ = (ä − b̈ cos ζ − c̈ sin ζ − 2(ċ cos ζ − ḃ sin ζ)ζ̇ + (b cos ζ + c sin ζ)ζ̇²)/(c cos ζ − b sin ζ).
    """
    pose, pose_dot, pose_ddot = (np.asarray(v, dtype=float) for v in (pose, pose_dot, pose_ddot))
    flat = pose.reshape(-1, 6)
    zeta = inverse_kinematics_batch(desc, flat, check=check).reshape(pose.shape)
    R = rotation_zyx(pose[..., 3], pose[..., 4], pose[..., 5])
    r = np.einsum("...ij,kj->...ki", R, desc.C)                       # (…, 6, 3) R c_i
    w = angular_velocity_zyx(pose[..., 3:], pose_dot[..., 3:])[..., None, :]
    wd = angular_acceleration_zyx(pose[..., 3:], pose_dot[..., 3:], pose_ddot[..., 3:])[..., None, :]
    w_r = np.cross(w, r)
    d = desc.A - (pose[..., None, :3] + r)                               # A − C
    dd = -(pose_dot[..., None, :3] + w_r)                                # −Ċ
    ddd = -(pose_ddot[..., None, :3] + np.cross(wd, r) + np.cross(w, w_r))
    ca, sa, la2 = np.cos(desc.alpha), np.sin(desc.alpha), 2.0 * desc.l_a

    def bc(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return -la2 * (ca * v[..., 0] + sa * v[..., 1]), la2 * v[..., 2]

    a = desc.l_d ** 2 - desc.l_a ** 2 - np.sum(d * d, -1)
    b, c = bc(d)
    a1 = -2.0 * np.sum(d * dd, -1)
    b1, c1 = bc(dd)
    a2 = -2.0 * (np.sum(dd * dd, -1) + np.sum(d * ddd, -1))
    b2, c2 = bc(ddd)
    cz, sz = np.cos(zeta), np.sin(zeta)
    den = c * cz - b * sz
    zd = (a1 - b1 * cz - c1 * sz) / den
    zdd = (a2 - b2 * cz - c2 * sz - 2.0 * (c1 * cz - b1 * sz) * zd + (b * cz + c * sz) * zd ** 2) / den
    return zeta, zd, zdd


# ------------------------------------------------------------------------------------------ Jacobians, screws
def _rods(desc: "HexaDescription", pose: np.ndarray, zeta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r_i = R c_i, C_i, unit rod directions n_i = (C_i − B_i)/|C_i − B_i|), each (6, 3)."""
    pose = np.asarray(pose, dtype=float)
    R = rotation_zyx(pose[3], pose[4], pose[5])
    r = desc.C @ R.T
    Cb = pose[:3] + r
    n = Cb - elbows(desc, zeta)
    n /= np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
    return r, Cb, n


def constraint_jacobians(desc: "HexaDescription", pose: np.ndarray,
                         zeta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """J_D (6,6) and J_I (6,6, diagonal) of the loop closures |C_i − B_i| = l_d, with J_D·t = J_I·ζ̇.

    t = (v_P, ω) in {O}; row i of J_D is [n_i, r_i × n_i] (n_i unit rod direction, r_i = R c_i);
    J_I = diag(l_a n_i · ∂u_i/∂ζ_i), ∂u_i/∂ζ = (cos α_i sin ζ_i, sin α_i sin ζ_i, cos ζ_i) (eq 10 differentiated).
    """
    zeta = np.asarray(zeta, dtype=float)
    r, _, n = _rods(desc, pose, zeta)
    J_D = np.empty((6, 6))
    J_D[:, :3] = n
    J_D[:, 3] = r[:, 1] * n[:, 2] - r[:, 2] * n[:, 1]
    J_D[:, 4] = r[:, 2] * n[:, 0] - r[:, 0] * n[:, 2]
    J_D[:, 5] = r[:, 0] * n[:, 1] - r[:, 1] * n[:, 0]
    sz, cz = np.sin(zeta), np.cos(zeta)
    du = np.stack([np.cos(desc.alpha) * sz, np.sin(desc.alpha) * sz, cz], -1)
    J_I = np.diag(desc.l_a * np.einsum("ij,ij->i", n, du))
    return J_D, J_I


def pose_rate_matrix(pose: np.ndarray) -> np.ndarray:
    """T (6,6) with twist = T·pose_dot: blockdiag(I, E(α, β))."""
    T = np.eye(6)
    T[3:, 3:] = zyx_rate_matrix(float(pose[3]), float(pose[4]))
    return T


def plate_twist(desc: "HexaDescription", pose: np.ndarray, zeta: np.ndarray, zeta_dot: np.ndarray) -> np.ndarray:
    """Plate twist t = J_D⁻¹ J_I ζ̇ (v_P, ω in {O}) from arm rates (forward velocity kinematics).

    Raises:
        KinematicsError: J_D is singular (type II singularity).
    """
    J_D, J_I = constraint_jacobians(desc, pose, zeta)
    try:
        return np.linalg.solve(J_D, J_I @ np.asarray(zeta_dot, dtype=float))
    except np.linalg.LinAlgError as exc:
        raise KinematicsError(f"J_D is singular at pose {np.asarray(pose).tolist()} (type II singularity)") from exc


def arm_rates(desc: "HexaDescription", pose: np.ndarray, zeta: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """Arm rates ζ̇ = J_I⁻¹ J_D t from the plate twist (v_P, ω) (inverse velocity kinematics)."""
    J_D, J_I = constraint_jacobians(desc, pose, zeta)
    return (J_D @ np.asarray(twist, dtype=float)) / np.diag(J_I)


def rod_wrench_screws(desc: "HexaDescription", pose: np.ndarray, zeta: np.ndarray | None = None) -> np.ndarray:
    """Transmission wrench screws (6,6): unit force along each rod B_i→C_i through C_i; rows [n_i, C_i × n_i].

    The moment is about the base origin O (seed 003 §2.3 applied to the Hexa as in DESIGN.md).
    """
    pose = np.asarray(pose, dtype=float)
    if zeta is None:
        zeta = inverse_kinematics(desc, pose)
    _, Cb, n = _rods(desc, pose, zeta)
    return np.concatenate([n, np.cross(Cb, n)], 1)


# ----------------------------------------------------------------------------------------- forward kinematics
def loop_closure_residual(desc: "HexaDescription", pose: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Φ_i = (|C_i − B_i|² − l_d²)/(2 l_d) (≈ rod length error, m); zero when pose and ζ are consistent."""
    d = plate_joints(desc, pose) - elbows(desc, zeta)
    return (np.einsum("...ij,...ij->...i", d, d) - desc.l_d ** 2) / (2.0 * desc.l_d)


def forward_kinematics(desc: "HexaDescription", zeta: np.ndarray, guess: np.ndarray | None = None,
                       tol: float = 1e-10, max_iter: int = 50) -> np.ndarray:
    """Pose [x y z α β γ] for arm angles ζ by damped Newton–Raphson on the loop closures (seed 000 §2.2.2).

    Iterates Δx = −(∂Φ/∂x)⁻¹Φ with ∂Φ/∂x = J_D(x)·T(x) (rod lengths Φ of `loop_closure_residual`), halving the
    step while it does not reduce |Φ|, until the step is below `tol` (m, rad) — then |Φ| is at round-off level.

    Args:
        guess: starting pose (default the home pose); pass the last solution to warm-start.
    Raises:
        ForwardKinematicsError: no convergence in `max_iter` steps or a singular Jacobian.
    """
    zeta = np.asarray(zeta, dtype=float)
    x = np.array(desc.home_pose if guess is None else guess, dtype=float)
    B = elbows(desc, zeta)
    Cp = desc.C
    l_d, inv2l = desc.l_d, 0.5 / desc.l_d
    J = np.empty((6, 6))

    def residual(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        ca, sa, cb, sb = math.cos(p[3]), math.sin(p[3]), math.cos(p[4]), math.sin(p[4])
        cg, sg = math.cos(p[5]), math.sin(p[5])
        R = np.array([[ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg],
                      [sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg],
                      [-sb, cb * sg, cb * cg]])
        r = Cp @ R.T
        n = p[:3] + r - B
        phi = (np.einsum("ij,ij->i", n, n) - l_d * l_d) * inv2l
        E = np.array([[0.0, -sa, ca * cb], [0.0, ca, sa * cb], [1.0, 0.0, -sb]])
        return r, n, phi, float(np.dot(phi, phi))

    r, n, phi, f = residual(x)
    for _ in range(max_iter):
        ca, sa, cb, sb = math.cos(x[3]), math.sin(x[3]), math.cos(x[4]), math.sin(x[4])
        E = np.array([[0.0, -sa, ca * cb], [0.0, ca, sa * cb], [1.0, 0.0, -sb]])
        J[:, :3] = n
        rxn = np.empty((6, 3))
        rxn[:, 0] = r[:, 1] * n[:, 2] - r[:, 2] * n[:, 1]
        rxn[:, 1] = r[:, 2] * n[:, 0] - r[:, 0] * n[:, 2]
        rxn[:, 2] = r[:, 0] * n[:, 1] - r[:, 1] * n[:, 0]
        J[:, 3:] = rxn @ E
        J *= 1.0 / l_d
        try:
            dx = np.linalg.solve(J, -phi)
        except np.linalg.LinAlgError as exc:
            raise ForwardKinematicsError(f"singular loop-closure Jacobian at pose {x.tolist()}") from exc
        step = 1.0
        for _halving in range(30):
            xn = x + step * dx
            rn, nn, phin, fn = residual(xn)
            if fn < f or fn < 1e-28:
                break
            step *= 0.5
        else:
            raise ForwardKinematicsError(f"Newton–Raphson stalled at pose {x.tolist()} for zeta {zeta.tolist()}")
        x, r, n, phi, f = xn, rn, nn, phin, fn
        if step == 1.0 and float(np.max(np.abs(dx))) < tol:
            return x
    raise ForwardKinematicsError(
        f"forward kinematics did not converge in {max_iter} steps for zeta {zeta.tolist()} (residual {math.sqrt(f):.3g} m)")


class ForwardKinematicsSolver:
    """Stateful FK: each solve is warm-started from the previous solution (the home pose at first)."""

    def __init__(self, desc: "HexaDescription", tol: float = 1e-10) -> None:
        self.desc = desc
        self.tol = tol
        self.last = np.array(desc.home_pose, dtype=float)

    def solve(self, zeta: np.ndarray) -> np.ndarray:
        """Pose for `zeta`, starting from the last solution; on failure retries from home once."""
        try:
            pose = forward_kinematics(self.desc, zeta, self.last, self.tol)
        except ForwardKinematicsError:
            pose = forward_kinematics(self.desc, zeta, self.desc.home_pose, self.tol)
        self.last = pose
        return pose.copy()


def _default_home() -> np.ndarray:
    try:
        from hexa.robots.hexa_description import load_hexa

        return np.array(load_hexa().home_pose)
    except Exception:  # noqa: BLE001 - only a convenience constant; load_hexa reports errors itself
        return np.array([0.0, 0.0, -0.55, 0.0, 0.0, 0.0])


#: Home pose of the default description (src/hexa/robots/hexa.yaml), x y z α β γ (m, rad).
HOME_POSE = _default_home()
HOME_POSE.setflags(write=False)
