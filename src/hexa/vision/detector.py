"""Plate detector of the YOLO family in plain torch: a small single-stage grid detector (objectness + box) + NMS.

Architecture: the 640x480 colour frame is resized to 192x144; five conv blocks (three stride-2, two dilated) give a
24x18 grid (stride 8). Each cell predicts [objectness logit, tx, ty, tw, th]: centre = (cell + σ(t_xy))·stride,
size = anchor·exp(t_wh) (YOLOv2/v3 parametrisation, one anchor, one class "plate"). Decoding, score threshold and
non-maximum suppression run in numpy, so inference needs only onnxruntime (torch is the fallback and the trainer).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
ONNX_PATH = WEIGHTS_DIR / "plate_detector.onnx"
TORCH_PATH = WEIGHTS_DIR / "plate_detector.pt"
INPUT_W, INPUT_H = 192, 144
STRIDE = 8
ANCHOR = (40.0, 40.0)  # px at input scale
MEAN, STD = 0.45, 0.25


class DetectorError(RuntimeError):
    """No usable weights/back-end, or an image the detector cannot take (naming it)."""


@dataclass(frozen=True)
class Detection:
    """A box in original-image pixels: (u0, v0, u1, v1) corners, score in 0..1, class "plate"."""

    box: np.ndarray
    score: float
    class_id: str = "plate"

    @property
    def center(self) -> np.ndarray:
        return np.array([(self.box[0] + self.box[2]) / 2, (self.box[1] + self.box[3]) / 2])

    @property
    def size(self) -> np.ndarray:
        return np.array([self.box[2] - self.box[0], self.box[3] - self.box[1]])


def build_model():
    """The torch module (imports torch lazily)."""
    import torch
    from torch import nn

    def block(cin: int, cout: int, stride: int = 1, dil: int = 1) -> nn.Sequential:
        return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, padding=dil, dilation=dil, bias=False),
                             nn.BatchNorm2d(cout), nn.LeakyReLU(0.1, inplace=True))

    class GridDetector(nn.Module):
        """Backbone of stride 8 and a 1x1 head with 5 channels per cell."""

        def __init__(self) -> None:
            super().__init__()
            self.features = nn.Sequential(block(3, 16, 2), block(16, 32, 2), block(32, 48, 2), block(48, 64, 1, 2),
                                          block(64, 64, 1, 4), block(64, 64, 1, 1))
            self.head = nn.Conv2d(64, 5, 1)
            bias = self.head.bias
            assert bias is not None   # Conv2d's default bias=True
            with torch.no_grad():
                bias.zero_()
                bias[0] = -4.0

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return self.head(self.features(x))

    return GridDetector()


def preprocess(rgb: np.ndarray) -> np.ndarray:
    """(1, 3, 144, 192) float32 network input from an RGB uint8 image of any size."""
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise DetectorError(f"detector needs an RGB uint8 (H, W, 3) image; got {rgb.dtype} {rgb.shape}")
    small = cv2.resize(rgb, (INPUT_W, INPUT_H), interpolation=cv2.INTER_AREA)
    x = (small.astype(np.float32) * (1.0 / 255.0) - MEAN) * (1.0 / STD)
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None])


def decode(grid: np.ndarray, scale_x: float, scale_y: float, score_threshold: float = 0.3,
           iou_threshold: float = 0.45, max_detections: int = 5) -> list[Detection]:
    """Boxes from one raw output grid (5, Gh, Gw): sigmoid objectness, YOLO box decoding, NMS, rescaling."""
    g = np.asarray(grid, dtype=np.float32)
    obj = 1.0 / (1.0 + np.exp(-g[0]))
    vv, uu = np.nonzero(obj >= score_threshold)
    if vv.size == 0:
        return []
    t = g[1:, vv, uu]
    cx = (uu + 1.0 / (1.0 + np.exp(-t[0]))) * STRIDE
    cy = (vv + 1.0 / (1.0 + np.exp(-t[1]))) * STRIDE
    w = ANCHOR[0] * np.exp(np.clip(t[2], -4, 4))
    h = ANCHOR[1] * np.exp(np.clip(t[3], -4, 4))
    boxes = np.stack([(cx - w / 2) * scale_x, (cy - h / 2) * scale_y, (cx + w / 2) * scale_x,
                      (cy + h / 2) * scale_y], axis=1)
    scores = obj[vv, uu]
    keep = nms(boxes, scores, iou_threshold)[:max_detections]
    return [Detection(boxes[k], float(scores[k])) for k in keep]


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU matrix (N, M) of boxes a (N, 4) and b (M, 4) given as corners (u0, v0, u1, v1)."""
    a = np.asarray(a, float).reshape(-1, 4)
    b = np.asarray(b, float).reshape(-1, 4)
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(rb - lt, 0, None), axis=2)
    area_a = np.prod(np.clip(a[:, 2:] - a[:, :2], 0, None), axis=1)
    area_b = np.prod(np.clip(b[:, 2:] - b[:, :2], 0, None), axis=1)
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float = 0.45) -> list[int]:
    """Greedy non-maximum suppression: indices kept, highest score first."""
    order = list(np.argsort(-np.asarray(scores)))
    keep: list[int] = []
    while order:
        i = order.pop(0)
        keep.append(int(i))
        if not order:
            break
        ious = box_iou(boxes[i], boxes[order])[0]
        order = [j for j, o in zip(order, ious) if o < iou_threshold]
    return keep


