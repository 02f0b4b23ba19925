"""Simulated RGB-D cameras: one-pass MuJoCo rendering of colour + aligned depth, D435-like noise and quantisation.

Depth model (per pixel, z = range along the optical axis in m):
    z_noisy = z * (1 + depth_noise_rel * n),  n ~ N(0, 1)        (sigma grows with range: 1 % of z by default)
    depth_mm = round(1000 * z_noisy)  (uint16),  0 where z < depth_min, z > depth_max or nothing was hit
Colour model: rgb = clip(render + round(rgb_noise_sigma * n), 0, 255) (uint8), n ~ N(0, 1) per channel.
Noise is drawn from a seeded bank of standard normals read at a random offset each frame (fast and deterministic).
"""
from __future__ import annotations

import os

import cv2
import numpy as np

from hexa.sim.config import CameraConfig
from hexa.vision.camera import CameraModel

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402  (MUJOCO_GL must be set before the import)


class RenderError(RuntimeError):
    """Rendering failed (no GL context, unknown camera)."""


def rendering_unavailable() -> str | None:
    """Why this process cannot render headless (the GL back-end's error, MUJOCO_GL named), or None when it can: a
    small offscreen GL context is made and freed."""
    try:
        gl = mujoco.GLContext(16, 16)
    except Exception as exc:  # noqa: BLE001 - any GL back-end failure
        return f"no headless GL context (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {exc}"
    try:
        gl.make_current()
    except Exception as exc:  # noqa: BLE001
        return f"the headless GL context cannot be made current (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {exc}"
    finally:
        gl.free()
    return None


def camera_model_of(cfg: CameraConfig) -> CameraModel:
    """The pinhole CameraModel (hexa.vision.camera) of a validated camera configuration."""
    return CameraModel(K=cfg.K, width=cfg.width, height=cfg.height, T_base_camera=cfg.T_base_camera, name=cfg.name,
                       frame_id=cfg.frame_id)


def mjcf_camera(cfg: CameraConfig) -> str:
    """The MJCF <camera> element (MuJoCo cameras look along -z with y up: x = optical x, y = -optical y)."""
    R = cfg.R_base_optical
    x, y = R[:, 0], -R[:, 1]
    pos = " ".join(f"{v:.6g}" for v in cfg.position)
    xy = " ".join(f"{v:.9g}" for v in (*x, *y))
    return (f'<camera name="{cfg.name}" mode="fixed" pos="{pos}" xyaxes="{xy}" fovy="{cfg.fovy_deg:.9g}" '
            f'resolution="{cfg.width} {cfg.height}"/>')


class NoiseBank:
    """A fixed block of standard normals, read at a seeded random offset: cheap per-frame noise, reproducible."""

    def __init__(self, size: int, seed: int) -> None:
        self._rng = np.random.default_rng(seed)
        self._bank = self._rng.standard_normal(2 * size).astype(np.float32)
        self._size = size
        self._levels: dict[float, np.ndarray] = {}

    def draw(self, n: int) -> np.ndarray:
        """n standard normals (a view; do not modify)."""
        if n > self._size:
            return self._rng.standard_normal(n).astype(np.float32)
        off = int(self._rng.integers(0, self._size))
        return self._bank[off:off + n]

    def draw_levels(self, n: int, sigma: float) -> np.ndarray:
        """The draw `draw(n)` would make, scaled by `sigma` and rounded to whole levels (int16; a view, do not
        modify): the same offset, so the noise stream is the same as `draw`'s."""
        if n > self._size:
            return np.rint(sigma * self.draw(n)).astype(np.int16)
        levels = self._levels.get(sigma)
        if levels is None:
            levels = self._levels[sigma] = np.rint(np.float32(sigma) * self._bank).astype(np.int16)
        off = int(self._rng.integers(0, self._size))
        return levels[off:off + n]

    @property
    def rng(self) -> np.random.Generator:
        return self._rng


