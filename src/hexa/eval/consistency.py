"""The live graph against `hexa eval` on the same case and seed: a demo case (`hexa demo`'s nominal scenario) run
through `hexa.eval.campaign.simulate`, and how its detection time, link/chain and force RMSE compare with the live
graph's (docs/eval_live.md).

Both sides are `hexa.report.collision_demo.compute_metrics` dictionaries (`CaseMetrics.as_dict()`): what `hexa demo
--json` prints per case, and what `offline_case` returns.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hexa.report.collision_demo import DEMO_CASES

if TYPE_CHECKING:
    from hexa.sim.scenarios import ScriptedCollision



@dataclass(frozen=True)
class Agreement:
    """How one case's live metrics compare with the offline run's: detection time difference live − offline (s),
    whether both found the same link and chain, and the live force RMSE over the offline one per axis."""

    case: str
    detect_live: float
    detect_offline: float
    same_link: bool
    rmse_live: tuple[float, float, float]
    rmse_offline: tuple[float, float, float]

    @property
    def detect_difference(self) -> float:
        return self.detect_live - self.detect_offline

    @property
    def rmse_ratio(self) -> tuple[float, ...]:
        return tuple(a / b if b > 0 else math.inf for a, b in zip(self.rmse_live, self.rmse_offline))

    def row(self) -> str:
        """A markdown table row: case, detection live / offline (s), difference (ms), links, RMSEs (N), ratios."""
        fmt = " ".join
        return (f"| {self.case} | {self.detect_live:.3f} | {self.detect_offline:.3f} | "
                f"{1e3 * self.detect_difference:+.0f} | {'yes' if self.same_link else 'no'} | "
                f"{fmt(f'{v:.3f}' for v in self.rmse_live)} | {fmt(f'{v:.3f}' for v in self.rmse_offline)} | "
                f"{fmt(f'{v:.2f}' for v in self.rmse_ratio)} |")


TABLE_HEADER = ("| case | detected live (s) | detected offline (s) | live − offline (ms) | same link/chain | "
                "force RMSE live x y z (N) | offline x y z (N) | live / offline |\n|---|---|---|---|---|---|---|---|")


def agreement(case: str, live: dict[str, Any], offline: dict[str, Any]) -> Agreement:
    """Compare two `CaseMetrics.as_dict()` of the same case."""
    same = (live["found_link"], live["found_chain"]) == (offline["found_link"], offline["found_chain"])
    return Agreement(case, float(live["detect_time"]), float(offline["detect_time"]), same,
                     tuple(float(v) for v in live["force_rmse"]),      # type: ignore[arg-type]
                     tuple(float(v) for v in offline["force_rmse"]))   # type: ignore[arg-type]


def offline_contact(collision: ScriptedCollision, duration: float, seed: int = 0, realism: str = "ideal",
                    command_phase: float = 0.0, isolation: str = "rendered", identify: bool = True) -> dict[str, Any]:
    """`collision` on its trajectory for `duration` s after the lead-in through `hexa.eval.campaign.simulate` with
    simulator seed `seed` on the robot `realism` ("ideal" | "realistic"), the commands going out `command_phase` s
    after a current sample, with `isolation` ("rendered" | "oracle") and the force identified (`identify`); its
    `CaseMetrics.as_dict()`. On a robot that is not its model the observer and the force tracker run the calibration
    overlay `hexa demo` gives the live nodes (`hexa.calibration.simulated.nodes_description_of`, the same cache).

    Raises:
        hexa.sim.camera.RenderError: no GL context for the rendered isolation;
        hexa.calibration.identify.CalibrationError, hexa.calibration.recording.RecordingError: no calibration.
    """
    from hexa.calibration.simulated import nodes_description_of
    from hexa.eval.campaign import R_LOW, case_data, simulate
    from hexa.report.collision_demo import compute_metrics
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim.realism import RealismConfig

    cfg = RealismConfig.named(realism)
    overlay = nodes_description_of(seed, cfg)
    rec = simulate(collision, collision.trajectory, duration, cfg, seed, identify=identify, isolation=isolation,
                   command_phase=command_phase, nodes_desc=load_hexa(overlay) if overlay else None)
    d = case_data(collision.name, rec, rec.events, (2.0,) * 3 + (0.2,) * 3, (0.35,) * 6)
    return compute_metrics(d, r_low=R_LOW).as_dict()


def offline_case(case: str, seed: int = 0, realism: str = "ideal", command_phase: float = 0.0,
                 isolation: str = "rendered", identify: bool = True) -> dict[str, Any]:
    """The demo case `case` (its nominal scenario, trajectory and duration) through `offline_contact`.

    Raises:
        KeyError: an unknown case; hexa.sim.camera.RenderError: no GL context for the rendered isolation.
    """
    from hexa.sim.scenarios import draw_collision, load_scenario

    scenario, trajectory, duration = DEMO_CASES[case]
    collision = dataclasses.replace(draw_collision(load_scenario(scenario)), trajectory=trajectory)
    return offline_contact(collision, duration, seed, realism, command_phase, isolation, identify)


#: command phases (s after a current sample; the samples come every 5 ms) the offline detection times span
PHASES = (0.0, 0.001, 0.002, 0.003, 0.004)


def detection_span(case: str, seed: int = 0, realism: str = "ideal", phases: tuple[float, ...] = PHASES
                   ) -> tuple[float, float]:
    """The earliest and latest offline detection time (s) of `case` over the command `phases` (oracle isolation, no
    force identification: only the detector's output is compared). In the live graph the phase is wherever the
    host's scheduling puts each command; the detector's output depends on it (docs/eval_live.md)."""
    times = [offline_case(case, seed, realism, p, isolation="oracle", identify=False)["detect_time"] for p in phases]
    return min(times), max(times)
