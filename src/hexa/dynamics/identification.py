"""Contact force at a known point by Newton–Euler (seed 000 §3.3, eqs 27–36), for the plate, any arm or any rod.

Per chain i without external load (eqs 28–30, made explicit):
- rod i, moments about B_i: d_i × f_Ci = −κ d_i × F_ri − M_ri fixes f_Ci's part perpendicular to the rod;
- arm i, moments about its motor axis e_i (the bearing takes the other two components, so only this one is known):
  J_a ζ̈_i = τ_i − l_a u'_i·f_Bi + m_a s_a u'_i·g − b ζ̇_i, with f_Bi = f_Ci + F_ri (rod force balance, eq 29) fixes
  the rod's axial force.
Here F_ri = m_r (a_ri − g) and M_ri = I_r ω̇_ri are the rod's inertial loads (eq 27, gravity included), f_Ci the force
of rod i on the plate, f_Bi the force of arm i on rod i, d_i = C_i − B_i.

- Plate hit (eqs 28–31): F_e = F_p − Σ_i f_Ci, F_p = m_p (a_p − g). Rank 3 always; the plate's moment balance is
  not needed and its mismatch (with the given point D) is reported as `residual_norm` (N·m).
- Arm k hit (eqs 32–33): f_Ck = F_p − Σ_{i≠k} f_Ci, f_Bk = f_Ck + F_rk, then e_k·((D − A_k) × F_e) = J_a ζ̈_k − τ_k +
  l_a u'_k·f_Bk − m_a s_a u'_k·g + b ζ̇_k. One equation: only the component of F_e along e_k × (D − A_k) (the arm's
  direction of motion) is observable — the motor bearing takes the rest. Rank 1, `observable` False, the two
  unobservable directions are returned. (The paper's eq 33 treats n_A as known in 3-D; a real hinge does not.)
  `arm_force_model` chooses the rest: "min_norm" gives the unobservable directions no force; "surface_normal"
  assumes a frictionless push, along the link's inward surface normal at D (from D to the arm's axis — the vision
  puts D on the surface facing the object), scaled to match the observed component; it falls back to min_norm when
  D lies on the axis or the normal makes more than 72.5° with the arm's direction of motion (cos < ARM_NORMAL_MIN_GAIN:
  the observed component would be amplified more than 1/0.3). "object_axis" takes the direction the vision measured
  (`push_direction`: the pushing object's axis, hexa.vision.isolation step 6) — a push along the object's own axis,
  friction or not — with the same gain test, and falls back to "surface_normal" without a usable direction.
  "friction_cone" (Coulomb) lies between the two: the push along the object's axis while that axis lies inside the
  friction cone about the inward normal (half-angle atan μ, `friction`), else along the cone's edge nearest the
  axis (a sliding contact); μ = 0 is "surface_normal", μ → ∞ is "object_axis".
- Rod k hit (eqs 34–36): f_Ck as in eq 32; rod moments about B_k: (D − B_k) × F_e = d_k × f_Ck + κ d_k × F_rk + M_rk
  (rank 2: a force along the rod is invisible in it) and the arm's axis equation u'_k·(f_Ck + F_rk − F_e) = s_Bk
  (one more). Least squares on the 4×3 system (moment rows divided by |D − B_k| so all rows are in N): rank 3 unless
  the arm's motion direction u'_k is perpendicular to the rod (serial singularity) or D = B_k.

Least squares by SVD; directions with a singular value below `rcond`·σ_max are reported unobservable and get no
force (minimum-norm solution), never noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexa.dynamics._kernel import KernelError, SampleKernel
from hexa.dynamics.lagrange import DynamicsError, HexaDynamicParameters, MotionState

if TYPE_CHECKING:
    from numpy.typing import NDArray

LINKS = ("plate", "arm", "rod")
ARM_FORCE_MODELS = ("min_norm", "surface_normal", "object_axis", "friction_cone")
ARM_NORMAL_MIN_GAIN = 0.3      # |cos| between the assumed force direction and the arm's direction of motion, at least
ARM_NORMAL_MIN_OFFSET = 5e-4   # m: D this close to the arm's axis gives no normal


class IdentificationError(ValueError):
    """Bad identification request (unknown link, chain out of 1..6, no accelerations); the message names it."""


@dataclass(frozen=True)
class ContactForceEstimate:
    """Identified contact force F_e (N, `base`) at `point` on `link` (chain 1..6; 0 for the plate).

    rank / singular_values / condition describe the least-squares system (rows in N); observable is False when
    some direction of F_e cannot be seen (listed as unit vectors in unobservable_directions, its force component set
    to 0, unless force_model says otherwise); residual_norm is the least-squares residual (plate: the moment balance
    mismatch in N·m). chain_forces: f_Ci (6, 3), the forces of the rods on the plate. force_model: "measured"
    (rank 3), "min_norm" (unobservable directions get no force), "surface_normal" (an arm force along the inward
    surface normal at the point), "object_axis" (along the measured push direction) or "friction_cone" (the push
    direction clamped into the friction cone about the normal; module docstring).
    """

    force: NDArray
    link: str
    chain: int
    point: NDArray
    rank: int
    singular_values: NDArray
    condition: float
    observable: bool
    unobservable_directions: NDArray
    residual_norm: float
    chain_forces: NDArray
    force_model: str = "measured"


_KERNELS: dict[int, tuple[HexaDynamicParameters, SampleKernel]] = {}


def _kernel_of(params: HexaDynamicParameters) -> SampleKernel:
    """The single-sample kernel of these parameters (cached; the cache holds the parameters, so ids stay unique)."""
    hit = _KERNELS.get(id(params))
    if hit is None:
        if len(_KERNELS) > 32:
            _KERNELS.clear()
        hit = (params, SampleKernel(params))
        _KERNELS[id(params)] = hit
    return hit[1]


def _cross3(a, b) -> list[float]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _lstsq(A: NDArray, b: NDArray, rcond: float) -> tuple[NDArray, int, NDArray, float, NDArray, float]:
    U, s, Vt = np.linalg.svd(A, full_matrices=True)
    smax = s[0] if s.size else 0.0
    keep = s > rcond * smax if smax > 0 else np.zeros_like(s, dtype=bool)
    rank = int(keep.sum())
    x = ((U[:, :rank].T @ b) / s[:rank]) @ Vt[:rank]
    svals = np.zeros(A.shape[1])
    svals[: s.size] = s
    cond = float(svals[0] / svals[-1]) if svals[-1] > 0 else float("inf")
    null = Vt[rank:]
    res = float(np.linalg.norm(A @ x - b))
    return x, rank, svals, cond, null, res


def arm_surface_normal(point: NDArray, axis_origin: NDArray, axis_dir: NDArray) -> NDArray | None:
    """Unit vector from `point` to the closest point of the arm's axis line (origin A_k, unit direction u_k): the
    inward surface normal where a frictionless push at `point` acts. None when the point lies on the axis."""
    D, A, u = (np.asarray(v, dtype=float) for v in (point, axis_origin, axis_dir))
    q = A + ((D - A) @ u) * u
    v = q - D
    dist = float(np.linalg.norm(v))
    return None if dist < ARM_NORMAL_MIN_OFFSET else v / dist


def push_direction_unit(direction: NDArray | None) -> NDArray | None:
    """`direction` as a unit vector, or None when it is missing, not 3 finite numbers, or (near) zero."""
    if direction is None:
        return None
    v = np.asarray(direction, dtype=float).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        return None
    nrm = float(np.linalg.norm(v))
    return None if nrm < 1e-9 else v / nrm


def friction_cone_direction(push: NDArray, normal: NDArray, friction: float) -> NDArray:
    """Direction of a Coulomb contact force pushed along unit `push` on a surface with inward unit `normal`:
    `push` itself inside the friction cone (angle to the normal ≤ atan μ: the contact sticks), else the cone's edge
    in the plane of `push` and the normal (the contact slides). Unit vector."""
    p, n = np.asarray(push, dtype=float), np.asarray(normal, dtype=float)
    c = float(p @ n)
    half = math.atan(friction)
    if math.acos(max(-1.0, min(1.0, c))) <= half:
        return p
    t = p - c * n
    nt = float(np.linalg.norm(t))
    if nt < 1e-12:          # pushing straight out of the surface: no side to slide to
        return n
    return math.cos(half) * n + math.sin(half) * (t / nt)


def carry_observed_component(row: NDArray, value: float, arm_force_model: str, normal: NDArray | None,
                             push: NDArray | None, friction: float = 0.2) -> tuple[NDArray | None, str]:
    """An arm force whose only observed component is row·F = value, carried along the direction `arm_force_model`
    assumes (module docstring): the measured push direction (unit `push`; "object_axis"), or it clamped into the
    friction cone about the inward `normal` ("friction_cone"), falling back to the normal, then to nothing.
    A direction qualifies when |row·n| ≥ ARM_NORMAL_MIN_GAIN·|row|. Returns (F, model) or (None, "min_norm")."""
    candidates: list[tuple[str, NDArray | None]] = []
    if arm_force_model == "object_axis":
        candidates.append(("object_axis", push))
    elif arm_force_model == "friction_cone" and push is not None and normal is not None:
        candidates.append(("friction_cone", friction_cone_direction(push, normal, friction)))
    if arm_force_model != "min_norm":
        candidates.append(("surface_normal", normal))
    row = np.asarray(row, dtype=float)
    for name, n in candidates:
        if n is None:
            continue
        gain = float(row @ n)
        if abs(gain) >= ARM_NORMAL_MIN_GAIN * float(np.linalg.norm(row)):
            return (value / gain) * np.asarray(n, dtype=float), name
    return None, "min_norm"


def identify_contact_force(params: HexaDynamicParameters, state: MotionState, tau: NDArray, link: str,
                           chain: int, point: NDArray, rcond: float = 1e-3,
                           arm_force_model: str = "min_norm", push_direction: NDArray | None = None,
                           friction: float = 0.2) -> ContactForceEstimate:
    """Contact force at `point` (base, m) on `link` of `chain` from one sample (seed 000 eqs 27–36).

    state: one sample (N = 1) with accelerations (motion_from_joint_rates(..., zeta_ddot) or motion_from_plate with
    twist_dot); tau: servo torques K_t·I (6,) in N·m; arm_force_model: what an arm force's two unobservable
    directions get, "min_norm", "surface_normal", "object_axis" or "friction_cone" (module docstring);
    push_direction: the measured direction of the push (base, any length; None or non-finite = not measured), used
    by "object_axis" and "friction_cone"; friction: Coulomb coefficient μ ≥ 0 of "friction_cone".

    Raises:
        IdentificationError: unknown link or arm_force_model, chain not in 1..6 for an arm/rod, missing
            accelerations, bad point.
    """
    if link not in LINKS:
        raise IdentificationError(f"link must be one of {LINKS}, got {link!r}")
    if arm_force_model not in ARM_FORCE_MODELS:
        raise IdentificationError(f"arm_force_model must be one of {ARM_FORCE_MODELS}, got {arm_force_model!r}")
    if not (isinstance(friction, (int, float, np.floating)) and friction >= 0 and math.isfinite(friction)):
        raise IdentificationError(f"friction must be a finite coefficient >= 0, got {friction!r}")
    if link != "plate" and not (isinstance(chain, (int, np.integer)) and 1 <= int(chain) <= 6):
        raise IdentificationError(f"chain must be 1..6 for link {link!r}, got {chain!r}")
    if state.V_dot is None or state.n != 1:
        raise IdentificationError("identification needs one sample (N = 1) with accelerations (V_dot)")
    D = np.asarray(point, dtype=float).reshape(-1)
    if D.shape != (3,) or not np.all(np.isfinite(D)):
        raise IdentificationError(f"point must be 3 finite coordinates (m), got {point!r}")
    tau = np.asarray(tau, dtype=float).reshape(6)
    if not np.all(np.isfinite(tau)):
        raise IdentificationError(f"tau must be 6 finite torques (N·m), got {tau.tolist()}")
    prm = params
    ker = _kernel_of(prm)
    p_l, R_l = state.p[0].tolist(), state.R[0].ravel().tolist()
    geo, _ = ker.geometry(state.zeta[0].tolist(), p_l, R_l)
    try:
        # per chain without load: f_Ci from the rod's moments about B_i (eq 30) and the arm's axis moment (eq 28)
        ne = ker.newton_euler(geo, state.V[0].tolist(), state.V_dot[0].tolist(), tau.tolist(), R_l)
    except KernelError as exc:
        raise DynamicsError(str(exc)) from exc
    fC = ne["fC"]  # 6 × [x, y, z]: forces of the rods on the plate (chains without load)
    rod_F, rod_M, plate_F = ne["rod_F"], ne["rod_M"], ne["plate_F"]
    P = p_l
    Dl = D.tolist()
    if link == "plate":
        F = [plate_F[m] - sum(f[m] for f in fC) for m in range(3)]  # eq 31
        need = list(ne["plate_N"])
        for g_i, f in zip(geo, fC):
            c = _cross3(g_i[0:3], f)
            need = [need[m] - c[m] for m in range(3)]
        lever = [Dl[m] - P[m] for m in range(3)]
        mism = _cross3(lever, F)
        res = math.sqrt(sum((mism[m] - need[m]) ** 2 for m in range(3)))
        return ContactForceEstimate(force=np.array(F), link=link, chain=0, point=D, rank=3,
                                    singular_values=np.ones(3), condition=1.0, observable=True,
                                    unobservable_directions=np.zeros((0, 3)), residual_norm=res,
                                    chain_forces=np.array(fC))
    k = int(chain) - 1
    fC = [list(f) for f in fC]
    fC[k] = [plate_F[m] - sum(fC[i][m] for i in range(6) if i != k) for m in range(3)]  # eq 32
    fk, Fr = fC[k], rod_F[k]
    rk, upk, dk = geo[k][0:3], geo[k][6:9], geo[k][9:12]
    s_B = ne["s_B"][k]
    if link == "arm":
        lever = [Dl[m] - float(prm.A[k][m]) for m in range(3)]
        e_k = (-math.sin(prm.alpha[k]), math.cos(prm.alpha[k]), 0.0)
        row = _cross3(e_k, lever)  # e·(lever × F) = (e × lever)·F
        fB = [fk[m] + Fr[m] for m in range(3)]
        rhs = prm.l_a * (sum(upk[m] * fB[m] for m in range(3)) - s_B)  # eq 33 on the motor axis
        L = max(math.sqrt(sum(x * x for x in lever)), 1e-12)
        A = np.array([row]) / L
        b = np.array([rhs]) / L
    else:
        B_k = [P[m] + rk[m] - dk[m] for m in range(3)]
        lever = [Dl[m] - B_k[m] for m in range(3)]
        L = max(math.sqrt(sum(x * x for x in lever)), 1e-12)
        c1, c2 = _cross3(dk, fk), _cross3(dk, Fr)
        mom = [c1[m] + prm.kappa * c2[m] + rod_M[k][m] for m in range(3)]  # eq 36
        lx, ly, lz = lever
        A = np.array([[0.0, -lz, ly], [lz, 0.0, -lx], [-ly, lx, 0.0],
                      [-upk[0] * L, -upk[1] * L, -upk[2] * L]]) / L  # eqs 35–36 and the arm's axis eq (34)
        b = np.array([mom[0] / L, mom[1] / L, mom[2] / L,
                      s_B - sum(upk[m] * (fk[m] + Fr[m]) for m in range(3))])
    x, rank, sv, cond, null, res = _lstsq(A, b, rcond)
    model = "measured" if rank == 3 else "min_norm"
    if link == "arm" and arm_force_model != "min_norm":
        assumed, name = carry_observed_component(A[0], float(b[0]), arm_force_model,
                                                 arm_surface_normal(D, prm.A[k], geo[k][3:6]),
                                                 push_direction_unit(push_direction), float(friction))
        if assumed is not None:
            x, model = assumed, name
    return ContactForceEstimate(force=x, link=link, chain=k + 1, point=D, rank=rank, singular_values=sv,
                                condition=cond, observable=rank == 3, unobservable_directions=null,
                                residual_norm=res, chain_forces=np.array(fC), force_model=model)