def average_precision(detections: Sequence[Sequence[Detection]], truths: Sequence[np.ndarray | None],
                      iou_threshold: float = 0.5) -> tuple[float, float]:
    """(AP at `iou_threshold`, mean IoU of the best detection per true box) over a set of images.

    Args:
        detections: per image, its detections.
        truths: per image, the true box (4,) or None when the plate is not visible.
    """
    recs: list[tuple[float, bool]] = []
    n_true = sum(t is not None for t in truths)
    ious: list[float] = []
    for dets, gt in zip(detections, truths):
        matched = False
        best = 0.0
        for d in sorted(dets, key=lambda d: -d.score):
            iou = float(box_iou(d.box, gt)[0, 0]) if gt is not None else 0.0
            best = max(best, iou)
            if gt is not None and not matched and iou >= iou_threshold:
                recs.append((d.score, True))
                matched = True
            else:
                recs.append((d.score, False))
        if gt is not None:
            ious.append(best)
    if n_true == 0:
        return float("nan"), float("nan")
    recs.sort(key=lambda r: -r[0])
    tp = np.cumsum([r[1] for r in recs]) if recs else np.zeros(0)
    fp = np.cumsum([not r[1] for r in recs]) if recs else np.zeros(0)
    recall = tp / n_true if recs else np.zeros(0)
    precision = tp / np.maximum(tp + fp, 1) if recs else np.zeros(0)
    # all-point interpolated AP (VOC 2010+)
    mrec = np.concatenate([[0.0], recall, [1.0]])
    mpre = np.concatenate([[1.0], precision, [0.0]])
    for i in range(len(mpre) - 2, -1, -1):
        mpre[i] = max(mpre[i], mpre[i + 1])
    idx = np.nonzero(mrec[1:] != mrec[:-1])[0]
    ap = float(np.sum((mrec[idx + 1] - mrec[idx]) * mpre[idx + 1]))
    return ap, float(np.mean(ious)) if ious else float("nan")


def export_onnx(model, path: Path | str = ONNX_PATH) -> Path:
    """Export a trained GridDetector to ONNX (opset 17, fixed 1x3x144x192 input named "image")."""
    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    model.eval()
    dummy = torch.zeros(1, 3, INPUT_H, INPUT_W)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(model, (dummy,), str(path), input_names=["image"], output_names=["grid"],
                          opset_version=17, dynamo=False)
    return path


class PlateDetector:
    """Plate boxes in a colour frame, with onnxruntime (default) or torch (fallback / `backend="torch"`).

    Args:
        backend: "auto" (onnxruntime if the ONNX file and library exist, else torch), "onnx" or "torch".
        onnx_path, torch_path: weight files (defaults: the committed ones in hexa/vision/weights/).
        score_threshold, iou_threshold: decoding parameters.

    Raises:
        DetectorError: no back-end can load its weights.
    """

    def __init__(self, backend: str = "auto", onnx_path: Path | str | None = None,
                 torch_path: Path | str | None = None, score_threshold: float = 0.3, iou_threshold: float = 0.45,
                 model=None) -> None:
        self.score_threshold = score_threshold
        self.iou_threshold = iou_threshold
        self._session = None
        self._model = model
        onnx_path = Path(onnx_path) if onnx_path else ONNX_PATH
        torch_path = Path(torch_path) if torch_path else TORCH_PATH
        errors = []
        if model is not None:
            self.backend = "torch"
            self._model.eval()
            return
        if backend in ("auto", "onnx"):
            try:
                import onnxruntime as ort

                if not onnx_path.exists():
                    raise FileNotFoundError(f"no ONNX weights at {onnx_path}")
                opts = ort.SessionOptions()
                opts.intra_op_num_threads = 1
                opts.inter_op_num_threads = 1
                self._session = ort.InferenceSession(str(onnx_path), opts, providers=["CPUExecutionProvider"])
                self.backend = "onnx"
                return
            except Exception as exc:
                errors.append(f"onnxruntime: {exc}")
                if backend == "onnx":
                    raise DetectorError("; ".join(errors)) from exc
        try:
            import torch

            torch.set_num_threads(1)
            if not torch_path.exists():
                raise FileNotFoundError(f"no torch weights at {torch_path}")
            m = build_model()
            m.load_state_dict(torch.load(str(torch_path), map_location="cpu", weights_only=True))
            m.eval()
            self._model = m
            self.backend = "torch"
        except Exception as exc:
            errors.append(f"torch: {exc}")
            raise DetectorError("no detector back-end: " + "; ".join(errors)) from exc

    def raw(self, x: np.ndarray) -> np.ndarray:
        """Raw grid (5, 18, 24) for a preprocessed input (1, 3, 144, 192)."""
        if self._session is not None:
            return self._session.run(None, {"image": x})[0][0]
        import torch

        with torch.no_grad():
            return self._model(torch.from_numpy(x)).numpy()[0]

    def detect(self, rgb: np.ndarray) -> list[Detection]:
        """Plate boxes (original pixels), best first."""
        x = preprocess(rgb)
        grid = self.raw(x)
        h, w = rgb.shape[:2]
        return decode(grid, w / INPUT_W, h / INPUT_H, self.score_threshold, self.iou_threshold)
