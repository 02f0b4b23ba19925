"""Domain randomisation of the simulator's images (for training the plate detector); the physics is untouched.

    from hexa.sim.randomize import randomize_scene, restore_scene
    rng = np.random.default_rng(7)
    drawn = randomize_scene(sim, rng)              # lighting, colours, background, occluders, noise
    rgb, depth = sim.render("cam_top")
    restore_scene(sim)                             # back to the description's appearance

What each switch perturbs (all drawn from `rng`, so a seed reproduces a scene):
- lighting: headlight ambient 0.15–0.5 and diffuse 0.3–0.8; top light intensity ×0.4–1.4, direction tilted ≤ 35°.
- colours: arm blue (hue 0.58–0.68, saturation 0.6–1, value 0.5–1 — still "blue" for the HSV isolation), rods near
  white (value 0.75–1), plate dark (value 0.03–0.3), markers' hue ±0.02, the object any hue outside the blues.
- background: walls/floor/ceiling one low-saturation colour (saturation ≤ 0.25, value 0.2–0.7).
- occluders: 0–3 boxes (2–8 cm) floating in the workspace between the base and the plate, random colours.
- noise: colour noise σ 0–5 levels, depth noise 0.5–2 % of range.
"""
from __future__ import annotations

import colorsys
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.sim.mjcf import N_OCCLUDERS, PARK_POS

if TYPE_CHECKING:
    from hexa.sim.simulator import Simulator

_SAVED = "_appearance_saved"


def _hsv(h: float, s: float, v: float) -> list[float]:
    return [*colorsys.hsv_to_rgb(h % 1.0, s, v), 1.0]


def _save(sim: "Simulator") -> dict[str, Any]:
    saved = getattr(sim, _SAVED, None)
    if saved is None:
        m = sim.model
        saved = {"mat_rgba": m.mat_rgba.copy(), "light_diffuse": m.light_diffuse.copy(),
                 "light_dir": m.light_dir.copy(), "ambient": m.vis.headlight.ambient.copy(),
                 "diffuse": m.vis.headlight.diffuse.copy(), "geom_size": m.geom_size.copy(),
                 "geom_rgba": m.geom_rgba.copy(), "rgb_noise": sim.rgb_noise_sigma,
                 "depth_noise": sim.depth_noise_rel}
        setattr(sim, _SAVED, saved)
    return saved


def restore_scene(sim: "Simulator") -> None:
    """Undo every `randomize_scene` on `sim` (appearance of the description, occluders parked)."""
    saved = getattr(sim, _SAVED, None)
    if saved is None:
        return
    m = sim.model
    m.mat_rgba[:] = saved["mat_rgba"]
    m.light_diffuse[:] = saved["light_diffuse"]
    m.light_dir[:] = saved["light_dir"]
    m.vis.headlight.ambient[:] = saved["ambient"]
    m.vis.headlight.diffuse[:] = saved["diffuse"]
    m.geom_size[:] = saved["geom_size"]
    m.geom_rgba[:] = saved["geom_rgba"]
    sim.rgb_noise_sigma = saved["rgb_noise"]
    sim.depth_noise_rel = saved["depth_noise"]
    for k in range(N_OCCLUDERS):
        sim.data.mocap_pos[_occluder_mocap(sim, k)] = PARK_POS


def _occluder_mocap(sim: "Simulator", k: int) -> int:
    return int(sim.model.body_mocapid[sim.model.body(f"occluder_{k}").id])


def randomize_scene(sim: "Simulator", rng: np.random.Generator, lighting: bool = True, colours: bool = True,
                    background: bool = True, occluders: bool = True, noise: bool = True) -> dict[str, Any]:
    """Perturb the appearance of `sim`'s renders (see module docstring); returns what was drawn.

    Calls accumulate on the description's appearance (each call starts from it, not from the previous draw).
    """
    saved = _save(sim)
    restore_scene(sim)
    m = sim.model
    drawn: dict[str, Any] = {}

    def mat(name: str) -> int:
        return m.material(name).id

    if lighting:
        amb = rng.uniform(0.15, 0.5)
        dif = rng.uniform(0.3, 0.8)
        m.vis.headlight.ambient[:] = amb
        m.vis.headlight.diffuse[:] = dif
        top = m.light("top").id
        m.light_diffuse[top] = saved["light_diffuse"][top] * rng.uniform(0.4, 1.4)
        tilt, az = np.radians(rng.uniform(0, 35)), rng.uniform(0, 2 * np.pi)
        m.light_dir[top] = [np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), -np.cos(tilt)]
        drawn["lighting"] = {"ambient": amb, "diffuse": dif}
    if colours:
        m.mat_rgba[mat("arm")] = _hsv(rng.uniform(0.58, 0.68), rng.uniform(0.6, 1.0), rng.uniform(0.5, 1.0))
        m.mat_rgba[mat("rod")] = _hsv(rng.uniform(0, 1), rng.uniform(0, 0.08), rng.uniform(0.75, 1.0))
        m.mat_rgba[mat("plate")] = _hsv(rng.uniform(0, 1), rng.uniform(0, 0.3), rng.uniform(0.03, 0.3))
        for mk in sim.config.markers.items:
            i = mat(f"marker_{mk.name}")
            h, s, v = colorsys.rgb_to_hsv(*saved["mat_rgba"][i][:3])
            m.mat_rgba[i] = _hsv(h + rng.uniform(-0.02, 0.02), s, np.clip(v * rng.uniform(0.8, 1.1), 0, 1))
        h = rng.uniform(0.0, 0.45) if rng.random() < 0.8 else rng.uniform(0.75, 1.0)   # anything but blue
        m.mat_rgba[mat("object")] = _hsv(h, rng.uniform(0.5, 1.0), rng.uniform(0.5, 1.0))
        drawn["colours"] = {"arm": m.mat_rgba[mat("arm")].tolist(), "object": m.mat_rgba[mat("object")].tolist()}
    if background:
        m.mat_rgba[mat("background")] = _hsv(rng.uniform(0, 1), rng.uniform(0, 0.25), rng.uniform(0.2, 0.7))
        drawn["background"] = m.mat_rgba[mat("background")].tolist()
    if occluders:
        n = int(rng.integers(0, N_OCCLUDERS + 1))
        boxes = []
        for k in range(N_OCCLUDERS):
            mid = _occluder_mocap(sim, k)
            if k >= n:
                sim.data.mocap_pos[mid] = PARK_POS
                continue
            r, phi = rng.uniform(0.0, 0.3), rng.uniform(0, 2 * np.pi)
            pos = [r * np.cos(phi), r * np.sin(phi), rng.uniform(-0.5, -0.12)]
            sim.data.mocap_pos[mid] = pos
            q = rng.normal(size=4)
            sim.data.mocap_quat[mid] = q / np.linalg.norm(q)
            g = m.geom(f"occluder_{k}").id
            m.geom_size[g] = rng.uniform(0.01, 0.04, 3)
            m.geom_rgba[g] = _hsv(rng.uniform(0, 1), rng.uniform(0, 1), rng.uniform(0.2, 1))
            boxes.append(pos)
        drawn["occluders"] = boxes
    if noise:
        sim.rgb_noise_sigma = float(rng.uniform(0.0, 5.0))
        sim.depth_noise_rel = float(rng.uniform(0.005, 0.02))
        drawn["noise"] = {"rgb_sigma": sim.rgb_noise_sigma, "depth_rel": sim.depth_noise_rel}
    return drawn
