"""`hexa eval`: a randomized campaign of contacts and free motion on the simulated robot, run through the nodes' own
core classes without ROS, in parallel over the local cores (a process pool) or on a Dask distributed cluster. See
docs/eval.md.

    from hexa.eval import CampaignConfig, run_campaign
    from hexa.eval.report import write_report
    result = run_campaign(CampaignConfig(cases=6, free_seconds=20.0, workers=2))
    write_report(result, "out/eval")
"""
from __future__ import annotations

import math
import multiprocessing
import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable, TextIO

from hexa.eval.campaign import (ISOLATION_MODES, TRAJECTORIES, kinds_of, run_calibration_job, run_contact_job,
                                run_free_job)

if TYPE_CHECKING:
    from distributed import Client, LocalCluster

#: free motion is cut into jobs of at most this many seconds (one trajectory each, looped), for the parallel pool
FREE_CHUNK_S = 60.0


@dataclass(frozen=True)
class CampaignConfig:
    """What to run: `cases` random contacts and `free_seconds` of free motion on each robot of `realisms` ("ideal",
    "realistic"), over the `trajectories` "paper" (the paper's three), "random" (random smooth reachable ones,
    hexa.random_trajectory) or "all" (both: contacts alternate, free motion is split in halves); `seed` draws the
    contacts and the random trajectories and seeds the simulators; `workers`
    processes (default: the CPU count); `identify`: run the force identification (rnea's tracker) in the contact
    cases; `observer`: ObserverConfig fields that replace the node's defaults; `detector`: the live detector
    ("cusum" | "threshold", the node's `detector` parameter) and `cusum`: CusumConfig fields; `scheduler`: None
    (the local process pool), "local:N" (a Dask LocalCluster of N single-threaded worker processes) or a Dask
    scheduler's address ("tcp://host:8786"; its workers need hexa installed); `isolation`: "rendered" (the
    isolation node's core on rendered frames, the default; the oracle when this machine cannot render, see
    `isolation_mode`) or "oracle" (the true contact at the START: isolation not measured); `calibrate`: an
    excitation file (`hexa calibrate excite`): the nodes run the calibration overlay identified in-process on their
    simulated robot (two runs of the file, hexa.calibration.simulated; ≈ 10–30 s a robot) instead of the
    description; `robots`: 0 (default) draws a robot for every job, N > 0 runs the jobs on N robots in turn (robot
    seeds seed·100003 + 90000 + n), each calibrated once before the jobs when `calibrate` is given;
    `stream_rate_hz`: the currents' rate (default the driver's `stream_rate_hz`, 200 Hz)."""

    cases: int = 6
    free_seconds: float = 20.0
    realisms: tuple[str, ...] = ("ideal",)
    seed: int = 0
    workers: int | None = None
    identify: bool = True
    observer: dict[str, Any] = field(default_factory=dict)
    scheduler: str | None = None
    detector: str = "threshold"
    cusum: dict[str, Any] = field(default_factory=dict)
    trajectories: str = "all"
    isolation: str = "rendered"
    calibrate: str | None = None
    stream_rate_hz: float | None = None
    robots: int = 0

    def __post_init__(self) -> None:
        from hexa.sim.realism import RealismConfig

        kinds_of(self.trajectories)   # raises ValueError naming the choices
        if self.isolation not in ISOLATION_MODES:
            raise ValueError(f"isolation must be one of {ISOLATION_MODES}, got {self.isolation!r}")
        if self.cases < 0 or not math.isfinite(self.free_seconds) or self.free_seconds < 0:
            raise ValueError(f"cases ({self.cases}) and free_seconds ({self.free_seconds}) must be >= 0")
        if self.cases == 0 and self.free_seconds == 0:
            raise ValueError("nothing to run: give cases > 0 or free_seconds > 0")
        if self.robots < 0:
            raise ValueError(f"robots must be >= 0 (0: a robot per job), got {self.robots}")
        if self.workers is not None and self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")
        for r in self.realisms:
            RealismConfig.named(r)   # raises ValueError naming the presets
        if self.calibrate is not None:
            if not os.path.isfile(self.calibrate):
                raise ValueError(f"no excitation file {self.calibrate} (write one with `hexa calibrate excite "
                                 f"--out {self.calibrate}`)")
            from hexa.trajectories import load_pose_file

            try:
                load_pose_file(self.calibrate)
            except (ValueError, OSError) as exc:
                raise ValueError(f"{self.calibrate} is not a pose file of `hexa calibrate excite` ({exc})") from exc
        if self.stream_rate_hz is not None and not (math.isfinite(self.stream_rate_hz) and self.stream_rate_hz > 0):
            raise ValueError(f"stream_rate_hz must be > 0, got {self.stream_rate_hz}")
        if self.scheduler is not None:
            local_workers(self.scheduler)   # raises ValueError naming a bad "local:N"
        from hexa.dynamics.cusum import DETECTORS, CusumConfig

        if self.detector not in DETECTORS:
            raise ValueError(f"detector must be one of {DETECTORS}, got {self.detector!r}")
        try:
            CusumConfig(**self.cusum)   # raises naming a bad value
        except TypeError as exc:
            raise ValueError(f"cusum settings: {exc}") from exc


