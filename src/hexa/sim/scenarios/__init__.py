"""Scripted collisions as data: YAML scenarios (the paper's three cases) drawn into concrete collisions by a seed.

A scenario names the trajectory, the link ("plate", "arm", "rod"), the candidate chains and ranges for the onset
time, rise and release times, peak force, position on the link and force direction. `draw_collision(spec, rng)`
picks one concrete `ScriptedCollision`; the force magnitude rises as sin² from 0 at `onset` to `peak_force` at
`onset + rise_time` and falls as cos² to 0 over `release_time` (seed 000 sec 5: contact ≈ 3.4 / 5.2 / 4.4 s, peak
≈ 0.4 s later, 5–10 N).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

SCENARIO_DIR = Path(__file__).resolve().parent
LINKS = ("plate", "arm", "rod")


class ScenarioError(ValueError):
    """A scenario file is missing, malformed, or holds a bad value (named)."""


@dataclass(frozen=True)
class Range:
    nominal: float
    lo: float
    hi: float

    def draw(self, rng: np.random.Generator | None) -> float:
        return self.nominal if rng is None else float(rng.uniform(self.lo, self.hi))


@dataclass(frozen=True)
class ScenarioSpec:
    """A scenario as written in YAML (ranges, not yet drawn)."""

    name: str
    trajectory: str
    link: str
    chains: tuple[int, ...]
    onset: Range
    rise_time: Range
    release_time: Range
    peak_force: Range
    position: Range
    elevation: Range          # rad
    azimuth_jitter: float     # rad
    approach_time: float
    approach_distance: float
    azimuth: float = 0.0      # rad: the nominal deviation of the force direction from the inward normal
    hold_time: float = 0.0    # s at the peak force


@dataclass(frozen=True)
class ScriptedCollision:
    """One concrete collision: everything drawn. Angles in rad, times in s, force in N."""

    name: str
    trajectory: str
    link: str
    chain: int                # 1..6, 0 for the plate
    onset: float
    rise_time: float
    release_time: float
    peak_force: float
    position: float           # plate: polar angle of the border point in {P}; arm/rod: fraction along the link
    elevation: float
    azimuth: float            # deviation of the force direction from the inward normal
    approach_time: float
    approach_distance: float
    hold_time: float = 0.0    # s at the peak force between the rise and the release

    @property
    def peak_time(self) -> float:
        return self.onset + self.rise_time

    @property
    def end_time(self) -> float:
        return self.onset + self.rise_time + self.hold_time + self.release_time

    def force_magnitude(self, t: float) -> float:
        """|F|(t) (N): sin² rise from onset to the peak, held `hold_time`, cos² release, 0 outside."""
        if t < self.onset or t >= self.end_time:
            return 0.0
        if t < self.peak_time:
            return self.peak_force * float(np.sin(0.5 * np.pi * (t - self.onset) / self.rise_time) ** 2)
        if t < self.peak_time + self.hold_time:
            return self.peak_force
        return self.peak_force * float(np.cos(0.5 * np.pi * (t - self.peak_time - self.hold_time)
                                              / self.release_time) ** 2)

    def object_distance(self, t: float) -> float | None:
        """Distance (m) of the object's tip from the contact point at `t`; None when parked out of view."""
        start = self.onset - self.approach_time
        if t < start or t > self.end_time + self.approach_time:
            return None
        if t < self.onset:
            s = (self.onset - t) / self.approach_time
        elif t <= self.end_time:
            return 0.0
        else:
            s = (t - self.end_time) / self.approach_time
        return self.approach_distance * float(s * s * (3 - 2 * s))


def push_direction(collision: ScriptedCollision, point: np.ndarray, axis: np.ndarray | None = None) -> np.ndarray:
    """Unit force direction (base) of a scripted contact at `point` (base, m): the horizontal normal towards the
    base axis turned by the azimuth, raised by the elevation and, on an arm or a rod (`axis`: the link's unit axis),
    made normal to the link."""
    inward = -np.array([point[0], point[1], 0.0])
    if np.linalg.norm(inward) < 1e-9:
        inward = np.array([1.0, 0.0, 0.0])
    inward /= np.linalg.norm(inward)
    ca, sa = np.cos(collision.azimuth), np.sin(collision.azimuth)
    inward = np.array([ca * inward[0] - sa * inward[1], sa * inward[0] + ca * inward[1], 0.0])
    direction = np.cos(collision.elevation) * inward + np.array([0.0, 0.0, np.sin(collision.elevation)])
    if axis is not None:
        direction = direction - (direction @ axis) * axis
    return direction / np.linalg.norm(direction)


def _range(d: dict[str, Any], key: str, scale: float = 1.0) -> Range:
    v = d.get(key)
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return Range(v * scale, v * scale, v * scale)
    if not isinstance(v, dict) or "nominal" not in v:
        raise ScenarioError(f"scenario key '{key}' must be a number or a mapping with 'nominal', got {v!r}")
    try:
        nom = float(v["nominal"])
        if "jitter" in v:
            lo, hi = nom - float(v["jitter"]), nom + float(v["jitter"])
        else:
            lo, hi = float(v.get("min", nom)), float(v.get("max", nom))
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"scenario key '{key}' has a non-numeric value: {v!r}") from exc
    if not lo <= nom <= hi:
        raise ScenarioError(f"scenario key '{key}': nominal {nom} outside [{lo}, {hi}]")
    return Range(nom * scale, lo * scale, hi * scale)


