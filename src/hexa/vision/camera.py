"""Pinhole camera model (distortion-free): projection, back-projection and extrinsics, CameraInfo fields."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class CameraModelError(ValueError):
    """Intrinsics/extrinsics are malformed, or CameraInfo fields cannot define a pinhole camera."""


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A pinhole camera: intrinsics K (px), image size, and the pose of its optical frame in `base`.

    The optical frame is REP-103's: z forward, x right, y down. A pixel (u, v) with depth z (m, along the
    optical axis) back-projects to x_c = z·K⁻¹·[u, v, 1]; points map to base by T_base_camera.
    """

    K: np.ndarray
    width: int
    height: int
    T_base_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    name: str = "camera"
    frame_id: str = "camera_color_optical_frame"

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=float)
        T = np.asarray(self.T_base_camera, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CameraModelError(f"intrinsics K must be a finite 3x3 with fx, fy > 0; got {K.tolist()}")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise CameraModelError(f"T_base_camera must be a finite 4x4; got shape {T.shape}")
        Rm = T[:3, :3]
        if not np.allclose(Rm.T @ Rm, np.eye(3), atol=1e-6) or np.linalg.det(Rm) < 0:
            raise CameraModelError("T_base_camera rotation is not a proper rotation")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise CameraModelError(f"image size must be positive; got {self.width}x{self.height}")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "T_base_camera", T)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    def same_as(self, other: CameraModel | None) -> bool:
        """True when `other` has the same intrinsics, size and extrinsics."""
        return (other is not None and self.width == other.width and self.height == other.height
                and np.array_equal(self.K, other.K) and np.array_equal(self.T_base_camera, other.T_base_camera))

    # --- frames -------------------------------------------------------------------------------------------------
    @property
    def T_camera_base(self) -> np.ndarray:
        """Inverse extrinsics: base → optical frame."""
        T = np.eye(4)
        R = self.T_base_camera[:3, :3]
        T[:3, :3] = R.T
        T[:3, 3] = -R.T @ self.T_base_camera[:3, 3]
        return T

    @property
    def position(self) -> np.ndarray:
        """Optical centre in base (m)."""
        return self.T_base_camera[:3, 3].copy()

    def to_camera(self, points_base: np.ndarray) -> np.ndarray:
        """Points (…, 3) from base into the optical frame."""
        p = np.asarray(points_base, dtype=float)
        R = self.T_base_camera[:3, :3]
        return (p - self.T_base_camera[:3, 3]) @ R

    def to_base(self, points_camera: np.ndarray) -> np.ndarray:
        """Points (…, 3) from the optical frame into base."""
        p = np.asarray(points_camera, dtype=float)
        return p @ self.T_base_camera[:3, :3].T + self.T_base_camera[:3, 3]

    # --- projection ---------------------------------------------------------------------------------------------
    def project(self, points_base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (…, 2) as (u, v) and depths z (…) (m) of points given in base; z ≤ 0 means behind the camera."""
        pc = self.to_camera(points_base)
        z = pc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.K[0, 0] * pc[..., 0] / z + self.K[0, 1] * pc[..., 1] / z + self.K[0, 2]
            v = self.K[1, 1] * pc[..., 1] / z + self.K[1, 2]
        return np.stack([u, v], axis=-1), z

    def back_project(self, pixels: np.ndarray, depth: np.ndarray | float) -> np.ndarray:
        """Points (…, 3) in base for pixels (…, 2) (u, v) at optical-axis depth z (m)."""
        uv = np.asarray(pixels, dtype=float)
        z = np.asarray(depth, dtype=float)
        fx, fy, cx, cy, s = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2], self.K[0, 1]
        y = (uv[..., 1] - cy) / fy
        x = (uv[..., 0] - cx - s * y) / fx
        pc = np.stack([x * z, y * z, np.broadcast_to(z, x.shape)], axis=-1)
        return self.to_base(pc)

    def ray(self, pixels: np.ndarray) -> np.ndarray:
        """Unit viewing directions (…, 3) in base through pixels (…, 2)."""
        p = self.back_project(pixels, 1.0) - self.position
        return p / np.linalg.norm(p, axis=-1, keepdims=True)

    def in_image(self, pixels: np.ndarray) -> np.ndarray:
        """Boolean mask of pixels inside the image."""
        uv = np.asarray(pixels, dtype=float)
        return (uv[..., 0] >= 0) & (uv[..., 0] <= self.width - 1) & (uv[..., 1] >= 0) & (uv[..., 1] <= self.height - 1)

    def point_cloud(self, depth_m: np.ndarray, stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Base-frame points (M, 3) and their (v, u) pixel indices (M, 2) for valid depths (finite, > 0)."""
        d = np.asarray(depth_m, dtype=float)[::stride, ::stride]
        vv, uu = np.nonzero(np.isfinite(d) & (d > 0))
        uv = np.stack([uu * stride, vv * stride], axis=1).astype(float)
        return self.back_project(uv, d[vv, uu]), np.stack([vv * stride, uu * stride], axis=1)

    # --- CameraInfo ---------------------------------------------------------------------------------------------
    def camera_info_fields(self) -> dict:
        """sensor_msgs/CameraInfo fields (plumb_bob, zero distortion) for this model."""
        P = np.zeros((3, 4))
        P[:, :3] = self.K
        return {"width": self.width, "height": self.height, "distortion_model": "plumb_bob",
                "d": [0.0] * 5, "k": self.K.reshape(-1).tolist(), "r": np.eye(3).reshape(-1).tolist(),
                "p": P.reshape(-1).tolist()}

    @classmethod
    def from_camera_info(cls, width: int, height: int, k, d=None, T_base_camera: np.ndarray | None = None,
                         name: str = "camera", frame_id: str = "camera_color_optical_frame") -> CameraModel:
        """Model from CameraInfo fields (k row-major 9 values); non-zero distortion is rejected.

        Raises:
            CameraModelError: k is all zeros (an empty CameraInfo) or distortion is non-zero.
        """
        K = np.asarray(list(k), dtype=float)
        if K.size != 9 or not np.any(K):
            raise CameraModelError(f"CameraInfo k must hold 9 values with fx, fy > 0; got {K.tolist()}")
        if d is not None and len(d) and np.any(np.abs(np.asarray(list(d), dtype=float)) > 1e-9):
            raise CameraModelError(f"distortion {list(d)} is not supported (images must be rectified)")
        return cls(K.reshape(3, 3), int(width), int(height),
                   np.eye(4) if T_base_camera is None else np.asarray(T_base_camera, dtype=float), name, frame_id)

    @classmethod
    def from_any(cls, obj, name: str = "camera") -> CameraModel:
        """Model from another object with K, width, height and T_base_camera attributes or keys (e.g. the
        simulator's)."""
        if isinstance(obj, CameraModel):
            return obj
        get = (lambda k: obj[k]) if isinstance(obj, dict) else (lambda k: getattr(obj, k))
        T = None
        for key in ("T_base_camera", "extrinsics", "T"):
            try:
                T = get(key)
                break
            except (KeyError, AttributeError):
                continue
        frame = name + "_color_optical_frame"
        return cls(np.asarray(get("K"), dtype=float), int(get("width")), int(get("height")),
                   np.eye(4) if T is None else np.asarray(T, dtype=float), name, frame)


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 1.0)
            ) -> np.ndarray:
    """T_base_camera of an optical frame at `eye` looking at `target` (z forward, y down, x right)."""
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z /= np.linalg.norm(z)
    upv = np.asarray(up, dtype=float)
    if abs(np.dot(z, upv)) > 0.999:
        upv = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(z, upv)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def intrinsics(width: int, height: int, fov_y_rad: float) -> np.ndarray:
    """K for a centred pinhole with vertical field of view fov_y (square pixels)."""
    f = 0.5 * height / np.tan(0.5 * fov_y_rad)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