def isolation_mode(requested: str) -> tuple[str, str]:
    """(mode, note): "rendered" when requested and this process can render headless, else "oracle" with a note
    saying why ("" when the oracle was asked for)."""
    if requested != "rendered":
        return requested, ""
    from hexa.sim.camera import rendering_unavailable

    why = rendering_unavailable()
    if why is None:
        return "rendered", ""
    return "oracle", f"isolation on rendered frames needs a headless renderer ({why}); the oracle isolation runs"


def local_workers(scheduler: str) -> int | None:
    """N of a "local:N" scheduler (a Dask LocalCluster of N workers), None for a scheduler address.

    Raises:
        ValueError: "local:" without a positive count, or an empty address.
    """
    s = scheduler.strip()
    if not s:
        raise ValueError("scheduler must be 'local:N' or a Dask scheduler address (tcp://host:port), got ''")
    if not s.startswith("local:"):
        return None
    try:
        n = int(s[len("local:"):])
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"scheduler 'local:N' needs N >= 1 workers, got {scheduler!r}")
    return n


def pool_robot_seed(cfg: CampaignConfig, n: int) -> int:
    """The seed of robot n mod `cfg.robots` of a campaign on a few robots: seed·100003 + 90000 + n mod robots, apart
    from every simulator seed."""
    return cfg.seed * 100003 + 90000 + n % cfg.robots


def robot_seed(cfg: CampaignConfig, n: int, sim_seed: int) -> int:
    """The simulated robot of a campaign's n-th job of a kind: its own (`sim_seed`) without `cfg.robots`, else
    `pool_robot_seed`."""
    return sim_seed if cfg.robots <= 0 else pool_robot_seed(cfg, n)


def jobs_of(cfg: CampaignConfig) -> list[tuple[str, dict[str, Any]]]:
    """The campaign's jobs: ("calibrate", job) per robot to calibrate first (`cfg.robots` with `cfg.calibrate`), then
    ("free", job) per free-motion chunk and robot, then ("contact", job) per case and robot (the long jobs first, so
    that the pool's workers finish together). Free motion is split evenly over the selected trajectory kinds; chunk
    k has the simulator seed seed·100003 + 50000 + k and follows, looped, the paper's trajectories in turn or the
    random trajectory random:<its simulator seed>. Each job's simulated robot is `robot_seed`'s."""
    calibrations: list[tuple[str, dict[str, Any]]] = []
    jobs: list[tuple[str, dict[str, Any]]] = []
    contacts: list[tuple[str, dict[str, Any]]] = []
    kinds = kinds_of(cfg.trajectories)
    if cfg.calibrate and cfg.robots > 0:
        from hexa.trajectories import load_pose_file

        excitation = 2.0 * load_pose_file(cfg.calibrate)[1]   # s simulated per robot: the file, twice
    for realism in cfg.realisms:
        if cfg.calibrate and cfg.robots > 0:
            calibrations += [("calibrate", {"calibrate": os.path.abspath(cfg.calibrate), "realism": realism,
                                            "robot_seed": pool_robot_seed(cfg, n), "seconds": excitation})
                             for n in range(cfg.robots)]
        for i in range(cfg.cases):
            sim_seed = cfg.seed * 100003 + i
            contacts.append(("contact", {"campaign_seed": cfg.seed, "index": i, "sim_seed": sim_seed,
                                         "robot_seed": robot_seed(cfg, i, sim_seed),
                                         "realism": realism, "identify": cfg.identify, "observer": cfg.observer,
                                         "detector": cfg.detector, "cusum": cfg.cusum,
                                         "trajectories": cfg.trajectories, "isolation": cfg.isolation,
                                         **_model_fields(cfg)}))
        k = 0
        for kind in kinds:
            left, j = cfg.free_seconds / len(kinds), 0
            while left > 1e-9:
                chunk = min(FREE_CHUNK_S, left)
                sim_seed = cfg.seed * 100003 + 50000 + k
                name = TRAJECTORIES[j % len(TRAJECTORIES)] if kind == "paper" else f"random:{sim_seed}"
                jobs.append(("free", {"trajectory": name, "seconds": chunk, "sim_seed": sim_seed,
                                      "robot_seed": robot_seed(cfg, k, sim_seed), "realism": realism,
                                      "observer": cfg.observer, "detector": cfg.detector, "cusum": cfg.cusum,
                                      **_model_fields(cfg)}))
                left -= chunk
                k, j = k + 1, j + 1
    return calibrations + jobs + contacts


