#!/usr/bin/env python3
"""Train the plate detector (hexa.vision.detector) on simulator renders with domain randomisation; export ONNX.

    MUJOCO_GL=egl .venv/bin/python scripts/train_detector.py            # ~10 min on one CPU core
    MUJOCO_GL=egl .venv/bin/python scripts/train_detector.py --quick    # smoke run (tiny set, few steps)

Data: random reachable plate poses; both cameras (mostly the top one, as in the paper); per image the MuJoCo scene
is randomised (background/floor/wall colours, plate shade, light levels, up to three occluder boxes near the plate,
the pushing object) and the rendered image is randomised again (background replaced by random textures where the
depth is beyond the workspace, brightness/contrast/hue jitter, Gaussian noise, blur, horizontal flips). The true
box is the projection of the plate prism's corners. Weights (torch state dict + ONNX) and the held-out metrics
(mAP@0.5, mean IoU, on renders from another seed) go to src/hexa/vision/weights/. Single thread, seeded.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")
REPO = Path(__file__).resolve().parents[1]


def plate_box(cam, T_plate: np.ndarray, hexagon: np.ndarray, half_t: float) -> np.ndarray | None:
    """Box (u0, v0, u1, v1) of the plate prism in the image, None when less than 40 % of it is inside."""
    loc = np.array([[x, y, z] for z in (-half_t, half_t) for x, y in hexagon])
    pts = loc @ T_plate[:3, :3].T + T_plate[:3, 3]
    uv, z = cam.project(pts)
    if np.any(z <= 0.02):
        return None
    u0, v0 = uv.min(axis=0)
    u1, v1 = uv.max(axis=0)
    area = max((u1 - u0) * (v1 - v0), 1e-9)
    cu0, cv0, cu1, cv1 = max(u0, 0), max(v0, 0), min(u1, cam.width - 1), min(v1, cam.height - 1)
    if cu1 <= cu0 or cv1 <= cv0 or (cu1 - cu0) * (cv1 - cv0) / area < 0.4:
        return None
    return np.array([cu0, cv0, cu1, cv1])


def random_texture(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A random background: smooth colour noise, stripes or rectangles."""
    kind = rng.integers(0, 3)
    if kind == 0:
        small = rng.integers(0, 256, (rng.integers(2, 9), rng.integers(2, 9), 3)).astype(np.uint8)
        return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    img = np.empty((h, w, 3), np.uint8)
    img[:] = rng.integers(0, 256, 3)
    if kind == 1:
        period = int(rng.integers(8, 60))
        col = rng.integers(0, 256, 3)
        for x in range(0, w, period):
            img[:, x:x + period // 2] = col
        if rng.random() < 0.5:
            img = np.ascontiguousarray(np.rot90(img, k=1))[:h, :w] if h == w else img
        return img
    for _ in range(int(rng.integers(3, 12))):
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        cv2.rectangle(img, (x0, y0), (x0 + int(rng.integers(10, w // 2)), y0 + int(rng.integers(10, h // 2))),
                      tuple(int(c) for c in rng.integers(0, 256, 3)), -1)
    return img


def augment(rng: np.random.Generator, rgb: np.ndarray, depth_mm: np.ndarray, far_mm: float) -> np.ndarray:
    """Image-space randomisation of one render (see module docstring)."""
    out = rgb.astype(np.float32)
    if rng.random() < 0.5:
        bg = random_texture(rng, *rgb.shape[:2]).astype(np.float32)
        far = (depth_mm == 0) | (depth_mm > far_mm)
        out[far] = bg[far]
    out = out * rng.uniform(0.6, 1.4) + rng.uniform(-30, 30)
    out = (out - out.mean()) * rng.uniform(0.7, 1.3) + out.mean()
    out += rng.uniform(-20, 20, 3)
    out = np.clip(out, 0, 255).astype(np.uint8)
    if rng.random() < 0.3:
        hsv = cv2.cvtColor(out, cv2.COLOR_RGB2HSV)
        hsv[:, :, 0] = ((hsv[:, :, 0].astype(int) + int(rng.integers(-12, 13))) % 180).astype(np.uint8)
        out = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    if rng.random() < 0.3:
        out = cv2.GaussianBlur(out, (0, 0), rng.uniform(0.5, 1.5))
    if rng.random() < 0.5:
        out = np.clip(out + rng.normal(0, rng.uniform(2, 10), out.shape), 0, 255).astype(np.uint8)
    return out


def randomise_scene(sim, rng: np.random.Generator, T_plate: np.ndarray) -> None:
    """Colours, lights and occluders of the MuJoCo scene (visual only)."""
    m, d = sim.model, sim.data
    import mujoco

    for name in ("floor", "ceiling", "wall_px", "wall_nx", "wall_py", "wall_ny"):
        gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
        if gid >= 0:
            m.geom_rgba[gid, :3] = rng.uniform(0.05, 0.95, 3)
            m.geom_matid[gid] = -1
    gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "plate")
    if gid >= 0:
        m.geom_matid[gid] = -1
        m.geom_rgba[gid, :3] = rng.uniform(0.03, 0.35) * np.ones(3) + rng.uniform(-0.03, 0.03, 3)
    m.light_diffuse[:] = rng.uniform(0.2, 0.8)
    m.vis.headlight.ambient[:] = rng.uniform(0.15, 0.5)
    m.vis.headlight.diffuse[:] = rng.uniform(0.3, 0.7)
    for k in range(3):
        bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"occluder_{k}")
        if bid < 0:
            continue
        mid = m.body_mocapid[bid]
        if rng.random() < 0.35:
            ang = rng.uniform(0, 2 * np.pi)
            r = rng.uniform(0.06, 0.16)
            d.mocap_pos[mid] = T_plate[:3, 3] + [r * np.cos(ang), r * np.sin(ang), rng.uniform(0.0, 0.12)]
            q = rng.normal(size=4)
            d.mocap_quat[mid] = q / np.linalg.norm(q)
            gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"occluder_{k}")
            m.geom_rgba[gid, :3] = rng.uniform(0, 1, 3)
        else:
            d.mocap_pos[mid] = (0.0, 0.0, 5.0)


def render_set(n: int, seed: int, augment_images: bool = True, side_fraction: float = 0.2
               ) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """n images resized to the detector input (N, 144, 192, 3) and their boxes at input scale (or None)."""
    from hexa.kinematics import hexa6rus as kin
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim import Simulator
    from hexa.vision import detector as D
    from hexa.vision.camera import CameraModel

    desc = load_hexa()
    rng = np.random.default_rng(seed)
    Cp = np.asarray(desc.C, float)[:, :2]
    hexagon = Cp[np.argsort(np.arctan2(Cp[:, 1], Cp[:, 0]))]
    half_t = float(desc.section("appearance")["plate_thickness"]) / 2
    images, boxes = [], []
    sim = None
    per_sim = 4
    while len(images) < n:
        pose = np.array([*rng.uniform(-0.12, 0.12, 2), rng.uniform(-0.62, -0.47), *np.radians(rng.uniform(-30, 30, 3))])
        try:
            kin.inverse_kinematics(desc, pose)
            if sim is not None:
                sim.close()
            sim = Simulator(desc, pose=pose, seed=int(rng.integers(0, 2 ** 31)), settle=0.0)
        except Exception:  # noqa: BLE001 - unreachable pose: draw another
            continue
        st = sim.state()
        T = np.eye(4)
        T[:3, :3] = kin.rotation_zyx(*st.pose[3:])
        T[:3, 3] = st.pose[:3]
        for _ in range(per_sim):
            if len(images) >= n:
                break
            cam_name = "cam_side" if rng.random() < side_fraction else "cam_top"
            cam = CameraModel.from_any(sim.camera_model(cam_name), cam_name)
            if augment_images:
                randomise_scene(sim, rng, T)
            rgb, depth = sim.render(cam_name)
            box = plate_box(cam, T, hexagon, half_t)
            if augment_images:
                far = 700.0 if cam_name == "cam_top" else 1400.0
                rgb = augment(rng, rgb, depth, far)
                if rng.random() < 0.5:
                    rgb = np.ascontiguousarray(rgb[:, ::-1])
                    if box is not None:
                        box = np.array([cam.width - 1 - box[2], box[1], cam.width - 1 - box[0], box[3]])
            sx, sy = D.INPUT_W / cam.width, D.INPUT_H / cam.height
            images.append(cv2.resize(rgb, (D.INPUT_W, D.INPUT_H), interpolation=cv2.INTER_AREA))
            boxes.append(None if box is None else box * [sx, sy, sx, sy])
    if sim is not None:
        sim.close()
    return np.stack(images), boxes


def targets(boxes: list[np.ndarray | None]):
    """Per-image training targets on the grid: objectness (N, Gh, Gw), ignore mask, box targets at the centre cell."""
    from hexa.vision import detector as D

    gh, gw = D.INPUT_H // D.STRIDE, D.INPUT_W // D.STRIDE
    n = len(boxes)
    obj = np.zeros((n, gh, gw), np.float32)
    ignore = np.zeros((n, gh, gw), bool)
    box_t = np.zeros((n, 4), np.float32)
    cell = np.zeros((n, 2), np.int64)
    has = np.zeros(n, bool)
    for i, b in enumerate(boxes):
        if b is None:
            continue
        cx, cy = (b[0] + b[2]) / 2 / D.STRIDE, (b[1] + b[3]) / 2 / D.STRIDE
        u, v = min(int(cx), gw - 1), min(int(cy), gh - 1)
        obj[i, v, u] = 1.0
        ignore[i, max(v - 1, 0):v + 2, max(u - 1, 0):u + 2] = True
        ignore[i, v, u] = False
        w, h = max(b[2] - b[0], 1.0), max(b[3] - b[1], 1.0)
        box_t[i] = [np.clip(cx - u, 0.01, 0.99), np.clip(cy - v, 0.01, 0.99), np.log(w / D.ANCHOR[0]),
                    np.log(h / D.ANCHOR[1])]
        cell[i] = [v, u]
        has[i] = True
    return obj, ignore, box_t, cell, has


def train(images: np.ndarray, boxes: list, steps: int, seed: int, batch: int = 32, log_every: int = 50):
    import torch
    from torch.nn import functional as F

    from hexa.vision import detector as D

    torch.manual_seed(seed)
    torch.set_num_threads(1)
    model = D.build_model()
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=3e-3, total_steps=steps, pct_start=0.1)
    x_all = torch.from_numpy(((images.astype(np.float32) / 255.0 - D.MEAN) / D.STD).transpose(0, 3, 1, 2).copy())
    obj, ign, box_t, cell, has = (torch.from_numpy(a) for a in targets(boxes))
    rng = np.random.default_rng(seed)
    model.train()
    t0 = time.time()
    for step in range(steps):
        idx = torch.from_numpy(rng.integers(0, len(images), batch))
        out = model(x_all[idx])
        logits = out[:, 0]
        o, ig = obj[idx], ign[idx]
        w = torch.where(ig, torch.zeros_like(o), torch.where(o > 0, torch.full_like(o, 5.0), torch.ones_like(o)))
        l_obj = (F.binary_cross_entropy_with_logits(logits, o, reduction="none") * w).sum() / batch
        hb = has[idx]
        if hb.any():
            bi = torch.nonzero(hb).squeeze(1)
            c = cell[idx][bi]
            pred = out[bi, 1:, c[:, 0], c[:, 1]]
            tb = box_t[idx][bi]
            l_xy = F.binary_cross_entropy_with_logits(pred[:, :2], tb[:, :2])
            l_wh = F.smooth_l1_loss(pred[:, 2:], tb[:, 2:], beta=0.1)
            l_box = 5.0 * (l_xy + l_wh)
        else:
            l_box = torch.zeros(())
        loss = l_obj + l_box
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % log_every == 0 or step == steps - 1:
            print(f"step {step:5d}  loss {loss.item():.3f}  obj {l_obj.item():.3f}  box {float(l_box):.3f}  "
                  f"{time.time() - t0:.0f} s", flush=True)
    model.eval()
    return model


