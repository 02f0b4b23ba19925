"""Single-sample momentum terms in plain Python floats (the 1 kHz path; numpy call overhead dominates at N = 1).

Same mathematics as `lagrange._momentum_terms` (tested equal to it to rounding): for one sample returns the plate
twist V = J_ζ⁻¹ ζ̇, the generalized momentum π = M̃ V and u = J_ζᵀ(τ − b ζ̇) + G + β. Per chain the terms collapse to
π += a_i j_i + J_Cᵢᵀ f_i and u += c_i j_i + a_i j̇_i + J_Cᵢᵀ g_i + [0, (ω×r_i)×f_i], with j_i the row of J_ζ.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:
    from hexa.dynamics.lagrange import HexaDynamicParameters

Vec = list[float]


class KernelError(ArithmeticError):
    """Singular J_ζ / constraint Jacobian or a serial singularity at this sample."""


_GESV = None


def _gesv():
    global _GESV
    if _GESV is None:
        from scipy.linalg import get_lapack_funcs

        _GESV = get_lapack_funcs("gesv", (np.zeros((6, 6)),))
    return _GESV


def solve6(M: list[list[float]] | np.ndarray, b: Sequence[float] | np.ndarray) -> Vec:
    """x with M x = b for a 6×6 M, nested lists or an array (LAPACK gesv: the cheapest call for one small system;
    it factorizes a copy, M is not changed)."""
    _, _, x, info = (_GESV or _gesv())(np.asarray(M, dtype=float), np.asarray(b, dtype=float))
    if info != 0:
        raise KernelError("singular 6x6 system")
    return x.tolist()


def solve6_python(M: list[list[float]], b: Sequence[float]) -> Vec:
    """x with M x = b for a 6×6 M (Gaussian elimination, partial pivoting, pure Python); M is consumed."""
    n = 6
    x = list(b)
    for c in range(n):
        piv = c
        big = abs(M[c][c])
        for r in range(c + 1, n):
            v = abs(M[r][c])
            if v > big:
                big, piv = v, r
        if big < 1e-300:
            raise KernelError("singular 6x6 system")
        if piv != c:
            M[c], M[piv] = M[piv], M[c]
            x[c], x[piv] = x[piv], x[c]
        row = M[c]
        inv = 1.0 / row[c]
        for r in range(c + 1, n):
            rr = M[r]
            f = rr[c] * inv
            if f != 0.0:
                for k in range(c + 1, n):
                    rr[k] -= f * row[k]
                x[r] -= f * x[c]
    for c in range(n - 1, -1, -1):
        row = M[c]
        s = x[c]
        for k in range(c + 1, n):
            s -= row[k] * x[k]
        x[c] = s / row[c]
    return x


def _jacobian_flat(geo: list) -> list[float]:
    """J_ζ row-major in one list of 36 floats (chain_jacobian_rows)."""
    J: list[float] = []
    for (rx, ry, rz, ux, uy, uz, vx, vy, vz, dx, dy, dz, dd, D) in geo:
        if abs(D) < 1e-12:
            raise KernelError("serial singularity (rod perpendicular to the arm's motion)")
        iD = 1.0 / D
        J += (dx * iD, dy * iD, dz * iD, (ry * dz - rz * dy) * iD, (rz * dx - rx * dz) * iD, (rx * dy - ry * dx) * iD)
    return J


def chain_jacobian_rows(geo: list) -> list[list[float]]:
    """J_ζ (6×6, ζ̇ = J_ζ V, seed 000 eq 17) from `SampleKernel.geometry` rows: j_i = [d_i, r_i × d_i] / D_i."""
    J = _jacobian_flat(geo)
    return [J[k:k + 6] for k in range(0, 36, 6)]


def chain_jacobian_array(geo: list) -> np.ndarray:
    """chain_jacobian_rows as a (6, 6) array, built without nested lists (the per-sample path solves with it)."""
    return np.fromiter(_jacobian_flat(geo), float, 36).reshape(6, 6)


def exp_rotate(w0: float, w1: float, w2: float, R: Sequence[float]) -> tuple[float, ...]:
    """exp([w]×)·R for a flat row-major 3×3 R."""
    th2 = w0 * w0 + w1 * w1 + w2 * w2
    if th2 < 1e-24:
        a, b = 1.0, 0.5
    else:
        th = math.sqrt(th2)
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    # E = I + a K + b K², K = [w]×
    e00 = 1.0 - b * (w1 * w1 + w2 * w2)
    e11 = 1.0 - b * (w0 * w0 + w2 * w2)
    e22 = 1.0 - b * (w0 * w0 + w1 * w1)
    e01 = -a * w2 + b * w0 * w1
    e10 = a * w2 + b * w0 * w1
    e02 = a * w1 + b * w0 * w2
    e20 = -a * w1 + b * w0 * w2
    e12 = -a * w0 + b * w1 * w2
    e21 = a * w0 + b * w1 * w2
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    return (e00 * r00 + e01 * r10 + e02 * r20, e00 * r01 + e01 * r11 + e02 * r21, e00 * r02 + e01 * r12 + e02 * r22,
            e10 * r00 + e11 * r10 + e12 * r20, e10 * r01 + e11 * r11 + e12 * r21, e10 * r02 + e11 * r12 + e12 * r22,
            e20 * r00 + e21 * r10 + e22 * r20, e20 * r01 + e21 * r11 + e22 * r21, e20 * r02 + e21 * r12 + e22 * r22)


class SampleKernel:
    """Precomputed constants of one robot; `terms(...)` evaluates one sample."""

    def __init__(self, prm: HexaDynamicParameters) -> None:
        _gesv()  # import LAPACK now, not in the first 1 kHz sample
        self.la = prm.l_a
        self.ld2 = prm.l_d**2
        self.A = [tuple(map(float, a)) for a in prm.A]
        self.C = [tuple(map(float, c)) for c in prm.C]
        self.ca = [math.cos(a) for a in prm.alpha]
        self.sa = [math.sin(a) for a in prm.alpha]
        self.mp = prm.m_p
        self.Ip = [[float(v) for v in row] for row in prm.I_p]
        self.cp = tuple(map(float, prm.c_p))
        self.Ja = prm.J_a
        self.mas = prm.m_a * prm.s_a
        self.mr = prm.m_r
        self.Ir = prm.I_r
        self.k = prm.kappa
        self.b = prm.arm_damping
        self.g = tuple(map(float, prm.gravity))

    def geometry(self, zeta: Sequence[float], p: Sequence[float], R: Sequence[float]) -> tuple[list, float]:
        """Per-chain (r, u, u', d, |d|², D, j) and max |f_i| (f_i = |d_i|² − l_d², eq 15)."""
        la, ld2 = self.la, self.ld2
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        px, py, pz = p
        out = []
        fmax = 0.0
        for i in range(6):
            cx, cy, cz = self.C[i]
            rx = r00 * cx + r01 * cy + r02 * cz
            ry = r10 * cx + r11 * cy + r12 * cz
            rz = r20 * cx + r21 * cy + r22 * cz
            z = zeta[i]
            c, s = math.cos(z), math.sin(z)
            ca, sa = self.ca[i], self.sa[i]
            ux, uy, uz = -ca * c, -sa * c, s
            vx, vy, vz = ca * s, sa * s, c  # u' = ∂u/∂ζ
            ax, ay, az = self.A[i]
            dx = px + rx - ax - la * ux
            dy = py + ry - ay - la * uy
            dz = pz + rz - az - la * uz
            dd = dx * dx + dy * dy + dz * dz
            f = dd - ld2
            if f > fmax:
                fmax = f
            elif -f > fmax:   # |f| without a call
                fmax = -f
            D = la * (dx * vx + dy * vy + dz * vz)
            out.append((rx, ry, rz, ux, uy, uz, vx, vy, vz, dx, dy, dz, dd, D))
        return out, fmax

    def track_pose(self, zeta: Sequence[float], p: Sequence[float], R: Sequence[float], tol: float,
                   iterations: int) -> tuple[list, tuple, tuple]:
        """Newton steps on f(ζ, pose) = 0 from (p, R); returns the geometry at the converged pose, p, R."""
        p = tuple(p)
        R = tuple(R)
        for _ in range(iterations + 1):
            geo, fmax = self.geometry(zeta, p, R)
            if fmax < tol:
                return geo, p, R
            M: list[float] = []   # row-major, flat: one cheap conversion to an array
            rhs = []
            for (rx, ry, rz, _ux, _uy, _uz, _vx, _vy, _vz, dx, dy, dz, dd, _D) in geo:
                M += (2 * dx, 2 * dy, 2 * dz, 2 * (ry * dz - rz * dy), 2 * (rz * dx - rx * dz),
                      2 * (rx * dy - ry * dx))
                rhs.append(self.ld2 - dd)
            dx6 = solve6(np.fromiter(M, float, 36).reshape(6, 6), rhs)
            p = (p[0] + dx6[0], p[1] + dx6[1], p[2] + dx6[2])
            R = exp_rotate(dx6[3], dx6[4], dx6[5], R)
        raise KernelError(f"pose tracking did not converge (max |f| = {fmax:.3g} m²)")

    def arm_angles(self, zeta0: Sequence[float], p: Sequence[float], R: Sequence[float], tol: float = 1e-13,
                   iterations: int = 8) -> list[float]:
        """ζ of the plate pose (p, R) by per-chain Newton on f_i(ζ_i) = 0 (eq 15) from the guess zeta0 (the branch
        of the guess is kept)."""
        la, ld2 = self.la, self.ld2
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        px, py, pz = p
        out = []
        for i in range(6):
            cx, cy, cz = self.C[i]
            ax, ay, az = self.A[i]
            Cx = px + r00 * cx + r01 * cy + r02 * cz - ax
            Cy = py + r10 * cx + r11 * cy + r12 * cz - ay
            Cz = pz + r20 * cx + r21 * cy + r22 * cz - az
            ca, sa = self.ca[i], self.sa[i]
            z = zeta0[i]
            for _ in range(iterations):
                c, s_ = math.cos(z), math.sin(z)
                dx, dy, dz = Cx + la * ca * c, Cy + la * sa * c, Cz - la * s_
                f = dx * dx + dy * dy + dz * dz - ld2
                if abs(f) < tol:
                    break
                dfdz = -2.0 * la * (dx * ca * s_ + dy * sa * s_ + dz * c)
                if abs(dfdz) < 1e-12:
                    raise KernelError(f"chain {i + 1}: serial singularity while solving its arm angle")
                z -= f / dfdz
            else:
                raise KernelError(f"chain {i + 1}: arm angle did not converge (|f| = {abs(f):.3g} m²)")
            out.append(z)
        return out

    def terms(self, geo: list, zd: Sequence[float] | None, tau: Sequence[float], p: Sequence[float],
              R: Sequence[float], twist: Sequence[float] | None = None,
              jacobian: list[list[float]] | np.ndarray | None = None) -> tuple[Vec, Vec, Vec]:
        """(V, π, u) for one sample with geometry `geo` (from geometry/track_pose); the twist is J_ζ⁻¹ζ̇, or
        `twist` as given (then ζ̇ = J_ζ V). `jacobian`: chain_jacobian_rows(geo) if the caller has it already.

        Per chain, with j_i = [d, r × d]/D, everything folds into forces at C_i plus couples:
        π_i = [Y, r × Y] with Y = (a/D) d + f_C, u_i = [X, r × X + (ω × r) × Y] with X = (c'/D) d + (a/D) ḋ + g_C
        (a = J_a ζ̇ + l_a u'·f_B, c' = c − a Ḋ/D; see lagrange._momentum_terms for the unfolded terms)."""
        la, k1, k0 = self.la, self.k, 1.0 - self.k
        Ja, mr, Ir, b = self.Ja, self.mr, self.Ir, self.b
        gx, gy, gz = self.g
        mk0, mk1 = mr * k0, mr * k1
        gcx0, gcy0, gcz0 = mk1 * gx, mk1 * gy, mk1 * gz
        mg = self.mas + la * mk0
        zdv: Sequence[float] = () if zd is None else zd
        if twist is None:
            V = solve6(chain_jacobian_rows(geo) if jacobian is None else jacobian, zdv)
        else:
            V = list(twist)
        v0, v1, v2, w0, w1, w2 = V
        p0 = p1 = p2 = p3 = p4 = p5 = 0.0
        u0 = u1 = u2 = u3 = u4 = u5 = 0.0
        for i in range(6):
            rx, ry, rz, ux, uy, uz, vx, vy, vz, dx, dy, dz, dd, D = geo[i]
            if abs(D) < 1e-12:
                raise KernelError("serial singularity (rod perpendicular to the arm's motion)")
            iD = 1.0 / D
            qx = w1 * rz - w2 * ry  # ω × r
            qy = w2 * rx - w0 * rz
            qz = w0 * ry - w1 * rx
            cdx, cdy, cdz = v0 + qx, v1 + qy, v2 + qz  # Ċ
            z1 = zdv[i] if twist is None else (dx * cdx + dy * cdy + dz * cdz) * iD  # ζ̇ = j·V
            lz = la * z1
            bdx, bdy, bdz = lz * vx, lz * vy, lz * vz  # Ḃ
            ex, ey, ez = cdx - bdx, cdy - bdy, cdz - bdz  # ḋ
            Dd = la * (ex * vx + ey * vy + ez * vz - z1 * (dx * ux + dy * uy + dz * uz))
            idd = 1.0 / dd
            sg = (dx * ex + dy * ey + dz * ez) * idd  # (d·ḋ)/|d|² (0 on the constraint manifold)
            cI = Ir * idd
            # rod: linear momentum at the COM, angular momentum I_r ω_r as a couple wc = (I_r ω_r) × d / |d|²
            hx, hy, hz = mk0 * bdx + mk1 * cdx, mk0 * bdy + mk1 * cdy, mk0 * bdz + mk1 * cdz
            wcx, wcy, wcz = cI * (ex - sg * dx), cI * (ey - sg * dy), cI * (ez - sg * dz)
            fcx, fcy, fcz = k1 * hx + wcx, k1 * hy + wcy, k1 * hz + wcz
            fbx, fby, fbz = k0 * hx - wcx, k0 * hy - wcy, k0 * hz - wcz
            # ac = ((I_r ω_r) × ḋ − 2 (d·ḋ)/|d|² (I_r ω_r) × d) / |d|²
            a1 = cI * sg
            a2 = cI * (ex * ex + ey * ey + ez * ez) * idd
            a3 = 2.0 * sg
            acx = a1 * ex - a2 * dx - a3 * wcx
            acy = a1 * ey - a2 * dy - a3 * wcy
            acz = a1 * ez - a2 * dz - a3 * wcz
            a = Ja * z1 + la * (vx * fbx + vy * fby + vz * fbz)
            c = (tau[i] - b * z1 + mg * (vx * gx + vy * gy + vz * gz)
                 - la * (z1 * (ux * fbx + uy * fby + uz * fbz) + vx * acx + vy * acy + vz * acz))
            aD = a * iD
            cD = (c - aD * Dd) * iD
            Yx, Yy, Yz = aD * dx + fcx, aD * dy + fcy, aD * dz + fcz
            Xx = cD * dx + aD * ex + gcx0 + acx
            Xy = cD * dy + aD * ey + gcy0 + acy
            Xz = cD * dz + aD * ez + gcz0 + acz
            p0 += Yx
            p1 += Yy
            p2 += Yz
            p3 += ry * Yz - rz * Yy
            p4 += rz * Yx - rx * Yz
            p5 += rx * Yy - ry * Yx
            u0 += Xx
            u1 += Xy
            u2 += Xz
            u3 += ry * Xz - rz * Xy + qy * Yz - qz * Yy
            u4 += rz * Xx - rx * Xz + qz * Yx - qx * Yz
            u5 += rx * Xy - ry * Xx + qx * Yy - qy * Yx
        pi = [p0, p1, p2, p3, p4, p5]
        u = [u0, u1, u2, u3, u4, u5]
        # plate
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        cx, cy, cz = self.cp
        ox = r00 * cx + r01 * cy + r02 * cz  # ρ = R c_p
        oy = r10 * cx + r11 * cy + r12 * cz
        oz = r20 * cx + r21 * cy + r22 * cz
        wox, woy, woz = w1 * oz - w2 * oy, w2 * ox - w0 * oz, w0 * oy - w1 * ox  # ω × ρ
        mp = self.mp
        hpx, hpy, hpz = mp * (v0 + wox), mp * (v1 + woy), mp * (v2 + woz)
        # I_world ω = R I_p Rᵀ ω
        b0 = r00 * w0 + r10 * w1 + r20 * w2
        b1 = r01 * w0 + r11 * w1 + r21 * w2
        b2 = r02 * w0 + r12 * w1 + r22 * w2
        Ip = self.Ip
        c0 = Ip[0][0] * b0 + Ip[0][1] * b1 + Ip[0][2] * b2
        c1 = Ip[1][0] * b0 + Ip[1][1] * b1 + Ip[1][2] * b2
        c2 = Ip[2][0] * b0 + Ip[2][1] * b1 + Ip[2][2] * b2
        Lpx = r00 * c0 + r01 * c1 + r02 * c2
        Lpy = r10 * c0 + r11 * c1 + r12 * c2
        Lpz = r20 * c0 + r21 * c1 + r22 * c2
        pi[0] += hpx
        pi[1] += hpy
        pi[2] += hpz
        pi[3] += oy * hpz - oz * hpy + Lpx
        pi[4] += oz * hpx - ox * hpz + Lpy
        pi[5] += ox * hpy - oy * hpx + Lpz
        mgx, mgy, mgz = mp * gx, mp * gy, mp * gz
        u[0] += mgx
        u[1] += mgy
        u[2] += mgz
        u[3] += oy * mgz - oz * mgy + (woy * hpz - woz * hpy)
        u[4] += oz * mgx - ox * mgz + (woz * hpx - wox * hpz)
        u[5] += ox * mgy - oy * mgx + (wox * hpy - woy * hpx)
        return V, pi, u

    def newton_euler(self, geo: list, V: Sequence[float], Vd: Sequence[float], tau: Sequence[float],
                     R: Sequence[float]) -> dict:
        """Per-chain loads of one sample for the identification (seed 000 eqs 27–30), no external load assumed:
        f_C (force of rod i on the plate), F_r = m_r(a_r − g), M_r = I_r ω̇_r, s_B = u'·f_B from the arm's axis
        moment, ζ̈, ζ̇; and the plate's F_p = m_p(a_p − g), its moment need N_p = ρ × F_p + I ω̇ + ω × I ω, ρ."""
        la, k1, k0 = self.la, self.k, 1.0 - self.k
        Ja, mr, Ir, b, mas = self.Ja, self.mr, self.Ir, self.b, self.mas
        gx, gy, gz = self.g
        v0, v1, v2, w0, w1, w2 = V
        a0, a1, a2, e0, e1, e2 = Vd
        fC, rodF, rodM, sB, zdd_l, zd_l = [], [], [], [], [], []
        for i in range(6):
            rx, ry, rz, ux, uy, uz, vx, vy, vz, dx, dy, dz, dd, D = geo[i]
            if abs(D) < 1e-12:
                raise KernelError(f"chain {i + 1} is at a serial singularity (rod ⟂ arm motion)")
            iD, idd = 1.0 / D, 1.0 / dd
            qx, qy, qz = w1 * rz - w2 * ry, w2 * rx - w0 * rz, w0 * ry - w1 * rx  # ω × r
            cdx, cdy, cdz = v0 + qx, v1 + qy, v2 + qz  # Ċ
            z1 = (dx * cdx + dy * cdy + dz * cdz) * iD  # ζ̇
            lz = la * z1
            ex, ey, ez = cdx - lz * vx, cdy - lz * vy, cdz - lz * vz  # ḋ
            # C̈ = v̇ + ω̇ × r + ω × (ω × r)
            ccx = a0 + e1 * rz - e2 * ry + w1 * qz - w2 * qy
            ccy = a1 + e2 * rx - e0 * rz + w2 * qx - w0 * qz
            ccz = a2 + e0 * ry - e1 * rx + w0 * qy - w1 * qx
            z2 = (dx * ccx + dy * ccy + dz * ccz + lz * z1 * (dx * ux + dy * uy + dz * uz)
                  + ex * ex + ey * ey + ez * ez) * iD  # ζ̈ (differentiated eq 15 twice)
            l2, l1 = la * z2, la * z1 * z1
            bbx, bby, bbz = l2 * vx - l1 * ux, l2 * vy - l1 * uy, l2 * vz - l1 * uz  # B̈
            fx = mr * (k0 * bbx + k1 * ccx - gx)  # F_r = m_r (a_r − g)
            fy = mr * (k0 * bby + k1 * ccy - gy)
            fz = mr * (k0 * bbz + k1 * ccz - gz)
            ddx, ddy, ddz = ccx - bbx, ccy - bby, ccz - bbz  # d̈
            s2 = 2.0 * (dx * ex + dy * ey + dz * ez) * idd
            mx = Ir * ((dy * ddz - dz * ddy) - s2 * (dy * ez - dz * ey)) * idd  # M_r = I_r ω̇_r
            my = Ir * ((dz * ddx - dx * ddz) - s2 * (dz * ex - dx * ez)) * idd
            mz = Ir * ((dx * ddy - dy * ddx) - s2 * (dx * ey - dy * ex)) * idd
            # moments about B: d × f_C = −κ d × F_r − M_r
            nbx = -k1 * (dy * fz - dz * fy) - mx
            nby = -k1 * (dz * fx - dx * fz) - my
            nbz = -k1 * (dx * fy - dy * fx) - mz
            px_, py_, pz_ = (nby * dz - nbz * dy) * idd, (nbz * dx - nbx * dz) * idd, (nbx * dy - nby * dx) * idd
            s_b = (tau[i] - Ja * z2 + mas * (vx * gx + vy * gy + vz * gz) - b * z1) / la
            nd = math.sqrt(dd)
            hx, hy, hz = dx / nd, dy / nd, dz / nd
            den = vx * hx + vy * hy + vz * hz
            if abs(den) < 1e-9:
                raise KernelError(f"chain {i + 1} is at a serial singularity (u'·d = 0)")
            t_ax = (s_b - (vx * (px_ + fx) + vy * (py_ + fy) + vz * (pz_ + fz))) / den
            fC.append([t_ax * hx + px_, t_ax * hy + py_, t_ax * hz + pz_])
            rodF.append([fx, fy, fz])
            rodM.append([mx, my, mz])
            sB.append(s_b)
            zdd_l.append(z2)
            zd_l.append(z1)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        cx, cy, cz = self.cp
        ox, oy, oz = r00 * cx + r01 * cy + r02 * cz, r10 * cx + r11 * cy + r12 * cz, r20 * cx + r21 * cy + r22 * cz
        qx, qy, qz = w1 * oz - w2 * oy, w2 * ox - w0 * oz, w0 * oy - w1 * ox
        apx = a0 + e1 * oz - e2 * oy + w1 * qz - w2 * qy
        apy = a1 + e2 * ox - e0 * oz + w2 * qx - w0 * qz
        apz = a2 + e0 * oy - e1 * ox + w0 * qy - w1 * qx
        mp = self.mp
        Fp = [mp * (apx - gx), mp * (apy - gy), mp * (apz - gz)]
        # I_world x = R I_p Rᵀ x
        Ip = self.Ip

        def iw(x0: float, x1: float, x2: float) -> tuple[float, float, float]:
            b0 = r00 * x0 + r10 * x1 + r20 * x2
            b1 = r01 * x0 + r11 * x1 + r21 * x2
            b2 = r02 * x0 + r12 * x1 + r22 * x2
            c0 = Ip[0][0] * b0 + Ip[0][1] * b1 + Ip[0][2] * b2
            c1 = Ip[1][0] * b0 + Ip[1][1] * b1 + Ip[1][2] * b2
            c2 = Ip[2][0] * b0 + Ip[2][1] * b1 + Ip[2][2] * b2
            return (r00 * c0 + r01 * c1 + r02 * c2, r10 * c0 + r11 * c1 + r12 * c2, r20 * c0 + r21 * c1 + r22 * c2)

        ia = iw(e0, e1, e2)
        lw = iw(w0, w1, w2)
        Np = [oy * Fp[2] - oz * Fp[1] + ia[0] + w1 * lw[2] - w2 * lw[1],
              oz * Fp[0] - ox * Fp[2] + ia[1] + w2 * lw[0] - w0 * lw[2],
              ox * Fp[1] - oy * Fp[0] + ia[2] + w0 * lw[1] - w1 * lw[0]]
        return {"fC": fC, "rod_F": rodF, "rod_M": rodM, "s_B": sB, "zeta_ddot": zdd_l, "zeta_dot": zd_l,
                "plate_F": Fp, "plate_N": Np, "rho": [ox, oy, oz]}
