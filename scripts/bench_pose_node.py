#!/usr/bin/env python3
"""CPU time per frame of the pose node's callbacks on the simulator's renders (docs/vision.md, "Pose node cost").

    .venv/bin/python scripts/bench_pose_node.py [--frames 300] [--cache /tmp/pose_frames.npz] [--out poses.npy]
                                                [--module hexa_vision.pose_node] [--repeat 3]
                                                [--ros-args -p roi_from_detector:=false ...]

Renders `--frames` top-camera frames (colour + aligned depth, with the simulator's noise) along the circle
trajectory, or loads them from `--cache`; turns them into what the node's subscriptions deliver (the images as
serialized bytes: the node subscribes to them raw; CameraInfo as a message), outside the timing; then feeds
camera_info, colour and depth of each frame to the node's callbacks in-process and measures time.process_time() per
frame. As in the live graph, one
subscriber listens to `plate_pose`, nobody to `plate_detections` and `plate_pose_cov`. The poses published are saved
with `--out` (to check that a change leaves them unchanged) and the median / mean / 95th percentile per frame are
printed, best of `--repeat` passes. Arguments after `--ros-args` go to the node (its parameters).
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import sys
import time
from pathlib import Path

import numpy as np


def render_frames(n: int) -> tuple[np.ndarray, np.ndarray]:
    """`n` (rgb, depth mm) renders of cam_top along the circle trajectory (30 fps)."""
    from hexa.sim import Simulator
    from hexa.trajectories import TRAJECTORIES

    rgbs, depths = [], []
    with Simulator(seed=3) as sim:
        for k in range(n):
            sim.set_pose(np.asarray(TRAJECTORIES["circle"](k / 30.0)[0], float))
            rgb, depth = sim.render("cam_top")
            rgbs.append(rgb)
            depths.append(depth)
    return np.stack(rgbs), np.stack(depths)


def load_node_module(name: str):
    """A module by dotted name or by file path."""
    if name.endswith(".py"):
        spec = importlib.util.spec_from_file_location("bench_pose_node_module", name)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    return importlib.import_module(name)


def main() -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")        # headless rendering
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--cache", type=Path, default=None, help="npz of rendered frames (written when missing)")
    ap.add_argument("--module", default="hexa_vision.pose_node", help="node module (dotted name or .py path)")
    ap.add_argument("--out", type=Path, default=None, help="save the published poses (N, 7) here (.npy)")
    ap.add_argument("--repeat", type=int, default=3)
    argv = sys.argv[1:]
    cut = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    args = ap.parse_args(argv[:cut])
    node_kwargs = {"cli_args": argv[cut:]} if argv[cut:] else {}

    if args.cache is not None and args.cache.exists():
        data = np.load(args.cache)
        rgbs, depths = data["rgb"][: args.frames], data["depth"][: args.frames]
    else:
        rgbs, depths = render_frames(args.frames)
        if args.cache is not None:
            np.savez(args.cache, rgb=rgbs, depth=depths)

    from hexa_ros.env import apply_defaults

    apply_defaults()
    import cv2
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import CameraInfo

    from hexa.sim import Simulator
    from hexa_vision.common import camera_info_msg, image_msg

    cv2.setNumThreads(1)
    with Simulator(seed=3, cameras=False) as sim:
        cam = sim.camera_model("cam_top")
    rclpy.init()
    mod = load_node_module(args.module)
    node = mod.PoseNode(**node_kwargs)
    probe = rclpy.create_node("bench_pose_probe")
    probe.create_subscription(PoseStamped, "plate_pose", lambda _m: None, 10)
    t_end = time.monotonic() + 10.0
    while node.pub_pose.get_subscription_count() == 0 and time.monotonic() < t_end:
        time.sleep(0.05)
    frame = "cam_top_color_optical_frame"
    msgs = []
    for k, (rgb, depth) in enumerate(zip(rgbs, depths)):
        stamp = probe.get_clock().now().to_msg()
        stamp.sec, stamp.nanosec = 100 + k // 30, (k % 30) * 33_333_333
        info = camera_info_msg(cam, frame, stamp)
        # the node subscribes to the images raw (their serialized bytes) and to camera_info as a message
        msgs.append((deserialize_message(serialize_message(info), CameraInfo),
                     serialize_message(image_msg(rgb, "rgb8", frame, stamp)),
                     serialize_message(image_msg(depth, "16UC1", frame, stamp))))
    assert isinstance(msgs[0][0], CameraInfo) and isinstance(msgs[0][1], bytes)

    poses: list[list[float]] = []
    publish = node.pub_pose.publish

    def record(m) -> None:
        p, o = m.pose.position, m.pose.orientation
        poses.append([p.x, p.y, p.z, o.x, o.y, o.z, o.w])
        publish(m)

    node.pub_pose.publish = record
    best = None
    for _ in range(max(1, args.repeat)):
        poses.clear()
        per_frame = np.empty(len(msgs))
        for k, (info, color, depth) in enumerate(msgs):
            t0 = time.process_time()
            node._on_info(info)
            node._on_color(color)
            node._on_depth(depth)
            per_frame[k] = time.process_time() - t0
        if best is None or np.median(per_frame) < np.median(best):
            best = per_frame
    print(f"{args.module}: {len(msgs)} frames, {len(poses)} poses; CPU per frame (ms): median "
          f"{np.median(best) * 1e3:.2f}, mean {best.mean() * 1e3:.2f}, p95 {np.percentile(best, 95) * 1e3:.2f}")
    if args.out is not None:
        np.save(args.out, np.asarray(poses))
    probe.destroy_node()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
