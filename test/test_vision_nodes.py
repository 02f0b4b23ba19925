"""Vision nodes as processes: PNG-folder camera → pose node → plate_pose; isolation node → contact; bad sources."""
from __future__ import annotations

import os
import sys
import time

import cv2
import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("hexa_msgs.msg")
pytest.importorskip("mujoco")

PY = sys.executable


def _wait(node, predicate, timeout: float) -> bool:
    import rclpy

    t_end = time.time() + timeout
    while time.time() < t_end:
        rclpy.spin_once(node, timeout_sec=0.1)
        if predicate():
            return True
    return False


@pytest.fixture
def rclpy_node(ros_env):
    old = dict(os.environ)
    os.environ.update(ros_env)
    import rclpy

    rclpy.init()
    node = rclpy.create_node("vision_test_probe")
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.shutdown()
        os.environ.clear()
        os.environ.update(old)


@pytest.mark.ros_parallel   # starts a node that refuses its parameters: no live timing
def test_camera_node_reports_missing_sources_clearly(ros_env, procs) -> None:
    p = procs.start([PY, "-m", "hexa_vision.camera_node", "--ros-args", "-p", "source:=folder", "-p",
                     "path:=/nonexistent/frames"], ros_env)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 2 and "does not exist" in err
    # an absent RealSense (or pyrealsense2) keeps the node running and retrying: test/test_realsense_source.py


