#!/usr/bin/env python3
"""The vision path at 1×, without the observer: collision START → first `contact` of the isolation node.

    .venv/bin/python scripts/bench_vision_start.py [BAG] [--rate 1.0] [--onset 4.584] [--start 4.604] [--end 5.049]
        [-p NAME:=VALUE ...]

Plays the bag's camera topics (both cameras, with /clock) at `--rate` into the pose and isolation nodes as `hexa
bringup replay` starts them, and publishes a collision START (onset `--onset` s) when /clock reaches `--start` s and
its END at `--end` s, as the observer did on the slow replay of `hexa bench graph`'s default bag (its figures are
the defaults). Prints, as JSON: wall s from publishing the START to the first `contact` of that id, the contacts
(stamp, link, chain, point in mm), the plate poses received per top frame, the frame → plate_pose latency, and CPU
per node. The observer's own START latency is not in these figures (`hexa bench graph` has it); this isolates the
part of START → contact that the vision nodes own.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag", nargs="?", type=Path, default=Path("out/bench/graph_bag"))
    ap.add_argument("--rate", type=float, default=1.0)
    ap.add_argument("--onset", type=float, default=4.584)
    ap.add_argument("--start", type=float, default=4.604)
    ap.add_argument("--end", type=float, default=5.049)
    ap.add_argument("-p", "--isolation-param", action="append", default=[], metavar="NAME:=VALUE",
                    help="a parameter of the isolation node (e.g. onset_pose_wait:=0.5)")
    args = ap.parse_args()
    if not args.bag.exists():
        print(f"no bag {args.bag}: run `hexa bench graph` once (it records it)", file=sys.stderr)
        return 2

    from hexa_bringup.bench_graph import Children, CpuSampler, graph_specs
    from hexa_ros.env import apply_defaults, held_ros_domain, ros_env

    apply_defaults()
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.experimental import EventsExecutor
    from rosgraph_msgs.msg import Clock

    from hexa_msgs.msg import CollisionEvent, Contact
    from hexa_ros import qos
    from hexa_ros.stamps import fill_stamp, to_sec

    ns = "/hexa"
    params = Path(__file__).resolve().parents[1] / "hexa_bringup" / "hexa_bringup" / "config" / "hexa_params.yaml"
    cams = [f"{ns}/{c}/{k}" for c in ("cam_top", "cam_side")
            for k in ("color/image_raw", "aligned_depth_to_color/image_raw", "color/camera_info")]
    with held_ros_domain() as domain:
        env = ros_env(domain)
        import os

        os.environ.update({"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
        specs = [s for s in graph_specs("replay", ns, params) if s.name in ("pose", "isolation")]
        for s in specs:
            if s.name == "isolation":
                s.cmd.extend(a for p in args.isolation_param for a in ("-p", p))
        rclpy.init()
        node = rclpy.create_node("bench_vision_start")
        seen: dict = {"clock": 0.0, "contacts": [], "poses": [], "start_wall": None}
        pub = node.create_publisher(CollisionEvent, f"{ns}/collision", qos.EVENT)

        def on_clock(m: Clock) -> None:
            seen["clock"] = to_sec(m.clock)

        def on_contact(m: Contact) -> None:
            seen["contacts"].append((time.monotonic(), to_sec(m.header.stamp), int(m.collision_id), int(m.link),
                                     int(m.chain), [round(1e3 * v, 1) for v in (m.point.x, m.point.y, m.point.z)]))

        def on_pose(m: PoseStamped) -> None:
            seen["poses"].append((time.monotonic(), to_sec(m.header.stamp)))

        node.create_subscription(Clock, "/clock", on_clock, 10)
        node.create_subscription(Contact, f"{ns}/contact", on_contact, qos.EVENT)
        node.create_subscription(PoseStamped, f"{ns}/plate_pose", on_pose, qos.RELIABLE)
        ex = EventsExecutor()
        ex.add_node(node)
        log = Path("/tmp") / f"bench_vision_start_{domain}.log"
        with Children(env) as ch:
            for s in specs:
                ch.start(s.name, s.cmd, log=Path("/tmp") / f"bench_vision_start_{s.name}.log")
            deadline = time.monotonic() + 120
            while pub.get_subscription_count() < 1 or node.count_publishers(f"{ns}/contact") < 1:
                ex.spin_once(timeout_sec=0.1)
                if time.monotonic() > deadline:
                    print("the nodes did not come up", file=sys.stderr)
                    return 2
            time.sleep(3.0)                           # the nodes finish their start-up
            player = subprocess.Popen([sys.executable, "-m", "hexa_bringup.cli", "play", str(args.bag), "--clock",
                                       "--rate", str(args.rate), "--topics", *cams, "--wait", "20",
                                       "--wait-subscribers", "--log", str(log)], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            pids = {s.name: ch.procs[s.name].pid for s in specs}
            ended = False
            with CpuSampler(pids) as cpu:
                t0 = time.monotonic()
                while player.poll() is None:
                    ex.spin_once(timeout_sec=0.002)
                    if seen["start_wall"] is None and seen["clock"] >= args.start:
                        ev = CollisionEvent(event=CollisionEvent.START, id=1, axis=2, axis_name="fz")
                        fill_stamp(ev.header.stamp, args.start)
                        fill_stamp(ev.onset, args.onset)
                        pub.publish(ev)
                        seen["start_wall"], seen["start_time"] = time.monotonic(), time.time()
                    if not ended and seen["clock"] >= args.end:
                        ev = CollisionEvent(event=CollisionEvent.END, id=1, axis=2, axis_name="fz")
                        fill_stamp(ev.header.stamp, args.end)
                        fill_stamp(ev.onset, args.onset)
                        pub.publish(ev)
                        ended = True
                t1 = time.monotonic()
            end = time.monotonic() + 2.0
            while time.monotonic() < end:
                ex.spin_once(timeout_sec=0.05)
        published = {}
        for line in log.read_text().splitlines():
            t_ns, stamp_ns, topic = line.split()
            if topic.endswith("cam_top/color/image_raw") or topic.endswith("cam_top/aligned_depth_to_color/image_raw"):
                published.setdefault(int(stamp_ns), []).append(int(t_ns) * 1e-9)
        frames = {round(k * 1e-9, 6): max(v) for k, v in published.items() if len(v) == 2}
        lat = [t - frames[round(st, 6)] for t, st in seen["poses"] if round(st, 6) in frames]
        first = next((c for c in seen["contacts"] if c[2] == 1), None)
        out = {"rate": args.rate, "load_average": open("/proc/loadavg").read().split()[:3],
               "start_published_unix_s": seen.get("start_time"),
               "start_to_first_contact_s": None if first is None or seen["start_wall"] is None
               else first[0] - seen["start_wall"],
               "contacts": [{"stamp": round(c[1], 3), "link": c[3], "chain": c[4], "point_mm": c[5],
                             "after_start_s": round(c[0] - seen["start_wall"], 3)} for c in seen["contacts"]],
               "top_frames": len(frames), "plate_poses": len(seen["poses"]),
               "top_frames_without_pose": sorted(set(frames) - {round(st, 6) for _, st in seen["poses"]}),
               "frame_to_pose_s": {"p50": float(np.percentile(lat, 50)), "p95": float(np.percentile(lat, 95)),
                                   "max": float(np.max(lat))} if lat else None,
               "cpu_percent": {n: round(cpu.percent(n, t0, t1), 1) for n in pids},
               "isolation_params": args.isolation_param}
        print(json.dumps(out, indent=1))
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
