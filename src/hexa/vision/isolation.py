"""Collision isolation with two RGB-D cameras (seed 000 §3.2, Figures 4, 5, 12, 17, 22): which link, which chain,
and where.

Per camera (the paper's flow, Figure 4):
  1. the robot is "determined": its links are known from the plate pose (markers) and the inverse kinematics, and
     are drawn into a robot mask; the paper's colour cues are computed too — YCbCr (bright, unsaturated) + Canny +
     Hough lines for the rods, HSV blue for the arms — and shown in the debug image;
  2. grayscale background subtraction (plus depth change) gives the changed pixels; depth gating keeps only points
     inside the robot's workspace (the paper's "objects in the workspace", Fig. 12d / 17b);
  3. external object = changed, in-workspace pixels minus the robot mask (Fig. 12e);
  4. object pixels touching a link with consistent depth (their 3D point within `touch_distance` of the link's
     surface) are the contact candidates (Fig. 12f / 17f / 22f); the link with the most, closest candidates wins,
     unless an elongated object's axis, followed out of its end, meets another link first (not in the paper: a
     stick pushes with its end, and its body may lie along a link it does not push);
  5. contact point: plate — mean of the candidates, the line from the plate centre through it, intersected with
     the hexagonal border (Fig. 12g); rod/arm — mean of the candidates projected on the link axis, moved to the
     surface facing the object (Fig. 17g / 22g).
  6. push direction (not in the paper): when the object is elongated (a stick, a forearm), its axis — the principal
     direction of its points — oriented from the object into the link; of the cameras that agree on the link, the
     one that sees the object longest (least foreshortened) gives it. The rnea node can take it as the direction
     of an arm force, whose two other components the dynamics cannot see (hexa.dynamics.identification).
The top camera is evaluated first (plate and rods, case 1); the side camera (arms, case 2) when the top camera
finds nothing, and the more confident answer is kept when both do. Pixels → 3D with the camera model.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from hexa.robots.plate import hexagon_border_point, plate_outline
from hexa.vision.camera import CameraModel

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

LINK_PLATE, LINK_ARM, LINK_ROD, LINK_UNKNOWN = 0, 1, 2, 255
LINK_NAMES = {LINK_PLATE: "plate", LINK_ARM: "arm", LINK_ROD: "rod", LINK_UNKNOWN: "none"}


class IsolationError(ValueError):
    """Input frames cannot be used (no background yet, size or encoding mismatch, empty depth); names the problem."""


# ----------------------------------------------------------------------------------------------------------------
# geometry of the robot at one instant
@dataclass(frozen=True)
class RobotGeometry:
    """Links of the Hexa in base at one instant: arms A_i→B_i, rods B_i→C_i (capsules), the hexagonal plate prism.

    hexagon: (6, 2) plate outline in {P} through the C_i, ordered by angle; T_plate: 4x4 plate pose in base.
    """

    arms: np.ndarray          # (6, 2, 3)
    rods: np.ndarray          # (6, 2, 3)
    T_plate: np.ndarray       # (4, 4)
    hexagon: np.ndarray       # (6, 2)
    arm_radius: float
    rod_radius: float
    plate_half_thickness: float

    @classmethod
    def from_state(cls, desc: HexaDescription, pose: np.ndarray, zeta: np.ndarray | None = None) -> RobotGeometry:
        """Geometry from the plate pose [x y z α β γ] (m, rad) and arm angles ζ (IK of the pose when None)."""
        from hexa.kinematics import hexa6rus as kin

        pose = np.asarray(pose, dtype=float)
        if zeta is None:
            zeta = kin.inverse_kinematics(desc, pose)
        A = np.asarray(desc.A, dtype=float)
        B = np.asarray(kin.elbows(desc, np.asarray(zeta, dtype=float)), dtype=float)
        C = np.asarray(kin.plate_joints(desc, pose), dtype=float)
        T = np.eye(4)
        T[:3, :3] = kin.rotation_zyx(*pose[3:])
        T[:3, 3] = pose[:3]
        hexagon = plate_outline(desc)
        ap = _appearance(desc)
        return cls(np.stack([A, B], axis=1), np.stack([B, C], axis=1), T, hexagon, ap["arm_radius"],
                   ap["rod_radius"], ap["plate_thickness"] / 2.0)

    def link_segments(self, rod_end_clearance: float = 0.0) -> list[tuple[int, int, np.ndarray, float]]:
        """(link code, chain, (2, 3) end points, radius) for the 12 capsules; rods may stop `rod_end_clearance`
        (m) short of the plate joint, so that points at the plate's corners count for the plate."""
        out = [(LINK_ARM, i + 1, self.arms[i], self.arm_radius) for i in range(6)]
        for i in range(6):
            seg = self.rods[i].copy()
            if rod_end_clearance > 0:
                e = seg[1] - seg[0]
                seg[1] = seg[1] - rod_end_clearance * e / np.linalg.norm(e)
            out.append((LINK_ROD, i + 1, seg, self.rod_radius))
        return out

    def plate_corners(self) -> np.ndarray:
        """(12, 3) corners of the plate prism in base."""
        h = self.plate_half_thickness
        loc = np.array([[x, y, z] for z in (-h, h) for x, y in self.hexagon])
        return loc @ self.T_plate[:3, :3].T + self.T_plate[:3, 3]


def _appearance(desc: HexaDescription) -> dict[str, float]:
    try:
        ap = desc.section("appearance")
    except Exception:  # noqa: BLE001 - description without the simulator's section: nominal sizes
        ap = {}
    return {"arm_radius": float(ap.get("arm_radius", 0.006)), "rod_radius": float(ap.get("rod_radius", 0.004)),
            "plate_thickness": float(ap.get("plate_thickness", 0.01))}


def segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances (N,) of points (N, 3) to the segment a–b and the segment parameter s ∈ [0, 1] of the closest point."""
    ab = b - a
    s = np.clip(((points - a) @ ab) / max(float(ab @ ab), 1e-18), 0.0, 1.0)
    closest = a + s[:, None] * ab
    return np.linalg.norm(points - closest, axis=1), s


def segment_distances(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`segment_distance` of points (N, 3) to K segments a[k]–b[k] at once: distances and parameters, both (K, N).

    One matrix product gives every p·a_k and p·(b_k − a_k); the distance follows from
    |p − a − s·ab|² = |p − a|² − 2 s (p − a)·ab + s² |ab|² (equal to the per-segment form to ~1e-12 m at the
    robot's scale, several times faster for the tens of thousands of object points of a frame).
    """
    p = np.asarray(points, float)
    a, ab = np.asarray(a, float), np.asarray(b, float) - np.asarray(a, float)
    k = len(a)
    pa_ab = p @ np.concatenate([a, ab]).T                       # (N, 2K): p·a_k, p·ab_k
    ab2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    t = (pa_ab[:, k:] - np.einsum("ij,ij->i", a, ab)).T          # (K, N): (p − a)·ab
    s = np.clip(t / ab2[:, None], 0.0, 1.0)
    pa2 = np.einsum("ij,ij->i", p, p)[None, :] - 2.0 * pa_ab[:, :k].T + np.einsum("ij,ij->i", a, a)[:, None]
    d2 = pa2 - s * (2.0 * t - s * ab2[:, None])
    return np.sqrt(np.maximum(d2, 0.0)), s


