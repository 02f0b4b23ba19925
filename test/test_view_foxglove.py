"""`hexa view` serves a running simulated graph over the Foxglove WebSocket protocol: a client subscribes to the
channels the shipped layout uses and decodes JPEG frames of the simulator's cameras, /tf, markers, residual with
thresholds and /diagnostics (residual, plate pose and markers from a stand-in publisher)."""
from __future__ import annotations

import json
import re
import sys
import time

import numpy as np
import pytest

pytest.importorskip("foxglove")
pytest.importorskip("websockets")

from hexa.foxglove_client import FoxgloveClient, FoxgloveClientError  # noqa: E402

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

PY = sys.executable


def _start_view(procs, env, ns="/hexa"):
    view = procs.start([PY, "-m", "hexa_bringup.cli", "view", "--ns", ns, "--port", "0", "--image-rate", "5"], env)
    deadline = time.monotonic() + 60
    line = ""
    while time.monotonic() < deadline:
        line = view.stdout.readline()
        m = re.search(r"ws://[\d.]+:(\d+)", line)
        if m:
            return view, f"ws://127.0.0.1:{m.group(1)}"
        if view.poll() is not None:
            break
    pytest.fail(f"hexa view did not print its URL: {line!r} {view.stderr.read() if view.poll() is not None else ''}")


def _layout_topics() -> set[str]:
    from hexa_bringup.view_node import LAYOUT

    text = LAYOUT.read_text()
    topics = set(re.findall(r'"(?:imageTopic|topicPath)": "([^"]+)"', text))
    topics |= {v.split(".", 1)[0] for v in re.findall(r'"value": "([^"]+)"', text)}
    topics |= set(json.loads(text)["configById"]["3D!scene"]["topics"])
    return topics


def _publish_graph_outputs(env, stop):
    """Residual, plate pose and markers as the observer publishes them (real DDS, until `stop` is set)."""
    import os
    import threading

    os.environ.update(env)
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from hexa_msgs.msg import Residual
    from visualization_msgs.msg import MarkerArray

    from hexa_ros import markers, qos

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("observer_stand_in", namespace="/hexa", context=ctx)
    pub_r = node.create_publisher(Residual, "residual", qos.STREAM)
    pub_p = node.create_publisher(PoseStamped, "plate_pose", qos.RELIABLE)
    pub_m = node.create_publisher(MarkerArray, "markers", qos.RELIABLE)

    def run():
        k = 0
        while not stop.is_set():
            stamp = node.get_clock().now().to_msg()
            r = Residual()
            r.header.stamp, r.header.frame_id = stamp, "base"
            r.r = [0.1 * k, 0.0, -0.5, 0.0, 0.0, float("nan")]
            r.threshold = [2.0, 2.0, 2.0, 0.2, 0.2, 0.2]
            pub_r.publish(r)
            p = PoseStamped()
            p.header.stamp, p.header.frame_id = stamp, "base"
            p.pose.position.z, p.pose.orientation.w = 0.42, 1.0
            pub_p.publish(p)
            pub_m.publish(MarkerArray(markers=[markers.arrow("residual_force", "base", stamp, (0, 0, 0.42),
                                                             (0, 0, 0.32), (0.0, 1.0, 0.0, 1.0))]))
            k += 1
            stop.wait(0.1)
        node.destroy_node()
        rclpy.shutdown(context=ctx)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    return th


def test_view_serves_the_simulated_graph_to_a_foxglove_client(procs, ros_env):
    import threading

    env = dict(ros_env, MUJOCO_GL="egl")
    procs.start([PY, "-m", "hexa_bringup.sim_node", "--ros-args", "-r", "__ns:=/hexa", "-p", "scenario:=plate",
                 "-p", "boards:=false", "-p", "real_time_factor:=0.5", "-p", "camera_rate_hz:=10.0",
                 "-p", "duration:=60.0"], env)
    stop = threading.Event()
    publisher = _publish_graph_outputs(env, stop)
    view, url = _start_view(procs, env)
    layout = _layout_topics()
    with FoxgloveClient(url) as client:
        channels = client.wait_for_topics(layout, timeout=20)
        assert channels["/hexa/cam_top/color/image_raw/compressed"]["schemaName"] == "foxglove.CompressedImage"
        assert channels["/tf"]["schemaName"] == "foxglove.FrameTransforms"
        assert channels["/hexa/markers"]["schemaName"] == "foxglove.SceneUpdate"
        want = ["/hexa/cam_top/color/image_raw/compressed", "/hexa/cam_side/color/image_raw/compressed", "/tf",
                "/hexa/residual", "/diagnostics", "/hexa/markers"]
        client.subscribe(want)

        def enough(msgs):
            return set(want) <= {m.topic for m in msgs}

        msgs = client.messages(90.0, until=enough)
    got = {m.topic for m in msgs}
    assert set(want) <= got, f"no message on {sorted(set(want) - got)}; got {sorted(got)}"
    import cv2

    img = next(m for m in msgs if m.topic.endswith("cam_top/color/image_raw/compressed")).data
    assert img.format == "jpeg" and img.frame_id == "cam_top_color_optical_frame"
    rgb = cv2.imdecode(np.frombuffer(img.data, np.uint8), cv2.IMREAD_COLOR)
    assert rgb is not None and rgb.shape[2] == 3 and rgb.shape[0] >= 240 and rgb.std() > 5, "not a rendered frame"
    res = next(m for m in msgs if m.topic == "/hexa/residual").data
    assert len(res["r"]) == 6 and len(res["threshold"]) == 6 and all(t > 0 for t in res["threshold"][:3])
    assert res["header"]["frame_id"] == "base" and isinstance(res["in_collision"], bool)
    tf = next(m for m in msgs if m.topic == "/tf").data
    assert [(t.parent_frame_id, t.child_frame_id, round(t.translation.z, 3)) for t in tf.transforms] == [
        ("base", "plate", 0.42)]
    scene = next(m for m in msgs if m.topic == "/hexa/markers").data
    arrow = scene.entities[0].arrows[0]
    assert scene.entities[0].frame_id == "base" and arrow.pose.position.z == pytest.approx(0.42)
    assert arrow.shaft_length + arrow.head_length == pytest.approx(0.10)
    assert abs(arrow.pose.orientation.y) == pytest.approx(np.sqrt(0.5), abs=1e-6), "arrow not turned to -z"
    assert res["r"][5] is None, "NaN must reach JSON as null"
    diag = [m.data for m in msgs if m.topic == "/diagnostics"]
    mine = [s for d in diag for s in d["status"] if s["name"].startswith("/hexa/view")]
    assert mine and mine[-1]["level"] == 0 and int(dict((kv["key"], kv["value"]) for kv in mine[-1]["values"])[
        "forwarded"]) > 0
    assert view.poll() is None
    stop.set()
    publisher.join(timeout=5)


def test_client_names_a_missing_server_and_view_names_a_bad_port(procs, ros_env):
    with pytest.raises(FoxgloveClientError, match="no Foxglove server"):
        FoxgloveClient("ws://127.0.0.1:9", timeout=2)
    p = procs.start([PY, "-m", "hexa_bringup.cli", "view", "--port", "70000"], ros_env)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 2 and "--port must be 0..65535" in out + err and "Traceback" not in err
