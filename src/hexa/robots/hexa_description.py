"""The Hexa (6-RUS) robot description: YAML (SI units) loaded into an immutable, validated model object."""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hexa.robots.schema import (DESCRIPTION_DIR, RobotDescriptionError, load_yaml, require_array, require_float,
                                require_str)

DEFAULT_PATH = DESCRIPTION_DIR / "hexa.yaml"

#: Top-level sections owned by this module; every other top-level key is kept for `section(name)`.
_OWN_SECTIONS = ("name", "kind", "geometry", "kinematics", "inertia", "actuators")


@dataclass(frozen=True, eq=False)
class LinkInertia:
    """Mass (kg), centre of mass (m) and inertia about the COM (kg·m²), both in the link's body frame."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True, eq=False)
class HexaDescription:
    """Immutable Hexa model: geometry (seed 000 §2.1), joint limits, inertias and servo data, all SI.

    `A` (6,3): motor axis points A_i in {O}; `C` (6,3): spherical joints C_i in {P}; `alpha` (6): chain angles
    of eq 5; `sigma` (6): ±1 side of each chain; `l_a`, `l_d`: arm and rod lengths; `zeta_min`, `zeta_max`:
    arm-angle limits; `home_pose`: x y z alpha beta gamma (Z-Y-X, eq 38).
    """

    name: str
    path: Path
    A: np.ndarray
    C: np.ndarray
    alpha: np.ndarray
    sigma: np.ndarray
    l_a: float
    l_d: float
    base_radius: float
    base_half_spacing: float
    plate_radius: float
    plate_joint_angle: float
    home_pose: np.ndarray
    branch: int
    zeta_min: float
    zeta_max: float
    max_alignment: float
    plate: LinkInertia
    arm: LinkInertia
    rod: LinkInertia
    K_t: float
    torque_max: float
    speed_max: float
    current_max: float
    pulse_center_us: float
    us_per_rad: float
    pulse_min_us: float
    pulse_max_us: float
    servo_direction: np.ndarray
    _sections: dict[str, Any] = field(repr=False, compare=False, default_factory=dict)

    # Convenience aliases used by the dynamics.
    @property
    def m_plate(self) -> float:
        return self.plate.mass

    @property
    def m_arm(self) -> float:
        return self.arm.mass

    @property
    def m_rod(self) -> float:
        return self.rod.mass

    @property
    def zeta_center(self) -> float:
        """Middle of the arm-angle range; IK reports ζ in (zeta_center − π, zeta_center + π]."""
        return 0.5 * (self.zeta_min + self.zeta_max)

    def section(self, name: str) -> dict[str, Any]:
        """A deep copy of the extra top-level YAML section `name` (cameras, markers, appearance, sim, …).

        Raises:
            RobotDescriptionError: the description has no such section.
        """
        if name not in self._sections:
            raise RobotDescriptionError(f"missing section '{name}' in robot description {self.path}")
        return copy.deepcopy(self._sections[name])

    def sections(self) -> tuple[str, ...]:
        """Names of the extra top-level sections present."""
        return tuple(self._sections)

    def as_dict(self) -> dict[str, Any]:
        """The model as plain JSON-able data (SI units), for `hexa robot show --json`."""
        def link(li: LinkInertia) -> dict[str, Any]:
            return {"mass": li.mass, "com": li.com.tolist(), "inertia": li.inertia.tolist()}

        return {
            "name": self.name, "kind": "hexa6rus", "path": str(self.path),
            "A": self.A.tolist(), "C": self.C.tolist(), "alpha": self.alpha.tolist(), "sigma": self.sigma.tolist(),
            "l_a": self.l_a, "l_d": self.l_d, "home_pose": self.home_pose.tolist(), "branch": self.branch,
            "zeta_min": self.zeta_min, "zeta_max": self.zeta_max, "max_alignment": self.max_alignment,
            "plate": link(self.plate), "arm": link(self.arm), "rod": link(self.rod),
            "K_t": self.K_t, "torque_max": self.torque_max, "speed_max": self.speed_max,
            "current_max": self.current_max, "pulse_center_us": self.pulse_center_us,
            "us_per_rad": self.us_per_rad, "pulse_min_us": self.pulse_min_us, "pulse_max_us": self.pulse_max_us,
            "servo_direction": self.servo_direction.tolist(), "sections": list(self._sections),
        }


def _rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _length(data: dict[str, Any], key: str, nonneg: bool = False) -> float:
    """A length in metres; values above 5 m are taken for millimetres and rejected."""
    v = require_float(data, key, nonneg=nonneg, positive=not nonneg)
    if v > 5.0:
        raise RobotDescriptionError(f"key '{key}' = {v} is not a plausible length in metres (SI units; mm given?)")
    return v


def _angles(data: dict[str, Any], key: str, shape: tuple[int, ...], bound: float) -> np.ndarray:
    """Angles in radians; magnitudes above `bound` are taken for degrees and rejected."""
    arr = require_array(data, key, shape)
    if np.any(np.abs(arr) > bound):
        raise RobotDescriptionError(f"key '{key}' must hold radians within ±{bound:.4f} (SI units; degrees given?), "
                                    f"got {arr.tolist()}")
    return arr


def _signs(data: dict[str, Any], key: str) -> np.ndarray:
    arr = require_array(data, key, (6,))
    if not np.all(np.isin(arr, (-1.0, 1.0))):
        raise RobotDescriptionError(f"key '{key}' must hold only +1 / -1, got {arr.tolist()}")
    return arr


def _link(data: dict[str, Any], name: str) -> LinkInertia:
    key = f"inertia.{name}"
    mass = require_float(data, f"{key}.mass", positive=True)
    com = require_array(data, f"{key}.com", (3,))
    inertia = require_array(data, f"{key}.inertia", (3, 3))
    if not np.allclose(inertia, inertia.T, atol=1e-12):
        raise RobotDescriptionError(f"key '{key}.inertia' must be symmetric, got {inertia.tolist()}")
    eig = np.linalg.eigvalsh(inertia)
    if np.any(eig < 0):
        raise RobotDescriptionError(f"key '{key}.inertia' must be positive semi-definite, eigenvalues {eig.tolist()}")
    if eig[0] + eig[1] < eig[2] * (1 - 1e-9) - 1e-15:
        raise RobotDescriptionError(f"key '{key}.inertia' violates the triangle inequality, eigenvalues {eig.tolist()}")
    return LinkInertia(mass, com, inertia)


def _freeze(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def parse_hexa(data: dict[str, Any], path: str | Path = "<memory>") -> HexaDescription:
    """Validate a Hexa description mapping and build the model (seed 000 §2.1, eqs 4–5).

    Raises:
        RobotDescriptionError: naming the missing or bad key and its value.
    """
    kind = require_str(data, "kind", ("hexa6rus",))
    del kind
    name = require_str(data, "name")
    r_a = _length(data, "geometry.base_radius")
    h_a = _length(data, "geometry.base_half_spacing", nonneg=True)
    r_c = _length(data, "geometry.plate_radius")
    ang_c = require_float(data, "geometry.plate_joint_angle", lo=0.0, hi=math.pi / 2)
    alpha = _angles(data, "geometry.alpha", (6,), 2 * math.pi)
    sigma = _signs(data, "geometry.sigma")
    l_a = _length(data, "geometry.arm_length")
    l_d = _length(data, "geometry.rod_length")
    if h_a >= r_a:
        raise RobotDescriptionError(f"key 'geometry.base_half_spacing' must be < base_radius {r_a}, got {h_a}")
    home = require_array(data, "kinematics.home_pose", (6,))
    if np.any(np.abs(home[:3]) > 5.0) or np.any(np.abs(home[3:]) > math.pi):
        raise RobotDescriptionError(f"key 'kinematics.home_pose' must be x y z (m) and alpha beta gamma (rad), "
                                    f"got {home.tolist()} (SI units; mm or degrees given?)")
    raw_branch = require_float(data, "kinematics.branch")
    if raw_branch not in (1.0, -1.0):
        raise RobotDescriptionError(f"key 'kinematics.branch' must be +1 or -1, got {raw_branch}")
    zmin = require_float(data, "kinematics.zeta_min", lo=-2 * math.pi, hi=2 * math.pi)
    zmax = require_float(data, "kinematics.zeta_max", lo=-2 * math.pi, hi=2 * math.pi)
    if not zmin < zmax <= zmin + 2 * math.pi:
        raise RobotDescriptionError(
            f"key 'kinematics.zeta_max' must lie in (zeta_min, zeta_min + 2π], got zeta_min={zmin}, zeta_max={zmax}")
    max_align = require_float(data, "kinematics.max_alignment", positive=True, hi=1.0)
    A = np.array([_rz(a) @ (r_a, s * h_a, 0.0) for a, s in zip(alpha, sigma)])
    C = np.array([_rz(a) @ (r_c * math.cos(ang_c), s * r_c * math.sin(ang_c), 0.0) for a, s in zip(alpha, sigma)])
    K_t = require_float(data, "actuators.K_t", positive=True)
    torque_max = require_float(data, "actuators.torque_max", positive=True)
    speed_max = require_float(data, "actuators.speed_max", positive=True)
    current_max = require_float(data, "actuators.current_max", positive=True)
    p_c = require_float(data, "actuators.pulse_center_us", positive=True)
    us_rad = require_float(data, "actuators.us_per_rad", positive=True)
    p_min = require_float(data, "actuators.pulse_min_us", positive=True)
    p_max = require_float(data, "actuators.pulse_max_us", positive=True)
    if not p_min < p_c < p_max:
        raise RobotDescriptionError(
            f"key 'actuators.pulse_center_us' must lie between pulse_min_us {p_min} and pulse_max_us {p_max}, "
            f"got {p_c}")
    direction = _signs(data, "actuators.direction")
    sections = {k: copy.deepcopy(v) for k, v in data.items() if k not in _OWN_SECTIONS}
    return HexaDescription(
        name=name, path=Path(path), A=_freeze(A), C=_freeze(C), alpha=alpha, sigma=sigma, l_a=l_a, l_d=l_d,
        base_radius=r_a, base_half_spacing=h_a, plate_radius=r_c, plate_joint_angle=ang_c, home_pose=home,
        branch=int(raw_branch), zeta_min=zmin, zeta_max=zmax, max_alignment=max_align,
        plate=_link(data, "plate"), arm=_link(data, "arm"), rod=_link(data, "rod"),
        K_t=K_t, torque_max=torque_max, speed_max=speed_max, current_max=current_max,
        pulse_center_us=p_c, us_per_rad=us_rad, pulse_min_us=p_min, pulse_max_us=p_max,
        servo_direction=direction, _sections=sections)


#: the key that makes a YAML file a calibration overlay: the robot description it refines ("" = the packaged one;
#: a relative path is relative to the overlay's directory)
OVERLAY_KEY = "calibration_of"


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """`base` with `over` laid on it: mappings merge key by key, any other value replaces."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