class RGBDRenderer:
    """Offscreen EGL renderer of one model: colour and depth read from a single render pass per camera."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int) -> None:
        self.model = model
        self.width, self.height = width, height
        try:
            self._gl = mujoco.GLContext(width, height)
            self._gl.make_current()
        except Exception as exc:  # noqa: BLE001 - any GL back-end failure
            raise RenderError(f"cannot create a headless GL context (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): "
                              f"{exc}") from exc
        self._con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._con)
        self._con.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=2000)
        self._opt = mujoco.MjvOption()
        self._cam = mujoco.MjvCamera()
        self._cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._rgb = np.empty((height, width, 3), np.uint8)
        self._depth = np.empty((height, width), np.float32)
        extent = model.stat.extent
        znear = np.float32(model.vis.map.znear * extent)
        zfar = np.float32(model.vis.map.zfar * extent)
        c = -(zfar + znear) / (zfar - znear)
        d = -(np.float32(2) * zfar * znear) / (zfar - znear)
        self._c = float(np.float32(-0.5) * c - np.float32(0.5))
        self._d = float(np.float32(-0.5) * d)
        self._zfar = float(zfar)

    def render(self, data: mujoco.MjData, camera_id: int) -> tuple[np.ndarray, np.ndarray]:
        """Colour (H,W,3 uint8, row 0 at the top) and metric depth along the optical axis (H,W float32 m; inf =
        nothing hit) from camera `camera_id`."""
        if not 0 <= camera_id < self.model.ncam:
            raise RenderError(f"camera id {camera_id} outside 0..{self.model.ncam - 1}")
        self._gl.make_current()
        self._cam.fixedcamid = camera_id
        mujoco.mjv_updateScene(self.model, data, self._opt, None, self._cam, mujoco.mjtCatBit.mjCAT_ALL.value,
                               self._scene)
        mujoco.mjr_render(self._rect, self._scene, self._con)
        mujoco.mjr_readPixels(self._rgb, self._depth, self._rect, self._con)
        rgb = np.flipud(self._rgb).copy()
        buf = np.flipud(self._depth).astype(np.float64)
        with np.errstate(divide="ignore"):
            depth = (self._d / (buf + self._c)).astype(np.float32)
        depth[(buf <= 0.0) | (depth >= self._zfar * 0.999)] = np.inf
        return rgb, depth

    def close(self) -> None:
        if getattr(self, "_gl", None) is not None:
            try:
                self._gl.make_current()
                self._con.free()
            finally:
                self._gl.free()
                self._gl = None

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001
            pass


def depth_image_mm(depth_m: np.ndarray, cfg: CameraConfig, rel_sigma: float, noise: NoiseBank | None
                   ) -> np.ndarray:
    """uint16 depth in mm with range-proportional Gaussian noise and 1 mm quantisation; 0 = invalid (see module)."""
    z = depth_m
    invalid = ~((z >= cfg.depth_min) & (z <= cfg.depth_max))      # also inf (nothing hit) and NaN
    if noise is not None and rel_sigma > 0:
        zn = np.multiply(noise.draw(z.size).reshape(z.shape), rel_sigma, dtype=np.float32)
        zn += 1.0
        zn *= z                                                     # z (1 + rel_sigma n), in place
    else:
        zn = z.astype(np.float32)
    zn *= 1000.0
    with np.errstate(invalid="ignore"):
        np.rint(zn, out=zn)
        np.clip(zn, 0, 65535, out=zn)
        mm = zn.astype(np.uint16)
    mm[invalid] = 0
    return mm


def noisy_rgb(rgb: np.ndarray, sigma: float, noise: NoiseBank | None) -> np.ndarray:
    """uint8 colour with additive Gaussian noise of `sigma` levels (see module)."""
    if noise is None or sigma <= 0:
        return rgb
    levels = noise.draw_levels(rgb.size, sigma).reshape(rgb.shape)
    # rgb + round(sigma n) saturated to 0..255 in one pass: round(x + y) = x + round(y) for whole x
    return cv2.add(np.ascontiguousarray(rgb), levels, dtype=cv2.CV_8U)