def _model_fields(cfg: CampaignConfig) -> dict[str, Any]:
    """A job's optional calibration (excitation file, absolute: workers may run elsewhere) and currents' rate."""
    out: dict[str, Any] = {}
    if cfg.calibrate:
        out["calibrate"] = os.path.abspath(cfg.calibrate)
    if cfg.stream_rate_hz:
        out["stream_rate_hz"] = float(cfg.stream_rate_hz)
    return out


def _run_job(kind: str, job: dict[str, Any]) -> dict[str, Any]:
    run = {"contact": run_contact_job, "free": run_free_job, "calibrate": run_calibration_job}[kind]
    r = run(job)
    r["pid"] = os.getpid()   # the worker process that ran it
    return r


class ProgressBar:
    """A one-line progress bar on a stream (stderr): jobs done, simulated seconds, speed against real time, ETA. The
    bar and the ETA follow the simulated seconds (`total_sim_s` expected), not the job count: a campaign's jobs run
    from a few seconds (a contact) to a minute (a free-motion chunk, a robot's calibration)."""

    def __init__(self, total_jobs: int, total_sim_s: float, stream: TextIO | None = None, width: int = 30) -> None:
        self.total, self.total_sim, self.width = total_jobs, total_sim_s, width
        self.stream = stream if stream is not None else sys.stderr
        self.done, self.sim_s, self.t0 = 0, 0.0, time.monotonic()

    def update(self, sim_seconds: float) -> str:
        self.done += 1
        self.sim_s += sim_seconds
        wall = max(time.monotonic() - self.t0, 1e-9)
        frac = min(1.0, self.sim_s / self.total_sim) if self.total_sim > 0 else self.done / max(self.total, 1)
        if self.done == self.total:
            frac = 1.0
        eta = wall / frac - wall if frac > 0 else float("nan")
        bar = "#" * int(round(frac * self.width))
        line = (f"\rhexa eval [{bar:<{self.width}}] {self.done}/{self.total} jobs, {self.sim_s:.0f} s simulated, "
                f"{self.sim_s / wall:.1f}x real time, ETA {eta:.0f} s")
        self.stream.write(line + ("\n" if self.done == self.total else ""))
        self.stream.flush()
        return line


