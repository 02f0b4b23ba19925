"""The isolation node's core on the simulator's rendered frames, for `hexa eval` (ROS-free).

The isolation node (hexa_vision/isolation_node.py) buffers both cameras' frames, the pose node's plate poses and the
observer's collision events in an `IsolationScheduler` and isolates the pairs it hands out with a `ContactLocator`.
`RenderedIsolation` feeds the same two classes, with the node's defaults, from a running `hexa.sim.Simulator`:
- a frame of each camera every 1/`camera_rate` s of sim time, at the step at which the sim node renders one (its
  `camera_rate_hz`, 30 Hz, from t = 0): the instant's `FrameState` (joints and the pushing object) enters the
  scheduler, and is rendered only when the scheduler hands it out — as a background or in a pair to isolate. These
  are the frames the node would see; the others are never rendered;
- a rendered frame takes the sim node's image path (colour rgb8 and depth 16UC1 in mm with the simulator's image
  noise, `Simulator.render_frame`) and the node's decoding (`FrameAssembler`, given the camera_info of the
  description's cameras);
- the plate poses the run hands over as the pose node's (`add_pose`) and the observer's START / END (`collision`);
- sim time stands for the node's wall clock, and frames, poses and events arrive without transport latency.
Each contact the locator finds (a link, not "none") is what the node publishes on `contact`; `collision` and
`add_pose` return them as the rnea node's `LocatedContact`, with the push direction where measured.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.dynamics.contact_force import LocatedContact
from hexa.rotations import transform_from_pose6
from hexa.sim.camera import camera_model_of
from hexa.sim.config import CAMERA_NAMES, sim_config_of
from hexa.vision.isolation import LINK_NAMES, LINK_UNKNOWN
from hexa.vision.isolation_scheduler import BACKGROUND, ContactLocator, IsolationScheduler, Located
from hexa.vision.sync import RawFrame, RawImage

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription
    from hexa.sim.simulator import FrameState, Simulator

#: Hz of sim time between camera frames (the sim node's `camera_rate_hz` default)
CAMERA_RATE = 30.0


@dataclass
class _Frame:
    """A camera frame in the scheduler's buffer: its stamp and the instant to render (once, when handed out)."""

    stamp: float
    state: FrameState
    raw: RawFrame | None = None


@dataclass
class Evaluation:
    """One isolated pair: its stamp (s), collision id, whether it is the onset pair, the answer (link code, chain,
    point in base, camera, confidence), each camera's reason, and whether its pose was carried forward."""

    stamp: float
    collision_id: int
    onset: bool
    link: int
    chain: int
    point: np.ndarray
    camera: str
    confidence: float
    reasons: dict[str, str]
    coarse: bool

    def as_dict(self) -> dict[str, Any]:
        return {"stamp": self.stamp, "collision_id": self.collision_id, "onset": self.onset,
                "link": LINK_NAMES[self.link], "chain": self.chain, "point": self.point.tolist(),
                "camera": self.camera, "confidence": self.confidence, "reasons": self.reasons, "coarse": self.coarse}


@dataclass
class RenderCost:
    """Wall time spent rendering frames and isolating pairs (s), and how many of each."""

    render_s: float = 0.0
    isolate_s: float = 0.0
    frames_rendered: int = 0
    pairs_isolated: int = 0

    def as_dict(self) -> dict[str, float]:
        return dict(self.__dict__)


