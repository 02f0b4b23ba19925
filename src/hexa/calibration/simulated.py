"""Calibration of a simulated robot in-process: the runs of an excitation file on the simulator of a seed (one free,
one carrying a known mass), identified into an overlay — what `hexa calibrate identify --simulate SEED` does and what
`hexa eval --calibrate` gives each robot's nodes."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from hexa.calibration.recording import CALIBRATION_RATE_HZ

if TYPE_CHECKING:
    from hexa.calibration.identify import Calibration
    from hexa.calibration.recording import Recording
    from hexa.robots.hexa_description import HexaDescription
    from hexa.sim.realism import RealismConfig, RobotTruth

#: kg: the known mass of a simulated payload run, at the plate's origin
SIM_PAYLOAD = 0.5


def simulate_excitation_runs(excitation: str | Path, seed: int, realism: RealismConfig, desc: HexaDescription,
                             payload: float = SIM_PAYLOAD, payload_point: Any = (0.0, 0.0, 0.0),
                             current_rate_hz: float = CALIBRATION_RATE_HZ,
                             progress: Callable[[str], Callable[[float], None] | None] | None = None
                             ) -> tuple[list[Recording], RobotTruth | None]:
    """The excitation file played on the simulated robot of `seed`: without payload, then (payload > 0) with the
    known mass at `payload_point` ({P}, m). `progress(label)` gives each run's progress callback."""
    from hexa.calibration.recording import simulate_recording
    from hexa.trajectories import load_pose_file

    pose_of, duration = load_pose_file(excitation)
    recs, truth = [], None
    for k, m in enumerate((0.0, payload) if payload > 0 else (0.0,)):
        rec, truth = simulate_recording(lambda t: pose_of(t)[0], duration, seed=seed, realism=realism, desc=desc,
                                        payload=m, payload_point=np.asarray(payload_point, dtype=float),
                                        progress=progress(f"simulating run {k + 1} (payload {m:g} kg)")
                                        if progress else None, current_rate_hz=current_rate_hz)
        recs.append(rec)
    return recs, truth


def calibrate_simulated_robot(excitation: str | Path, seed: int, realism: RealismConfig, desc: HexaDescription,
                              out: str | Path) -> tuple[HexaDescription, Calibration]:
    """Identify the simulated robot of `seed` from the excitation file (two runs, currents at CALIBRATION_RATE_HZ)
    and write its overlay to `out`; returns (the description with the overlay, as a node loads it, the calibration).

    Raises:
        hexa.calibration.identify.CalibrationError, RecordingError: the file is no excitation, or the runs cannot be
            identified.
    """
    from hexa.calibration.excitation import Excitation
    from hexa.calibration.identify import CalibrationError, identify, prepare
    from hexa.calibration.overlay import write_overlay
    from hexa.robots.hexa_description import load_hexa

    exc = Excitation.read_design(excitation)
    if exc is None:
        raise CalibrationError(f"{excitation} holds no excitation design (not written by `hexa calibrate excite`)")
    recs, _ = simulate_excitation_runs(excitation, seed, realism, desc)
    cal = identify([prepare(r, desc, period=exc.period) for r in recs], desc)
    return load_hexa(write_overlay(out, cal, desc)), cal