class _Engine:
    """Where the jobs run: in this process, a spawned process pool, or Dask distributed (`cfg.scheduler`; a
    "local:N" cluster lives as long as the engine, an address is connected to and left running). `run(jobs, done)`
    runs a batch and calls `done(kind, result)` as each job finishes; batches run one after another on the same
    workers."""

    def __init__(self, cfg: CampaignConfig) -> None:
        self.cfg, self.workers = cfg, cfg.workers or os.cpu_count() or 1
        self.name = "process pool" if self.workers > 1 else "in process"
        self._pool: ProcessPoolExecutor | None = None
        self._client: Client | None = None
        self._cluster: LocalCluster | None = None

    def __enter__(self) -> "_Engine":
        cfg = self.cfg
        if cfg.scheduler is not None:
            try:
                from distributed import Client, LocalCluster
            except ImportError as exc:   # the set-up installs it (requirements/core.txt)
                raise ValueError(f"scheduler {cfg.scheduler!r} needs Dask distributed (pip install "
                                 f"'dask[distributed]'): {exc}") from exc
            n = local_workers(cfg.scheduler)
            self.name = f"dask {cfg.scheduler}"
            self._cluster = (LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
                             if n is not None else None)
            try:
                self._client = Client(self._cluster if self._cluster is not None else cfg.scheduler, timeout="10s")
            except BaseException:
                self._close_cluster()
                raise
            self.workers = len(self._client.scheduler_info(n_workers=-1).get("workers", {})) or (n or 0)
        elif self.workers > 1:
            # spawn: each worker imports MuJoCo afresh (no state inherited from a parent that may hold a GL context)
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"))
        return self

    def run(self, jobs: list[tuple[str, dict[str, Any]]], done: Callable[[str, dict[str, Any]], None]) -> None:
        if self._client is not None:
            from distributed import as_completed

            # pure=False: equal jobs are still separate runs; each task holds one job's small dict
            futures = {self._client.submit(_run_job, kind, job, pure=False): kind for kind, job in jobs}
            for f in as_completed(list(futures)):
                done(futures[f], f.result())
        elif self._pool is not None:
            pool_futures = {self._pool.submit(_run_job, kind, job): kind for kind, job in jobs}
            pending = set(pool_futures)
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in finished:
                    done(pool_futures[f], f.result())
        else:
            for kind, job in jobs:
                done(kind, _run_job(kind, job))

    def __exit__(self, exc_type: type[BaseException] | None, *_: object) -> None:
        if self._pool is not None:
            if exc_type is None:
                self._pool.shutdown()
            else:
                # interrupted (Ctrl-C, SIGTERM) or a job failed: the workers stop now, not after their running and
                # queued jobs (ProcessPoolExecutor has no public way to end its running workers before 3.14)
                procs = list((getattr(self._pool, "_processes", None) or {}).values())   # shutdown() forgets them
                self._pool.shutdown(wait=False, cancel_futures=True)
                for proc in procs:
                    proc.terminate()
        if self._client is not None:
            self._client.close()
        self._close_cluster()

    def _close_cluster(self) -> None:
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


def run_campaign(cfg: CampaignConfig, progress: Callable[[float], Any] | None = None) -> dict[str, Any]:
    """Run every job of `cfg` on a process pool (`cfg.workers`; 1 = in this process) or on Dask distributed
    (`cfg.scheduler`) and collect the results: {"config", "contacts": [...], "free": [...], "robots": [...],
    "wall_s", "sim_s", "workers", "engine", "isolation_note"}. The robots' calibrations (`cfg.robots` with
    `cfg.calibrate`) run first and every later job gets its robot's overlay. `progress(sim_seconds)` is called after
    each job. Rendered isolation falls back to the oracle when this machine cannot render (`isolation_mode`; the
    note says why)."""
    mode, note = isolation_mode(cfg.isolation) if cfg.cases else (cfg.isolation, "")
    if mode != cfg.isolation:
        cfg = replace(cfg, isolation=mode)
    jobs = jobs_of(cfg)
    results: list[tuple[str, dict[str, Any]]] = []
    t0 = time.monotonic()

    def done(kind: str, r: dict[str, Any]) -> None:
        results.append((kind, r))
        if progress:
            progress(r.get("sim_seconds", 0.0))

    with _Engine(cfg) as engine:
        engine.run([j for j in jobs if j[0] == "calibrate"], done)
        overlays = {(r["realism"], r["robot_seed"]): r["overlay"] for k, r in results if k == "calibrate"}
        engine.run([(k, {**j, "nodes_overlay": overlays[(j["realism"], j["robot_seed"])]}
                     if (j["realism"], j["robot_seed"]) in overlays else j) for k, j in jobs if k != "calibrate"],
                   done)
    contacts = sorted((r for k, r in results if k == "contact"), key=lambda r: (r["realism"], r["index"]))
    free = sorted((r for k, r in results if k == "free"), key=lambda r: (r["realism"], r["trajectory"]))
    robots = sorted(({k: v for k, v in r.items() if k != "overlay"} for k, r in results if k == "calibrate"),
                    key=lambda r: (r["realism"], r["robot_seed"]))
    return {"config": asdict(cfg), "contacts": contacts, "free": free, "robots": robots, "workers": engine.workers,
            "engine": engine.name, "isolation_note": note, "wall_s": time.monotonic() - t0,
            "sim_s": sum(r.get("sim_seconds", 0.0) for _, r in results)}
