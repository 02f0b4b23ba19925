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

    Robust at θ = 0: the sum φ + ψ comes from (R21 − R12, R11 + R22) = (1 + cos θ)(sin, cos)(φ + ψ), which is
    well conditioned for θ < π/2; φ = atan2(R23, R13) as long as that direction is defined (else φ = ψ at θ = 0),
    and ψ = (φ + ψ) − φ. For θ > π/2 the difference φ − ψ from (−(R21 + R12), R22 − R11) = (1 − cos θ)(sin, cos)(φ − ψ)
    is used with ψ = atan2(R32, −R31). The returned angles always rebuild R to round-off.
    """
    R = np.asarray(R, dtype=float)
    r13, r23 = R[..., 0, 2], R[..., 1, 2]
    theta = np.arctan2(np.hypot(r13, r23), R[..., 2, 2])
    s = np.arctan2(R[..., 1, 0] - R[..., 0, 1], R[..., 0, 0] + R[..., 1, 1])
    d = np.arctan2(-(R[..., 1, 0] + R[..., 0, 1]), R[..., 1, 1] - R[..., 0, 0])
    defined = (r13 != 0.0) | (r23 != 0.0)
    phi_low = np.where(defined, np.arctan2(r23, r13), 0.5 * s)
    psi_low = s - phi_low
    psi_high = np.arctan2(R[..., 2, 1], -R[..., 2, 0])
    phi_high = d + psi_high
    low = theta <= 0.5 * math.pi
    return _wrap_pi(np.where(low, phi_low, phi_high)), theta, _wrap_pi(np.where(low, psi_low, psi_high))


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
             Cp[1].copy(), Cp[2].copy(), desc.l_d ** 2 - desc.l_a ** 2, 2.0 * desc.l_a, desc.zeta_center,
             tuple(tuple(float(v) for v in row) for row in np.column_stack([desc.A, desc.C, ca, sa])))
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


def arm_rotations(desc: "HexaDescription", zeta: np.ndarray) -> np.ndarray:
    """R_{A2i}^O = R_{Oi}^O R_{A1i}^{Oi} R_{A2i}^{A1i} of each arm frame (seed 000, eqs 4, 6, 7 → eq 10); (…, 6, 3, 3).

    Column 0 is the arm direction u_i, column 2 the motor axis (−sin α_i, cos α_i, 0).
    """
    zeta = np.asarray(zeta, dtype=float)
    ca, sa = np.cos(desc.alpha), np.sin(desc.alpha)
    cz, sz = np.cos(zeta), np.sin(zeta)
    z = np.zeros_like(cz)
    return np.stack([np.stack([-ca * cz, ca * sz, -sa + z], -1),
                     np.stack([-sa * cz, sa * sz, ca + z], -1),
                     np.stack([sz, cz, z], -1)], -2)


def rod_rotations(desc: "HexaDescription", pose: np.ndarray,
                  zeta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rod frames R_{B2i}^O (6, 3, 3) and universal-joint angles β_i, γ_i (6,) (seed 000, eqs 9, 11–13).

    The first column of eq 11 is the unit rod direction n_i = (C_i − B_i)/|C_i − B_i|, so eq 12 gives
    γ_i = asin(R21 cos α_i − R11 sin α_i) and β_i = atan2(R31, −(R11 cos α_i + R21 sin α_i)) − ζ_i (the
    quadrant-safe form of eq 12, −π/2 < β_i + ζ_i < π/2); eq 13 then fills R_{B2i}^O, which equals
    R_{A2i}^O · R_{B1i}^{A2i} (eq 8, identity) · R_{B2i}^{B1i}(β_i, γ_i) (eq 9).
    """
    zeta = np.asarray(zeta, dtype=float)
    _, _, n = _rods(desc, pose, zeta)
    ca, sa = np.cos(desc.alpha), np.sin(desc.alpha)
    gamma = np.arcsin(np.clip(n[:, 1] * ca - n[:, 0] * sa, -1.0, 1.0))
    bz = np.arctan2(n[:, 2], -(n[:, 0] * ca + n[:, 1] * sa))
    cg, sg, c2, s2 = np.cos(gamma), np.sin(gamma), np.cos(bz), np.sin(bz)
    R = np.stack([np.stack([-sa * sg - ca * c2 * cg, -sa * cg + ca * c2 * sg, -ca * s2], -1),
                  np.stack([ca * sg - sa * c2 * cg, ca * cg + sa * c2 * sg, -sa * s2], -1),
                  np.stack([s2 * cg, -s2 * sg, -c2], -1)], -2)
    return R, _wrap_pi(bz - zeta), gamma


