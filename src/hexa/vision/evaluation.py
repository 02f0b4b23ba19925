"""Accuracy of the vision pipeline against simulator ground truth: randomised scripted contacts on every link and
chain (isolation: link/chain confusion, point errors), random plate poses (markers), rendered detector sets.

    python -m hexa.vision.evaluation --contacts 120 --markers 60 --json build/vision_eval.json

Needs the simulator (MuJoCo + EGL). Everything is seeded and reproducible.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.robots.plate import hexagon_border_point, plate_outline
from hexa.vision.camera import CameraModel
from hexa.vision.images import depth_to_meters
from hexa.vision.isolation import (
    LINK_ARM,
    LINK_NAMES,
    LINK_PLATE,
    LINK_ROD,
    LINK_UNKNOWN,
    CollisionIsolator,
    ContactEstimate,
    IsolationConfig,
    RobotGeometry,
)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from hexa.robots.hexa_description import HexaDescription
    from hexa.sim.scenarios import ScriptedCollision
    from hexa.sim.simulator import Simulator

LINK_CODE = {"plate": LINK_PLATE, "arm": LINK_ARM, "rod": LINK_ROD, "none": LINK_UNKNOWN}
TRAJECTORIES = ("circle", "helix", "ellipse")
# ranges of the bundled scenarios (src/hexa/sim/scenarios/*.yaml), all chains
POSITION = {"plate": (-np.pi, np.pi), "arm": (0.45, 0.9), "rod": (0.35, 0.85)}
ELEVATION = {"plate": (np.radians(-35), np.radians(10)), "arm": (np.radians(-50), np.radians(-10)),
             "rod": (np.radians(-40), 0.0)}


@dataclass
class ContactSample:
    """Frames of one scripted contact at its force peak, the background frames, the robot state and the truth."""

    link: str
    chain: int
    point: np.ndarray
    pose: np.ndarray
    zeta: np.ndarray
    frames: dict[str, tuple[np.ndarray, np.ndarray]]
    backgrounds: dict[str, tuple[np.ndarray, np.ndarray]]
    cameras: dict[str, CameraModel]
    meta: dict[str, Any] = field(default_factory=dict)


def camera_models(sim: Simulator) -> dict[str, CameraModel]:
    """CameraModel of each simulated camera."""
    return {name: CameraModel.from_any(sim.camera_model(name), name) for name in ("cam_top", "cam_side")}


def draw_contacts(n: int, seed: int = 0, links: tuple[str, ...] = ("plate", "arm", "rod")) -> list[ScriptedCollision]:
    """n ScriptedCollisions cycling through links (and chains 1..6 for arms and rods), randomised within the
    bundled scenarios' ranges; onsets spread over 0.8..3.5 s so the robot is at varied poses of the trajectories."""
    from hexa.sim.scenarios import ScriptedCollision

    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        link = links[k % len(links)]
        chain = 0 if link == "plate" else 1 + (k // len(links)) % 6
        out.append(ScriptedCollision(
            name=f"eval_{k}", trajectory=TRAJECTORIES[int(rng.integers(0, 3))], link=link, chain=chain,
            onset=float(rng.uniform(0.8, 3.5)), rise_time=0.4, release_time=0.3,
            peak_force=float(rng.uniform(5, 10)), position=float(rng.uniform(*POSITION[link])),
            elevation=float(rng.uniform(*ELEVATION[link])), azimuth=float(rng.uniform(-0.35, 0.35)),
            approach_time=0.6, approach_distance=0.25))
    return out


OBJECT_RADIUS, OBJECT_LENGTH = 0.015, 0.25   # the simulator's pushing capsule (hexa.sim.mjcf)
#: m of gap the pushing capsule keeps from every other link for a contact to count as feasible
MIN_CLEARANCE = 0.003
#: s between the poses `contact_clearance` checks
CLEARANCE_STEP = 0.05


def object_clearance(desc: HexaDescription, pose: np.ndarray, zeta: np.ndarray, link: str, chain: int,
                     point: np.ndarray, direction: np.ndarray) -> float:
    """Smallest gap (m) between the simulator's pushing capsule (touching `point`, pushing along `direction`) and
    every link other than the touched one (and the plate itself beyond the capsule's tip, for plate contacts);
    negative when the capsule would pass through a link."""
    from hexa.vision.isolation import plate_distance, segment_distance

    geom = RobotGeometry.from_state(desc, pose, zeta)
    d = direction / np.linalg.norm(direction)
    c0 = point - d * OBJECT_RADIUS
    axis = c0 - np.linspace(0.0, OBJECT_LENGTH, 26)[:, None] * d
    gap = np.inf
    for code, ch, seg, radius in geom.link_segments():
        if LINK_NAMES[code] == link and ch == chain:
            continue
        dist, _ = segment_distance(axis, seg[0], seg[1])
        gap = min(gap, float(dist.min()) - radius - OBJECT_RADIUS)
    if link != "plate":
        gap = min(gap, float(plate_distance(axis, geom).min()) - OBJECT_RADIUS)
    else:   # pushing the border from the plate's inside would pass the capsule through the plate
        far = np.linalg.norm(axis - c0, axis=1) > 2 * OBJECT_RADIUS
        gap = min(gap, float(plate_distance(axis[far], geom).min()) - OBJECT_RADIUS)
    return gap


def contact_clearance(desc: HexaDescription, collision: ScriptedCollision, step: float = CLEARANCE_STEP) -> float:
    """Smallest `object_clearance` (m) of a scripted contact over its approach and hold, on the poses of its
    trajectory every `step` s from the approach's start to the release's end (trajectory time, clamped to the
    trajectory; the robot is kinematic here: IK of each pose). The point on the link and the push direction are
    fixed at the approach's start, as the simulator fixes them (`push_direction`); the capsule's tip is
    `object_distance` from the point. A robot that holds on a START only takes poses of earlier instants, so every
    pose it passes through during the contact is one of these."""
    from hexa.kinematics import hexa6rus as kin
    from hexa.sim.scenarios import push_direction
    from hexa.trajectories import trajectory_named

    traj, duration = trajectory_named(collision.trajectory)
    t0 = collision.onset - collision.approach_time
    times = np.r_[np.arange(t0, collision.end_time, step), collision.end_time]
    local = None
    if collision.link == "plate":
        border = hexagon_border_point(plate_outline(desc), [np.cos(collision.position), np.sin(collision.position)])
        local = np.array([border[0], border[1], 0.0])
    direction, gap = None, np.inf
    for t in times:
        pose = np.asarray(traj(float(np.clip(t, 0.0, duration)))[0], float)
        zeta = kin.inverse_kinematics(desc, pose)
        geom = RobotGeometry.from_state(desc, pose, zeta)
        if local is not None:
            axis, point = None, geom.T_plate[:3, :3] @ local + geom.T_plate[:3, 3]
        else:
            seg = (geom.arms if collision.link == "arm" else geom.rods)[collision.chain - 1]
            axis = (seg[1] - seg[0]) / np.linalg.norm(seg[1] - seg[0])
            point = seg[0] + collision.position * np.linalg.norm(seg[1] - seg[0]) * axis
        if direction is None:
            direction = push_direction(collision, point, axis)
        if axis is not None:
            point = point - (geom.arm_radius if collision.link == "arm" else geom.rod_radius) * direction
        dist = collision.object_distance(float(t)) or 0.0
        gap = min(gap, object_clearance(desc, pose, zeta, collision.link, collision.chain,
                                        point - dist * direction, direction))
    return float(gap)


def render_contact(collision: ScriptedCollision, seed: int = 0, desc: HexaDescription | None = None,
                   min_clearance: float | None = None) -> ContactSample | None:
    """Simulate one scripted contact; background frames at t = 0 (object parked), contact frames at the peak.

    With `min_clearance` (m), returns None when the pushing capsule would pass through another link (a contact no
    real object could make: it would hit that link first)."""
    from hexa.sim import Simulator

    sim = Simulator(scenario=collision, seed=seed)
    try:
        cams = camera_models(sim)
        bgs = {}
        for name in cams:
            rgb, d = sim.render(name)
            bgs[name] = (rgb, depth_to_meters(d, "16UC1"))
        sim.run_until(collision.peak_time)
        st = sim.state()
        truth = sim.ground_truth()
        gap = object_clearance(desc if desc is not None else sim.desc, st.pose, st.zeta, truth.link,
                               int(truth.chain), np.asarray(truth.point), np.asarray(truth.force))
        if min_clearance is not None and gap < min_clearance:
            return None
        frames = {}
        for name in cams:
            rgb, d = sim.render(name)
            frames[name] = (rgb, depth_to_meters(d, "16UC1"))
        return ContactSample(truth.link, int(truth.chain), np.asarray(truth.point, float), np.asarray(st.pose),
                             np.asarray(st.zeta), frames, bgs, cams,
                             {"trajectory": collision.trajectory, "time": float(st.time), "clearance_m": gap,
                              "force_truth": np.asarray(truth.force, float).tolist()})
    finally:
        sim.close()


def marker_pose(sample: ContactSample, desc: HexaDescription) -> np.ndarray | None:
    """Plate pose [x y z α β γ] from the sample's top-camera markers, or None when the fit fails."""
    from hexa.vision.markers import MarkerDetector, MarkerLayout, pose_from_transform

    det = MarkerDetector(MarkerLayout.from_description(desc), sample.cameras["cam_top"])
    fit, _ = det.estimate(*sample.frames["cam_top"])
    return pose_from_transform(fit.T) if fit.ok else None


def isolate_sample(sample: ContactSample, desc: HexaDescription, config: IsolationConfig | None = None,
                   debug: bool = False, pose_from_markers: bool = False
                   ) -> tuple[ContactEstimate, RobotGeometry, CollisionIsolator]:
    """Run the isolation on one sample: robot geometry from the sample's pose and ζ, or (`pose_from_markers`)
    from the plate pose the markers give and the inverse kinematics (the simulator's pose when the fit fails;
    `sample.meta["pose_source"]` says which)."""
    iso = CollisionIsolator(sample.cameras, config)
    for name, (rgb, d) in sample.backgrounds.items():
        iso.set_background(name, rgb, d)
    pose = marker_pose(sample, desc) if pose_from_markers else None
    sample.meta["pose_source"] = "markers" if pose is not None else "simulator"
    geom = (RobotGeometry.from_state(desc, pose) if pose is not None else
            RobotGeometry.from_state(desc, sample.pose, sample.zeta))
    return iso.isolate(sample.frames, geom, debug=debug), geom, iso


@dataclass
class IsolationReport:
    """Link/chain accuracy, point errors (m) and the confusion table (rows truth, columns estimate)."""

    n: int
    link_correct: float
    link_chain_correct: float
    median_error: float
    p90_error: float
    labels: list[str]
    confusion: np.ndarray
    errors: np.ndarray
    per_case: list[dict[str, Any]]

    def as_dict(self) -> dict[str, Any]:
        return {"n": self.n, "link_correct": self.link_correct, "link_chain_correct": self.link_chain_correct,
                "median_error_m": self.median_error, "p90_error_m": self.p90_error, "labels": self.labels,
                "confusion": self.confusion.tolist(), "cases": self.per_case}

    def confusion_markdown(self) -> str:
        """The confusion table in Markdown (rows: truth; columns: estimate)."""
        head = "| truth \\ estimate | " + " | ".join(self.labels) + " |"
        sep = "|---" * (len(self.labels) + 1) + "|"
        rows = [f"| {lab} | " + " | ".join(str(int(v)) for v in self.confusion[i]) + " |"
                for i, lab in enumerate(self.labels)]
        return "\n".join([head, sep, *rows])


def _label(link: str | int, chain: int) -> str:
    name = LINK_NAMES[link] if isinstance(link, int) else link
    return "plate" if name == "plate" else ("none" if name == "none" else f"{name} {chain}")


def contact_samples(n: int, seed: int = 0, min_clearance: float = MIN_CLEARANCE, desc: HexaDescription | None = None,
                    stats: dict[str, int] | None = None) -> Iterator[ContactSample]:
    """n feasible contact samples (see draw_contacts, render_contact); infeasible draws are replaced and counted
    in `stats` ("drawn <link>", "infeasible <link>")."""
    made = k = 0
    pool = draw_contacts(4 * n + 12, seed)
    stats = {} if stats is None else stats
    while made < n and k < len(pool):
        link = pool[k].link
        stats[f"drawn {link}"] = stats.get(f"drawn {link}", 0) + 1
        s = render_contact(pool[k], seed + k, desc, min_clearance)
        k += 1
        if s is not None:
            made += 1
            yield s
        else:
            stats[f"infeasible {link}"] = stats.get(f"infeasible {link}", 0) + 1


def push_direction_error(estimate: np.ndarray, force_truth: ArrayLike | None) -> float:
    """Angle (deg) between the estimated push direction and the true force; NaN when either is missing."""
    if force_truth is None:
        return float("nan")
    e, f = np.asarray(estimate, float), np.asarray(force_truth, float)
    if not (np.all(np.isfinite(e)) and np.linalg.norm(f) > 0):
        return float("nan")
    c = float(e @ f) / (np.linalg.norm(e) * np.linalg.norm(f))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def evaluate_isolation(samples: Iterator[ContactSample] | list[ContactSample], desc: HexaDescription,
                       config: IsolationConfig | None = None, pose_from_markers: bool = False) -> IsolationReport:
    """Isolation accuracy over samples (see IsolationReport and `isolate_sample`)."""
    labels = ["plate"] + [f"arm {i}" for i in range(1, 7)] + [f"rod {i}" for i in range(1, 7)] + ["none"]
    idx = {lab: i for i, lab in enumerate(labels)}
    conf = np.zeros((len(labels), len(labels)), int)
    errors, cases = [], []
    ok_link = ok_both = n = 0
    for s in samples:
        est, _, _ = isolate_sample(s, desc, config, pose_from_markers=pose_from_markers)
        t_lab, e_lab = _label(s.link, s.chain), _label(est.link, est.chain)
        conf[idx[t_lab], idx[e_lab]] += 1
        n += 1
        link_ok = LINK_CODE[s.link] == est.link
        both = link_ok and (s.link == "plate" or est.chain == s.chain)
        ok_link += link_ok
        ok_both += both
        err = float(np.linalg.norm(est.point - s.point)) if est.link != LINK_UNKNOWN else float("nan")
        if both:
            errors.append(err)
        cases.append({"truth": t_lab, "estimate": e_lab, "error_m": err, "camera": est.camera,
                      "push_direction_error_deg": push_direction_error(est.push_direction,
                                                                       s.meta.get("force_truth")),
                      "confidence": est.confidence, "point_truth": s.point.tolist(),
                      "point_estimate": np.asarray(est.point).tolist(), **s.meta})
    e = np.asarray(errors)
    return IsolationReport(n, ok_link / max(n, 1), ok_both / max(n, 1),
                           float(np.median(e)) if e.size else float("nan"),
                           float(np.percentile(e, 90)) if e.size else float("nan"), labels, conf, e, cases)


@dataclass
class MarkerReport:
    n: int
    ok: int
    median_position_error: float
    median_rotation_error: float
    p90_position_error: float
    p90_rotation_error: float

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def random_plate_poses(n: int, seed: int = 0) -> np.ndarray:
    """Plate poses around the paper's workspace (x, y ±0.1 m, z −0.60..−0.50 m, angles ±25°)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n), rng.uniform(-0.60, -0.50, n),
                            np.radians(rng.uniform(-25, 25, (n, 3)))])


def evaluate_markers(n: int, seed: int = 0) -> MarkerReport:
    """Marker pose error on the top camera at random reachable plate poses (rendered with noise)."""
    from hexa.kinematics import hexa6rus as kin
    from hexa.sim import Simulator
    from hexa.vision.markers import MarkerDetector, MarkerLayout
    from hexa.vision.rigid import rotation_angle

    pos, rot, ok = [], [], 0
    poses = random_plate_poses(3 * n, seed)
    used = 0
    for pose in poses:
        if used >= n:
            break
        try:
            sim = Simulator(pose=pose, seed=seed + used)
        except Exception:  # noqa: BLE001 - unreachable pose: draw another
            continue
        used += 1
        try:
            cam = CameraModel.from_any(sim.camera_model("cam_top"), "cam_top")
            det = MarkerDetector(MarkerLayout.from_description(sim.desc), cam)
            rgb, d = sim.render("cam_top")
            st = sim.state()
        finally:
            sim.close()
        fit, _ = det.estimate(rgb, depth_to_meters(d, "16UC1"))
        if not fit.ok:
            continue
        ok += 1
        pos.append(float(np.linalg.norm(fit.t - st.pose[:3])))
        rot.append(float(rotation_angle(fit.R, kin.rotation_zyx(*st.pose[3:]))))
    p, r = np.asarray(pos), np.asarray(rot)
    nan = float("nan")
    return MarkerReport(used, ok, float(np.median(p)) if p.size else nan, float(np.median(r)) if r.size else nan,
                        float(np.percentile(p, 90)) if p.size else nan, float(np.percentile(r, 90)) if r.size else nan)


def write_debug_images(desc: HexaDescription, folder: str, seed: int = 0) -> list[str]:
    """One debug mosaic (Figs. 12/17/22 style) per link, from the first correctly isolated sample of each."""
    import os

    import cv2

    from hexa.vision.isolation import debug_image

    os.makedirs(folder, exist_ok=True)
    done: list[str] = []
    for s in contact_samples(30, seed + 100, desc=desc):
        if s.link in done:
            continue
        est, geom, iso = isolate_sample(s, desc, debug=True)
        if est.link_name != s.link or (s.link != "plate" and est.chain != s.chain):
            continue
        if s.link in ("plate", "rod") and est.camera != "cam_top":
            continue   # the paper's case 1 / 3 figures come from the top camera
        box = None
        if est.camera == "cam_top":
            try:
                from hexa.vision.detector import PlateDetector

                dets = PlateDetector().detect(s.frames["cam_top"][0])
                box = dets[0].box if dets else None
            except Exception:  # noqa: BLE001 - no weights: no box in the mosaic
                box = None
        img = debug_image(est.per_camera[est.camera], iso, geom, box=None if box is None else box.tolist())
        path = os.path.join(folder, f"vision_{s.link}.png")
        cv2.imwrite(path, cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
        done.append(s.link)
        if len(done) == 3:
            break
    return done


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hexa.vision.evaluation", description=__doc__.split("\n")[0])
    ap.add_argument("--contacts", type=int, default=120)
    ap.add_argument("--markers", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default="")
    ap.add_argument("--pose-from-markers", action="store_true",
                    help="robot geometry from the marker pose + IK instead of the simulator's pose")
    ap.add_argument("--debug-dir", default="", help="write one debug mosaic per link (vision_<link>.png) here")
    a = ap.parse_args(argv)
    from hexa.robots.hexa_description import load_hexa

    desc = load_hexa()
    t0 = time.time()
    out: dict[str, Any] = {}
    if a.contacts:
        stats: dict[str, int] = {}
        rep = evaluate_isolation(contact_samples(a.contacts, a.seed, desc=desc, stats=stats), desc,
                                 pose_from_markers=a.pose_from_markers)
        out["isolation"] = rep.as_dict()
        out["isolation"]["draws"] = stats
        print("draws:", stats)
        print(f"isolation: n={rep.n} link {100 * rep.link_correct:.1f}% link+chain {100 * rep.link_chain_correct:.1f}% "
              f"median {1e3 * rep.median_error:.1f} mm p90 {1e3 * rep.p90_error:.1f} mm")
        print(rep.confusion_markdown())
    if a.debug_dir:
        write_debug_images(desc, a.debug_dir, a.seed)
    if a.markers:
        mr = evaluate_markers(a.markers, a.seed)
        out["markers"] = mr.as_dict()
        print(f"markers: {mr.ok}/{mr.n} fitted, median {1e3 * mr.median_position_error:.2f} mm / "
              f"{np.degrees(mr.median_rotation_error):.2f} deg, p90 {1e3 * mr.p90_position_error:.2f} mm / "
              f"{np.degrees(mr.p90_rotation_error):.2f} deg")
    out["seconds"] = time.time() - t0
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