@dataclass
class RenderedIsolation:
    """The isolation node's scheduler and locator on frames rendered from `sim` (module docstring).

    Args:
        sim: the simulator, built with cameras (`Simulator(cameras=True)`).
        desc: the nodes' robot description (the cameras' models and the robot drawn into the mask).
        camera_rate: frames per second of sim time.
    """

    sim: Simulator
    desc: HexaDescription
    camera_rate: float = CAMERA_RATE
    evaluations: list[Evaluation] = field(default_factory=list)
    cost: RenderCost = field(default_factory=RenderCost)

    def __post_init__(self) -> None:
        cfg = sim_config_of(self.desc)
        models = {c: camera_model_of(cfg.cameras[c]) for c in CAMERA_NAMES}
        self.scheduler = IsolationScheduler(CAMERA_NAMES)
        self.locator = ContactLocator(self.desc, models)
        for c, m in models.items():   # the camera_info the node receives
            info = m.camera_info_fields()
            self.locator.assemblers[c].set_camera_info(info["width"], info["height"], info["k"], info["d"])
        self._period = 1.0 / self.camera_rate
        self._next_frame = 0.0

    def step(self, now: float) -> list[LocatedContact]:
        """After each simulator step: a frame of each camera when one is due (the first at t = 0); the contacts
        found by the work that became due."""
        t = self.sim.time
        if t + 1e-9 < self._next_frame:
            return []
        self._next_frame += self._period
        state = self.sim.frame_state()
        for c in CAMERA_NAMES:
            self.scheduler.add_frame(c, _Frame(t, state), now)
        return self.run(now)

    def add_pose(self, t: float, pose: np.ndarray, now: float) -> list[LocatedContact]:
        """A plate pose [x y z α β γ] of the pose node at stamp `t`; the contacts found by the work that became due."""
        self.scheduler.add_pose(t, transform_from_pose6(np.asarray(pose, float)))
        return self.run(now)

    def collision(self, kind: str, collision_id: int, onset: float, t: float, now: float) -> list[LocatedContact]:
        """The observer's START (with its `onset`) or END (at `t`); the contacts found by the work that became
        due."""
        if kind == "START":
            self.scheduler.collision_start(collision_id, onset, now)
            return self.run(now)
        self.scheduler.collision_end(collision_id, t)
        return []

    def run(self, now: float) -> list[LocatedContact]:
        """The scheduler's due work, as the node's `_run`: backgrounds, then isolations."""
        out = []
        for work in self.scheduler.due(now):
            if work.kind == BACKGROUND:
                (cam, frame), = work.frames.items()
                if self.locator.take_background(dataclasses.replace(work, frames={cam: self._raw(cam, frame)})):
                    self.scheduler.background_taken(cam)
                continue
            frames = {c: self._raw(c, f) for c, f in work.frames.items() if c in self.locator.isolator.backgrounds}
            t0 = time.perf_counter()
            found = self.locator.locate(dataclasses.replace(work, frames=frames))
            self.cost.isolate_s += time.perf_counter() - t0
            self.cost.pairs_isolated += 1
            if found is None:
                continue
            self._record(found)
            e = found.estimate
            if e.link != LINK_UNKNOWN:
                push = e.push_direction if np.all(np.isfinite(e.push_direction)) else None
                out.append(LocatedContact(work.stamp, work.collision_id, LINK_NAMES[e.link], int(e.chain),
                                          np.asarray(e.point, float).copy(), push))
        return out

    def _raw(self, cam: str, frame: _Frame) -> RawFrame:
        """The frame as the sim node publishes it: rgb8 colour and 16UC1 depth (mm), undecoded."""
        if frame.raw is None:
            t0 = time.perf_counter()
            rgb, depth = self.sim.render_frame(cam, frame.state)
            self.cost.render_s += time.perf_counter() - t0
            self.cost.frames_rendered += 1
            h, w = depth.shape
            frame.raw = RawFrame(frame.stamp, RawImage(frame.stamp, h, w, "rgb8", 0, 3 * w, rgb),
                                 RawImage(frame.stamp, h, w, "16UC1", 0, 2 * w, depth))
        return frame.raw

    def _record(self, found: Located) -> None:
        e, w = found.estimate, found.work
        self.evaluations.append(Evaluation(
            w.stamp, w.collision_id, w.debug, int(e.link), int(e.chain), np.asarray(e.point, float).copy(), e.camera,
            float(e.confidence), {c: r.reason for c, r in e.per_camera.items()}, w.coarse))