def test_folder_camera_and_pose_node_publish_the_plate_pose(tmp_path, ros_env, procs, rclpy_node) -> None:
    from geometry_msgs.msg import PoseStamped

    from hexa.sim import Simulator
    from hexa_msgs.msg import PlateDetections

    pose = np.array([0.03, -0.02, -0.54, 0.1, -0.15, 0.2])
    with Simulator(pose=pose, seed=2) as sim:
        rgb, depth = sim.render("cam_top")
        truth = sim.state().pose
    for k in range(3):
        cv2.imwrite(str(tmp_path / f"color_{k:04d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(tmp_path / f"depth_{k:04d}.png"), depth)
    poses: list[PoseStamped] = []
    dets: list[PlateDetections] = []
    rclpy_node.create_subscription(PoseStamped, "/hexa/plate_pose", poses.append, 10)
    rclpy_node.create_subscription(PlateDetections, "/hexa/plate_detections", dets.append, 10)
    procs.start([PY, "-m", "hexa_vision.camera_node", "--ros-args", "-r", "__ns:=/hexa", "-p", "source:=folder",
                 "-p", f"path:={tmp_path}", "-p", "rate:=5.0"], ros_env)
    procs.start([PY, "-m", "hexa_vision.pose_node", "--ros-args", "-r", "__ns:=/hexa"], ros_env)
    assert _wait(rclpy_node, lambda: len(poses) >= 2, 60.0), "no plate_pose within 60 s"
    p = poses[-1]
    assert p.header.frame_id == "base"
    est = np.array([p.pose.position.x, p.pose.position.y, p.pose.position.z])
    assert np.linalg.norm(est - truth[:3]) < 0.003
    assert dets and dets[-1].detections and dets[-1].detections[0].class_id == "plate"


def test_isolation_node_publishes_a_contact_on_collision_start(ros_env, procs, rclpy_node) -> None:
    """The markers are hidden during the collision (no `plate_pose` after the backgrounds): the node carries the
    last camera pose forward by `plate_pose_estimate`, whose static offset from the camera pose cancels."""
    from geometry_msgs.msg import PoseStamped
    from hexa_vision.common import RELIABLE_QOS, camera_info_msg, image_msg
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image

    from hexa.kinematics.hexa6rus import rotation_zyx
    from hexa.robots.hexa_description import load_hexa
    from hexa.vision.evaluation import contact_samples
    from hexa.vision.markers import quaternion_from_matrix
    from hexa_msgs.msg import CollisionEvent, Contact

    desc = load_hexa()
    sample = next(contact_samples(1, seed=5, desc=desc))
    node = rclpy_node
    pubs = {}
    for c in ("cam_top", "cam_side"):
        pubs[c] = (node.create_publisher(Image, f"/hexa/{c}/color/image_raw", qos_profile_sensor_data),
                   node.create_publisher(Image, f"/hexa/{c}/aligned_depth_to_color/image_raw",
                                         qos_profile_sensor_data),
                   node.create_publisher(CameraInfo, f"/hexa/{c}/color/camera_info", qos_profile_sensor_data))
    pub_pose = node.create_publisher(PoseStamped, "/hexa/plate_pose", 10)
    pub_est = node.create_publisher(PoseStamped, "/hexa/plate_pose_estimate", 10)
    pub_col = node.create_publisher(CollisionEvent, "/hexa/collision", RELIABLE_QOS)
    contacts: list[Contact] = []
    node.create_subscription(Contact, "/hexa/contact", contacts.append, RELIABLE_QOS)
    from diagnostic_msgs.msg import DiagnosticArray

    diags: list[DiagnosticArray] = []
    node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, RELIABLE_QOS)
    proc = procs.start([PY, "-m", "hexa_vision.isolation_node", "--ros-args", "-r", "__ns:=/hexa", "-p",
                        "background_delay:=0.0", "-p", "debug_image:=false"], ros_env)
    pubs_all = [pub_pose, pub_est, pub_col, *(p for trio in pubs.values() for p in trio)]
    assert _wait(node, lambda: all(p.get_subscription_count() for p in pubs_all) and diags, 60.0), \
        "the isolation node did not subscribe within 60 s"

    def pose_msg(stamp, pose: np.ndarray) -> PoseStamped:
        ps = PoseStamped()
        ps.header.stamp = stamp
        ps.header.frame_id = "base"
        ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = (float(v) for v in pose[:3])
        q = quaternion_from_matrix(rotation_zyx(*pose[3:]))
        ps.pose.orientation.x, ps.pose.orientation.y, ps.pose.orientation.z, ps.pose.orientation.w = (
            float(v) for v in q)
        return ps

    def send(frames: dict, t: float, camera_pose: bool) -> None:
        stamp = node.get_clock().now().to_msg()
        stamp.sec, stamp.nanosec = int(t), int(round((t % 1) * 1e9))
        for c, (rgb, depth_m) in frames.items():
            cam = sample.cameras[c]
            depth_mm = np.nan_to_num(depth_m * 1000.0, nan=0.0).astype(np.uint16)
            pubs[c][2].publish(camera_info_msg(cam, f"{c}_color_optical_frame", stamp))
            pubs[c][0].publish(image_msg(rgb, "rgb8", f"{c}_color_optical_frame", stamp))
            pubs[c][1].publish(image_msg(depth_mm, "16UC1", f"{c}_color_optical_frame", stamp))
        pub_est.publish(pose_msg(stamp, sample.pose + np.array([0.004, -0.003, 0.002, 0.01, 0.0, 0.0])))
        if camera_pose:
            pub_pose.publish(pose_msg(stamp, sample.pose))

    for k in range(6):                       # backgrounds (workspace clear)
        send(sample.backgrounds, 10.0 + 0.1 * k, camera_pose=True)
        _wait(node, lambda: False, 0.2)
    ev = CollisionEvent()
    ev.event, ev.id = CollisionEvent.START, 7
    ev.onset.sec, ev.onset.nanosec = 11, 0
    pub_col.publish(ev)
    _wait(node, lambda: False, 0.3)
    for k in range(20):
        send(sample.frames, 11.0 + 0.1 * k, camera_pose=False)
        if _wait(node, lambda: bool(contacts), 0.5):
            break

    def values() -> dict[str, str]:
        return {v.key: v.value for d in diags[-1:] for st in d.status for v in st.values}

    _wait(node, lambda: int(values().get("pose carried forward", 0)) >= 1, 5.0)
    if not contacts:
        proc.terminate()
        _, err = proc.communicate(timeout=10)
        pytest.fail(f"no contact published; diagnostics {values()}; stderr {err[-2000:]}")
    assert int(values().get("pose carried forward", 0)) >= 1, sorted(values().items())
    c = contacts[-1]
    assert c.collision_id == 7 and c.header.frame_id == "base"
    link = {"plate": Contact.PLATE, "arm": Contact.ARM, "rod": Contact.ROD}[sample.link]
    assert c.link == link and c.chain == sample.chain
    assert np.linalg.norm([c.point.x - sample.point[0], c.point.y - sample.point[1],
                           c.point.z - sample.point[2]]) < 0.02
    push = np.array([c.push_direction.x, c.push_direction.y, c.push_direction.z])
    force = np.asarray(sample.meta["force_truth"])
    assert abs(np.linalg.norm(push) - 1.0) < 1e-6                 # the pushing capsule is elongated: measured
    assert push @ force / np.linalg.norm(force) > np.cos(np.radians(10.0))


def test_bag_camera_republishes_recorded_frames(tmp_path, ros_env, procs, rclpy_node) -> None:
    from hexa_bringup.bag import BagRecorder
    from hexa_vision.common import camera_info_msg, image_msg
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import CameraInfo, Image

    from hexa.vision.camera import CameraModel, intrinsics
    from hexa.vision.images import from_message

    cam = CameraModel(intrinsics(32, 24, 1.0), 32, 24)
    rgb = np.random.default_rng(0).integers(0, 255, (24, 32, 3)).astype(np.uint8)
    depth = np.full((24, 32), 812, np.uint16)
    bag = tmp_path / "cams"
    with BagRecorder(bag) as rec:
        for topic, typ in (("/hexa/cam_top/color/image_raw", "sensor_msgs/msg/Image"),
                           ("/hexa/cam_top/aligned_depth_to_color/image_raw", "sensor_msgs/msg/Image"),
                           ("/hexa/cam_top/color/camera_info", "sensor_msgs/msg/CameraInfo")):
            rec.add_topic(topic, typ, reliable=False)
        for k in range(5):
            stamp = rclpy_node.get_clock().now().to_msg()
            t_ns = 10 ** 9 + k * 10 ** 8
            rec.write("/hexa/cam_top/color/camera_info", t_ns, serialize_message(camera_info_msg(cam, "f", stamp)))
            rec.write("/hexa/cam_top/color/image_raw", t_ns, serialize_message(image_msg(rgb, "rgb8", "f", stamp)))
            rec.write("/hexa/cam_top/aligned_depth_to_color/image_raw", t_ns,
                      serialize_message(image_msg(depth, "16UC1", "f", stamp)))
    got: list[Image] = []
    infos: list[CameraInfo] = []
    rclpy_node.create_subscription(Image, "/hexa/cam_top/aligned_depth_to_color/image_raw", got.append,
                                   qos_profile_sensor_data)
    rclpy_node.create_subscription(CameraInfo, "/hexa/cam_top/color/camera_info", infos.append,
                                   qos_profile_sensor_data)
    procs.start([PY, "-m", "hexa_vision.camera_node", "--ros-args", "-r", "__ns:=/hexa", "-p", "source:=bag",
                 "-p", f"path:={bag}", "-p", "loop:=true"], ros_env)
    assert _wait(rclpy_node, lambda: len(got) >= 2 and infos, 30.0), "no depth image republished from the bag"
    assert np.array_equal(from_message(got[-1]), depth) and infos[-1].width == 32


def test_camera_node_image_qos_parameter_sets_the_publishers_reliability(tmp_path, ros_env, procs, rclpy_node) -> None:
    """image_qos:=reliable (realsense-ros' <stream>_qos): the graph reports RELIABLE publishers, and a RELIABLE
    subscriber (which never matches a best-effort publisher) receives the frames; a bad value is named at start."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image

    cv2.imwrite(str(tmp_path / "color_0000.png"), np.zeros((480, 640, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "depth_0000.png"), np.full((480, 640), 500, np.uint16))
    frames: list[Image] = []
    rclpy_node.create_subscription(Image, "/hexa/cam_top/color/image_raw", frames.append,
                                   QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE))
    procs.start([PY, "-m", "hexa_vision.camera_node", "--ros-args", "-r", "__ns:=/hexa", "-p", "source:=folder",
                 "-p", f"path:={tmp_path}", "-p", "rate:=10.0", "-p", "image_qos:=reliable"], ros_env)
    assert _wait(rclpy_node, lambda: len(frames) >= 2, 30.0), "a RELIABLE subscriber got no frame"
    info = rclpy_node.get_publishers_info_by_topic("/hexa/cam_top/color/image_raw")
    assert info and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in info)
    assert frames[-1].header.frame_id == "cam_top_color_optical_frame"
    bad = procs.start([PY, "-m", "hexa_vision.camera_node", "--ros-args", "-p", "source:=folder",
                       "-p", f"path:={tmp_path}", "-p", "image_qos:=fast"], ros_env)
    _out, err = bad.communicate(timeout=30)
    assert bad.returncode == 2 and "image_qos" in err and "'fast'" in err and "Traceback" not in err, err
