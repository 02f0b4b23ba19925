"""The one place that reads the robot description (HexaDescription) for the dynamics parameters."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

GRAVITY_SIM = 9.81  # the simulator's MJCF uses gravity="0 0 -9.81"


def _link(desc: HexaDescription, name: str) -> tuple[float, np.ndarray, np.ndarray]:
    li = getattr(desc, name)
    I = np.asarray(li.inertia, dtype=float)
    if I.shape == (3,):
        I = np.diag(I)
    return float(li.mass), np.asarray(li.com, dtype=float).reshape(3), I.reshape(3, 3)


def servo_armature_damping(desc: HexaDescription) -> tuple[float, float]:
    """Reflected rotor inertia (kg·m²) and viscous friction (N·m·s/rad) of a servo at the horn.

    Read from the description's `sim.servo` section when present (the modelled servo), else zero.
    """
    try:
        sim = desc.section("sim")
    except Exception:  # noqa: BLE001 — no sim section: an ideal actuator
        return 0.0, 0.0
    servo = (sim or {}).get("servo", {}) or {}
    return float(servo.get("armature", 0.0)), float(servo.get("damping", 0.0))


def dynamic_fields(desc: HexaDescription) -> dict:
    """Keyword arguments of HexaDynamicParameters from a HexaDescription.

    Arm: body frame {A2i} (x along A_i→B_i, z the motor axis); it turns about z through A_i, so only
    J_a = I_zz + m (x_c² + y_c²) + armature enters; its COM projection on the arm line gives s_a (a COM off the
    line by y_c along the arm's normal is folded into the gravity torque only through s_a — the default YAML has
    y_c = z_c = 0). Rod: frame {B2i} (x along B_i→C_i); slender: I_r = mean of I_yy, I_zz; kappa = x_c / l_d.
    """
    m_p, c_p, I_p = _link(desc, "plate")
    m_a, c_a, I_a = _link(desc, "arm")
    m_r, c_r, I_r = _link(desc, "rod")
    armature, damping = servo_armature_damping(desc)
    l_d = float(desc.l_d)
    return dict(
        A=np.asarray(desc.A, dtype=float),
        C=np.asarray(desc.C, dtype=float),
        alpha=np.asarray(desc.alpha, dtype=float),
        l_a=float(desc.l_a),
        l_d=l_d,
        m_p=m_p,
        I_p=I_p,
        c_p=c_p,
        m_a=m_a,
        J_a=float(I_a[2, 2] + m_a * (c_a[0] ** 2 + c_a[1] ** 2) + armature),
        s_a=float(c_a[0]),
        m_r=m_r,
        I_r=float(0.5 * (I_r[1, 1] + I_r[2, 2]) + m_r * (c_r[1] ** 2 + c_r[2] ** 2)),
        kappa=float(c_r[0] / l_d),
        arm_damping=damping,
        gravity=np.array([0.0, 0.0, -GRAVITY_SIM]),
        K_t=float(desc.K_t),
    )
