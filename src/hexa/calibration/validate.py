"""Free-motion residual of a held-out run before and after calibration (`hexa calibrate validate`).

The residual of free motion is the model error the collision observer sees: in servo space e = τ_measured − τ_model
(N·m), on the plate axes the wrench J_ζᵀ e in `base` (N, N·m; the observer's r of seed 000 eq 24 without the
filter lag). "Before": the description's model, τ = K_t·I. "After": the calibrated description as the nodes use it —
the overlay's symmetric model and `ServoTorqueModel` (per-servo K_i, offsets, friction, arm first moments).
Motion from the camera poses (low-pass, IK), currents low-passed as in identification.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from pathlib import Path

    from numpy.typing import NDArray

    from hexa.calibration.identify import Motion
    from hexa.calibration.recording import Recording
    from hexa.robots.hexa_description import HexaDescription

AXES = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


@dataclass
class ResidualComparison:
    """Residual time series (N, 6) on the plate axes and in servo space, before and after, at `t`."""

    t: NDArray
    before: NDArray
    after: NDArray
    servo_before: NDArray
    servo_after: NDArray

    def rms(self) -> dict[str, Any]:
        """RMS per plate axis and per servo, before / after and their ratio."""
        rb, ra = np.sqrt(np.mean(self.before ** 2, 0)), np.sqrt(np.mean(self.after ** 2, 0))
        sb, sa = np.sqrt(np.mean(self.servo_before ** 2, 0)), np.sqrt(np.mean(self.servo_after ** 2, 0))
        return {"axes": {a: {"before": float(b), "after": float(c), "ratio": float(c / b) if b > 0 else float("nan")}
                         for a, b, c in zip(AXES, rb, ra)},
                "servos": {f"arm_{i + 1}": {"before": float(b), "after": float(c),
                                            "ratio": float(c / b) if b > 0 else float("nan")}
                           for i, (b, c) in enumerate(zip(sb, sa))},
                "samples": int(self.t.size)}


def _model_torques(desc: HexaDescription, mo: Motion) -> NDArray:
    """The symmetric model's free-motion servo torques of `desc` along the prepared motion `mo`."""
    from hexa.calibration.regressor import sym_from_params
    from hexa.dynamics.lagrange import HexaDynamicParameters

    prm = HexaDynamicParameters.from_description(desc)
    r = mo.reg
    return r.torques(sym_from_params(prm), np.full(6, prm.J_a), np.full(6, prm.m_a * prm.s_a), np.zeros(6),
                     np.full(6, prm.arm_damping))


def compare(rec: Recording, desc_before: HexaDescription, desc_after: HexaDescription) -> ResidualComparison:
    """Residuals of the run `rec` with the two descriptions (module docstring).

    Raises:
        hexa.calibration.recording.RecordingError, hexa.calibration.identify.CalibrationError: unusable run.
    """
    from hexa.calibration.identify import prepare
    from hexa.calibration.overlay import ServoTorqueModel
    from hexa.dynamics.lagrange import _Geometry, pose_to_position_rotation

    mo = prepare(rec, desc_before)          # the motion is the camera's; the geometry is the same in both
    p, R = pose_to_position_rotation(mo.poses)
    out = []
    for desc in (desc_before, desc_after):
        from hexa.dynamics.lagrange import HexaDynamicParameters

        stm = ServoTorqueModel(desc)
        meas = stm.correct(stm.from_currents(mo.currents), mo.zeta, mo.zeta_dot)
        e = meas - _model_torques(desc, mo)
        j = _Geometry(HexaDynamicParameters.from_description(desc), mo.zeta, p, R).j
        out.append((np.einsum("ni,nik->nk", e, j), e))
    return ResidualComparison(t=mo.t, before=out[0][0], after=out[1][0], servo_before=out[0][1],
                              servo_after=out[1][1])


def plot(cmp: ResidualComparison, path: str | Path, title: str = "") -> str | Path:
    """PNG of the six plate-axis residuals before and after (matplotlib, Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(6, 1, figsize=(9, 10), sharex=True)
    t = cmp.t - cmp.t[0]
    for k, ax in enumerate(axs):
        ax.plot(t, cmp.before[:, k], lw=0.8, color="tab:red", label="before")
        ax.plot(t, cmp.after[:, k], lw=0.8, color="tab:blue", label="after")
        ax.set_ylabel(f"{AXES[k]} ({'N' if k < 3 else 'N·m'})")
        ax.grid(alpha=0.3)
    axs[0].legend(loc="upper right", ncol=2)
    axs[-1].set_xlabel("time (s)")
    fig.suptitle(title or "free-motion residual before and after calibration")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
