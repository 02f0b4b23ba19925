#!/usr/bin/env python3
"""CPU time per current sample of the observer node's callbacks (docs/realtime.md, "Hot paths in CPU time").

    .venv/bin/python scripts/bench_observer_node.py [--repeat 3] [--separate]

Feeds the plate case of `hexa bench realtime` (hexa.benchmarks.realtime.plate_case_stream: 6.5 s, currents at
1 kHz, camera poses at 30 Hz) to an ObserverNode's callbacks in-process, as its subscriptions deliver them
(motor_currents carrying the set-points as serialized bytes — with `--separate` the set-points on joint_states
instead, as in bags recorded before the field —, plate_pose as a message), with one subscriber on `residual`,
and prints the process CPU time per sample (time.process_time over the whole stream, best of `--repeat` fresh nodes).
What it leaves out is the executor and the transport (docs/realtime.md).
"""
from __future__ import annotations

import argparse
import time


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--separate", action="store_true", help="set-points on joint_states, not in motor_currents")
    args = ap.parse_args()

    from hexa.benchmarks.realtime import plate_case_stream
    from hexa_ros.env import apply_defaults

    apply_defaults()
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from hexa.kinematics.hexa6rus import rotation_zyx
    from hexa_dynamics.observer_node import ObserverNode
    from hexa_msgs.msg import MotorCurrents, Residual
    from hexa_ros.conversions import JOINT_NAMES, fill_pose_msg
    from hexa_ros.stamps import to_stamp

    stream = plate_case_stream()
    items: list[tuple[str, object]] = []
    k = 0
    for stamp, board_us, cur, cmd in stream.samples:
        while k < len(stream.poses) and stream.poses[k][0] <= stamp:
            t, q = stream.poses[k]
            k += 1
            ps = PoseStamped()
            ps.header.stamp, ps.header.frame_id = to_stamp(t), "base"
            fill_pose_msg(ps.pose, rotation_zyx(*q[3:]), q[:3])
            items.append(("pose", ps))
        mc = MotorCurrents(current=cur.tolist(), raw=[0] * 6, sequence=0, board_time_us=board_us, gaps=0,
                           setpoint=[] if args.separate else cmd.tolist())
        js = JointState(name=list(JOINT_NAMES), position=cmd.tolist())
        mc.header.stamp = js.header.stamp = to_stamp(stamp)
        items.append(("currents", serialize_message(mc)))
        if args.separate:
            items.append(("states", serialize_message(js)))

    rclpy.init()
    best = float("inf")
    try:
        for _ in range(max(1, args.repeat)):
            node = ObserverNode(cli_args=["--ros-args", "-p", "board_clock:=sim"])
            probe = rclpy.create_node("bench_observer_probe")
            probe.create_subscription(Residual, "residual", lambda _m: None, 10)
            t_end = time.monotonic() + 10.0
            while node.out.residual.get_subscription_count() == 0 and time.monotonic() < t_end:
                time.sleep(0.05)
            call = {"currents": node._on_currents, "states": node._on_states, "pose": node._on_pose}
            t0 = time.process_time()
            for kind, x in items:
                call[kind](x)
            best = min(best, (time.process_time() - t0) / len(stream.samples))
            accepted, events = node.monitor.observer.accepted, node.out.events_sent
            probe.destroy_node()
            node.destroy_node()
    finally:
        rclpy.try_shutdown()
    print(f"observer node ({'set-points on joint_states' if args.separate else 'set-points in motor_currents'}): "
          f"{len(stream.samples)} samples, {accepted} residuals, {events} collision events; "
          f"CPU per sample {best * 1e6:.1f} us (best of {max(1, args.repeat)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
