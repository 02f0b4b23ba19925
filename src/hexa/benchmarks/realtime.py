"""Real-time budget of the live graph's hot paths, in CPU time (time.process_time) per call: the observer node's
per-sample pipeline (hexa.dynamics.monitor: sample clock, pairing, ζ estimator, residual observer, detector) on the
plate case at 1 kHz, and the pose node's per-frame work (hexa.vision.plate_pose: image decoding, detector, markers).

CPU time, not wall time, so that the figures hold on a loaded machine; each is the best of several runs over the whole
stream. The share of one core is the figure times the input rate (1 kHz current samples, 30 fps top frames).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hexa.benchmarks import BenchRow, register

SAMPLE_RATE_HZ = 1000.0
FRAME_RATE_HZ = 30.0
SAMPLE_TARGET_S = 100e-6   # 10 % of one core at 1 kHz, the rest of the observer's share for its ROS layer
FRAME_TARGET_S = 10e-3     # 30 % of one core at 30 fps


@dataclass(frozen=True)
class SampleStream:
    """The driver's two streams and the camera poses of one simulated run, as the observer node receives them:
    samples (stamp s, board time µs, currents A, commanded ζ rad) and poses (image stamp s, [x y z α β γ])."""

    samples: list[tuple[float, int, np.ndarray, np.ndarray]]
    poses: list[tuple[float, np.ndarray]]


def plate_case_stream(duration: float = 6.5, rate_hz: float = SAMPLE_RATE_HZ, camera_hz: float = FRAME_RATE_HZ,
                      lead_in: float = 1.0, seed: int = 0) -> SampleStream:
    """The plate collision of `hexa demo` in the simulator without cameras: current samples τ/K_t at `rate_hz` with
    the servos' set-points, and the true plate pose at `camera_hz` (what the pose node would publish)."""
    from hexa.sim import Simulator

    sim = Simulator(seed=seed, scenario="plate", cameras=False, lead_in=lead_in)
    every = max(1, int(round(1.0 / (rate_hz * sim.timestep))))
    k_t = float(sim.desc.K_t)
    samples, poses = [], []
    next_cam = 0.0
    try:
        while sim.time < duration - 1e-9:
            sim.step(every)
            s = sim.state()
            samples.append((float(s.time), int(round(s.time * 1e6)), np.asarray(s.tau, float) / k_t,
                            np.asarray(s.targets, float)))
            if s.time + 1e-9 >= next_cam:
                poses.append((float(s.time), np.asarray(s.pose, float)))
                next_cam += 1.0 / camera_hz
    finally:
        sim.close()
    return SampleStream(samples, poses)


def run_monitor(stream: SampleStream, monitor=None, carried: bool = True) -> tuple[list, object]:
    """Feeds the stream to a CollisionMonitor (sim clock) in the driver's order, each current sample carrying its
    set-points (`carried`; else the set-points follow as a joint_states sample, as in bags recorded before the
    motor_currents field); returns its samples and itself."""
    from hexa.dynamics.monitor import CollisionMonitor, MonitorConfig
    from hexa.robots.hexa_description import load_hexa

    mon = monitor or CollisionMonitor(load_hexa(), MonitorConfig(sim_clock=True))
    out: list = []
    poses, k = stream.poses, 0
    for stamp, board_us, cur, cmd in stream.samples:
        while k < len(poses) and poses[k][0] <= stamp:
            out += mon.push_pose(*poses[k])
            k += 1
        if carried:
            out += mon.push_currents(stamp, board_us, cur, cmd)
        else:
            out += mon.push_currents(stamp, board_us, cur)
            out += mon.push_states(stamp, cmd, None, None)
    return out, mon


def run_estimator(stream: SampleStream, desc=None) -> object:
    """Feeds the stream's samples (set-points, torques K_t·I) to a fresh ZetaEstimator's per-sample call (`desc`:
    the robot description, default the packaged one); returns the estimator."""
    from hexa.estimation import ZetaEstimator
    from hexa.robots.hexa_description import load_hexa

    desc = desc or load_hexa()
    est, k_t = ZetaEstimator(desc), float(desc.K_t)
    for stamp, _board_us, cur, cmd in stream.samples:
        est.step(stamp, cmd, cur * k_t)
    return est


