"""hexa-vision-isolation: where did it hit? Evaluates the two cameras when the observer reports a collision.

Subscribes `cam_top/…` and `cam_side/…` (colour, aligned depth, camera_info; sensor-data QoS), `plate_pose`
(PoseStamped, base), `collision` (hexa_msgs/CollisionEvent, reliable). On START it isolates the contact on the
buffered frames nearest the onset, then on every new frame pair while the collision lasts (so the force peak is
covered), until END. Publishes `contact` (hexa_msgs/Contact, reliable), `isolation/debug_image` (rgb8 mosaic of the
steps, like the paper's Figs. 12/17/22) and `/diagnostics` (evaluations, contacts, rejects by reason).
Backgrounds are captured from the first frames after start-up (`background_delay` s) and again on the
`capture_background` service (std_srvs/Trigger) — with the workspace clear of objects.

Live timing: the plate pose of a frame comes from the pose node, which lags the cameras (0.3 s median, > 1 s under
load). A frame pair is therefore queued until a `plate_pose` at or after its stamp has arrived and evaluated with the
pose interpolated at its stamp (`hexa.vision.sync.PoseBuffer`); a stale pose would draw the links where they were
and leave phantom robot pixels touching a link. After `pose_wait` wall seconds without such a pose the nearest pose
within `max_pose_age` is used (counted); failing that (the object in front of the plate's markers hides two of them,
as in the demo's rod case), the newest camera pose before the frame is carried forward by the arm angles of
`joint_states`: pose(t) = pose_cam(t0) + FK(ζ(t)) − FK(ζ(t0)) (the difference cancels the servos' static offset;
counted as "pose from joint_states"; the robot mask then gets a `coarse_margin` of 8 mm); else the pair is dropped
(counted). At most `max_pending` pairs wait; the
onset pair is never dropped for a newer one.
While the collision lasts, complete frame pairs are evaluated every `eval_period` s of frame time (the node must
keep up on two shared cores; a queue of every frame would only be dropped).
The debug image is drawn for the onset pair of each collision only (it costs as much as the isolation itself).
Parameters: robot_description, background_delay (s), debug_image (bool), max_pose_age (s), pose_wait (s, wall),
max_pending, eval_period (s).
"""
from __future__ import annotations

import dataclasses
import sys
import time
from collections import Counter, deque

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from hexa_bringup.rosenv import apply_defaults
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_srvs.srv import Trigger

from hexa.vision.isolation import LINK_UNKNOWN, CollisionIsolator, IsolationError, RobotGeometry, debug_image
from hexa.vision.sync import FrameAssembler, PoseBuffer, RGBDFrame
from hexa_msgs.msg import CollisionEvent, Contact
from hexa_vision.common import (
    CAMERAS,
    RELIABLE_QOS,
    SENSOR_QOS,
    description_cameras,
    diagnostic_status,
    image_msg,
    sec_to_stamp,
    stamp_to_sec,
)


