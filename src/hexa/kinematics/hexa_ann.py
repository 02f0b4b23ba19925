"""The paper's neural-network forward kinematics of the Hexa (seed 000 §2.2.2, Figure 3), evaluated with numpy.

Training data (Figure 3): random plate poses in a box around the home pose, rejected when out of the workspace
(IK fails: unreachable, too close to arm/rod alignment, or outside the joint range) or near a type II singularity
(|det J_D| below a fraction of its home value); the IK of the kept poses gives the network inputs ζ. The MLP is trained
with torch by scripts/train_ann_fk.py and exported to `hexa_ann_fk.npz` next to this module; this module needs no
torch. Inputs and outputs are standardised with the training-set mean and standard deviation.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.kinematics import hexa6rus

if TYPE_CHECKING:
    from hexa.robots.hexa_description import HexaDescription

DEFAULT_WEIGHTS = Path(__file__).resolve().parent / "hexa_ann_fk.npz"

#: Half-widths of the sampling box around the home pose: x, y, z (m), alpha, beta, gamma (rad). It covers the
#: paper's trajectories (|x|, |y| <= 0.11 m, z in [-0.55, -0.50] m, alpha = -6°, |beta|, |gamma| <= 31°).
SAMPLE_SPAN = (0.13, 0.13, 0.08, 0.20, 0.62, 0.62)
#: Reject poses whose |det J_D| is below this fraction of the home value (near type II singularity).
SINGULAR_FRACTION = 0.2


class AnnModelError(ValueError):
    """The ANN weight file is missing, malformed, or was trained for another geometry (named)."""


def geometry_fingerprint(desc: "HexaDescription") -> np.ndarray:
    """The numbers the network depends on: A (18), C (18), l_a, l_d, branch (39,)."""
    return np.concatenate([desc.A.ravel(), desc.C.ravel(), [desc.l_a, desc.l_d, float(desc.branch)]])


def sample_training_set(desc: "HexaDescription", n: int, seed: int = 0,
                        span: tuple[float, ...] = SAMPLE_SPAN) -> tuple[np.ndarray, np.ndarray]:
    """(ζ (n, 6), pose (n, 6)) from uniform random poses around home, out-of-workspace and near-singular rejected.

    Follows Figure 3 of seed 000: target data = poses, input data = their IK.
    """
    rng = np.random.default_rng(seed)
    home = np.asarray(desc.home_pose)
    zeta_home = hexa6rus.inverse_kinematics(desc, home)
    det_home = abs(np.linalg.det(hexa6rus.constraint_jacobians(desc, home, zeta_home)[0]))
    poses, zetas = [], []
    have = 0
    while have < n:
        cand = home + rng.uniform(-1.0, 1.0, (max(2 * (n - have), 1024), 6)) * np.asarray(span)
        zeta = hexa6rus.inverse_kinematics_batch(desc, cand, check=False)
        a, b, c = hexa6rus.ik_coefficients(desc, cand)
        ok = (np.abs(a / np.hypot(b, c)) <= desc.max_alignment).all(1)
        ok &= ((zeta >= desc.zeta_min) & (zeta <= desc.zeta_max)).all(1)
        idx = np.flatnonzero(ok)
        dets = np.abs(np.linalg.det(hexa6rus.constraint_jacobian_jd_batch(desc, cand[idx], zeta[idx])))
        keep = idx[dets > SINGULAR_FRACTION * det_home]
        poses.append(cand[keep])
        zetas.append(zeta[keep])
        have += len(keep)
    return np.concatenate(zetas)[:n], np.concatenate(poses)[:n]


@dataclass(frozen=True)
class AnnForwardKinematics:
    """A tanh MLP ζ → pose with standardised inputs/outputs; `predict` takes (6,) or (N, 6) arm angles (rad)."""

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    x_mean: np.ndarray
    x_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray
    fingerprint: np.ndarray
    meta: dict

    def predict(self, zeta: np.ndarray) -> np.ndarray:
        """Approximate pose [x y z α β γ] (m, rad) for arm angles ζ (seed 000 §2.2.2)."""
        h = (np.asarray(zeta, dtype=float) - self.x_mean) / self.x_std
        last = len(self.weights) - 1
        for k, (W, b) in enumerate(zip(self.weights, self.biases)):
            h = h @ W + b
            if k < last:
                h = np.tanh(h)
        return h * self.y_std + self.y_mean

    def matches(self, desc: "HexaDescription") -> bool:
        """True when the network was trained for this geometry (A, C, l_a, l_d, branch)."""
        fp = geometry_fingerprint(desc)
        return fp.shape == self.fingerprint.shape and bool(np.allclose(fp, self.fingerprint, atol=1e-12))

    @property
    def n_parameters(self) -> int:
        return int(sum(W.size + b.size for W, b in zip(self.weights, self.biases)))


def save_ann_fk(path: str | Path, weights: list[np.ndarray], biases: list[np.ndarray], x_mean: np.ndarray,
                x_std: np.ndarray, y_mean: np.ndarray, y_std: np.ndarray, fingerprint: np.ndarray,
                meta: dict) -> None:
    """Write the network as a compressed .npz (float32 weights, layer k as W{k}/b{k}, metadata as JSON)."""
    arrays: dict[str, Any] = {f"W{k}": np.asarray(W, np.float32) for k, W in enumerate(weights)}
    arrays.update({f"b{k}": np.asarray(b, np.float32) for k, b in enumerate(biases)})
    np.savez_compressed(path, x_mean=x_mean, x_std=x_std, y_mean=y_mean, y_std=y_std, fingerprint=fingerprint,
                        meta=np.array(json.dumps(meta)), **arrays)


def load_ann_fk(path: str | Path | None = None, desc: "HexaDescription | None" = None) -> AnnForwardKinematics:
    """Load the exported network (default src/hexa/kinematics/hexa_ann_fk.npz); weights kept in float64.

    Raises:
        AnnModelError: file missing or malformed, or trained for a different geometry than `desc`.
    """
    p = Path(path) if path is not None else DEFAULT_WEIGHTS
    if not p.is_file():
        raise AnnModelError(f"ANN weights {p} do not exist (run scripts/train_ann_fk.py)")
    try:
        with np.load(p, allow_pickle=False) as z:
            n = sum(1 for k in z.files if k.startswith("W"))
            weights = tuple(z[f"W{k}"].astype(float) for k in range(n))
            biases = tuple(z[f"b{k}"].astype(float) for k in range(n))
            model = AnnForwardKinematics(weights, biases, z["x_mean"], z["x_std"], z["y_mean"], z["y_std"],
                                         z["fingerprint"], json.loads(str(z["meta"])))
    except (KeyError, ValueError, OSError) as exc:
        raise AnnModelError(f"ANN weights {p} are malformed: {exc}") from exc
    if desc is not None and not model.matches(desc):
        raise AnnModelError(f"ANN weights {p} were trained for another geometry than {desc.path}; retrain")
    return model
