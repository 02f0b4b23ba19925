"""Seed 003 sec 3.1 experiments in simulation: drive to a singular pose, wait, enable the SRM, measure.

For each trajectory: move from the home pose to the Table 3 singular pose at constant velocity, stay there
`wait_before_enable` s (15 s; optionally pushed by hand), then enable the SRM for `release_window` s (15 s).
The hybrid controller runs at t_s = 0.01 s: X_c from the simulated tracking system, V_Omega and det J_D at
X_c, Algorithm 1, then the actuators' inner loop.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.kinematics import upsrpu as kin
from hexa.singularity import upsrpu_indices
from hexa.srm import metrics
from hexa.srm.algorithm import SingularityReleaseModule
from hexa.srm.plant import SimulatedUpsrpu, half_sine_push

if TYPE_CHECKING:
    from hexa.robots.upsrpu_description import UpsrpuDescription

__all__ = ["ReleaseResult", "reference_path", "run_release_experiment", "PAPER_TABLE4", "PAPER_TABLE5"]

#: Seed 003 Table 4 (simulation): trajectory -> {variant: (MAE mm, MAPE %, MDSR mm)}.
PAPER_TABLE4 = {1: {1: (3.87, 0.53, 7.01), 2: (10.74, 1.40, 18.18)}, 2: {1: (1.09, 0.14, 5.05), 2: (2.04, 0.28, 2.92)},
                3: {1: (1.77, 0.24, 4.78), 2: (6.15, 0.82, 6.74)}, 4: {1: (3.00, 0.38, 7.48), 2: (10.24, 1.25, 10.81)},
                5: {1: (10.74, 1.43, 15.47), 2: (10.44, 1.37, 35.23)}}
#: Seed 003 Table 5 (experiment, SRM-V1): trajectory -> (MAE mm, MAPE %, MDSR mm, AVR N).
PAPER_TABLE5 = {1: (3.26, 0.45, 3.64, 0.22), 2: (3.02, 0.41, 7.61, 0.52), 3: (2.05, 0.27, 1.60, 0.17),
                4: (2.14, 0.27, 1.90, 0.46), 5: (10.66, 1.42, 11.82, 1.44)}


@dataclass
class ReleaseResult:
    """Time series (rows = controller samples) and the metrics of one run."""

    trajectory: str
    variant: int
    t: np.ndarray
    X_r: np.ndarray
    X_c: np.ndarray
    X_kin: np.ndarray
    q_r: np.ndarray
    q_d: np.ndarray
    q_c: np.ndarray
    tau: np.ndarray
    det_jd: np.ndarray
    min_omega: np.ndarray
    min_pair: list[str]
    enabled: np.ndarray
    k: int                                    # first sample with the enable pin set
    released: bool
    release_time: float | None                # s after activation until both indices are above their limits
    metrics: dict[str, float] = field(default_factory=dict)
    moved_limbs: tuple[int, ...] = ()         # limbs (from 1) whose Delta ever changed
    implicated: tuple[int, ...] = ()          # limbs (from 1) implicated by min Omega at activation
    final_delta: tuple[int, ...] = ()

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary in SI units plus mm/deg for the paper's tables."""
        return {
            "trajectory": self.trajectory, "variant": f"v{self.variant}", "released": self.released,
            "release_time_s": self.release_time, "implicated_limbs": list(self.implicated),
            "moved_limbs": list(self.moved_limbs), "final_delta": list(self.final_delta),
            "at_activation": {"det_jd": float(self.det_jd[self.k]),
                              "min_omega_deg": math.degrees(self.min_omega[self.k]),
                              "min_pair": self.min_pair[self.k]},
            "at_end": {"det_jd": float(self.det_jd[-1]), "min_omega_deg": math.degrees(self.min_omega[-1]),
                       "min_pair": self.min_pair[-1]},
            "metrics": dict(self.metrics),
        }


def reference_path(desc: UpsrpuDescription, trajectory: str | int) -> np.ndarray:
    """Cartesian reference (N, 4) at t_s from the start until arrival at the singular pose.

    `trajectory` is 1..5 (Table 3) or the name of an authors' reference file ("TR15", "TRR0"; the trailing
    hold is trimmed, the 15 s wait is added by the experiment).
    """
    if str(trajectory).isdigit():
        _, X = kin.table3_trajectory(desc, int(trajectory), dt=desc.t_s)
        return X
    _, X = kin.load_reference_trajectory(str(trajectory), rate=1.0 / desc.t_s)
    moving = np.flatnonzero(np.any(np.abs(np.diff(X, axis=0)) > 0, axis=1))
    return X[: moving[-1] + 2] if len(moving) else X