def _rot_from_quat(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _pose6(T: np.ndarray) -> np.ndarray:
    """[x y z α β γ] (ZYX angles) of a 4x4 pose."""
    R = T[:3, :3]
    return np.array([T[0, 3], T[1, 3], T[2, 3], np.arctan2(R[1, 0], R[0, 0]),
                     np.arcsin(np.clip(-R[2, 0], -1, 1)), np.arctan2(R[2, 1], R[2, 2])])


class IsolationNode(Node):
    def __init__(self) -> None:
        super().__init__("hexa_vision_isolation")
        desc_path = self.declare_parameter("robot_description", "").value
        self.background_delay = float(self.declare_parameter("background_delay", 1.0).value)
        self.want_debug = bool(self.declare_parameter("debug_image", True).value)
        self.max_pose_age = float(self.declare_parameter("max_pose_age", 0.2).value)
        self.pose_wait = float(self.declare_parameter("pose_wait", 0.5).value)
        self.max_pending = int(self.declare_parameter("max_pending", 8).value)
        self.eval_period = float(self.declare_parameter("eval_period", 0.1).value)
        self.coarse_margin = float(self.declare_parameter("coarse_margin", 0.008).value)
        from hexa.robots.hexa_description import load_hexa

        self.desc = load_hexa(desc_path or None)
        models = description_cameras(desc_path)
        self.isolator = CollisionIsolator({c: models[c] for c in CAMERAS})
        self.assemblers = {c: FrameAssembler(c, models[c].T_base_camera) for c in CAMERAS}
        self.frames: dict[str, deque[RGBDFrame]] = {c: deque(maxlen=30) for c in CAMERAS}
        self.poses = PoseBuffer(keep=400)
        self.joints: deque[tuple[float, np.ndarray]] = deque(maxlen=600)
        self.ended: dict[int, float] = {}     # collision id -> END stamp: later frames are not that collision's
        # (wall time queued, frame pair, is the onset pair, collision id)
        self.pending: list[tuple[float, dict[str, RGBDFrame], bool, int]] = []
        self.counters: Counter[str] = Counter()
        self.t_start: float | None = None
        self.want_background = set(CAMERAS)
        self.active: CollisionEvent | None = None
        self.last_eval: dict[str, float] = {}   # stamp and camera count of the last evaluation
        for c in CAMERAS:
            self.create_subscription(Image, f"{c}/color/image_raw", lambda m, c=c: self._on_image(c, m, True),
                                     SENSOR_QOS)
            self.create_subscription(Image, f"{c}/aligned_depth_to_color/image_raw",
                                     lambda m, c=c: self._on_image(c, m, False), SENSOR_QOS)
            self.create_subscription(CameraInfo, f"{c}/color/camera_info", lambda m, c=c: self._on_info(c, m),
                                     SENSOR_QOS)
        self.create_subscription(PoseStamped, "plate_pose", self._on_pose, 10)
        self.create_subscription(JointState, "joint_states", self._on_joints, 50)
        self.create_subscription(CollisionEvent, "collision", self._on_collision, RELIABLE_QOS)
        self.pub_contact = self.create_publisher(Contact, "contact", RELIABLE_QOS)
        self.pub_debug = self.create_publisher(Image, "isolation/debug_image", SENSOR_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE_QOS)
        self.create_service(Trigger, "capture_background", self._on_capture)
        self.create_timer(1.0, self._diagnostics)
        self.create_timer(0.05, self._drain)

    # ------------------------------------------------------------------ inputs
    def _on_info(self, cam: str, msg: CameraInfo) -> None:
        self.assemblers[cam].set_camera_info(msg.width, msg.height, msg.k, msg.d)

    def _on_image(self, cam: str, msg: Image, color: bool) -> None:
        a = self.assemblers[cam]
        args = (stamp_to_sec(msg.header.stamp), msg.height, msg.width, msg.encoding, msg.is_bigendian, msg.step,
                msg.data)
        frame = a.add_color(*args) if color else a.add_depth(*args)
        if frame is not None:
            self._on_frame(cam, frame)

    def _on_pose(self, msg: PoseStamped) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        T = np.eye(4)
        T[:3, :3] = _rot_from_quat(q.x, q.y, q.z, q.w)
        T[:3, 3] = [p.x, p.y, p.z]
        self.poses.add(stamp_to_sec(msg.header.stamp), T)
        self.counters["plate_pose received"] += 1
        self._drain()

    def _on_joints(self, msg: JointState) -> None:
        if len(msg.position) == 6:
            self.joints.append((stamp_to_sec(msg.header.stamp), np.asarray(msg.position, float)))

    def _zeta_at(self, stamp: float) -> np.ndarray | None:
        if not self.joints or self.joints[-1][0] < stamp - 0.02:
            return None
        t, z = min(self.joints, key=lambda j: abs(j[0] - stamp))
        return z if abs(t - stamp) <= 0.02 else None

    def _pose_from_joints(self, stamp: float) -> np.ndarray | None:
        """The newest camera pose before `stamp` carried forward by FK of the arm angles (module docstring)."""
        from hexa.kinematics import hexa6rus as kin

        before = [p for p in self.poses._poses if p[0] <= stamp]
        if not before:
            return None
        t0, T0 = before[-1]
        z0, z1 = self._zeta_at(t0), self._zeta_at(stamp)
        if z0 is None or z1 is None:
            return None
        p0 = _pose6(T0)
        try:
            f0 = kin.forward_kinematics(self.desc, z0, guess=p0)
            f1 = kin.forward_kinematics(self.desc, z1, guess=f0)
        except Exception:  # noqa: BLE001 - no FK solution: no geometry for this frame
            return None
        p = p0 + (np.asarray(f1) - np.asarray(f0))
        T = np.eye(4)
        T[:3, :3] = kin.rotation_zyx(*p[3:])
        T[:3, 3] = p[:3]
        return T

    def _on_capture(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.want_background = set(CAMERAS)
        response.success = True
        response.message = "background will be taken from the next frame of each camera"
        return response

    def _on_collision(self, msg: CollisionEvent) -> None:
        if msg.event == CollisionEvent.START:
            self.active = msg
            self.counters["collisions"] += 1
            onset = stamp_to_sec(msg.onset)
            pair = {}
            for c in CAMERAS:
                if self.frames[c]:
                    pair[c] = min(self.frames[c], key=lambda f: abs(f.stamp - onset))
            if pair:
                self.last_eval["t"] = max(f.stamp for f in pair.values())
                self._submit(pair, onset=True)
                # the START reaches this node late under load: frames after the onset that are already buffered
                # are queued too (every eval_period), so the force peak is covered
                for f in sorted(self.frames[CAMERAS[0]], key=lambda f: f.stamp):
                    if f.stamp - self.last_eval["t"] < self.eval_period - 1e-6:
                        continue
                    other = [g for g in self.frames[CAMERAS[1]] if abs(g.stamp - f.stamp) < 0.005]
                    if other:
                        self.last_eval["t"] = f.stamp
                        self._submit({CAMERAS[0]: f, CAMERAS[1]: other[0]})
            self.get_logger().info(
                f"collision {msg.id} START, onset {onset:.3f} s: frames {[round(f.stamp, 3) for f in pair.values()]}, "
                f"newest frames {[round(self.frames[c][-1].stamp, 3) for c in CAMERAS if self.frames[c]]}, "
                f"newest pose {self.poses.latest}, pending {len(self.pending)}")
        elif msg.event == CollisionEvent.END:
            self.active = None
            self.ended[int(msg.id)] = stamp_to_sec(msg.header.stamp)

    def _on_frame(self, cam: str, frame: RGBDFrame) -> None:
        now = frame.stamp
        if self.t_start is None:
            self.t_start = now
        self.frames[cam].append(frame)
        if cam in self.want_background and now - self.t_start >= self.background_delay:
            try:
                self.isolator.set_background(cam, frame.rgb, frame.depth)
                self.want_background.discard(cam)
                self.counters[f"background {cam}"] += 1
            except IsolationError:
                self.counters["reject: background frame"] += 1
        if self.active is not None:
            other = [c for c in CAMERAS if c != cam and self.frames[c]]
            pair = {cam: frame}
            for c in other:
                f = self.frames[c][-1]
                if abs(f.stamp - now) < 0.05:
                    pair[c] = f
            t_last = self.last_eval.get("t", -1.0)
            if len(pair) == len(CAMERAS) and now - t_last >= self.eval_period - 1e-6:
                self.last_eval["t"], self.last_eval["n"] = now, len(pair)
                self._submit(pair)

    # ------------------------------------------------------------------ work
    def _submit(self, pair: dict[str, RGBDFrame], onset: bool = False) -> None:
        """Queue a frame pair until the plate pose of its stamp has arrived (see module docstring)."""
        cid = int(self.active.id) if self.active is not None else 0
        self.pending.append((time.monotonic(), pair, onset, cid))
        while len(self.pending) > self.max_pending:
            drop = next((i for i, p in enumerate(self.pending) if not p[2]), 0)
            self.pending.pop(drop)
            self.counters["dropped: waiting for plate_pose"] += 1
        self._drain()

    def _drain(self) -> None:
        """Evaluate the queued pairs whose pose has arrived (or whose wait is over), oldest first."""
        now = time.monotonic()
        keep = []
        for queued, pair, onset, cid in self.pending:
            stamp = max(f.stamp for f in pair.values())
            if cid in self.ended and stamp > self.ended[cid] + 1e-3:
                self.counters["skipped: frame after END"] += 1
            elif self.poses.covers(stamp):
                self._evaluate(pair, self.poses.at(stamp, self.max_pose_age), cid, debug=onset)
            elif now - queued > self.pose_wait:
                T = self.poses.at(stamp, self.max_pose_age)
                from_joints = False
                if T is None and self.joints and self.joints[-1][0] >= stamp - 0.02:
                    T = self._pose_from_joints(stamp)   # FK only once the arm angles of the stamp are here
                    from_joints = T is not None
                if T is None and now - queued <= 6 * self.pose_wait:
                    keep.append((queued, pair, onset, cid))    # joint_states not there yet either: wait on
                    continue
                self.counters["pose wait expired"] += 1
                self.counters["pose from joint_states"] += int(from_joints)
                self._evaluate(pair, T, cid, coarse=from_joints, debug=onset)
            else:
                keep.append((queued, pair, onset, cid))
        self.pending = keep

    def _geometry(self, T: np.ndarray | None) -> RobotGeometry | None:
        if T is None:
            self.counters["reject: no plate_pose near the frame"] += 1
            return None
        pose = _pose6(T)
        try:
            return RobotGeometry.from_state(self.desc, pose)
        except Exception:  # noqa: BLE001 - unreachable pose from a bad fit
            self.counters["reject: plate_pose unreachable"] += 1
            return None

    def _evaluate(self, pair: dict[str, RGBDFrame], T_plate: np.ndarray | None, collision_id: int = 0,
                  coarse: bool = False, debug: bool = True) -> None:
        debug = debug and self.want_debug   # the mosaic costs as much as the isolation: onset pairs only
        stamp = max(f.stamp for f in pair.values())
        missing = [c for c in pair if c not in self.isolator.backgrounds]
        for c in missing:
            self.counters["no background"] += 1
            pair.pop(c)
        if not pair:
            return
        geom = self._geometry(T_plate)
        if geom is None:
            return
        config = self.isolator.config
        if coarse:   # a pose carried by the commanded angles is good to a few mm: a wider robot mask
            self.isolator.config = dataclasses.replace(config, robot_margin_m=self.coarse_margin)
        try:
            est = self.isolator.isolate({c: (f.rgb, f.depth) for c, f in pair.items()}, geom, debug=debug)
        except IsolationError as exc:
            self.counters["isolation error"] += 1
            self.get_logger().debug(str(exc))
            return
        finally:
            self.isolator.config = config
        self.counters["evaluations"] += 1
        self.get_logger().info(
            f"isolation at {stamp:.3f} s (pose lag {self.poses.latest - stamp:+.3f} s, cameras {sorted(pair)}): "
            f"{est.link_name} {est.chain} from {est.camera}, point {np.round(1e3 * np.asarray(est.point), 1).tolist()} "
            f"mm; " + "; ".join(f"{c}: {r.link} {r.chain} {r.reason}" for c, r in est.per_camera.items()))
        if est.link == LINK_UNKNOWN:
            self.counters["no contact found"] += 1
        else:
            self.counters["contacts"] += 1
            msg = Contact()
            sec_to_stamp(msg.header.stamp, stamp)
            msg.header.frame_id = "base"
            msg.collision_id = collision_id
            msg.link, msg.chain = int(est.link), int(est.chain)
            msg.point.x, msg.point.y, msg.point.z = (float(v) for v in est.point)
            msg.pixel_u, msg.pixel_v = (float(v) for v in est.pixel)
            msg.camera = est.camera
            msg.confidence = float(est.confidence)
            if np.all(np.isfinite(est.push_direction)):
                msg.push_direction.x, msg.push_direction.y, msg.push_direction.z = (float(v) for v in
                                                                                    est.push_direction)
            self.pub_contact.publish(msg)
        if debug:
            res = est.per_camera.get(est.camera) or next(iter(est.per_camera.values()))
            img = debug_image(res, self.isolator, geom)
            st = self.get_clock().now().to_msg()
            self.pub_debug.publish(image_msg(img, "rgb8", res.camera + "_color_optical_frame", st))

    def _diagnostics(self) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        counters = Counter(self.counters)
        for a in self.assemblers.values():
            counters.update({f"{a.name}: {k}": v for k, v in a.rejects.items()})
            counters[f"{a.name}: frames"] = a.frames
        status = diagnostic_status("hexa_vision: isolation", "cam_top+cam_side", counters,
                                   "waiting for collisions" if self.active is None else "isolating")
        arr.status.append(status)
        self.pub_diag.publish(arr)


def main(args: list[str] | None = None) -> int:
    apply_defaults()
    rclpy.init(args=args)
    node = IsolationNode()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