def surface_distances(points: np.ndarray, seg_ends: np.ndarray, radii: np.ndarray, geom: RobotGeometry
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Distances (K + 1, N) of points (N, 3) to the surfaces of K capsules (`seg_ends` (K, 2, 3), `radii` (K,)) and,
    in the last row, to the plate prism; and the capsules' segment parameters (K, N) of the closest points."""
    d = np.empty((len(seg_ends) + 1, len(points)))
    d[:-1], s = segment_distances(points, seg_ends[:, 0], seg_ends[:, 1])
    d[:-1] -= np.asarray(radii, float)[:, None]
    d[-1] = plate_distance(points, geom)
    return d, s


def plate_distance(points: np.ndarray, geom: RobotGeometry) -> np.ndarray:
    """Distances (N,) of points in base to the plate prism (0 inside)."""
    R, t = geom.T_plate[:3, :3], geom.T_plate[:3, 3]
    q = (points - t) @ R
    hexa = np.asarray(geom.hexagon, float)
    e = np.roll(hexa, -1, axis=0) - hexa                         # edge k: hexa[k] → hexa[k + 1]
    # inside: on the left of every edge, e_x (q_y − a_y) − e_y (q_x − a_x) ≥ 0
    cross = q[:, :2] @ np.stack([-e[:, 1], e[:, 0]]) - (e[:, 0] * hexa[:, 1] - e[:, 1] * hexa[:, 0])
    inside = np.all(cross >= 0, axis=1)
    zero = np.zeros((len(hexa), 1))
    d_edge, _ = segment_distances(np.column_stack([q[:, :2], np.zeros(len(q))]), np.hstack([hexa, zero]),
                                  np.hstack([hexa + e, zero]))
    d_xy = np.where(inside, 0.0, d_edge.min(axis=0))
    d_z = np.maximum(np.abs(q[:, 2]) - geom.plate_half_thickness, 0.0)
    return np.hypot(d_xy, d_z)


def hexagon_line_entry(hexagon: np.ndarray, origin: np.ndarray, direction: np.ndarray,
                       max_back: float = 0.05) -> np.ndarray | None:
    """Where the 2D line origin + s·direction crosses the hexagon border nearest to `origin` (s ≥ −max_back), or
    None when it misses the hexagon."""
    best = None
    n = len(hexagon)
    for k in range(n):
        a, b = hexagon[k], hexagon[(k + 1) % n]
        M = np.column_stack([direction, a - b])
        if abs(np.linalg.det(M)) < 1e-12:
            continue
        s, u = np.linalg.solve(M, a - origin)
        if -1e-9 <= u <= 1 + 1e-9 and s >= -max_back and (best is None or abs(s) < abs(best)):
            best = s
    return None if best is None else origin + best * direction


def hexagon_line_crossing(hexagon: np.ndarray, origin: np.ndarray, direction: np.ndarray, near: np.ndarray
                          ) -> np.ndarray | None:
    """The crossing of the 2D line origin + s·direction with the hexagon border that lies nearest to `near`, or
    None when the line misses the hexagon."""
    best, best_d = None, np.inf
    n = len(hexagon)
    for k in range(n):
        a, b = hexagon[k], hexagon[(k + 1) % n]
        M = np.column_stack([direction, a - b])
        if abs(np.linalg.det(M)) < 1e-12:
            continue
        s, u = np.linalg.solve(M, a - origin)
        if -1e-9 <= u <= 1 + 1e-9:
            p = origin + s * direction
            d = float(np.linalg.norm(p - near))
            if d < best_d:
                best, best_d = p, d
    return best


# ----------------------------------------------------------------------------------------------------------------
@dataclass
class IsolationConfig:
    """Thresholds of the isolation procedure (SI units; pixel thresholds in grey levels / px)."""

    gray_threshold: int = 22            # |gray − background| that counts as changed
    depth_change: float = 0.03          # m of depth change that counts as changed
    workspace_radius: float = 0.45      # m, cylinder about the base z axis
    workspace_z: tuple[float, float] = (-0.74, 0.06)   # m, z range in base (floor at -0.80 excluded)
    robot_margin_px: float = 2.0        # px added around the drawn robot links
    robot_margin_m: float = 0.002       # m added to link radii when drawing the robot
    touch_distance: float = 0.03        # m between an object point and a link surface to count as touching
    rod_end_clearance: float = 0.03     # m of each rod next to its plate joint attributed to the plate
    corner_radius: float = 0.045        # m: a rod contact this near its plate joint is the plate's corner when
    #                                     another camera finds the plate touched
    closest_points: int = 12            # k nearest object points that decide which link the object comes closest to
    contact_gap: float = 0.018          # m: the object must come this close to a link to call it a contact
    contact_sigma: float = 0.003        # m: width of the Gaussian weights on the nearest points
    smooth_px: int = 7                  # normalised box filter (px) of the object's depth before lifting to 3D
    axis_elongation: float = 2.5        # object point spread ratio above which its axis guides the plate contact
    above_plate: float = 0.010          # m: a coloured pixel this far above the plate's surface is an object
    axis_contact: bool = True           # arm/rod: the contact lies where the object's axis crosses the link
    axis_max_shift: float = 0.03        # m: largest move along the link from the nearest points' mean
    tip_length: float = 0.02            # m of the object's ends compared to find its pushing end
    tip_gap: float = 0.006              # m: an elongated object's axis, followed out of its end, meets a link when
    #                                     it passes this near its surface (0: the nearest points alone decide)
    tip_reach: float = 0.04             # m beyond the object's visible end that its axis is followed
    min_confidence: float = 0.5         # a camera earlier in `order` wins unless its confidence is below this
    min_touch_points: int = 12          # fewer candidates → no contact in this camera
    min_object_area: int = 30           # px, smaller object blobs are noise
    depth_rel_sigma: float = 0.01       # depth noise relative to range (for the confidence)
    blue_hsv: tuple[tuple[int, int, int], tuple[int, int, int]] = ((95, 80, 30), (130, 255, 255))
    rod_ycbcr: tuple[int, int] = (150, 24)  # Y ≥ …, |Cb − 128| and |Cr − 128| ≤ … (bright unsaturated rods)
    foreign_min_saturation: int = 110   # HSV S ≥ … and V ≥ … (and not blue): an object pixel in front of a link
    foreign_min_value: int = 60


@dataclass
class CameraResult:
    """What one camera concluded: link code, chain, contact point (base), pixel, confidence, counts; debug layers."""

    camera: str
    link: int = LINK_UNKNOWN
    chain: int = 0
    point: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    pixel: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    confidence: float = 0.0
    n_candidates: int = 0
    n_object: int = 0
    reason: str = ""
    push_direction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    elongation: float = 0.0     # spread ratio of the object's points (1st / 2nd principal direction)
    layers: dict[str, Any] = field(default_factory=dict)

    @property
    def found(self) -> bool:
        return self.link != LINK_UNKNOWN


@dataclass
class ContactEstimate:
    """The isolation's answer (hexa_msgs/Contact fields): link code, chain 1..6 (0 plate/unknown), point in base (m),
    pixel in `camera`'s image, confidence 0..1; and each camera's result. push_direction: unit vector (base) along
    the elongated object's axis, from the object into the link (NaN when the object is not elongated, step 6)."""

    link: int
    chain: int
    point: np.ndarray
    pixel: np.ndarray
    camera: str
    confidence: float
    per_camera: dict[str, CameraResult]
    push_direction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))

    @property
    def link_name(self) -> str:
        return LINK_NAMES[self.link]


class Background:
    """A background frame of one camera (grayscale + depth in m), captured with the workspace clear of objects."""

    def __init__(self, rgb: np.ndarray, depth_m: np.ndarray) -> None:
        if rgb.ndim != 3 or rgb.shape[:2] != depth_m.shape:
            raise IsolationError(f"background rgb {rgb.shape} and depth {depth_m.shape} are not an aligned pair")
        self.gray = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY)
        self.depth = np.asarray(depth_m, np.float32)
        self.valid = np.isfinite(self.depth) & (self.depth > 0)
        self.shape = depth_m.shape


def _box(vv: np.ndarray, uu: np.ndarray, margin: int, shape: tuple[int, ...]) -> tuple[slice, slice]:
    """Rows and columns of the pixels (vv, uu) plus `margin` px, clipped to the image: a filter of half-width
    ≤ `margin` gives these pixels the same values on the crop as on the whole image (where the crop meets the
    image's border, the border rule is the same)."""
    return (slice(max(int(vv.min()) - margin, 0), min(int(vv.max()) + margin + 1, shape[0])),
            slice(max(int(uu.min()) - margin, 0), min(int(uu.max()) + margin + 1, shape[1])))