def run_release_experiment(desc: UpsrpuDescription, trajectory: str | int, variant: int = 1, push: bool = False,
                           push_force: float = 10.0, pose_noise: float = 0.0, seed: int = 0,
                           wait: float | None = None, window: float | None = None,
                           marker_noise: float | None = None) -> ReleaseResult:
    """Simulate one trajectory with SRM-V`variant` and compute MAE, MAPE, MDSR and AVR after activation.

    Args:
        push: apply a push by hand (half-sine generalised force of `push_force` N on x_m and N m on psi,
            2 s long, 5 s into the wait) while the robot sits at the singular pose.
        pose_noise: standard deviation of a noise added directly to X_c (m / rad).
        marker_noise: when given, X_c is measured like the paper's 3D tracking system: simulated markers of
            both platforms with this noise (m, std per coordinate) fitted by `hexa.srm.tracking`.
    """
    ts = desc.t_s
    wait = desc.wait_before_enable if wait is None else wait
    window = desc.release_window if window is None else window
    X_path = reference_path(desc, trajectory)
    n_move = len(X_path)
    n_wait = int(round(wait / ts))
    n_win = int(round(window / ts))
    X_r = np.vstack([X_path, np.repeat(X_path[-1][None], n_wait + n_win, axis=0)])
    N = len(X_r)
    t = np.arange(N) * ts
    k = n_move + n_wait
    q_r = kin.inverse_kinematics_batch(desc, X_r)
    push_fn = None
    if push:
        push_fn = half_sine_push(t[n_move] + min(5.0, wait / 3), min(2.0, wait / 3),
                                 np.array([push_force, 0.0, 0.0, push_force * 0.1]))
    plant = SimulatedUpsrpu(desc, X_r[0], push=push_fn, pose_noise=pose_noise, seed=seed)
    srm = SingularityReleaseModule(desc, variant)
    out = {name: np.empty((N, 4)) for name in ("X_c", "X_kin", "q_d", "q_c", "tau")}
    det = np.empty(N)
    min_om = np.empty(N)
    pairs: list[str] = []
    enabled = np.zeros(N, dtype=bool)
    moved: set[int] = set()
    implicated: tuple[int, ...] = ()
    tracking = None
    if marker_noise is not None:
        from hexa.srm.tracking import markers_from_pose, pose_from_markers, tracking_model

        tracking = tracking_model(desc)
        rng = np.random.default_rng(seed + 1)
    state = plant.state()
    for j in range(N):
        if tracking is not None:
            fixed, mobile = markers_from_pose(tracking, state.X, rng, marker_noise)
            state.X = pose_from_markers(tracking, fixed, mobile)[0]
        rep = upsrpu_indices(desc, state.X)
        enabled[j] = j >= k
        q_d = srm.step(q_r[j], state.X, enabled[j], rep)
        if srm.last.moved:
            moved.update(i + 1 for i in srm.last.moved)
        if j == k and srm.last.active:
            implicated = tuple(i + 1 for i in srm.last.i_ch)
        out["X_c"][j], out["X_kin"][j], out["q_c"][j], out["tau"][j] = state.X, state.X_kin, state.q, state.tau
        out["q_d"][j] = q_d
        det[j], min_om[j] = rep.det_jd, rep.min_omega
        pairs.append(rep.min_pair)
        state = plant.advance(q_d, ts)
    near = (np.abs(det) < desc.det_jd_limit) | (min_om < desc.omega_limit)
    after = np.flatnonzero(~near[k:])
    released = bool(not near[-1])
    release_time = float(after[0] * ts) if len(after) else None
    sl = slice(k, N)
    res = ReleaseResult(
        trajectory=str(trajectory), variant=variant, t=t, X_r=X_r, X_c=out["X_c"], X_kin=out["X_kin"], q_r=q_r,
        q_d=out["q_d"], q_c=out["q_c"], tau=out["tau"], det_jd=det, min_omega=min_om, min_pair=pairs,
        enabled=enabled, k=k, released=released, release_time=release_time, moved_limbs=tuple(sorted(moved)),
        implicated=implicated, final_delta=tuple(int(v) for v in srm.delta))
    res.metrics = {
        "mae_m": metrics.mae(q_r[sl], out["q_c"][sl]),
        "mape_pct": metrics.mape(q_r[sl], out["q_c"][sl]),
        "mdsr_m": metrics.mdsr(out["q_c"][sl]),
        "mdsr_as_printed_m": metrics.mdsr_as_printed(q_r[sl], out["q_c"][sl]),
        "max_deviation_m": float(np.mean(np.max(np.abs(q_r[sl] - out["q_c"][sl]), axis=0))),
        "avr_n": metrics.avr(out["tau"][sl]),
    }
    return res
