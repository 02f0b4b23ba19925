"""The RealSense path without a camera: a recording made with pyrealsense2's own software device and recorder is
played by librealsense through the camera node's realsense source (depth aligned to colour by rs.align, camera_info
as realsense-ros fills it); and robot mode with numeric serials, absent cameras and absent ports starts, names each
missing device on the console and in /diagnostics, and keeps retrying without a traceback."""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hexa.vision.sources import RealSenseSource

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

try:
    import pyrealsense2 as rs
except ImportError:   # the recording tests need it (make setup-robot); robot mode without cameras does not
    rs = None
needs_rs = pytest.mark.skipif(rs is None, reason="pyrealsense2 not installed (make setup-robot)")

PY = sys.executable
W, H, FPS = 64, 48, 30
#: depth and colour intrinsics differ (fx, ppx) so that alignment moves the depth edge: at depth column 32,
#: x/z = (32 - 28) / 50 = 0.08, which lands on colour column 55 · 0.08 + 32 = 36.4
DEPTH_FX, DEPTH_PPX, COLOR_FX, COLOR_PPX = 50.0, 28.0, 55.0, 32.0
SERIAL = "012345678901"


def _intrinsics(fx: float, ppx: float):
    i = rs.intrinsics()
    i.width, i.height, i.fx, i.fy, i.ppx, i.ppy = W, H, fx, fx, ppx, H / 2
    i.model, i.coeffs = rs.distortion.brown_conrady, [0.0] * 5
    return i