def overlay_base(path: str | Path, data: dict[str, Any]) -> Path:
    """The description an overlay at `path` (its mapping `data`) refines."""
    ref = str(data.get(OVERLAY_KEY) or "")
    if not ref:
        return DEFAULT_PATH
    q = Path(ref).expanduser()
    return q if q.is_absolute() else Path(path).resolve().parent / q


def load_hexa(path: str | Path | None = None) -> HexaDescription:
    """Load and validate the Hexa description at `path` (default src/hexa/robots/hexa.yaml).

    `path` may also be a calibration overlay (`hexa calibrate identify`): a YAML file with `calibration_of: BASE`
    whose sections are laid over the description BASE; the result's `path` is the overlay and its
    `section("calibration")` holds the per-servo values (`calibration_summary` says which overlay is in use).

    Raises:
        RobotDescriptionError: the file is missing or a key is missing / out of range (named).
    """
    p = Path(path) if path is not None else DEFAULT_PATH
    data = load_yaml(p)
    if OVERLAY_KEY in data:
        base = overlay_base(p, data)
        if base.resolve() == p.resolve():
            raise RobotDescriptionError(f"calibration overlay {p} names itself as its base")
        base_data = load_yaml(base)
        if OVERLAY_KEY in base_data:
            raise RobotDescriptionError(f"calibration overlay {p}: its base {base} is an overlay too (one level only)")
        over = {k: v for k, v in data.items() if k != OVERLAY_KEY}
        merged = _merge(base_data, over)
        merged.setdefault("calibration", {})["base"] = str(base)
        return parse_hexa(merged, p)
    return parse_hexa(data, p)


def calibration_summary(desc: HexaDescription) -> str:
    """One line for a node's log: the description in use and the calibration overlay on it, if any."""
    if "calibration" not in desc.sections():
        return f"robot description {desc.path} (no calibration overlay)"
    cal = desc.section("calibration")
    return (f"robot description {cal.get('base', '?')} with calibration overlay {desc.path} "
            f"({cal.get('created', 'undated')}; scale from {cal.get('scale', '?')})")