def evaluate(model, images: np.ndarray, boxes: list) -> dict:
    from hexa.vision import detector as D

    det = D.PlateDetector(model=model)
    dets = []
    for img in images:
        x = ((img.astype(np.float32) / 255.0 - D.MEAN) / D.STD).transpose(2, 0, 1)[None].copy()
        dets.append(D.decode(det.raw(x), 1.0, 1.0, 0.05))
    ap, miou = D.average_precision(dets, boxes, 0.5)
    return {"mAP@0.5": ap, "mean_IoU": miou, "n_images": len(images),
            "n_with_plate": int(sum(b is not None for b in boxes))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--train-images", type=int, default=900)
    ap.add_argument("--test-images", type=int, default=150)
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(REPO / "src/hexa/vision/weights"))
    ap.add_argument("--quick", action="store_true", help="tiny smoke run (does not overwrite the weights)")
    a = ap.parse_args(argv)
    import torch

    from hexa.vision import detector as D

    torch.set_num_threads(1)
    if a.quick:
        a.train_images, a.test_images, a.steps = 24, 8, 5
        a.out = str(Path("/tmp") / "hexa_detector_quick")
    t0 = time.time()
    images, boxes = render_set(a.train_images, a.seed)
    test_images, test_boxes = render_set(a.test_images, a.seed + 1000, augment_images=False)
    t_data = time.time() - t0
    print(f"rendered {len(images)} training and {len(test_images)} held-out images in {t_data:.0f} s", flush=True)
    model = train(images, boxes, a.steps, a.seed)
    t_train = time.time() - t0 - t_data
    metrics = evaluate(model, test_images, test_boxes)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    torch.save(model.state_dict(), out / "plate_detector.pt")
    D.export_onnx(model, out / "plate_detector.onnx")
    info = {"metrics_held_out": metrics, "train_images": a.train_images, "test_images": a.test_images,
            "steps": a.steps, "seed": a.seed, "render_seconds": t_data, "train_seconds": t_train,
            "input": [D.INPUT_W, D.INPUT_H], "stride": D.STRIDE, "anchor": D.ANCHOR,
            "parameters": int(sum(p.numel() for p in model.parameters()))}
    (out / "plate_detector.json").write_text(json.dumps(info, indent=1))
    print(json.dumps(info, indent=1))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO / "src"))
    sys.exit(main())