class CollisionIsolator:
    """Locates a contact from the top and side RGB-D frames (see module docstring).

    Args:
        cameras: camera models by name ("cam_top", "cam_side").
        config: thresholds.
        order: cameras in the order the paper evaluates them.
    """

    def __init__(self, cameras: dict[str, CameraModel], config: IsolationConfig | None = None,
                 order: Sequence[str] = ("cam_top", "cam_side")) -> None:
        self.cameras = dict(cameras)
        self.config = config or IsolationConfig()
        self.order = [c for c in order if c in self.cameras] + [c for c in self.cameras if c not in order]
        self.backgrounds: dict[str, Background] = {}
        self._rays: dict[str, np.ndarray] = {}
        for name, cam in self.cameras.items():
            uu, vv = np.meshgrid(np.arange(cam.width, dtype=np.float32), np.arange(cam.height, dtype=np.float32))
            # optical-frame ray per pixel with z = 1 (x/z, y/z)
            fx, fy, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
            self._rays[name] = np.stack([(uu - cx) / fx, (vv - cy) / fy], axis=-1).astype(np.float32)

    # -- background --------------------------------------------------------------------------------------------
    def set_background(self, camera: str, rgb: np.ndarray, depth_m: np.ndarray) -> None:
        """Store the background of `camera` (workspace clear of external objects)."""
        self._check(camera, rgb, depth_m)
        self.backgrounds[camera] = Background(rgb, depth_m)

    def _check(self, camera: str, rgb: np.ndarray, depth_m: np.ndarray) -> CameraModel:
        if camera not in self.cameras:
            raise IsolationError(f"unknown camera {camera!r}; known: {list(self.cameras)}")
        cam = self.cameras[camera]
        if rgb is None or depth_m is None:
            raise IsolationError(f"{camera}: missing colour or depth frame")
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise IsolationError(f"{camera}: colour must be RGB uint8 (H, W, 3), got {rgb.dtype} {rgb.shape}")
        if rgb.shape[:2] != depth_m.shape:
            raise IsolationError(f"{camera}: colour {rgb.shape[:2]} and depth {depth_m.shape} sizes differ")
        if depth_m.shape != (cam.height, cam.width):
            raise IsolationError(f"{camera}: frame {depth_m.shape[1]}x{depth_m.shape[0]} does not match camera_info "
                                 f"{cam.width}x{cam.height}")
        return cam

    # -- masks -------------------------------------------------------------------------------------------------
    def robot_mask(self, camera: str, geom: RobotGeometry, rgb: np.ndarray | None = None,
                   depth: np.ndarray | None = None) -> np.ndarray:
        """uint8 mask of the robot's links drawn from the geometry (the "determined" robot), with a margin.

        With `rgb`, pixels whose colour cannot be a link's — saturated and not the arms' HSV blue (the rods are
        unsaturated, as the paper's YCbCr step assumes) — are released everywhere but on the plate itself (its
        markers are coloured; there, with `depth`, only pixels standing `above_plate` clear of its surface): an
        object in front of or next to a link is kept as object.
        """
        cam = self.cameras[camera]
        cfg = self.config
        mask = np.zeros((cam.height, cam.width), np.uint8)
        plate = np.zeros_like(mask)
        f = 0.5 * (cam.K[0, 0] + cam.K[1, 1])
        for code, _, seg, radius in geom.link_segments():
            n = 8
            pts = seg[0] + np.linspace(0, 1, n + 1)[:, None] * (seg[1] - seg[0])
            uv, z = cam.project(pts)
            if np.any(z <= 0.01) or np.any(np.abs(uv) > 10 ** 5):
                keep_seg = (z[:-1] > 0.01) & (z[1:] > 0.01)
                uv = np.clip(np.nan_to_num(uv), -10 ** 5, 10 ** 5)
            else:
                keep_seg = np.ones(n, bool)
            uvi = np.round(uv).astype(int).tolist()
            th = np.ceil(2 * (radius + cfg.robot_margin_m) * f / np.maximum(0.5 * (z[:-1] + z[1:]), 1e-3)
                         + 2 * cfg.robot_margin_px).astype(int).tolist()
            for k in range(n):
                if keep_seg[k]:
                    cv2.line(mask, uvi[k], uvi[k + 1], 255, max(th[k], 1), cv2.LINE_8)
        uv, z = cam.project(geom.plate_corners())
        if np.all(z > 0.01) and np.all(np.abs(uv) < 10 ** 5):
            hull = cv2.convexHull(np.round(uv).astype(np.int32))
            cv2.fillConvexPoly(mask, hull, 255)
            cv2.fillConvexPoly(plate, hull, 255)
            m = int(np.ceil(cfg.robot_margin_px + cfg.robot_margin_m * f / float(np.mean(z))))
            if m > 0:
                cv2.polylines(mask, [hull], True, 255, 2 * m + 1)
        if rgb is not None:
            hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
            blue = cv2.inRange(hsv, np.array(cfg.blue_hsv[0]), np.array(cfg.blue_hsv[1])) > 0
            foreign = (hsv[:, :, 1] >= cfg.foreign_min_saturation) & (hsv[:, :, 2] >= cfg.foreign_min_value) & ~blue
            mask[foreign & (plate == 0)] = 0
            if depth is not None:
                # on the plate, a foreign pixel is an object only when it stands clear of the plate's top surface
                # (the coloured markers are flush with it); median-filtered depth against the plate plane
                vv, uu = np.nonzero(foreign & (plate > 0))
                if vv.size:
                    rows, cols = _box(vv, uu, 2, depth.shape)     # the 5x5 median of these pixels only
                    dmm = np.nan_to_num(np.asarray(depth[rows, cols], np.float32) * 1000.0, nan=0.0)
                    dmed = cv2.medianBlur(np.clip(dmm, 0, 65535).astype(np.uint16), 5)[
                        vv - rows.start, uu - cols.start] * 1e-3
                    ok = dmed > 0
                    ray = self._rays[camera][vv[ok], uu[ok]]
                    pc = np.column_stack([ray * dmed[ok][:, None], dmed[ok]])
                    pb = pc @ cam.T_base_camera[:3, :3].T + cam.T_base_camera[:3, 3]
                    h = (pb - geom.T_plate[:3, 3]) @ geom.T_plate[:3, 2]
                    side = np.sign((cam.position - geom.T_plate[:3, 3]) @ geom.T_plate[:3, 2]) or 1.0
                    clear = side * h - geom.plate_half_thickness > cfg.above_plate
                    mask[vv[ok][clear], uu[ok][clear]] = 0
        return mask

    def paper_colour_cues(self, rgb: np.ndarray) -> dict[str, Any]:
        """The paper's colour steps: YCbCr rods + Canny + Hough lines (Fig. 12b–c), HSV blue arms + Canny + Hough
        (Fig. 17c–d). Returned for the debug image; the decision uses the geometric robot mask."""
        cfg = self.config
        ycc = cv2.cvtColor(rgb, cv2.COLOR_RGB2YCrCb)
        y, cr, cb = ycc[:, :, 0], ycc[:, :, 1].astype(np.int16), ycc[:, :, 2].astype(np.int16)
        rods = ((y >= cfg.rod_ycbcr[0]) & (np.abs(cb - 128) <= cfg.rod_ycbcr[1]) &
                (np.abs(cr - 128) <= cfg.rod_ycbcr[1])).astype(np.uint8) * 255
        hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
        blue = cv2.inRange(hsv, np.array(cfg.blue_hsv[0]), np.array(cfg.blue_hsv[1]))
        out = {"rods_ycbcr": rods, "arms_hsv": blue}
        for key, m in (("rod_lines", rods), ("arm_lines", blue)):
            edges = cv2.Canny(m, 50, 150)
            lines = cv2.HoughLinesP(edges, 1, np.pi / 180, 30, minLineLength=25, maxLineGap=6)
            out[key] = np.zeros((0, 4), np.int32) if lines is None else lines[:, 0, :]
        return out

    # -- one camera --------------------------------------------------------------------------------------------
    def isolate_camera(self, camera: str, rgb: np.ndarray, depth_m: np.ndarray, geom: RobotGeometry,
                       debug: bool = False) -> CameraResult:
        """Contact candidates and the contact in one camera's frame (module docstring, steps 1–5).

        Raises:
            IsolationError: no background for this camera, or a malformed frame.
        """
        cam = self._check(camera, rgb, depth_m)
        bg = self.backgrounds.get(camera)
        if bg is None:
            raise IsolationError(f"{camera}: no background captured yet")
        cfg = self.config
        res = CameraResult(camera)
        depth = np.asarray(depth_m, np.float32)
        valid = np.isfinite(depth) & (depth > 0)
        if not valid.any():
            raise IsolationError(f"{camera}: depth frame has no valid pixel")
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        changed = cv2.absdiff(gray, bg.gray) > cfg.gray_threshold
        with np.errstate(invalid="ignore"):
            changed |= valid & (~bg.valid | (np.abs(depth - bg.depth) > cfg.depth_change))
        changed &= valid
        robot = self.robot_mask(camera, geom, rgb, depth)
        cand = changed & (robot == 0)
        cand = cv2.morphologyEx(cand.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)) > 0
        vv, uu = np.nonzero(cand)
        if debug:
            res.layers.update({"rgb": rgb, "changed": changed, "robot": robot})
        if vv.size == 0:
            res.reason = "no external object"
            if debug:
                res.layers.update({"workspace": changed & False, "object": cand})
            return res
        z = depth[vv, uu]
        ray = self._rays[camera][vv, uu]
        pc = np.column_stack([ray * z[:, None], z])
        pts = pc @ cam.T_base_camera[:3, :3].T + cam.T_base_camera[:3, 3]
        inws = ((np.hypot(pts[:, 0], pts[:, 1]) <= cfg.workspace_radius) & (pts[:, 2] >= cfg.workspace_z[0]) &
                (pts[:, 2] <= cfg.workspace_z[1]))
        vv, uu, pts, z = vv[inws], uu[inws], pts[inws], z[inws]
        obj = np.zeros_like(cand)
        obj[vv, uu] = True
        if debug:
            res.layers["workspace"] = obj.copy()
        if vv.size:
            ltype = cv2.CV_16U if vv.size < 65535 else cv2.CV_32S   # 16-bit labels: faster, safe below 2^16 px
            rows, cols = _box(vv, uu, 0, obj.shape)                # the object's pixels lie in this box
            n, labels, stats, _ = cv2.connectedComponentsWithStats(obj[rows, cols].astype(np.uint8),
                                                                   connectivity=8, ltype=ltype)
            big = np.zeros(n, bool)
            big[1:] = stats[1:, cv2.CC_STAT_AREA] >= cfg.min_object_area
            keep = big[labels[vv - rows.start, uu - cols.start]]
            vv, uu, pts, z = vv[keep], uu[keep], pts[keep], z[keep]
            obj[:] = False
            obj[vv, uu] = True
        res.n_object = int(vv.size)
        if debug:
            res.layers["object"] = obj
        if vv.size == 0:
            res.reason = "no external object in the workspace"
            return res
        if cfg.smooth_px > 1:
            # normalised box filter of the depth over the object only: the object's own surface, less noise
            rows, cols = _box(vv, uu, cfg.smooth_px // 2 + 1, obj.shape)
            o = obj[rows, cols]
            m = o.astype(np.float32)
            dz = np.where(o, depth[rows, cols], 0.0).astype(np.float32)
            k = (cfg.smooth_px, cfg.smooth_px)
            num = cv2.boxFilter(dz, -1, k, normalize=False)[vv - rows.start, uu - cols.start]
            den = cv2.boxFilter(m, -1, k, normalize=False)[vv - rows.start, uu - cols.start]
            z = num / np.maximum(den, 1.0)
            ray = self._rays[camera][vv, uu]
            pts = np.column_stack([ray * z[:, None], z]) @ cam.T_base_camera[:3, :3].T + cam.T_base_camera[:3, 3]

        # distances of object points to every link surface
        links = geom.link_segments(rod_end_clearance=cfg.rod_end_clearance)
        seg_ends = np.array([seg for _, _, seg, _ in links])
        radii = np.array([radius for *_, radius in links])
        D, S = surface_distances(pts, seg_ends, radii, geom)
        nearest = np.argmin(D, axis=0)
        dmin = D[nearest, np.arange(len(pts))]
        touching = dmin <= cfg.touch_distance
        res.n_candidates = int(touching.sum())
        if debug:
            res.layers["candidates"] = np.stack([uu[touching], vv[touching]], axis=1)
        if res.n_candidates < cfg.min_touch_points:
            res.reason = f"{res.n_candidates} object pixels touch the robot (need {cfg.min_touch_points})"
            return res
        # the touched link is the one the object comes closest to: mean of its k smallest surface distances
        kk = min(cfg.closest_points, D.shape[1])
        closest = np.partition(D, kk - 1, axis=1)[:, :kk].mean(axis=1)
        counts = (D <= cfg.touch_distance).sum(axis=1)
        closest[counts < cfg.min_touch_points] = np.inf
        best = int(np.argmin(closest))
        if not np.isfinite(closest[best]) or closest[best] > cfg.contact_gap:
            res.reason = (f"object comes no closer than {1e3 * float(np.min(closest)):.0f} mm to a link "
                          f"(contact gap {1e3 * cfg.contact_gap:.0f} mm)")
            return res
        obj_axis = self._object_axis(pts, cam)
        pushing = self._pushing_end_link(pts, obj_axis, seg_ends, radii, geom, closest, best)
        if pushing is not None:
            best = pushing
        order = np.sort(closest)
        if debug:
            res.layers["closest"] = closest
        # the object's points nearest the link carry the contact: Gaussian weights on the surface distance
        sig = max(cfg.contact_sigma, 0.001)
        sel = D[best] <= closest[best] + 3.0 * sig
        d_sel = np.maximum(D[best][sel] - closest[best], 0.0)
        wk = np.exp(-0.5 * (d_sel / sig) ** 2)
        mean_pt = (wk[:, None] * pts[sel]).sum(axis=0) / wk.sum()
        if best == len(links):
            res.link, res.chain = LINK_PLATE, 0
            R, t = geom.T_plate[:3, :3], geom.T_plate[:3, 3]
            q = R.T @ (mean_pt - t)
            border = None
            # the object's own axis (principal direction of its points, corrected for seeing only its near
            # side), followed to where it crosses the plate's hexagonal border nearest the object's tip
            loc = (pts - t) @ R
            c = loc.mean(axis=0)
            _, sv, vt = np.linalg.svd(loc - c, full_matrices=False)
            a = vt[0]
            if sv[0] > cfg.axis_elongation * max(sv[1], 1e-12):
                if a @ (q - c) < 0:
                    a = -a
                eye = R.T @ (cam.position - t)
                wv = (eye - c) - ((eye - c) @ a) * a
                if np.linalg.norm(wv) > 1e-9:
                    wv /= np.linalg.norm(wv)
                    u = np.cross(a, wv)
                    off = (loc - c) @ u
                    r_est = 0.5 * float(np.percentile(off, 95) - np.percentile(off, 5))
                    c = c - wv * (2.0 / np.pi) * r_est
                # the pushing end: of the object's two ends (along its axis), the one nearer the plate
                sa = (loc - loc.mean(axis=0)) @ a
                lo, hi = np.percentile(sa, 1), np.percentile(sa, 99)
                d_plate = D[-1]
                end_lo = float(np.median(d_plate[sa <= lo + cfg.tip_length]))
                end_hi = float(np.median(d_plate[sa >= hi - cfg.tip_length]))
                tip = loc.mean(axis=0) + a * (hi if end_hi <= end_lo else lo)
                if np.linalg.norm(a[:2]) > 0.2:
                    border = hexagon_line_crossing(geom.hexagon, c[:2], a[:2] / np.linalg.norm(a[:2]), tip[:2])
            if border is None:   # the paper's line through the plate centre
                try:
                    border = hexagon_border_point(geom.hexagon, q[:2])
                except ValueError as exc:
                    raise IsolationError(str(exc)) from exc
            point = t + R @ np.array([border[0], border[1], 0.0])
        else:
            code, chain, seg, radius = links[best]
            res.link, res.chain = code, chain
            s = float(np.clip((wk * S[best][sel]).sum() / wk.sum(), 0.0, 1.0))
            if cfg.axis_contact:
                s_axis = self._axis_crossing(obj_axis, seg)
                if s_axis is not None and abs(s_axis - s) * np.linalg.norm(seg[1] - seg[0]) <= cfg.axis_max_shift:
                    s = s_axis
            axis_pt = seg[0] + s * (seg[1] - seg[0])
            e = (seg[1] - seg[0]) / np.linalg.norm(seg[1] - seg[0])
            off = mean_pt - axis_pt
            off -= (off @ e) * e
            nrm = np.linalg.norm(off)
            point = axis_pt + (radius * off / nrm if nrm > 1e-9 else 0.0)
        res.point = point
        if obj_axis is not None:   # step 6: the object's axis, pointing from the object into the link
            a, c, res.elongation = obj_axis
            res.push_direction = a if a @ (point - c) >= 0 else -a
        uv, _ = cam.project(point)
        res.pixel = uv
        # confidence: how much nearer this link is than the runner-up, and how many points support it
        margin = (order[1] - order[0]) if len(order) > 1 and np.isfinite(order[1]) else cfg.contact_gap
        res.confidence = float(np.clip(min(1.0, margin / cfg.contact_gap + 0.3) *
                                       min(1.0, int(sel.sum()) / (2.0 * cfg.min_touch_points)), 0.0, 1.0))
        if debug:
            res.layers["selected"] = np.stack([uu[sel], vv[sel]], axis=1)
        return res

    def _object_axis(self, pts: np.ndarray, cam: CameraModel) -> tuple[np.ndarray, np.ndarray, float] | None:
        """(unit axis a, point c on the axis, spread ratio) of an elongated object: its points' principal direction,
        the mean moved from the visible near side to the axis; None when the object is not elongated (spread ratio
        below `axis_elongation`)."""
        cfg = self.config
        c = pts.mean(axis=0)
        _, sv, vt = np.linalg.svd(pts - c, full_matrices=False)
        ratio = float(sv[0] / max(sv[1], 1e-12))
        if ratio < cfg.axis_elongation:
            return None
        a = vt[0]
        wv = (cam.position - c) - ((cam.position - c) @ a) * a
        if np.linalg.norm(wv) > 1e-9:
            wv /= np.linalg.norm(wv)
            off = (pts - c) @ np.cross(a, wv)
            r_est = 0.5 * float(np.percentile(off, 95) - np.percentile(off, 5))
            c = c - wv * (2.0 / np.pi) * r_est
        return a, c, ratio

    def _pushing_end_link(self, pts: np.ndarray, axis: tuple[np.ndarray, np.ndarray, float] | None,
                          seg_ends: np.ndarray, radii: np.ndarray, geom: RobotGeometry, closest: np.ndarray,
                          best: int) -> int | None:
        """Row of `closest` (links, then the plate) that the elongated object pushes with its end, when it is not
        `best` (the link of the nearest points); else None.

        A stick pushes with its end, and its body may lie along another link, nearer over its length than the
        pushed link is to the stick's visible surface: a stick along a rod whose end, hidden behind the plate,
        pushes the plate's edge. The object's axis (`_object_axis`) is followed out of each of its visible ends
        (the 1st and 99th percentiles of its points along it), from `tip_reach` / 4 inside to `tip_reach` beyond;
        the first link surface it passes within `tip_gap` of is the one that end pushes. The pushing end is the
        one that meets its link first. The answer needs the pixel support of `closest` (finite). None: no axis,
        neither end meets a link, or the end meets `best`.
        """
        cfg = self.config
        if axis is None or cfg.tip_gap <= 0:
            return None
        a, c, _ = axis
        s = (pts - c) @ a
        ends = np.percentile(s, [1.0, 99.0])
        steps = np.arange(-0.25 * cfg.tip_reach, cfg.tip_reach + 1e-9, 0.002)
        first: list[tuple[float, int]] = []
        for end, out in zip(ends, (-1.0, 1.0)):
            q = c + np.outer(end + out * steps, a)                                # (S, 3) along the axis, outwards
            d, _ = surface_distances(q, seg_ends, radii, geom)
            d[~np.isfinite(closest)] = np.inf
            hit = np.nonzero((d <= cfg.tip_gap).any(axis=0))[0]
            if hit.size:
                first.append((float(steps[hit[0]]), int(np.argmin(d[:, hit[0]]))))
        if not first:
            return None
        k = min(first)[1]
        return k if k != best else None

    @staticmethod
    def _axis_crossing(axis: tuple[np.ndarray, np.ndarray, float] | None, seg: np.ndarray) -> float | None:
        """Segment parameter where the object's axis (`_object_axis`) passes closest to the link's axis, or None
        (no axis, lines parallel)."""
        if axis is None:
            return None
        a, c, _ = axis
        e = seg[1] - seg[0]
        w0 = seg[0] - c
        A, B, C = float(e @ e), float(e @ a), float(a @ a)
        den = A * C - B * B
        if den <= 1e-12 * A * C:
            return None
        s = (B * float(a @ w0) - C * float(e @ w0)) / den
        return float(np.clip(s, 0.0, 1.0))

    # -- both cameras ------------------------------------------------------------------------------------------
    def isolate(self, frames: dict[str, tuple[np.ndarray, np.ndarray]], geom: RobotGeometry, debug: bool = False
                ) -> ContactEstimate:
        """Contact from the frames of the cameras present (top first, then side; the most confident wins).

        Args:
            frames: camera name → (rgb uint8, depth m) aligned pair.
            geom: robot links at the frames' instant.
            debug: keep the intermediate layers for `debug_image`.

        Raises:
            IsolationError: no usable frame from any camera (each camera's problem named).
        """
        results: dict[str, CameraResult] = {}
        problems = []
        for name in self.order:
            if name not in frames:
                continue
            rgb, depth = frames[name]
            try:
                results[name] = self.isolate_camera(name, rgb, depth, geom, debug)
            except IsolationError as exc:
                problems.append(str(exc))
        if not results:
            raise IsolationError("no usable camera frame: " + ("; ".join(problems) or "none given"))
        found = [r for r in results.values() if r.found]
        if not found:
            first = next(iter(results.values()))
            return ContactEstimate(LINK_UNKNOWN, 0, np.full(3, np.nan), np.full(2, np.nan), first.camera, 0.0,
                                   results)
        best = found[0]   # the paper's order: top camera (plate, rods) first, then the side camera
        if best.confidence < self.config.min_confidence:
            best = max(found, key=lambda r: (r.confidence, r.n_candidates))
        if best.link == LINK_ROD:
            # a rod answer at the rod's plate joint while another camera sees the plate touched: the object sits
            # on the plate's corner (the top camera sees the object's far side and the rod next to it)
            joint = geom.rods[best.chain - 1, 1]
            plate = [r for r in found if r.link == LINK_PLATE]
            if plate and np.linalg.norm(best.point - joint) <= self.config.corner_radius:
                best = plate[0]
        # the push direction from the camera that sees the object longest (least foreshortened), of those that
        # agree on the link
        agree = [r for r in found if r.link == best.link and r.chain == best.chain and r.elongation > 0]
        push = max(agree, key=lambda r: r.elongation).push_direction.copy() if agree else np.full(3, np.nan)
        return ContactEstimate(best.link, best.chain, best.point, best.pixel, best.camera, best.confidence, results,
                               push)


# ----------------------------------------------------------------------------------------------------------------
def _tile(img: np.ndarray | None, title: str, size: tuple[int, int]) -> np.ndarray:
    if img is None:    # a step that did not run: an empty tile
        img = np.zeros((size[1], size[0], 3), np.uint8)
    if img.dtype == bool:
        img = img.astype(np.uint8) * 255
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    t = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    cv2.rectangle(t, (0, 0), (size[0] - 1, 18), (0, 0, 0), -1)
    cv2.putText(t, title, (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
    return t


def debug_image(result: CameraResult, isolator: CollisionIsolator, geom: RobotGeometry,
                box: Sequence[float] | None = None, tile: tuple[int, int] = (320, 240)) -> np.ndarray:
    """A 4x2 mosaic of the procedure's steps for one camera, like the paper's Figures 12, 17 and 22 (RGB uint8).

    Tiles: (a) frame + plate box + projected links, (b) Hough lines on the colour cues, (c) robot mask,
    (d) changed pixels in the workspace, (e) external object, (f) candidates touching a link, (g) contact,
    (h) legend with the answer.
    """
    L = result.layers
    rgb = L.get("rgb")
    if rgb is None:
        raise IsolationError("debug layers missing: call isolate(..., debug=True)")
    cam = isolator.cameras[result.camera]
    a = rgb.copy()
    if box is not None:
        cv2.rectangle(a, (int(box[0]), int(box[1])), (int(box[2]), int(box[3])), (0, 255, 0), 2)
    for code, chain, seg, _ in geom.link_segments():
        uv, z = cam.project(seg)
        if np.all(z > 0.01) and np.all(np.abs(uv) < 1e4):
            col = (0, 120, 255) if code == LINK_ARM else (255, 200, 0)
            cv2.line(a, tuple(np.round(uv[0]).astype(int)), tuple(np.round(uv[1]).astype(int)), col, 1)
            cv2.putText(a, str(chain), tuple(np.round(uv.mean(0)).astype(int)), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                        col, 1)
    cues = isolator.paper_colour_cues(rgb)
    b = rgb.copy() // 2
    for key, col in (("rod_lines", (255, 255, 0)), ("arm_lines", (0, 160, 255))):
        for x0, y0, x1, y1 in cues[key]:
            cv2.line(b, (int(x0), int(y0)), (int(x1), int(y1)), col, 2)
    f = rgb.copy() // 2
    for key, col in (("candidates", (255, 255, 0)), ("selected", (255, 0, 0))):
        for u, v in L.get(key, np.zeros((0, 2), int)):
            f[v, u] = col
    g = rgb.copy()
    if result.found and np.all(np.isfinite(result.pixel)):
        p = tuple(np.round(result.pixel).astype(int))
        cv2.circle(g, p, 8, (255, 0, 0), 2)
        cv2.drawMarker(g, p, (255, 0, 0), cv2.MARKER_CROSS, 14, 1)
    h = np.zeros((tile[1], tile[0], 3), np.uint8)
    lines = [f"camera: {result.camera}", f"link: {LINK_NAMES[result.link]}  chain: {result.chain}",
             "point (mm): " + (" ".join(f"{1e3 * c:.1f}" for c in result.point) if result.found else "-"),
             f"pixel: {np.round(result.pixel, 1).tolist()}", f"object px: {result.n_object}",
             f"candidates: {result.n_candidates}", f"confidence: {result.confidence:.2f}", result.reason[:44]]
    for k, s in enumerate(lines):
        cv2.putText(h, s, (6, 24 + 22 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    tiles = [_tile(a, "(a) frame, plate box, links", tile), _tile(b, "(b) YCbCr rods / HSV arms + Hough", tile),
             _tile(L.get("robot"), "(c) robot (determined)", tile),
             _tile(L.get("workspace"), "(d) changed, not robot, in workspace", tile),
             _tile(L.get("object"), "(e) external object", tile), _tile(f, "(f) touching candidates", tile),
             _tile(g, "(g) contact point", tile), _tile(h, "(h) result", tile)]
    return np.vstack([np.hstack(tiles[:4]), np.hstack(tiles[4:])])
