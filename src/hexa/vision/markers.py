"""Plate pose from coloured markers: colour blobs → depth lift → rigid fit with any 3 of 4, outlier rejection.

The same fitting (`fit_marker_set`) serves motion-capture rigid bodies (seed 003 §2.4: three markers per platform
plus one redundant, any three enough to reconstruct the pose).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import combinations
from typing import TYPE_CHECKING

import cv2
import numpy as np

from hexa.rotations import quaternion_from_matrix  # noqa: F401 - part of this module's interface
from hexa.vision.camera import CameraModel
from hexa.vision.rigid import RigidFitError, fit_plane, fit_rigid_transform, residuals

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription


class MarkerError(ValueError):
    """Marker layout or input images are unusable (naming the value)."""


@dataclass(frozen=True)
class MarkerLayout:
    """Marker names, their 3D points in the plate frame {P} as seen by a camera (m), and nominal colours (0..1)."""

    names: tuple[str, ...]
    points: np.ndarray
    rgb: np.ndarray
    radius: float = 0.01
    surface_offset: float = 0.0   # height of the marker tops above the plate surface (m)

    @classmethod
    def from_description(cls, desc: HexaDescription) -> MarkerLayout:
        """Layout from the robot description's `markers` section (top face of each disc: position + plate
        half-thickness + disc thickness along z of {P})."""
        try:
            mk = desc.section("markers")
            ap = desc.section("appearance")
        except Exception as exc:
            raise MarkerError(f"robot description has no markers/appearance section ({exc})") from exc
        items = mk.get("items") or []
        if len(items) < 3:
            raise MarkerError(f"markers.items must list at least 3 markers; got {len(items)}")
        lift = float(ap.get("plate_thickness", 0.0)) / 2.0 + float(mk.get("thickness", 0.0))
        pts = np.array([np.asarray(it["position"], float) + [0.0, 0.0, lift] for it in items])
        return cls(tuple(str(it["name"]) for it in items), pts, np.array([it["rgb"] for it in items], float),
                   float(mk.get("radius", 0.01)), float(mk.get("thickness", 0.0)))


@dataclass
class MarkerFit:
    """Result of a marker-set fit: T_base_body (4x4), which markers were used/rejected, residuals and covariance."""

    ok: bool
    T: np.ndarray = field(default_factory=lambda: np.eye(4))
    rms: float = float("nan")
    used: tuple[int, ...] = ()
    rejected: tuple[int, ...] = ()
    covariance: np.ndarray = field(default_factory=lambda: np.full((6, 6), np.nan))
    reason: str = ""

    @property
    def R(self) -> np.ndarray:
        return self.T[:3, :3]

    @property
    def t(self) -> np.ndarray:
        return self.T[:3, 3]


def pose_covariance(R: np.ndarray, model_pts: np.ndarray, sigmas: np.ndarray) -> np.ndarray:
    """6x6 covariance of (x, y, z, rot_x, rot_y, rot_z) (m, rad; rotations about base axes through the body origin)
    of a rigid fit with isotropic point noise σ_i: (Σ J_iᵀ J_i / σ_i²)⁻¹, J_i = [I, −[R m_i]×]."""
    A = np.zeros((6, 6))
    for m, s in zip(np.asarray(model_pts, float), np.asarray(sigmas, float)):
        q = R @ m
        J = np.zeros((3, 6))
        J[:, :3] = np.eye(3)
        J[:, 3:] = -np.array([[0, -q[2], q[1]], [q[2], 0, -q[0]], [-q[1], q[0], 0]])
        A += J.T @ J / (s * s)
    try:
        return np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return np.full((6, 6), np.nan)


def fit_marker_set(model_pts: np.ndarray, measured_pts: np.ndarray, tol: float = 0.004,
                   sigmas: np.ndarray | None = None) -> MarkerFit:
    """Rigid pose of a marker body from measured markers, any 3 or more; rows of NaN are missing markers.

    The fit uses all present markers; if its largest residual exceeds `tol`, every subset with one marker fewer
    (down to 3) is tried and the best consistent one kept (the dropped markers are reported as rejected). With only
    3 markers present, the check is the residual of the 3-point fit (inter-marker distances must match the model).

    Args:
        model_pts: (N, 3) markers in the body frame (m).
        measured_pts: (N, 3) measured markers (m); NaN rows are missing.
        tol: largest per-marker residual (m) accepted.
        sigmas: (N,) per-marker position noise (m) for the covariance (default tol/3).

    Returns:
        MarkerFit with ok False and a reason when fewer than 3 markers are present or no subset is consistent.
    """
    M = np.asarray(model_pts, float)
    Q = np.asarray(measured_pts, float)
    if M.shape != Q.shape or M.ndim != 2 or M.shape[1] != 3:
        raise MarkerError(f"model {M.shape} and measured {Q.shape} must both be (N, 3)")
    sig = np.full(M.shape[0], tol / 3.0) if sigmas is None else np.asarray(sigmas, float)
    present = [i for i in range(M.shape[0]) if np.all(np.isfinite(Q[i]))]
    if len(present) < 3:
        return MarkerFit(False, reason=f"only {len(present)} marker(s) measured; need 3")
    best: tuple[float, tuple[int, ...], np.ndarray, np.ndarray, float] | None = None
    for k in range(len(present), 2, -1):
        for sub in combinations(present, k):
            idx = list(sub)
            try:
                R, t, rms = fit_rigid_transform(M[idx], Q[idx])
            except RigidFitError:
                continue
            worst = float(residuals(R, t, M[idx], Q[idx]).max())
            if worst <= tol and (best is None or rms < best[0]):
                best = (rms, sub, R, t, worst)
        if best is not None:
            break
    if best is None:
        return MarkerFit(False, reason=f"no consistent subset of markers {present} within {tol * 1e3:.1f} mm")
    rms, sub, R, t, _ = best
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    cov = pose_covariance(R, M[list(sub)], sig[list(sub)])
    rejected = tuple(i for i in present if i not in sub)
    return MarkerFit(True, T, rms, tuple(sub), rejected, cov)


@dataclass
class MarkerObservation:
    """One detected marker blob: centroid pixel, pixel count, 3D point in base (NaN if no valid depth)."""

    index: int
    pixel: np.ndarray
    area: int
    point: np.ndarray
    n_depth: int


def _hue_of(rgb01: np.ndarray) -> float:
    px = np.clip(np.asarray(rgb01, float) * 255, 0, 255).astype(np.uint8).reshape(1, 1, 3)
    return float(cv2.cvtColor(px, cv2.COLOR_RGB2HSV)[0, 0, 0])


class MarkerDetector:
    """Finds the layout's coloured discs in an RGB image, lifts them with the aligned depth, fits the plate pose.

    Args:
        layout: marker layout in {P}.
        camera: the colour camera (aligned depth shares it).
        hue_tol: accepted hue distance (OpenCV units, 0..180).
        min_sat, min_val: minimum saturation / value (0..255) of a marker pixel.
        min_area: smallest blob (px).
        tol: largest per-marker fit residual (m).
        depth_rel_sigma: depth noise relative to range, for the covariance.
    """

    def __init__(self, layout: MarkerLayout, camera: CameraModel, hue_tol: float = 10.0, min_sat: int = 90,
                 min_val: int = 50, min_area: int = 6, tol: float = 0.006, depth_rel_sigma: float = 0.01) -> None:
        self.layout = layout
        self.camera = camera
        self.hues = np.array([_hue_of(c) for c in layout.rgb])
        self.hue_tol = hue_tol
        self.min_sat, self.min_val, self.min_area = min_sat, min_val, min_area
        self.tol = tol
        self.depth_rel_sigma = depth_rel_sigma
        self.rejected_fits = 0
        self.missing_markers = 0
        self.plane_region_scale = 3.2
        self.plate_gray_tol = 30

    def _blobs(self, rgb: np.ndarray, roi: Sequence[float] | None) -> tuple[list, tuple[int, int]]:
        """Saturated colour blobs (one connected-components pass) assigned to the layout's markers by hue."""
        H, W = rgb.shape[:2]
        u0, v0, u1, v1 = 0, 0, W, H
        if roi is not None:
            u0, v0 = max(int(np.floor(roi[0])), 0), max(int(np.floor(roi[1])), 0)
            u1, v1 = min(int(np.ceil(roi[2])) + 1, W), min(int(np.ceil(roi[3])) + 1, H)
            if u1 <= u0 or v1 <= v0:
                return [None] * len(self.layout.names), (u0, v0)
        hsv = cv2.cvtColor(np.ascontiguousarray(rgb[v0:v1, u0:u1]), cv2.COLOR_RGB2HSV)
        sat = ((hsv[:, :, 1] >= self.min_sat) & (hsv[:, :, 2] >= self.min_val)).astype(np.uint8)
        # 16-bit labels are ~3x faster; safe when there are fewer set pixels than 16-bit labels
        ltype = cv2.CV_16U if int(np.count_nonzero(sat)) < 65535 else cv2.CV_32S
        n, labels, stats, cents = cv2.connectedComponentsWithStats(sat, connectivity=8, ltype=ltype)
        best: list = [None] * len(self.layout.names)
        if n <= 1:
            return best, (u0, v0)
        big = [j for j in range(1, n) if stats[j, cv2.CC_STAT_AREA] >= self.min_area]
        for j in big:
            x, y, w, h = stats[j, :4]
            sub = labels[y:y + h, x:x + w] == j
            hue = hsv[y:y + h, x:x + w, 0][sub].astype(float) * (np.pi / 90.0)
            mean_h = (np.degrees(np.arctan2(np.sin(hue).mean(), np.cos(hue).mean())) / 2.0) % 180.0
            dh = np.abs(self.hues - mean_h)
            dh = np.minimum(dh, 180 - dh)
            k = int(np.argmin(dh))
            if dh[k] <= self.hue_tol and (best[k] is None or stats[j, cv2.CC_STAT_AREA] > best[k][1]):
                best[k] = (j, int(stats[j, cv2.CC_STAT_AREA]), (x, y, w, h), cents[j])
        return [None if b is None else (b, labels) for b in best], (u0, v0)

    def detect(self, rgb: np.ndarray, depth_m: np.ndarray, roi: Sequence[float] | None = None
               ) -> list[MarkerObservation | None]:
        """One observation (or None) per layout marker: blob centroid, and its 3D point.

        The 3D point is the viewing ray through the blob centroid intersected with the plate plane (fitted to the
        depth of the plate around the markers, robustly) lifted by the marker thickness; with fewer than three
        blobs, or when the plane fit fails, the mean of the blob's own back-projected depth pixels.

        Args:
            rgb: (H, W, 3) uint8 RGB.
            depth_m: (H, W) depth in m (NaN/0 invalid), aligned to rgb.
            roi: optional box (u0, v0, u1, v1) in pixels to search in (e.g. the detector's plate box).

        Raises:
            MarkerError: rgb and depth sizes differ or do not match the camera.
        """
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[:2] != depth_m.shape:
            raise MarkerError(f"rgb {rgb.shape} and depth {depth_m.shape} are not an aligned pair")
        H, W = depth_m.shape
        if (W, H) != (self.camera.width, self.camera.height):
            raise MarkerError(f"image {W}x{H} does not match camera {self.camera.width}x{self.camera.height}")
        blobs, (u0, v0) = self._blobs(rgb, roi)
        cam = self.camera
        Kinv = np.linalg.inv(cam.K)
        out: list[MarkerObservation | None] = []
        for k, b in enumerate(blobs):
            if b is None:
                out.append(None)
                continue
            (j, area, (x, y, w, h), cent), labels = b
            vv, uu = np.nonzero(labels[y:y + h, x:x + w] == j)
            vv, uu = vv + y + v0, uu + x + u0
            z = depth_m[vv, uu]
            good = np.isfinite(z) & (z > 0)
            point_c = np.full(3, np.nan)
            nd = 0
            if good.sum() >= 3:
                zg = z[good]
                med = float(np.median(zg))
                keep = np.abs(zg - med) <= max(3.0 * self.depth_rel_sigma * med, 0.004)
                if keep.sum() >= 3:
                    uv1 = np.column_stack([uu[good][keep], vv[good][keep], np.ones(int(keep.sum()))])
                    point_c = ((uv1 @ Kinv.T) * zg[keep][:, None]).mean(axis=0)
                    nd = int(keep.sum())
            pix = np.array([cent[0] + u0, cent[1] + v0])
            out.append(MarkerObservation(k, pix, area, point_c, nd))
        self._lift_on_plane(out, rgb, depth_m, Kinv)
        for o in out:
            if o is not None and np.all(np.isfinite(o.point)):
                o.point = cam.to_base(o.point)
        return out

    def _lift_on_plane(self, obs: list[MarkerObservation | None], rgb: np.ndarray, depth_m: np.ndarray,
                       Kinv: np.ndarray) -> None:
        """Replace the camera-frame marker points by centroid rays ∩ the fitted plate plane (see `detect`).

        Plate pixels: inside the markers' hull scaled by `plane_region_scale`, unsaturated, of the region's median
        grey level (± `plate_gray_tol`: the plate is one colour; rods and markers differ) and near the markers'
        depth; the plane is refitted three times keeping residuals within 2.5 σ of the depth noise."""
        seen = [o for o in obs if o is not None and np.all(np.isfinite(o.point))]
        if len(seen) < 3:
            return
        H, W = depth_m.shape
        cents = np.array([o.pixel for o in seen])
        mid = cents.mean(axis=0)
        hull = cv2.convexHull(np.round(mid + self.plane_region_scale * (cents - mid)).astype(np.int32))
        x, y, w, h = cv2.boundingRect(hull)
        x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + w, W), min(y + h, H)
        if x1 - x0 < 3 or y1 - y0 < 3:
            return
        region = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(region, hull - [x0, y0], 1)
        d = depth_m[y0:y1, x0:x1]
        hsv = cv2.cvtColor(np.ascontiguousarray(rgb[y0:y1, x0:x1]), cv2.COLOR_RGB2HSV)
        inside = (region > 0) & np.isfinite(d) & (d > 0) & (hsv[:, :, 1] < self.min_sat)
        if inside.sum() < 50:
            return
        gray = hsv[:, :, 2].astype(np.int16)
        g0 = int(np.median(gray[inside]))
        vv, uu = np.nonzero(inside & (np.abs(gray - g0) <= self.plate_gray_tol))
        if vv.size < 50:
            return
        step = max(1, vv.size // 6000)
        vv, uu = vv[::step], uu[::step]
        z = d[vv, uu].astype(float)
        # points as columns (3, N): the refits below reduce along contiguous rows
        pts = (Kinv @ np.vstack([uu + x0, vv + y0, np.ones(vv.size)])) * z
        zmed = float(np.median(np.array([o.point[2] for o in seen])))
        keep = np.abs(z - zmed) < 0.05
        for _ in range(3):
            if keep.sum() < 50:
                return
            c, n = fit_plane(pts.compress(keep, axis=1))   # compress: 4x cheaper than pts[:, keep]
            n = n if n[2] < 0 else -n          # normal towards the camera
            r = n @ (pts - c[:, None])
            sigma = max(self.depth_rel_sigma * zmed, 1e-3)
            keep = np.abs(r) < 2.5 * sigma
        c = c + n * self.layout.surface_offset
        for o in seen:
            ray = Kinv @ np.array([o.pixel[0], o.pixel[1], 1.0])
            den = float(n @ ray)
            if abs(den) < 1e-6:
                continue
            o.point = ray * float(n @ c) / den
            o.n_depth = int(keep.sum())

    def estimate(self, rgb: np.ndarray, depth_m: np.ndarray, roi: Sequence[float] | None = None
                 ) -> tuple[MarkerFit, list[MarkerObservation | None]]:
        """Plate pose T_base_plate from one aligned RGB-D pair (see `detect` and `fit_marker_set`)."""
        obs = self.detect(rgb, depth_m, roi)
        meas = np.full((len(obs), 3), np.nan)
        sig = np.full(len(obs), 1e-3)
        for k, o in enumerate(obs):
            if o is None or not np.all(np.isfinite(o.point)):
                self.missing_markers += 1
                continue
            meas[k] = o.point
            z = float(self.camera.to_camera(o.point)[2])
            sig[k] = max(self.depth_rel_sigma * z / np.sqrt(max(o.n_depth, 1)), 2e-4)
        fit = fit_marker_set(self.layout.points, meas, self.tol, sig)
        if not fit.ok:
            self.rejected_fits += 1
        return fit, obs


def pose_from_transform(T: np.ndarray) -> np.ndarray:
    """[x, y, z, α, β, γ] (m, rad; Z-Y-X Tait–Bryan as seed 000 eq 38) of a 4x4 transform."""
    R = np.asarray(T)[:3, :3]
    beta = float(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
    alpha = float(np.arctan2(R[1, 0], R[0, 0]))
    gamma = float(np.arctan2(R[2, 1], R[2, 2]))
    return np.array([T[0, 3], T[1, 3], T[2, 3], alpha, beta, gamma])