def record_software_camera(path: Path, frames: int = 12) -> None:
    """A librealsense recording of a software device: depth (left half 500 mm, right half 800 mm) and colour."""
    dev = rs.software_device()
    ds, cs = dev.add_sensor("Depth"), dev.add_sensor("Color")
    profiles = []
    for sensor, stream, fmt, bpp, uid, intr in ((ds, rs.stream.depth, rs.format.z16, 2, 0, (DEPTH_FX, DEPTH_PPX)),
                                                (cs, rs.stream.color, rs.format.rgb8, 3, 1, (COLOR_FX, COLOR_PPX))):
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid, vs.width, vs.height, vs.fps, vs.bpp, vs.fmt = stream, 0, uid, W, H, FPS, bpp, fmt
        vs.intrinsics = _intrinsics(*intr)
        profiles.append(sensor.add_video_stream(vs))
    ds.add_read_only_option(rs.option.depth_units, 0.001)
    ex = rs.extrinsics()
    ex.rotation, ex.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0.0, 0.0, 0.0]
    profiles[0].register_extrinsics_to(profiles[1], ex)
    dev.register_info(rs.camera_info.serial_number, SERIAL)
    recorder = rs.recorder(str(path), dev)
    for sensor, prof in zip((ds, cs), profiles):
        sensor.open(prof)
        sensor.start(lambda f: None)
    depth = np.full((H, W), 500, np.uint16)
    depth[:, W // 2:] = 800
    for k in range(frames):
        rgb = np.zeros((H, W, 3), np.uint8)
        rgb[:, :, 1] = 10 * k
        for sensor, prof, pix, bpp in ((ds, profiles[0], depth, 2), (cs, profiles[1], rgb, 3)):
            f = rs.software_video_frame()
            f.pixels, f.bpp, f.stride, f.timestamp = pix, bpp, bpp * W, k * 1000.0 / FPS
            f.domain, f.frame_number, f.profile = rs.timestamp_domain.hardware_clock, k, prof.as_video_stream_profile()
            if sensor is ds:
                f.depth_units = 0.001
            sensor.on_video_frame(f)
        time.sleep(1.0 / FPS)
    for sensor in (ds, cs):
        sensor.stop()
        sensor.close()
    del recorder


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rs") / "software_camera.db3"
    record_software_camera(path)
    assert path.stat().st_size > 0
    return path


def _aligned_edge(depth_mm: np.ndarray) -> float:
    row = depth_mm[H // 2].astype(float)
    cols = np.nonzero(row >= 800)[0]
    return float(cols.min())


@needs_rs
def test_realsense_source_plays_a_recording_with_depth_aligned_to_colour(recording):
    src = RealSenseSource("cam_top", playback=str(recording))
    pairs = []
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and len(pairs) < 3:
        p = src.poll()
        if p is not None:
            pairs.append(p)
        time.sleep(0.005)
    src.stop()
    assert len(pairs) >= 3, src.status
    rgb, depth = pairs[-1]
    assert rgb.shape == (H, W, 3) and depth.dtype == np.uint16 and depth.shape == (H, W)
    assert set(np.unique(depth[depth > 0])) <= {500, 800}
    assert _aligned_edge(depth) == pytest.approx(36.4, abs=1.0), "depth not resampled onto the colour image"
    f = src.info_fields
    assert f["k"] == [COLOR_FX, 0.0, COLOR_PPX, 0.0, COLOR_FX, H / 2, 0.0, 0.0, 1.0]
    assert f["distortion_model"] == "plumb_bob" and f["d"] == [0.0] * 5 and f["p"][3] == 0.0
    assert src.device == SERIAL


def test_realsense_source_names_an_absent_serial_and_retries():
    t = [0.0]
    src = RealSenseSource("cam_top", serial="123456789012", retry_period=2.0, clock=lambda: t[0])
    assert src.poll() is None and src.attempts == 1
    assert "123456789012" in src.status and "retrying" in src.status
    assert src.poll() is None and src.attempts == 1        # not before the retry period
    t[0] = 2.5
    assert src.poll() is None and src.attempts == 2 and not src.connected


def test_realsense_source_without_pyrealsense2_names_the_package_and_the_serial(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)      # import fails as when it is not installed
    src = RealSenseSource("cam_side", serial="012345678902", clock=lambda: 0.0)
    assert src.poll() is None and not src.connected
    assert "012345678902" in src.status and "pyrealsense2" in src.status and "make setup-robot" in src.status


def _listen(env: dict[str, str], topics: dict[str, type], seconds: float, until=None) -> dict[str, list]:
    os.environ.update(env)
    import rclpy
    from rclpy.qos import qos_profile_sensor_data

    from hexa_ros import qos

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("rs_probe", context=ctx)
    got: dict[str, list] = {t: [] for t in topics}
    for topic, cls in topics.items():
        q = qos.RELIABLE if topic == "/diagnostics" else qos_profile_sensor_data
        node.create_subscription(cls, topic, got[topic].append, q)
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    deadline = time.monotonic() + seconds
    try:
        while time.monotonic() < deadline and not (until and until(got)):
            ex.spin_once(timeout_sec=0.1)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    return got


@needs_rs
def test_camera_node_publishes_a_recording_in_the_realsense_ros_layout(recording, procs, ros_env):
    from sensor_msgs.msg import CameraInfo, Image

    from hexa.vision.images import from_message

    node = procs.start([PY, "-m", "hexa_vision.camera_node", "--ros-args", "-r", "__ns:=/rs", "-p",
                        "source:=realsense", "-p", "camera:=cam_top", "-p", f"path:={recording}",
                        "-p", "serial:=012345678901"], ros_env)
    topics = {f"/rs/cam_top/{k}": c for k, c in (("color/image_raw", Image), ("color/camera_info", CameraInfo),
                                                  ("aligned_depth_to_color/image_raw", Image),
                                                  ("aligned_depth_to_color/camera_info", CameraInfo))}
    got = _listen(ros_env, topics, 40, until=lambda g: all(len(v) >= 2 for v in g.values()))
    assert node.poll() is None, node.communicate(timeout=5)[1]
    assert all(got.values()), {k: len(v) for k, v in got.items()}
    depth = got["/rs/cam_top/aligned_depth_to_color/image_raw"][-1]
    assert depth.encoding == "16UC1" and depth.header.frame_id == "cam_top_color_optical_frame"
    assert _aligned_edge(from_message(depth)) == pytest.approx(36.4, abs=1.0)
    ci, di = got["/rs/cam_top/color/camera_info"][-1], got["/rs/cam_top/aligned_depth_to_color/camera_info"][-1]
    for a, b in ((ci, di),):
        assert (a.width, a.height, list(a.k), list(a.d), a.distortion_model, a.header.frame_id) == (
            b.width, b.height, list(b.k), list(b.d), b.distortion_model, b.header.frame_id)
    assert list(di.k)[0] == COLOR_FX and di.distortion_model == "plumb_bob" and len(di.d) == 5


def test_robot_mode_with_numeric_serials_and_no_hardware_starts_names_what_is_missing_and_retries(
        procs, ros_env, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray

    serials = ("123456789012", "012345678902")
    uno, mega = tmp_path / "no_uno", tmp_path / "no_mega"
    log_dir = tmp_path / "logs"
    bring = procs.start([PY, "-m", "hexa_bringup.cli", "bringup", "robot", "--uno", str(uno), "--mega", str(mega),
                         "--cameras", *serials, "--compose", "--log-dir", str(log_dir), "--duration", "40",
                         "--status-every", "5"], ros_env)
    wanted = {*serials, str(uno), str(mega)}

    def named(g):
        text = " ".join(f"{s.name} {s.message} {s.hardware_id}" for a in g["/diagnostics"] for s in a.status)
        return {w for w in wanted if w in text}

    got = _listen(ros_env, {"/diagnostics": DiagnosticArray}, 60, until=lambda g: named(g) == wanted)
    assert named(got) == wanted, f"missing in /diagnostics: {wanted - named(got)}"
    attempts = [int(kv.value) for a in got["/diagnostics"] for s in a.status for kv in s.values
                if kv.key == "attempts" and s.hardware_id in serials]
    time.sleep(3)
    assert bring.poll() is None, "bringup ended"
    bring.send_signal(2)
    out, err = bring.communicate(timeout=40)
    console = out + err + "".join(p.read_text() for p in log_dir.glob("*.log"))
    assert "Traceback" not in console and "InvalidParameterTypeException" not in console, console[-3000:]
    for s in serials:
        assert f"RealSense {s}" in console, f"{s} not named on the console"
    for port in (uno, mega):
        assert f"at {port}: open failed" in console, f"{port} not named on the console"
    assert max(attempts) >= 2 or "retrying" in console
