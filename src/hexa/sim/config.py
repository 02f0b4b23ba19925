"""The simulator's sections of the robot description: `cameras`, `markers`, `appearance`, `sim` (SI units).

They live at top level of src/hexa/robots/hexa.yaml next to the geometry (one YAML per robot) and reach us through
`HexaDescription.section(name)`; this module validates them and names the offending key on error.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from hexa.robots.schema import RobotDescriptionError, require_array, require_float, require_str

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

CAMERA_NAMES = ("cam_top", "cam_side")


class SimConfigError(RobotDescriptionError):
    """A simulator section of the robot description is missing a key or holds a bad value (named)."""


@dataclass(frozen=True)
class CameraConfig:
    """One simulated RGB-D camera: intrinsics (pinhole, square pixels, centred principal point) and extrinsics.

    `T_base_camera` maps points in the camera's optical frame (z forward, x right, y down) to base.
    """

    name: str
    frame_id: str
    width: int
    height: int
    focal_px: float
    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    depth_min: float
    depth_max: float

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix (pixel centres at integer coordinates, OpenCV/ROS convention)."""
        return np.array([[self.focal_px, 0.0, (self.width - 1) / 2.0],
                         [0.0, self.focal_px, (self.height - 1) / 2.0],
                         [0.0, 0.0, 1.0]])

    @property
    def fovy_deg(self) -> float:
        """Vertical field of view (deg) of the MuJoCo camera with these intrinsics."""
        return float(np.degrees(2.0 * np.arctan(self.height / 2.0 / self.focal_px)))

    @property
    def R_base_optical(self) -> np.ndarray:
        """Rotation of the optical frame in base (columns: x right, y down, z forward)."""
        z = self.look_at - self.position
        z = z / np.linalg.norm(z)
        x = np.cross(z, self.up)  # right = forward x up (so that -y is "up" in the image)
        x = x / np.linalg.norm(x)
        y = np.cross(z, x)
        return np.column_stack([x, y, z])

    @property
    def T_base_camera(self) -> np.ndarray:
        """4x4 transform from the optical frame to base."""
        T = np.eye(4)
        T[:3, :3] = self.R_base_optical
        T[:3, 3] = self.position
        return T


@dataclass(frozen=True)
class Marker:
    """A flat coloured disc on the plate's camera-facing side; `position` in {P} (m) on the plate surface."""

    name: str
    position: np.ndarray
    rgb: np.ndarray


@dataclass(frozen=True)
class MarkerConfig:
    radius: float
    thickness: float
    items: tuple[Marker, ...]


@dataclass(frozen=True)
class ServoConfig:
    """Hobby-servo position loop (the torque/speed limits come from the description's servo fields)."""

    kp: float
    kv: float
    armature: float
    damping: float
    frame_period: float = 0.0        # s: servo-board pulse frame; 0: set-points at once (no frames)
    pulse_slot: float = 0.0015       # s from one servo's pulse end to the next one's


@dataclass(frozen=True)
class SimConfig:
    cameras: dict[str, CameraConfig]
    markers: MarkerConfig
    appearance: dict[str, Any]
    timestep: float
    servo: ServoConfig
    current_offset_sigma: float
    current_noise_counts: float
    current_rate_hz: float
    rgb_noise_sigma: float
    depth_noise_rel: float
    camera_rate_hz: float


_RGB_KEYS = ("arm_rgb", "rod_rgb", "plate_rgb", "base_rgb", "servo_rgb", "background_rgb", "object_rgb")
_SIZE_KEYS = ("arm_radius", "rod_radius", "plate_thickness", "base_radius", "room_half_size")


def _wrap(fn, *args, **kw):
    try:
        return fn(*args, **kw)
    except SimConfigError:
        raise
    except RobotDescriptionError as exc:
        raise SimConfigError(str(exc)) from exc


def _camera(name: str, d: Mapping[str, Any]) -> CameraConfig:
    root = {name: d}
    k = f"{name}."
    width = int(_wrap(require_float, root, k + "width", positive=True))
    height = int(_wrap(require_float, root, k + "height", positive=True))
    cam = CameraConfig(
        name=name,
        frame_id=_wrap(require_str, root, k + "frame_id"),
        width=width,
        height=height,
        focal_px=_wrap(require_float, root, k + "focal_px", positive=True),
        position=_wrap(require_array, root, k + "position", (3,)),
        look_at=_wrap(require_array, root, k + "look_at", (3,)),
        up=_wrap(require_array, root, k + "up", (3,)),
        depth_min=_wrap(require_float, root, k + "depth_min", nonneg=True),
        depth_max=_wrap(require_float, root, k + "depth_max", positive=True),
    )
    fwd = cam.look_at - cam.position
    if np.linalg.norm(fwd) < 1e-6:
        raise SimConfigError(f"cameras.{name}: look_at {cam.look_at.tolist()} equals position")
    if np.linalg.norm(np.cross(fwd, cam.up)) < 1e-6 * np.linalg.norm(fwd) * max(float(np.linalg.norm(cam.up)), 1e-12):
        raise SimConfigError(f"cameras.{name}.up {cam.up.tolist()} is parallel to the viewing direction")
    if cam.depth_max <= cam.depth_min:
        raise SimConfigError(f"cameras.{name}.depth_max {cam.depth_max} must exceed depth_min {cam.depth_min}")
    return cam


