"""The Hexa's plate outline: the hexagon through the plate joints C_i (in {P}), and where a ray from the plate's
centre meets it. The simulator builds the plate's mesh and places scripted plate contacts with it; the isolation
locates a plate contact on it (seed 000, Fig. 12g)."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription


def plate_outline(desc: HexaDescription) -> np.ndarray:
    """Hexagon (6, 2) through the plate joints C_i in {P} (x, y, m), ordered by angle."""
    C = np.asarray(desc.C, dtype=float)[:, :2]
    return C[np.argsort(np.arctan2(C[:, 1], C[:, 0]))]


def hexagon_border_point(hexagon: np.ndarray, direction_xy: ArrayLike) -> np.ndarray:
    """Border point (2,) of the polygon `hexagon` (in {P}) on the ray from the plate centre along `direction_xy`;
    ValueError when the ray meets no edge (a zero direction, or a centre outside the polygon)."""
    d = np.asarray(direction_xy, float)
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    n = len(hexagon)
    best = None
    for k in range(n):
        a, b = hexagon[k], hexagon[(k + 1) % n]
        M = np.column_stack([d, a - b])
        if abs(np.linalg.det(M)) < 1e-12:
            continue
        s, u = np.linalg.solve(M, a)
        if s > 0 and -1e-9 <= u <= 1 + 1e-9 and (best is None or s < best):
            best = s
    if best is None:
        raise ValueError(f"no hexagon border point along {d.tolist()}")
    return best * d