def parse_scenario(data: dict[str, Any]) -> ScenarioSpec:
    """ScenarioSpec from a YAML mapping.

    Raises:
        ScenarioError: naming the bad key.
    """
    if not isinstance(data, dict):
        raise ScenarioError(f"scenario must be a mapping, got {type(data).__name__}")
    for key in ("name", "trajectory", "link", "chains"):
        if key not in data:
            raise ScenarioError(f"scenario is missing key '{key}'")
    link = data["link"]
    if link not in LINKS:
        raise ScenarioError(f"scenario key 'link' must be one of {LINKS}, got {link!r}")
    chains = tuple(int(c) for c in data["chains"])
    valid = (0,) if link == "plate" else tuple(range(1, 7))
    if not chains or any(c not in valid for c in chains):
        raise ScenarioError(f"scenario key 'chains' must be a non-empty list from {valid}, got {list(chains)}")
    spec = ScenarioSpec(
        name=str(data["name"]), trajectory=str(data["trajectory"]), link=link, chains=chains,
        onset=_range(data, "onset"), rise_time=_range(data, "rise_time"),
        release_time=_range(data, "release_time"), peak_force=_range(data, "peak_force"),
        position=_range(data, "position", np.pi / 180 if link == "plate" else 1.0),
        elevation=_range(data, "elevation_deg", np.pi / 180),
        azimuth_jitter=float(np.radians(float(data.get("azimuth_jitter_deg", 0.0)))),
        approach_time=float(data.get("approach_time", 0.6)),
        approach_distance=float(data.get("approach_distance", 0.25)),
        azimuth=float(np.radians(float(data.get("azimuth_deg", 0.0)))),
        hold_time=float(data.get("hold_time", 0.0)),
    )
    if not spec.hold_time >= 0:
        raise ScenarioError(f"scenario key 'hold_time' must be >= 0 s, got {spec.hold_time}")
    if spec.rise_time.lo <= 0 or spec.release_time.lo <= 0:
        raise ScenarioError("scenario keys 'rise_time' and 'release_time' must be > 0")
    if spec.peak_force.lo < 0:
        raise ScenarioError(f"scenario key 'peak_force' must be >= 0, got min {spec.peak_force.lo}")
    if spec.link != "plate" and not 0.0 <= spec.position.lo <= spec.position.hi <= 1.0:
        raise ScenarioError("scenario key 'position' (fraction along the link) must lie in 0..1")
    if spec.approach_time <= 0:
        raise ScenarioError(f"scenario key 'approach_time' must be > 0, got {spec.approach_time}")
    return spec


def load_scenario(name_or_path: str | Path) -> ScenarioSpec:
    """A scenario by name ("plate", "arm", "rod": the files next to this module) or by YAML path.

    Raises:
        ScenarioError: unknown name, unreadable file, or bad content.
    """
    p = Path(name_or_path)
    if not p.suffix:
        p = SCENARIO_DIR / f"{name_or_path}.yaml"
    if not p.is_file():
        known = sorted(f.stem for f in SCENARIO_DIR.glob("*.yaml"))
        raise ScenarioError(f"scenario {str(name_or_path)!r} not found (known: {known})")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ScenarioError(f"scenario {p} is not valid YAML: {exc}") from exc
    return parse_scenario(data)


def scenario_names() -> list[str]:
    """Names of the bundled scenarios."""
    return sorted(f.stem for f in SCENARIO_DIR.glob("*.yaml"))


def draw_collision(spec: ScenarioSpec, rng: np.random.Generator | None = None) -> ScriptedCollision:
    """A concrete collision from `spec`: nominal values when `rng` is None, else drawn uniformly from the ranges."""
    chain = spec.chains[0] if rng is None else int(rng.choice(spec.chains))
    az = spec.azimuth + (0.0 if rng is None else float(rng.uniform(-spec.azimuth_jitter, spec.azimuth_jitter)))
    return ScriptedCollision(
        name=spec.name, trajectory=spec.trajectory, link=spec.link, chain=chain,
        onset=spec.onset.draw(rng), rise_time=spec.rise_time.draw(rng), release_time=spec.release_time.draw(rng),
        peak_force=spec.peak_force.draw(rng), position=spec.position.draw(rng), elevation=spec.elevation.draw(rng),
        azimuth=az, approach_time=spec.approach_time, approach_distance=spec.approach_distance,
        hold_time=spec.hold_time)


def scenario_data(c: ScriptedCollision) -> dict[str, Any]:
    """The YAML mapping of a scenario whose nominal collision is `c` (no ranges): a drawn contact (`hexa eval`'s)
    written for the simulator node's `scenario` parameter."""
    position = float(np.degrees(c.position)) if c.link == "plate" else c.position
    return {"name": c.name, "trajectory": c.trajectory, "link": c.link, "chains": [int(c.chain)],
            "onset": float(c.onset), "rise_time": float(c.rise_time), "release_time": float(c.release_time),
            "hold_time": float(c.hold_time), "peak_force": float(c.peak_force), "position": float(position),
            "elevation_deg": float(np.degrees(c.elevation)), "azimuth_deg": float(np.degrees(c.azimuth)),
            "approach_time": float(c.approach_time), "approach_distance": float(c.approach_distance)}
