"""hexa-vision-isolation: where did it hit? Isolates the contact on two cameras when the observer reports a collision.

Subscribes `cam_top/…`, `cam_side/…` (colour, aligned depth, camera_info; sensor-data QoS), `plate_pose` (the pose
node's, PoseStamped in base), `plate_pose_estimate` (the observer's tracked pose, PoseStamped in base at its sample
time) and `collision` (hexa_msgs/CollisionEvent). Publishes `contact` (hexa_msgs/Contact), `isolation/debug_image`
(rgb8 mosaic of the steps like the paper's Figs. 12/17/22; onset pairs only, only while subscribed) and
`/diagnostics`. Service `capture_background` (std_srvs/Trigger): the next frame of each camera becomes its background
(workspace clear); the first ones are taken `background_delay` s after the first frame. Parameters:
hexa_vision.isolation_params (read-only; the same defaults in hexa_bringup/config/hexa_params.yaml).

The images are not taken per message: they wait in their DDS readers (the last `frame_history` of each topic, on a
node `<name>_images` that no executor spins, hexa_ros.polled) and are taken as serialized bytes every 0.05 s and on
a collision START, so a START never waits behind queued images and finds the frames of its onset already buffered.
Taken images go undecoded (views of the delivered bytes) into the last second of frames per camera and are decoded
only when a pair is evaluated or becomes a background. On START the buffered pair nearest the onset is evaluated at
once with a pose already received, then a pair every `eval_period` s of frame time until END with the plate pose of
its stamp; the waits, the carried-forward poses and the queue are hexa.vision.isolation_scheduler's.
"""
from __future__ import annotations

import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from hexa_ros import diagnostics, node, qos, stamps
from hexa_ros.conversions import pose_fields
from hexa_ros.node import DESCRIPTION, declare_parameters
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger

from hexa.pose_check import PoseCheck
from hexa.robots.hexa_description import load_hexa
from hexa.vision.isolation import LINK_UNKNOWN
from hexa.vision.isolation_scheduler import BACKGROUND, ContactLocator, IsolationScheduler
from hexa_ros.cdr import CdrError, image_from_cdr
from hexa_ros.polled import PolledSubscriptions
from hexa_msgs.msg import CollisionEvent, Contact
from hexa_vision.common import CAMERAS, contact_msg, description_cameras, image_msg
from hexa_vision.isolation_params import PARAMETERS, SCHEDULER

class IsolationNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("hexa_vision_isolation", **kwargs)
        v = declare_parameters(self, PARAMETERS)
        self.want_debug = bool(v["debug_image"])
        self.sched = IsolationScheduler(CAMERAS, **{k: v[k] for k in SCHEDULER})
        models = description_cameras(v[DESCRIPTION])
        desc = load_hexa(v[DESCRIPTION] or None)
        self.locator = ContactLocator(desc, {c: models[c] for c in CAMERAS}, v["coarse_margin"])
        self.pose_checks = {k: PoseCheck.for_hexa(desc) for k in ("plate_pose", "plate_pose_estimate")}
        self.images = PolledSubscriptions(self, "images")
        image_qos = QoSProfile(depth=v["frame_history"], reliability=qos.SENSOR.reliability,
                               history=qos.SENSOR.history, durability=qos.SENSOR.durability)
        self.image_subs = [(c, color, self.images.subscribe(Image, f"{c}/{topic}", image_qos)) for c in CAMERAS
                           for topic, color in (("color/image_raw", True), ("aligned_depth_to_color/image_raw", False))]
        for c in CAMERAS:
            self.create_subscription(CameraInfo, f"{c}/color/camera_info", lambda m, c=c: self._on_info(c, m),
                                     qos.SENSOR)
        self.create_subscription(PoseStamped, "plate_pose", self._on_pose, qos.STREAM)
        self.create_subscription(PoseStamped, "plate_pose_estimate", self._on_estimate, qos.STREAM)
        self.create_subscription(CollisionEvent, "collision", self._on_collision, qos.EVENT)
        self.pub_contact = self.create_publisher(Contact, "contact", qos.EVENT)
        self.pub_debug = self.create_publisher(Image, "isolation/debug_image", qos.SENSOR)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.create_service(Trigger, "capture_background", self._on_capture)
        self.create_timer(1.0, self._diagnostics)
        self.create_timer(0.05, self._tick)

    def _on_info(self, cam: str, msg: CameraInfo) -> None:
        self.locator.assemblers[cam].set_camera_info(msg.width, msg.height, msg.k, msg.d)

    def close(self) -> None:
        self.images.close()

    def _take_images(self) -> int:
        """Take the images waiting in the readers into the scheduler; how many."""
        images = []
        for cam, color, sub in self.image_subs:
            for data in self.images.take(sub):
                try:
                    images.append((cam, image_from_cdr(data).raw(), color))   # pixels: a view of the bytes
                except CdrError:
                    self.sched.counters["reject: malformed image"] += 1
        self.sched.add_images(images, time.monotonic())
        return len(images)

    def _on_pose(self, msg: PoseStamped) -> None:
        T = self.pose_checks["plate_pose"].check(stamps.to_sec(msg.header.stamp), *pose_fields(msg.pose))
        if T is not None:     # non-unit quaternions, poses off the workspace and jumps are counted, not used
            self.sched.add_pose(stamps.to_sec(msg.header.stamp), T)
            self._run()

    def _on_estimate(self, msg: PoseStamped) -> None:
        T = self.pose_checks["plate_pose_estimate"].check(stamps.to_sec(msg.header.stamp), *pose_fields(msg.pose))
        if T is not None:
            self.sched.add_pose_estimate(stamps.to_sec(msg.header.stamp), T)

    def _on_capture(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.sched.capture_background()
        response.success, response.message = True, "background will be taken from the next frame of each camera"
        return response

    def _on_collision(self, msg: CollisionEvent) -> None:
        if msg.event == CollisionEvent.START:
            t0 = time.monotonic()
            taken = self._take_images()  # the frames since the last tick
            self.sched.collision_start(msg.id, stamps.to_sec(msg.onset), time.monotonic())
            self._run()
            self.get_logger().info(f"collision {msg.id} START, onset {stamps.to_sec(msg.onset):.3f} s: {taken} "
                                   f"images taken, onset pair handled in {1e3 * (time.monotonic() - t0):.0f} ms, "
                                   f"{len(self.sched.pending)} pair(s) waiting")
        elif msg.event == CollisionEvent.END:
            self.sched.collision_end(msg.id, stamps.to_sec(msg.header.stamp))

    def _tick(self) -> None:
        self._take_images()
        self._run()

    def _run(self) -> None:
        """Do the scheduler's due work: backgrounds, then isolations (a contact per answer)."""
        for work in self.sched.due(time.monotonic()):
            if work.kind == BACKGROUND:
                if self.locator.take_background(work):
                    self.sched.background_taken(next(iter(work.frames)))
                continue
            debug = work.debug and self.want_debug and self.pub_debug.get_subscription_count() > 0
            found = self.locator.locate(work, debug)
            if found is None:
                continue
            if found.estimate.link != LINK_UNKNOWN:
                self.pub_contact.publish(contact_msg(found))
            self.get_logger().info(found.summary())
            if debug:
                self.pub_debug.publish(image_msg(self.locator.debug_mosaic(found), "rgb8", found.estimate.camera
                                                 + "_color_optical_frame", self.get_clock().now().to_msg()))

    def _diagnostics(self) -> None:
        counters = self.locator.all_counters()
        counters.update(self.sched.counters)
        for topic, check in self.pose_checks.items():
            counters.update({f"reject: {topic} {k}": v for k, v in check.rejected.items()})
        state = "waiting for collisions" if self.sched.active is None else "isolating"
        self.pub_diag.publish(diagnostics.array(self, [diagnostics.counter_status(
            "hexa_vision: isolation", counters, state, "+".join(CAMERAS))]))


def main(args: list[str] | None = None) -> int:
    return node.main(IsolationNode, "isolation", args)


if __name__ == "__main__":
    raise SystemExit(main())