# ------------------------------------------------------------------------------------------ inverse kinematics
def ik_coefficients(desc: "HexaDescription", pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """a_i, b_i, c_i of seed 000 eq 17 (b_i cos ζ_i + c_i sin ζ_i = a_i, eq 15 restored); pose (…, 6) → 3 × (…, 6)."""
    d = desc.A - plate_joints(desc, pose)
    a = desc.l_d ** 2 - desc.l_a ** 2 - np.einsum("...k,...k->...", d, d)
    b = -2.0 * desc.l_a * (np.cos(desc.alpha) * d[..., 0] + np.sin(desc.alpha) * d[..., 1])
    c = 2.0 * desc.l_a * d[..., 2]
    return a, b, c


def _check_ik(desc: "HexaDescription", zeta: np.ndarray, ratio: np.ndarray, index: int | None) -> None:
    """Raise UnreachablePoseError for the first chain out of reach / alignment margin / joint range."""
    where = "" if index is None else f" (pose {index})"
    for i in range(6):
        q = float(ratio[i])
        if not abs(q) <= 1.0:
            raise UnreachablePoseError(
                f"chain {i + 1} cannot close{where}: |a_{i + 1}| / sqrt(b² + c²) = {abs(q):.4f} > 1 "
                f"(spherical joint C_{i + 1} too {'close to' if q > 0 else 'far from'} motor A_{i + 1} for arm + rod)",
                i + 1, "out_of_reach", index)
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

    Scalar code path (a few µs per chain); `inverse_kinematics_batch` is the vectorised twin.

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
    r00, r01, r02 = ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg
    r10, r11, r12 = sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg
    r20, r21, r22 = -sb, cb * sg, cb * cg
    L, la2, zc, br, lim = k[9], k[10], k[11], float(desc.branch), desc.max_alignment
    hi, lo = zc + math.pi, zc - math.pi
    zmin, zmax = desc.zeta_min, desc.zeta_max
    out = [0.0] * 6
    ok = True
    ratios = [0.0] * 6
    for i, (ax, ay, az, px, py, pz, c_, s_) in enumerate(k[12]):
        # d = A_i − C_i with C_i = r_P + R c_i (eq 14); a, b, c of eq 17
        dx = ax - x - r00 * px - r01 * py - r02 * pz
        dy = ay - y - r10 * px - r11 * py - r12 * pz
        dz = az - z - r20 * px - r21 * py - r22 * pz
        a = L - dx * dx - dy * dy - dz * dz
        b = -la2 * (c_ * dx + s_ * dy)
        c = la2 * dz
        q = a / math.hypot(b, c)
        ratios[i] = q
        if not -1.0 <= q <= 1.0:
            ok = False
            out[i] = math.nan
            continue
        zi = math.atan2(c, b) + br * math.acos(q)
        if zi >= hi:
            zi -= TWO_PI
        elif zi < lo:
            zi += TWO_PI
        out[i] = zi
        if not (-lim <= q <= lim and zmin <= zi <= zmax):
            ok = False
    zeta = np.array(out)
    if check and not ok:
        _check_ik(desc, zeta, np.array(ratios), None)
    return zeta


_CHUNK = 4096


def inverse_kinematics_batch(desc: "HexaDescription", poses: np.ndarray, check: bool = True) -> np.ndarray:
    """ζ (N, 6) for poses (N, 6), vectorised eqs 14–18 (same branch and range as `inverse_kinematics`).

    Works in cache-sized chunks without temporaries per pose.

    Raises:
        UnreachablePoseError: naming the first bad pose index and chain when `check`; otherwise rows with
            |a_i| > √(b_i²+c_i²) hold NaN and the others are returned unchecked.
    """
    k = _consts(desc)
    P = np.asarray(poses, dtype=float)
    if P.ndim != 2 or P.shape[1] != 6:
        raise KinematicsError(f"poses must have shape (N, 6), got {P.shape}")
    out = np.empty((len(P), 6))
    _ca, _sa, Ax, Ay, Az, cpx, cpy, cpz, L, la2, zc = k[1:12]
    bx, by = -la2 * _ca, -la2 * _sa
    has_z = bool(np.any(cpz))
    hi = zc + math.pi
    lo = zc - math.pi
    for s in range(0, len(P), _CHUNK):
        Q = P[s:s + _CHUNK]
        ca, sa, cb, sb = np.cos(Q[:, 3]), np.sin(Q[:, 3]), np.cos(Q[:, 4]), np.sin(Q[:, 4])
        cg, sg = np.cos(Q[:, 5]), np.sin(Q[:, 5])
        sbsg = sb * sg
        r00, r10, r20 = ca * cb, sa * cb, -sb
        r01, r11, r21 = ca * sbsg - sa * cg, sa * sbsg + ca * cg, cb * sg
        dx = np.subtract.outer(-Q[:, 0], -Ax)
        dx -= np.multiply.outer(r00, cpx)
        dx -= np.multiply.outer(r01, cpy)
        dy = np.subtract.outer(-Q[:, 1], -Ay)
        dy -= np.multiply.outer(r10, cpx)
        dy -= np.multiply.outer(r11, cpy)
        dz = np.subtract.outer(-Q[:, 2], -Az)
        dz -= np.multiply.outer(r20, cpx)
        dz -= np.multiply.outer(r21, cpy)
        if has_z:
            sbcg = sb * cg
            dx -= np.multiply.outer(ca * sbcg + sa * sg, cpz)
            dy -= np.multiply.outer(sa * sbcg - ca * sg, cpz)
            dz -= np.multiply.outer(cb * cg, cpz)
        b = dx * bx
        b += dy * by
        c = dz * la2
        a = dx * dx
        a += dy * dy
        a += dz * dz
        np.subtract(L, a, out=a)
        a /= np.hypot(b, c)                          # a_i / sqrt(b_i² + c_i²)
        with np.errstate(invalid="ignore"):
            z = np.arccos(a)
        if desc.branch < 0:
            np.negative(z, out=z)
        z += np.arctan2(c, b)
        z[z >= hi] -= TWO_PI
        z[z < lo] += TWO_PI
        out[s:s + _CHUNK] = z
        if check:
            bad = ~((np.abs(a) <= desc.max_alignment) & (z >= desc.zeta_min) & (z <= desc.zeta_max))
            if bad.any():
                n = int(np.argmax(bad.any(axis=1)))
                _check_ik(desc, z[n], a[n], s + n)
    return out


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


def constraint_jacobian_jd_batch(desc: "HexaDescription", poses: np.ndarray, zetas: np.ndarray) -> np.ndarray:
    """J_D (N, 6, 6) of `constraint_jacobians` for many poses (N, 6) and their arm angles (N, 6), vectorised."""
    poses, zetas = np.asarray(poses, dtype=float), np.asarray(zetas, dtype=float)
    R = rotation_zyx(poses[:, 3], poses[:, 4], poses[:, 5])
    r = np.einsum("nij,kj->nki", R, desc.C)
    n = poses[:, None, :3] + r - elbows(desc, zetas)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.concatenate([n, np.cross(r, n)], -1)


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


#: Sum of squared rod-length errors (m²) below which the NR iterate is converged: |Φ| ≤ 1e-13 m, so that the pose
#: error (|Φ| times the condition of J_D·T, < 1e3 inside the workspace) is below 1e-10 m / 1e-10 rad.
_FK_RESIDUAL_SQ = 1e-26


def _fk_residual(chains: tuple, Bl: list, l_d: float, p: list) -> tuple[list, list, float]:
    """Rod residuals Φ and the data for their Jacobian at pose p (pure-Python scalar code, 6 chains)."""
    x, y, z, al, be, ga = p
    ca, sa, cb, sb, cg, sg = math.cos(al), math.sin(al), math.cos(be), math.sin(be), math.cos(ga), math.sin(ga)
    r00, r01, r02 = ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg
    r10, r11, r12 = sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg
    r20, r21, r22 = -sb, cb * sg, cb * cg
    inv2l, l2 = 0.5 / l_d, l_d * l_d
    phi = [0.0] * 6
    geo: list[tuple[float, ...]] = [()] * 6
    f = 0.0
    for i in range(6):
        px, py, pz = chains[i][3], chains[i][4], chains[i][5]
        bx, by, bz = Bl[i]
        rx = r00 * px + r01 * py + r02 * pz
        ry = r10 * px + r11 * py + r12 * pz
        rz = r20 * px + r21 * py + r22 * pz
        nx, ny, nz = x + rx - bx, y + ry - by, z + rz - bz
        v = (nx * nx + ny * ny + nz * nz - l2) * inv2l
        phi[i] = v
        f += v * v
        geo[i] = (rx, ry, rz, nx, ny, nz)
    return phi, geo, f


def forward_kinematics(desc: "HexaDescription", zeta: np.ndarray, guess: np.ndarray | None = None,
                       tol: float = 1e-10, max_iter: int = 50) -> np.ndarray:
    """Pose [x y z α β γ] for arm angles ζ by damped Newton–Raphson on the loop closures (seed 000 §2.2.2).

    Iterates Δx = −(∂Φ/∂x)⁻¹Φ with ∂Φ/∂x = J_D(x)·T(x) (rod-length residuals Φ of `loop_closure_residual`),
    halving the step while it does not reduce |Φ|, until a full step is below `tol` (m, rad); |Φ| is then at
    round-off level (quadratic convergence); it also stops once |Φ| ≤ 1e-13 m. Converges to the assembly mode
    nearest the guess.

    Args:
        guess: starting pose (default the home pose); pass the last solution to warm-start.
    Raises:
        ForwardKinematicsError: no convergence in `max_iter` steps or a singular Jacobian.
    """
    k = _consts(desc)
    chains = k[12]
    zeta = np.asarray(zeta, dtype=float)
    la = desc.l_a
    Bl = []
    for (ax, ay, az, _px, _py, _pz, c_, s_), zi in zip(chains, zeta.tolist()):
        cz, sz = math.cos(zi), math.sin(zi)
        Bl.append((ax - la * c_ * cz, ay - la * s_ * cz, az + la * sz))      # B_i = A_i + l_a u_i (eq 10)
    x = [float(v) for v in (desc.home_pose if guess is None else guess)]
    l_d = desc.l_d
    inv_l = 1.0 / l_d
    J = np.empty((6, 6))
    phi, geo, f = _fk_residual(chains, Bl, l_d, x)
    for _ in range(max_iter):
        ca, sa, cb, sb = math.cos(x[3]), math.sin(x[3]), math.cos(x[4]), math.sin(x[4])
        e0, e1, e2, e3, e4 = -sa, ca * cb, ca, sa * cb, -sb   # E = [[0, e0, e1], [0, e2, e3], [1, 0, e4]]
        rows = []
        for rx, ry, rz, nx, ny, nz in geo:
            mx, my, mz = ry * nz - rz * ny, rz * nx - rx * nz, rx * ny - ry * nx     # r × n
            rows.append((nx * inv_l, ny * inv_l, nz * inv_l, mz * inv_l, (mx * e0 + my * e2) * inv_l,
                         (mx * e1 + my * e3 + mz * e4) * inv_l))
        J[:] = rows
        try:
            dx = np.linalg.solve(J, phi).tolist()
        except np.linalg.LinAlgError as exc:
            raise ForwardKinematicsError(f"singular loop-closure Jacobian at pose {x}") from exc
        step = 1.0
        for _halving in range(40):
            xn = [xi - step * di for xi, di in zip(x, dx)]
            phin, geon, fn = _fk_residual(chains, Bl, l_d, xn)
            if fn < f or fn < 1e-30:
                break
            step *= 0.5
        else:
            raise ForwardKinematicsError(f"Newton–Raphson stalled at pose {x} for zeta {zeta.tolist()}")
        x, phi, geo, f = xn, phin, geon, fn
        if step == 1.0 and (max(abs(di) for di in dx) < tol or fn < _FK_RESIDUAL_SQ):
            return np.array(x)
    raise ForwardKinematicsError(
        f"forward kinematics did not converge in {max_iter} steps for zeta {zeta.tolist()} "
        f"(residual {math.sqrt(f):.3g} m)")


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