def cpu_per_call(fn, calls: int, repeat: int = 3) -> float:
    """Best-of-`repeat` CPU seconds per call of a run `fn()` that makes `calls` calls."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, (time.process_time() - t0) / calls)
    return best


def _frame_inputs():
    from hexa.robots.hexa_description import load_hexa
    from hexa.vision.evaluation import contact_samples
    from hexa.vision.images import numpy_to_image

    desc = load_hexa()
    sample = next(contact_samples(1, seed=5, desc=desc))
    rgb, depth = sample.frames["cam_top"]
    depth_mm = np.where(np.isfinite(depth), np.round(depth * 1000.0), 0).astype(np.uint16)
    return desc, sample.cameras["cam_top"], numpy_to_image(rgb, "rgb8"), numpy_to_image(depth_mm, "16UC1")


def monitor_cpu_per_sample(stream: SampleStream, repeat: int) -> float:
    """CPU seconds per current sample of the collision monitor on `stream` (set-points in motor_currents), best of
    `repeat` runs: the first row below, and the machine's speed in `hexa bench graph`."""
    return cpu_per_call(lambda: run_monitor(stream), len(stream.samples), repeat=repeat)


@register("realtime")
def bench(quick: bool) -> list[BenchRow]:
    rows: list[BenchRow] = []
    stream = plate_case_stream(duration=3.0 if quick else 6.5)
    n = len(stream.samples)
    t = monitor_cpu_per_sample(stream, repeat=2 if quick else 3)
    rows.append(BenchRow("collision monitor per current sample (CPU)", t * 1e6, "us", "<= 100 us",
                         t <= SAMPLE_TARGET_S,
                         note=f"{100 * t * SAMPLE_RATE_HZ:.1f} % of one core at 1 kHz; {n} samples, plate case, "
                              f"set-points in motor_currents"))
    t = cpu_per_call(lambda: run_monitor(stream, carried=False), n, repeat=2 if quick else 3)
    rows.append(BenchRow("collision monitor per current sample, set-points on joint_states (CPU)", t * 1e6, "us",
                         "", None, note="bags recorded before motor_currents carried them: two inputs per sample"))
    from hexa.robots.hexa_description import load_hexa

    desc = load_hexa()
    t = cpu_per_call(lambda: run_estimator(stream, desc), n, repeat=2 if quick else 3)
    rows.append(BenchRow("zeta estimator per current sample (CPU)", t * 1e6, "us", "", None,
                         note="ZetaEstimator.step alone, part of the monitor row"))
    try:
        import cv2

        cv2.setNumThreads(1)
        desc, cam, color, depth = _frame_inputs()
    except Exception as exc:  # noqa: BLE001 - no simulator/EGL here
        rows.append(BenchRow("pose estimator per top frame (CPU)", float("nan"), "ms", "<= 10 ms", None,
                             note=f"simulator unavailable: {exc}"[:120]))
        return rows
    from hexa.vision.markers import MarkerLayout
    from hexa.vision.plate_pose import PlatePoseEstimator

    detector = None
    try:
        from hexa.vision.detector import PlateDetector

        detector = PlateDetector("auto")
    except Exception:  # noqa: BLE001 - markers in the whole frame then
        detector = None
    k = np.asarray(cam.K, float).reshape(-1).tolist()
    frames = 20 if quick else 60
    backend = detector.backend if detector is not None else "no detector"
    for track_age, what in ((0.1, "plate tracked: markers around the last pose"),
                            (0.0, f"not tracked: {backend} box every frame")):
        est = PlatePoseEstimator(MarkerLayout.from_description(desc), "cam_top", cam.T_base_camera, detector,
                                 track_age=track_age)
        est.set_camera_info(cam.width, cam.height, k)

        def frames_run(est: PlatePoseEstimator = est) -> None:
            for i in range(frames):
                stamp = i / FRAME_RATE_HZ
                est.add_color(stamp, color.height, color.width, color.encoding, color.is_bigendian, color.step,
                              color.data, False)
                out = est.add_depth(stamp, depth.height, depth.width, depth.encoding, depth.is_bigendian,
                                    depth.step, depth.data, False)
                if out is None or out.fit is None:
                    raise RuntimeError(f"benchmark frame gave no pose: {dict(est.counters())}")

        t = cpu_per_call(frames_run, frames, repeat=2 if quick else 3)
        rows.append(BenchRow(f"pose estimator per top frame (CPU, {what})", t * 1e3, "ms", "<= 10 ms",
                             t <= FRAME_TARGET_S, note=f"{100 * t * FRAME_RATE_HZ:.1f} % of one core at 30 fps; "
                                                       "decode + markers (+ detector)"))
    return rows
