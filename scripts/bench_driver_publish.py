#!/usr/bin/env python3
"""CPU per message of the driver's 1 kHz streams in the publishing process, as bytes and as message objects
(docs/node_layer.md, "The 1 kHz path in CPU per sample").

    .venv/bin/python scripts/bench_driver_publish.py [--messages 3000]

Publishes `motor_currents` and `joint_states` at 1 kHz (reliable, depth 500: hexa_ros.qos.STREAM) to one raw
subscriber in another process (EventsExecutor), each way in turn: bytes written by hexa_ros.cdr, as the driver
publishes them, and message objects built per message. Prints the process CPU per message (every thread: rclpy and
Fast DDS included) less that of the same 1 kHz loop publishing nothing, and the CPU inside the publishing call.
Uses a free ROS_DOMAIN_ID (the tests' lock files) and localhost discovery.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

TOPICS = ("motor_currents", "joint_states")


def subscriber(seconds: float) -> int:
    import rclpy
    from hexa_msgs.msg import MotorCurrents
    from rclpy.executors import ExternalShutdownException
    from rclpy.experimental import EventsExecutor
    from sensor_msgs.msg import JointState

    from hexa_ros import qos

    rclpy.init()
    node = rclpy.create_node("bench_driver_publish_sub")
    for topic, ty in zip(TOPICS, (MotorCurrents, JointState)):
        node.create_subscription(ty, topic, lambda _m: None, qos.STREAM, raw=True)
    ex = EventsExecutor()
    ex.add_node(node)
    t_end = time.monotonic() + seconds
    try:
        while time.monotonic() < t_end and rclpy.ok():
            ex.spin_once(timeout_sec=0.1)
    except (ExternalShutdownException, KeyboardInterrupt):   # the publisher's SIGTERM when it is done
        pass
    return 0


def paced(fn, n: int) -> tuple[float, float]:
    """(process CPU s, CPU s inside `fn`) of n calls of `fn` at 1 kHz (None: the loop alone)."""
    c0, w0, inside = time.process_time(), time.monotonic(), 0.0
    for k in range(n):
        wait = w0 + k * 1e-3 - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        if fn is not None:
            a = time.thread_time()
            fn()
            inside += time.thread_time() - a
    return time.process_time() - c0, inside


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=3000)
    ap.add_argument("--subscriber", type=float, default=0.0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    from hexa_ros.env import apply_defaults

    apply_defaults()
    if args.subscriber:
        return subscriber(args.subscriber)
    from hexa_bringup.bench_graph import held_domain

    with held_domain(None) as domain:
        os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        sub = subprocess.Popen([sys.executable, __file__, "--subscriber", str(8 + 0.006 * args.messages)])
        try:
            return publisher(args.messages)
        finally:
            sub.terminate()
            sub.wait()


def publisher(n: int) -> int:
    import rclpy
    from hexa_msgs.msg import MotorCurrents
    from sensor_msgs.msg import JointState

    from hexa_ros import cdr, qos
    from hexa_ros.conversions import JOINT_NAMES

    rclpy.init()
    try:
        node = rclpy.create_node("bench_driver_publish")
        pubs = [node.create_publisher(ty, topic, qos.STREAM) for topic, ty in zip(TOPICS, (MotorCurrents, JointState))]
        t_end = time.monotonic() + 20.0
        while any(p.get_subscription_count() == 0 for p in pubs) and time.monotonic() < t_end:
            time.sleep(0.05)
        if any(p.get_subscription_count() == 0 for p in pubs):
            print("the subscriber did not match within 20 s", file=sys.stderr)
            return 1
        names, cur, sp = list(JOINT_NAMES), [0.1] * 6, [-2.6] * 6

        def currents_object() -> MotorCurrents:
            m = MotorCurrents(current=cur, raw=[512] * 6, sequence=1, board_time_us=5, gaps=0, setpoint=sp)
            m.header.stamp.sec, m.header.frame_id = 1, "base"
            return m

        def states_object() -> JointState:
            m = JointState(name=names, position=sp, effort=cur)
            m.header.stamp.sec, m.header.frame_id = 1, "base"
            return m

        cases = {
            "motor_currents as bytes": lambda: pubs[0].publish(
                cdr.motor_currents_to_cdr(1, 0, "base", cur, [512] * 6, 1, 5, 0, sp)),
            "joint_states as bytes": lambda: pubs[1].publish(cdr.joint_state_to_cdr(1, 0, "base", names, sp, [], cur)),
            "motor_currents as a message object": lambda: pubs[0].publish(currents_object()),
            "joint_states as a message object": lambda: pubs[1].publish(states_object()),
        }
        idle, _ = paced(None, n)
        for name, fn in cases.items():
            cpu, inside = paced(fn, n)
            print(f"{name:36s} {1e6 * (cpu - idle) / n:6.1f} us of process CPU per message "
                  f"({1e6 * inside / n:5.1f} us in the call); load {os.getloadavg()[0]:.1f}")
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
