"""Plate detector: box decoding, NMS, AP metric, ONNX export matching torch, bad input; trained weights if present."""
from __future__ import annotations

import numpy as np
import pytest

from hexa.vision import detector as D


def _grid_with_box(cx: float, cy: float, w: float, h: float, score_logit: float = 5.0) -> np.ndarray:
    g = np.full((5, D.INPUT_H // D.STRIDE, D.INPUT_W // D.STRIDE), -10.0, np.float32)
    u, v = int(cx // D.STRIDE), int(cy // D.STRIDE)
    fx, fy = cx / D.STRIDE - u, cy / D.STRIDE - v
    g[:, v, u] = [score_logit, np.log(fx / (1 - fx)), np.log(fy / (1 - fy)), np.log(w / D.ANCHOR[0]),
                  np.log(h / D.ANCHOR[1])]
    return g


def test_decode_inverts_the_yolo_parametrisation_and_rescales() -> None:
    g = _grid_with_box(100.3, 60.7, 50.0, 30.0)
    dets = D.decode(g, 640 / D.INPUT_W, 480 / D.INPUT_H)
    assert len(dets) == 1
    sx, sy = 640 / D.INPUT_W, 480 / D.INPUT_H
    assert np.allclose(dets[0].box, [(100.3 - 25) * sx, (60.7 - 15) * sy, (100.3 + 25) * sx, (60.7 + 15) * sy],
                       atol=1e-3)
    assert dets[0].score == pytest.approx(1 / (1 + np.exp(-5)), rel=1e-5)


def test_nms_keeps_the_best_of_overlapping_boxes() -> None:
    boxes = np.array([[0, 0, 10, 10], [1, 1, 11, 11], [50, 50, 60, 60]], float)
    assert D.nms(boxes, np.array([0.5, 0.9, 0.7])) == [1, 2]


def test_box_iou_values() -> None:
    assert D.box_iou([0, 0, 2, 2], [1, 0, 3, 2])[0, 0] == pytest.approx(1 / 3)
    assert D.box_iou([0, 0, 1, 1], [2, 2, 3, 3])[0, 0] == 0.0


def test_average_precision_perfect_missed_and_false_positive() -> None:
    gt = [np.array([10, 10, 50, 50.0]), np.array([20, 20, 60, 60.0])]
    perfect = [[D.Detection(gt[0], 0.9)], [D.Detection(gt[1], 0.8)]]
    assert D.average_precision(perfect, gt) == (pytest.approx(1.0), pytest.approx(1.0))
    half = [[D.Detection(gt[0], 0.9)], []]
    ap, _ = D.average_precision(half, gt)
    assert ap == pytest.approx(0.5)
    fp_first = [[D.Detection(np.array([100, 100, 120, 120.0]), 0.95), D.Detection(gt[0], 0.9)],
                [D.Detection(gt[1], 0.8)]]
    ap, _ = D.average_precision(fp_first, gt)
    assert 0.5 < ap < 1.0


def test_preprocess_rejects_non_rgb() -> None:
    with pytest.raises(D.DetectorError, match="uint16"):
        D.preprocess(np.zeros((480, 640), np.uint16))
    x = D.preprocess(np.zeros((480, 640, 3), np.uint8))
    assert x.shape == (1, 3, D.INPUT_H, D.INPUT_W) and x.dtype == np.float32


@pytest.mark.slow
def test_onnx_export_matches_torch(tmp_path) -> None:
    torch = pytest.importorskip("torch")
    pytest.importorskip("onnxruntime")
    torch.manual_seed(0)
    torch.set_num_threads(1)
    model = D.build_model().eval()
    path = D.export_onnx(model, tmp_path / "d.onnx")
    rgb = np.random.default_rng(0).integers(0, 255, (480, 640, 3)).astype(np.uint8)
    x = D.preprocess(rgb)
    onnx_det = D.PlateDetector("onnx", onnx_path=path)
    torch_det = D.PlateDetector(model=model)
    assert onnx_det.backend == "onnx" and torch_det.backend == "torch"
    assert np.allclose(onnx_det.raw(x), torch_det.raw(x), atol=1e-4)


def test_missing_weights_raise_a_clear_error(tmp_path) -> None:
    with pytest.raises(D.DetectorError, match="no ONNX weights"):
        D.PlateDetector("onnx", onnx_path=tmp_path / "none.onnx")


def test_committed_weights_find_the_plate_in_a_render() -> None:
    """The trained weights (onnxruntime) box the plate of a rendered top-camera frame with IoU ≥ 0.6."""
    if not D.ONNX_PATH.exists():
        pytest.skip("no committed weights")
    pytest.importorskip("mujoco")
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    from train_detector import plate_box

    from hexa.kinematics.hexa6rus import rotation_zyx
    from hexa.sim import Simulator
    from hexa.vision.camera import CameraModel

    pose = np.array([-0.04, 0.05, -0.56, 0.2, 0.1, -0.2])
    with Simulator(pose=pose, seed=4) as sim:
        rgb, _ = sim.render("cam_top")
        cam = CameraModel.from_any(sim.camera_model("cam_top"), "cam_top")
        st = sim.state()
        Cp = np.asarray(sim.desc.C, float)[:, :2]
        half_t = float(sim.desc.section("appearance")["plate_thickness"]) / 2
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation_zyx(*st.pose[3:]), st.pose[:3]
    truth = plate_box(cam, T, Cp[np.argsort(np.arctan2(Cp[:, 1], Cp[:, 0]))], half_t)
    dets = D.PlateDetector("onnx").detect(rgb)
    assert dets and D.box_iou(dets[0].box, truth)[0, 0] >= 0.6
    assert dets[0].score > 0.5