def parse_sim_config(sections: Mapping[str, Any]) -> SimConfig:
    """Validate the simulator's top-level sections (`cameras`, `markers`, `appearance`, `sim`).

    Args:
        sections: mapping with those four keys (as returned by `desc.section(name)`).

    Raises:
        SimConfigError: naming the missing or bad key.
    """
    for top in ("cameras", "markers", "appearance", "sim"):
        if not isinstance(sections.get(top), Mapping):
            raise SimConfigError(f"missing or non-mapping section '{top}' in robot description")
    cams_raw = sections["cameras"]
    cameras = {}
    for name in CAMERA_NAMES:
        if not isinstance(cams_raw.get(name), Mapping):
            raise SimConfigError(f"missing camera 'cameras.{name}' in robot description")
        cameras[name] = _camera(name, cams_raw[name])

    mk = sections["markers"]
    items = mk.get("items")
    if not isinstance(items, list) or not items:
        raise SimConfigError("key 'markers.items' must be a non-empty list")
    markers = []
    for j, it in enumerate(items):
        root = {"markers": {"items": {str(j): it}}}
        key = f"markers.items.{j}"
        markers.append(Marker(name=_wrap(require_str, root, key + ".name"),
                              position=_wrap(require_array, root, key + ".position", (3,)),
                              rgb=_wrap(require_array, root, key + ".rgb", (3,))))
    root = {"markers": mk}
    marker_cfg = MarkerConfig(radius=_wrap(require_float, root, "markers.radius", positive=True),
                              thickness=_wrap(require_float, root, "markers.thickness", positive=True),
                              items=tuple(markers))

    ap_root = {"appearance": sections["appearance"]}
    appearance: dict[str, Any] = {}
    for key in _RGB_KEYS:
        rgb = _wrap(require_array, ap_root, "appearance." + key, (3,))
        if np.any(rgb < 0) or np.any(rgb > 1):
            raise SimConfigError(f"key 'appearance.{key}' must be within 0..1, got {rgb.tolist()}")
        appearance[key] = rgb
    for key in _SIZE_KEYS:
        appearance[key] = _wrap(require_float, ap_root, "appearance." + key, positive=True)
    appearance["floor_z"] = _wrap(require_float, ap_root, "appearance.floor_z")

    s = {"sim": sections["sim"]}
    # optional keys: absent, the dataclass default holds
    optional = {key: _wrap(require_float, s, f"sim.servo.{key}", **limits)
                for key, limits in (("frame_period", {"nonneg": True, "hi": 0.1}),
                                    ("pulse_slot", {"positive": True, "hi": 0.005}))
                if key in sections["sim"].get("servo", {})}
    servo = ServoConfig(kp=_wrap(require_float, s, "sim.servo.kp", positive=True),
                        kv=_wrap(require_float, s, "sim.servo.kv", nonneg=True),
                        armature=_wrap(require_float, s, "sim.servo.armature", nonneg=True),
                        damping=_wrap(require_float, s, "sim.servo.damping", nonneg=True), **optional)
    return SimConfig(
        cameras=cameras,
        markers=marker_cfg,
        appearance=appearance,
        timestep=_wrap(require_float, s, "sim.timestep", positive=True, hi=0.01),
        servo=servo,
        current_offset_sigma=_wrap(require_float, s, "sim.current_offset_sigma", nonneg=True),
        current_noise_counts=_wrap(require_float, s, "sim.current_noise_counts", nonneg=True),
        current_rate_hz=_wrap(require_float, s, "sim.current_rate_hz", lo=1.0, hi=1000.0),
        rgb_noise_sigma=_wrap(require_float, s, "sim.rgb_noise_sigma", nonneg=True),
        depth_noise_rel=_wrap(require_float, s, "sim.depth_noise_rel", nonneg=True, hi=0.2),
        camera_rate_hz=_wrap(require_float, s, "sim.camera_rate_hz", positive=True),
    )


def sim_config_of(desc: HexaDescription) -> SimConfig:
    """The validated simulator configuration of a HexaDescription (its `section(name)` accessor)."""
    sections = {}
    for top in ("cameras", "markers", "appearance", "sim"):
        try:
            sections[top] = desc.section(top)
        except (KeyError, RobotDescriptionError) as exc:
            raise SimConfigError(f"missing section '{top}' in robot description ({exc})") from exc
    return parse_sim_config(sections)
