"""The 3UPS+RPU knee-rehabilitation robot (seed 003) loaded from YAML into an immutable description."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hexa.robots.schema import (
    DESCRIPTION_DIR,
    RobotDescriptionError,
    load_yaml,
    require_array,
    require_float,
    require_str,
)

DEFAULT_UPSRPU_PATH = DESCRIPTION_DIR / "upsrpu.yaml"

__all__ = ["UpsrpuDescription", "load_upsrpu", "DEFAULT_UPSRPU_PATH", "RobotDescriptionError"]


@dataclass(frozen=True)
class UpsrpuDescription:
    """Geometry, limits and controller parameters of the 3UPS+RPU (seed 003, Tables 1-3), SI units.

    `base_joints` rows are A0, B0, C0, D0 in the fixed frame; `platform_joints` rows are A1, B1, C1 in the mobile
    frame. Pose X = (x_m, z_m, theta, psi), actuators q_ind = (q13, q23, q33, q42).
    """

    path: str
    geometry: dict[str, float]
    base_joints: np.ndarray           # (4, 3)
    platform_joints: np.ndarray       # (3, 3)
    q_min: np.ndarray                 # (4,)
    q_max: np.ndarray                 # (4,)
    spherical_max: float
    det_jd_limit: float
    omega_limit: float
    nu_d: float
    t_s: float
    wait_before_enable: float
    release_window: float
    actuator_wn: float
    actuator_damping: float
    actuator_v_max: float
    actuator_mass: float
    actuator_stiffness: float
    home: np.ndarray                  # (4,)
    v_translation: float
    v_rotation: float
    dwell_start: float
    singular_poses: np.ndarray        # (5, 4) Table 3
    singular_names: tuple[str, ...]
    _raw: dict[str, Any] = field(repr=False, compare=False)

    def section(self, name: str) -> dict[str, Any]:
        """An extra top-level YAML section owned by another module (validated there).

        Raises:
            RobotDescriptionError: the section is absent or not a mapping.
        """
        sec = self._raw.get(name)
        if not isinstance(sec, dict):
            raise RobotDescriptionError(f"missing section '{name}' in robot description {self.path}")
        return sec


def _read_only(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def load_upsrpu(path: str | Path | None = None) -> UpsrpuDescription:
    """Load and validate the 3UPS+RPU description (default src/hexa/robots/upsrpu.yaml).

    Raises:
        RobotDescriptionError: a key is missing, has the wrong shape, or is out of range (the message names it).
    """
    p = Path(path) if path is not None else DEFAULT_UPSRPU_PATH
    data = load_yaml(p)
    robot = require_str(data, "robot")
    if robot != "upsrpu":
        raise RobotDescriptionError(f"key 'robot' must be 'upsrpu' in {p}, got {robot!r}")
    g: dict[str, float] = {}
    for key in ("R1", "R2", "R3", "d_s", "R_m1", "R_m2", "R_m3"):
        g[key] = require_float(data, f"geometry.{key}", positive=True, hi=10.0)
    for key in ("beta_FD", "beta_FI", "beta_MD", "beta_MI"):
        g[key] = require_float(data, f"geometry.{key}", lo=-2 * np.pi, hi=2 * np.pi)
    base = np.array([
        [-g["R1"], 0.0, 0.0],
        [g["R2"] * np.cos(g["beta_FD"]), g["R2"] * np.sin(g["beta_FD"]), 0.0],
        [g["R3"] * np.cos(g["beta_FI"]), -g["R3"] * np.sin(g["beta_FI"]), 0.0],
        [g["d_s"], 0.0, 0.0],
    ])
    plat = np.array([
        [-g["R_m1"], 0.0, 0.0],
        [g["R_m2"] * np.cos(g["beta_MD"]), g["R_m2"] * np.sin(g["beta_MD"]), 0.0],
        [g["R_m3"] * np.cos(g["beta_MI"]), -g["R_m3"] * np.sin(g["beta_MI"]), 0.0],
    ])
    q_min = require_array(data, "limits.q_min", (4,))
    q_max = require_array(data, "limits.q_max", (4,))
    if np.any(q_min <= 0):
        raise RobotDescriptionError(f"key 'limits.q_min' must be > 0 (m), got {q_min.tolist()}")
    if np.any(q_max <= q_min):
        raise RobotDescriptionError(f"key 'limits.q_max' must exceed limits.q_min element-wise, got {q_max.tolist()}")
    spherical_max = require_float(data, "limits.spherical_max", positive=True, hi=np.pi / 2)
    det_lim = require_float(data, "singularity.det_jd_limit", positive=True)
    om_lim = require_float(data, "singularity.omega_limit", positive=True, hi=np.pi / 2)
    nu_d = require_float(data, "srm.nu_d", positive=True, hi=1.0)
    t_s = require_float(data, "srm.t_s", positive=True, hi=1.0)
    wait = require_float(data, "srm.wait_before_enable", nonneg=True)
    window = require_float(data, "srm.release_window", positive=True)
    wn = require_float(data, "actuators.wn", positive=True)
    damping = require_float(data, "actuators.damping", positive=True)
    v_max = require_float(data, "actuators.v_max", positive=True)
    mass = require_float(data, "actuators.effective_mass", positive=True)
    stiffness = require_float(data, "actuators.axial_stiffness", positive=True)
    home = require_array(data, "trajectories.home", (4,))
    v_tr = require_float(data, "trajectories.v_translation", positive=True, hi=1.0)
    v_rot = require_float(data, "trajectories.v_rotation", positive=True, hi=1.0)
    dwell = require_float(data, "trajectories.dwell_start", nonneg=True)
    raw_poses = data["trajectories"].get("singular_poses")
    if not isinstance(raw_poses, list) or not raw_poses:
        raise RobotDescriptionError("key 'trajectories.singular_poses' must be a non-empty list")
    poses, names = [], []
    for k, item in enumerate(raw_poses):
        key = f"trajectories.singular_poses[{k}]"
        if not isinstance(item, dict):
            raise RobotDescriptionError(f"key '{key}' must be a mapping with name and pose")
        names.append(require_str(item, "name"))
        try:
            poses.append(require_array(item, "pose", (4,)))
        except RobotDescriptionError as exc:
            raise RobotDescriptionError(f"key '{key}.pose': {exc}") from exc
    return UpsrpuDescription(
        path=str(p), geometry=g, base_joints=_read_only(base), platform_joints=_read_only(plat),
        q_min=q_min, q_max=q_max, spherical_max=spherical_max, det_jd_limit=det_lim, omega_limit=om_lim,
        nu_d=nu_d, t_s=t_s, wait_before_enable=wait, release_window=window, actuator_wn=wn,
        actuator_damping=damping, actuator_v_max=v_max, actuator_mass=mass,
        actuator_stiffness=stiffness, home=home,
        v_translation=v_tr, v_rotation=v_rot, dwell_start=dwell, singular_poses=_read_only(np.array(poses)),
        singular_names=tuple(names), _raw=data,
    )
