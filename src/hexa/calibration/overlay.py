"""The calibration overlay: what `hexa calibrate identify` writes and every node reads with the robot description.

An overlay is a YAML file with `calibration_of: BASE` (hexa.robots.hexa_description.load_hexa lays it over BASE):
- `inertia.plate` (mass, COM, inertia about the COM) and `inertia.arm.com` (the mean first moment along the arm),
- `actuators.K_t` (the mean torque constant), `sim.servo.armature` (the mean inertia about the motor axis beyond the
  arm's own: the rotor's) and `sim.servo.damping` (the mean viscous friction) — the nodes' symmetric model;
- `calibration`: the per-servo values (k_t, current_offset, coulomb, viscous, inertia, first_moment, first_moment_y,
  horn_offset), the speed ε of the Coulomb term's tanh(ζ̇/ε) (`coulomb_speed`, rad/s),
  their 95 % confidence half-widths, the runs used and how the torque scale was fixed.
`ServoTorqueModel` applies the per-servo part to the currents (the observer's torques), the driver applies
`horn_offset` to its angle ↔ pulse map.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from hexa.calibration.identify import Calibration
    from hexa.robots.hexa_description import HexaDescription

PER_SERVO = ("k_t", "current_offset", "coulomb", "viscous", "inertia", "first_moment", "first_moment_y",
             "horn_offset")


def _floats(a: ArrayLike) -> float | list[Any]:
    """Plain floats / nested lists of floats (what yaml.safe_dump writes) of a number or array."""
    return np.asarray(a, dtype=float).tolist()


def overlay_mapping(cal: "Calibration", desc: HexaDescription) -> dict[str, Any]:
    """The overlay (module docstring) of `cal` on the description `desc`."""
    from hexa.calibration.regressor import COULOMB_SPEED
    base = str(getattr(desc, "path", "") or "")
    from hexa.robots.hexa_description import DEFAULT_PATH

    if base and Path(base).resolve() == DEFAULT_PATH.resolve():
        base = ""
    m_a = float(desc.arm.mass)
    s_a = float(np.mean(cal.first_moment)) / m_a
    c_arm = np.asarray(desc.arm.com, dtype=float).copy()
    c_arm[0] = s_a
    I_arm = np.asarray(desc.arm.inertia, dtype=float)
    armature = float(max(0.0, float(np.mean(cal.inertia)) - float(I_arm[2, 2]) - m_a * (c_arm[0] ** 2 + c_arm[1] ** 2)))
    return {
        "calibration_of": base,
        "inertia": {"plate": {"mass": float(cal.plate_mass), "com": _floats(cal.plate_com),
                              "inertia": _floats(0.5 * (cal.plate_inertia + cal.plate_inertia.T))},
                    "arm": {"com": _floats(c_arm)}},
        "actuators": {"K_t": float(np.mean(cal.k_t))},
        "sim": {"servo": {"armature": armature, "damping": float(np.mean(cal.viscous))}},
        "calibration": {
            "created": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "sources": list(cal.sources), "scale": cal.scale, "consistency": cal.consistency,
            "samples": int(cal.samples), "fit_rms": _floats(cal.rms), "coulomb_speed": COULOMB_SPEED,
            **{k: _floats(getattr(cal, k)) for k in PER_SERVO},
            "ci95": {k: _floats(v) for k, v in cal.ci95.items()},
        },
    }


def write_overlay(path: str | Path, cal: "Calibration", desc: HexaDescription) -> Path:
    """Write the overlay of `cal` to `path` (YAML, SI units) and check it loads; returns the path.

    Raises:
        hexa.robots.schema.RobotDescriptionError: the result is not a valid description (e.g. an inertia that
            violates the triangle inequality).
    """
    from hexa.robots.hexa_description import load_hexa

    p = Path(path)
    head = ("# Calibration overlay of the Hexa (hexa calibrate identify), SI units (m, kg, kg·m², N·m, A, rad, s).\n"
            "# Give it to the nodes as their robot description (`description` parameter, `hexa bringup … "
            "--description FILE`);\n# it is laid over `calibration_of` (empty: the packaged hexa.yaml).\n")
    p.write_text(head + yaml.safe_dump(overlay_mapping(cal, desc), sort_keys=False, width=120,
                                                  default_flow_style=None), encoding="utf-8")
    load_hexa(p)
    return p


class ServoTorqueModel:
    """Servo torques from the driver's currents with the per-servo calibration of a description (none: K_t·I).

    τ_i = K_i (I_i − b_i) − f_c,i tanh(ζ̇_i/ε) − (f_v,i − f̄_v) ζ̇_i − ((ms)_i − m̄s) g cos ζ_i + (ms_y)_i g sin ζ_i:
    the current gain and offset, the friction beyond the model's mean viscous term and the arm's gravity beyond the
    model's (its mean first moment along the arm; the model has none across it) (hexa.calibration.regressor;
    u'_i·g = −g cos ζ_i, u_i·g = −g sin ζ_i). Without ζ̇ only the current part applies."""

    def __init__(self, desc: HexaDescription) -> None:
        from hexa.calibration.regressor import COULOMB_SPEED

        self.calibrated = "calibration" in desc.sections()
        cal = desc.section("calibration") if self.calibrated else {}
        n = 6

        def arr(key: str, default: float) -> NDArray:
            v = cal.get(key)
            return np.full(n, default) if v is None else np.asarray(v, dtype=float).reshape(n)

        self.k = arr("k_t", float(desc.K_t))
        self.b = arr("current_offset", 0.0)
        self.fc = arr("coulomb", 0.0)
        fv = arr("viscous", 0.0)
        self.dfv = fv - fv.mean()
        ms = arr("first_moment", 0.0)
        self.dms_g = (ms - ms.mean()) * 9.81
        self.msy_g = arr("first_moment_y", 0.0) * 9.81
        self.eps = float(cal.get("coulomb_speed", COULOMB_SPEED))   # the smoothing the friction was identified with
        self.friction = self.calibrated and bool(np.any(self.fc) or np.any(self.dfv) or np.any(self.dms_g)
                                                 or np.any(self.msy_g))

    def from_currents(self, currents: NDArray) -> NDArray:
        """K_i (I_i − b_i) (N·m) of six currents (A)."""
        return self.k * (currents - self.b)

    def correct(self, tau: NDArray, zeta: NDArray, zeta_dot: NDArray | None) -> NDArray:
        """`tau` (from `from_currents`) less the per-servo friction and gravity deviations (N·m)."""
        if not self.friction or zeta_dot is None:
            return tau
        zd = np.asarray(zeta_dot, dtype=float)
        return (tau - self.fc * np.tanh(zd / self.eps) - self.dfv * zd - self.dms_g * np.cos(zeta)
                + self.msy_g * np.sin(zeta))
