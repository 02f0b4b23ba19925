"""Calibration of a simulated robot in-process: the runs of an excitation file on the simulator of a seed (one free,
one carrying a known mass), identified into an overlay — what `hexa calibrate identify --simulate SEED` does and what
`hexa eval --calibrate` gives each robot's nodes."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from hexa.calibration.recording import CALIBRATION_RATE_HZ

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from hexa.calibration.identify import Calibration
    from hexa.calibration.recording import Recording
    from hexa.robots.hexa_description import HexaDescription
    from hexa.sim.realism import RealismConfig, RobotTruth

#: kg: the known mass of a simulated payload run, at the plate's origin
SIM_PAYLOAD = 0.5


def simulate_excitation_runs(excitation: str | Path, seed: int, realism: RealismConfig, desc: HexaDescription,
                             payload: float = SIM_PAYLOAD, payload_point: ArrayLike = (0.0, 0.0, 0.0),
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


#: the packages of hexa whose source a cached calibration of a simulated robot depends on besides its inputs (the
#: excitation's design on `calibration` alone)
_CACHE_SOURCES = ("calibration", "sim")


def cache_dir() -> Path:
    """Where simulated calibrations are kept: `HEXA_CACHE_DIR`, else `$XDG_CACHE_HOME/hexa`, else ~/.cache/hexa."""
    import os

    if os.environ.get("HEXA_CACHE_DIR"):
        return Path(os.environ["HEXA_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "hexa"


def _digest(*parts: bytes | str) -> str:
    import hashlib

    h = hashlib.sha256()
    for p in parts:
        b = p.encode() if isinstance(p, str) else p
        h.update(len(b).to_bytes(8, "little"))
        h.update(b)
    return h.hexdigest()[:16]


def _sources_digest(packages: tuple[str, ...] = _CACHE_SOURCES) -> str:
    """One digest of the code that shapes a simulated calibration (the source of hexa's `packages`)."""
    root = Path(__file__).resolve().parents[1]
    files = sorted(f for pkg in packages for f in (root / pkg).rglob("*") if f.suffix in (".py", ".yaml"))
    return _digest(*(f"{f.relative_to(root)}" for f in files), *(f.read_bytes() for f in files))


def _description_bytes(path: Path) -> bytes:
    """The bytes of a description file, and of its base if it is a calibration overlay."""
    from hexa.robots.hexa_description import OVERLAY_KEY, overlay_base
    from hexa.robots.schema import load_yaml

    data = load_yaml(path)
    return path.read_bytes() + (overlay_base(path, data).read_bytes() if OVERLAY_KEY in data else b"")


def simulated_calibration(seed: int, realism: RealismConfig, description: str | Path | None = None,
                          cache: str | Path | None = None,
                          log: Callable[[str], None] | None = None) -> Path:
    """The calibration overlay of the simulated robot of `seed` and `realism` (the robot `hexa-sim` runs with the
    same seed and realism), identified as `hexa calibrate` does — the default excitation design, a free run and a
    run carrying SIM_PAYLOAD, `identify` — from motion and currents only, never from the simulator's truth.

    Kept in `cache` (default `cache_dir()`/calibration) under a key of the seed, the realism, the description's
    bytes and the source of the packages that shape the result, so that repeated demos and tests identify each
    robot once; processes that ask for the same robot at once wait for the first. `log` gets one line per step
    that takes time. Returns the overlay's path (give it to the nodes as their `description`).

    Raises:
        hexa.calibration.identify.CalibrationError, RecordingError: the robot cannot be identified.
    """
    import fcntl
    import os
    import time

    from hexa.calibration.excitation import ExcitationSettings, design_excitation
    from hexa.robots.hexa_description import DEFAULT_PATH, load_hexa

    path = Path(description) if description is not None else DEFAULT_PATH
    folder = Path(cache) if cache is not None else cache_dir() / "calibration"
    folder.mkdir(parents=True, exist_ok=True)
    settings = ExcitationSettings()
    base_key = _digest(_description_bytes(path), repr(settings), _sources_digest(("calibration",)))
    excitation = folder / f"excitation-{base_key}.csv"
    robot_key = _digest(base_key, str(int(seed)), repr(realism), _sources_digest())
    overlay = folder / f"sim-seed{int(seed)}-{realism.name}-{robot_key}.yaml"
    say = log or (lambda _line: None)
    with open(folder / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)            # one identification at a time; the others then find its file
        try:
            if overlay.is_file():
                return overlay
            desc = load_hexa(path)
            if not excitation.is_file():
                t0 = time.monotonic()
                say(f"designing the calibration excitation (once per description) → {excitation}")
                tmp = excitation.with_suffix(f".tmp{os.getpid()}.csv")
                design_excitation(desc, settings).write(tmp, settings.rate_hz)
                os.replace(tmp, excitation)
                say(f"excitation designed in {time.monotonic() - t0:.0f} s")
            t0 = time.monotonic()
            say(f"calibrating the simulated {realism.name} robot of seed {seed} (excitation runs with and without "
                f"{SIM_PAYLOAD:g} kg, identification; once per robot) → {overlay}")
            tmp = overlay.with_suffix(f".tmp{os.getpid()}.yaml")
            calibrate_simulated_robot(excitation, seed, realism, desc, tmp)
            os.replace(tmp, overlay)
            say(f"calibrated in {time.monotonic() - t0:.0f} s")
            return overlay
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def nodes_description_of(seed: int, realism: RealismConfig,
                         log: Callable[[str], None] | None = None) -> Path | None:
    """The description the nodes run on the simulated robot of `seed` and `realism`: None (the packaged one) on a
    robot that is its model (no drawn truth, no servo mechanics), else its calibration overlay
    (`simulated_calibration`, cached). The live graph and the offline runs compared with it take it from here.

    Raises:
        hexa.calibration.identify.CalibrationError, RecordingError: the robot cannot be identified.
    """
    if not realism.truth and not realism.servo_mechanics:
        return None
    return simulated_calibration(seed, realism, log=log)
