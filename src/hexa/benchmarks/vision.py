"""Vision benchmarks: plate detector per 640x480 frame, marker pose per frame, isolation per frame pair (1 core)."""
from __future__ import annotations

import numpy as np

from hexa.benchmarks import BenchRow, register, time_per_call


def _sample():
    """One rendered contact (rod, top + side cameras) from the simulator, or None without it."""
    try:
        from hexa.robots.hexa_description import load_hexa
        from hexa.vision.evaluation import contact_samples

        desc = load_hexa()
        return desc, next(contact_samples(1, seed=5, desc=desc))
    except Exception as exc:  # noqa: BLE001 - no simulator/EGL here
        return None, exc


@register("vision")
def bench(quick: bool) -> list[BenchRow]:
    """Per-frame latencies of the vision pipeline (beside their targets)."""
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    import cv2

    cv2.setNumThreads(1)
    min_time = 0.1 if quick else 0.5
    rows: list[BenchRow] = []
    desc, sample = _sample()
    rgb = (sample.frames["cam_top"][0] if desc is not None else
           np.random.default_rng(0).integers(0, 255, (480, 640, 3)).astype(np.uint8))

    from hexa.vision.images import image_to_numpy, numpy_to_image

    f = numpy_to_image(rgb, "rgb8")
    t = time_per_call(lambda: image_to_numpy(f.height, f.width, f.encoding, 0, f.step, f.data), min_time=min_time)
    rows.append(BenchRow("image fields -> numpy (640x480 rgb8)", t * 1e3, "ms", "", None))

    try:
        from hexa.vision.detector import PlateDetector

        det = PlateDetector("auto")
        t = time_per_call(lambda: det.detect(rgb), min_time=min_time)
        rows.append(BenchRow(f"plate detector per 640x480 frame ({det.backend})", t * 1e3, "ms", "<= 15 ms",
                             t <= 15e-3))
    except Exception as exc:  # noqa: BLE001
        rows.append(BenchRow("plate detector per 640x480 frame", float("nan"), "ms", "<= 15 ms", None,
                             note=f"{type(exc).__name__}: {exc}"[:120]))

    if desc is None:
        note = f"simulator unavailable: {sample}"[:120]
        rows.append(BenchRow("marker pose per frame", float("nan"), "ms", "<= 10 ms", None, note=note))
        rows.append(BenchRow("isolation per frame pair", float("nan"), "ms", "<= 33 ms", None, note=note))
        return rows

    from hexa.vision.evaluation import isolate_sample
    from hexa.vision.isolation import CollisionIsolator, RobotGeometry
    from hexa.vision.markers import MarkerDetector, MarkerLayout

    cam = sample.cameras["cam_top"]
    mk = MarkerDetector(MarkerLayout.from_description(desc), cam)
    top_rgb, top_depth = sample.frames["cam_top"]
    t = time_per_call(lambda: mk.estimate(top_rgb, top_depth), min_time=min_time)
    rows.append(BenchRow("marker pose per frame (whole frame)", t * 1e3, "ms", "<= 10 ms", t <= 10e-3))

    try:
        from hexa.vision.detector import PlateDetector

        det = PlateDetector("auto")

        def pipeline() -> None:
            dets = det.detect(top_rgb)
            roi = None
            if dets:
                b = dets[0].box
                pw, ph = 0.2 * (b[2] - b[0]), 0.2 * (b[3] - b[1])
                roi = (b[0] - pw, b[1] - ph, b[2] + pw, b[3] + ph)
            mk.estimate(top_rgb, top_depth, roi)

        t = time_per_call(pipeline, min_time=min_time)
        rows.append(BenchRow("pose node per frame (detector + markers in the box)", t * 1e3, "ms", "<= 25 ms",
                             t <= 25e-3, note="detector 15 ms + markers 10 ms budgets"))
    except Exception as exc:  # noqa: BLE001
        rows.append(BenchRow("pose node per frame", float("nan"), "ms", "", None, note=str(exc)[:120]))

    est, geom, iso = isolate_sample(sample, desc)
    t = time_per_call(lambda: iso.isolate(sample.frames, geom), min_time=min_time)
    rows.append(BenchRow("isolation per frame pair (top + side)", t * 1e3, "ms", "<= 33 ms", t <= 33e-3,
                         note=f"found {est.link_name} {est.chain}"))
    t = time_per_call(lambda: RobotGeometry.from_state(desc, sample.pose, sample.zeta), min_time=min_time)
    rows.append(BenchRow("robot geometry from pose (IK)", t * 1e3, "ms", "", None))
    del CollisionIsolator
    return rows
