"""`hexa topic list|echo|hz`: what operators would use `ros2 topic` for (no ros2 CLI wheel exists)."""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import deque


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("topic", help="list topics, print messages, measure rates (like `ros2 topic`)")
    tsub = p.add_subparsers(dest="topic_command", metavar="ACTION")
    tsub.required = True

    pl = tsub.add_parser("list", help="topics in the graph with their types")
    pl.add_argument("-t", "--show-types", action="store_true", help="also print each topic's type")
    pl.add_argument("--json", action="store_true")
    pl.add_argument("--wait", type=float, default=1.5, help="seconds of discovery before listing (default 1.5)")
    pl.set_defaults(func=run_list)

    pe = tsub.add_parser("echo", help="print messages of a topic (type resolved from the graph)")
    pe.add_argument("topic")
    pe.add_argument("type", nargs="?", help="message type pkg/msg/Name (default: from the graph)")
    pe.add_argument("--once", action="store_true", help="exit after the first message")
    pe.add_argument("-n", "--count", type=int, default=0, help="exit after N messages")
    pe.add_argument("--json", action="store_true", help="one JSON object per line")
    pe.add_argument("--timeout", type=float, default=0.0,
                    help="give up (exit 1) after this many seconds without the wanted messages; 0 = wait forever")
    pe.add_argument("--max-array", type=int, default=32, help="cut arrays longer than this (images); 0 = no cut")
    pe.set_defaults(func=run_echo)

    ph = tsub.add_parser("hz", help="measure the publishing rate of a topic")
    ph.add_argument("topic")
    ph.add_argument("type", nargs="?")
    ph.add_argument("--window", type=int, default=100, help="samples in the moving window")
    ph.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0 = until Ctrl-C)")
    ph.add_argument("--json", action="store_true", help="print one JSON summary at the end")
    ph.set_defaults(func=run_hz)


class _Cli:
    """An rclpy context + node for one CLI call; closes cleanly."""

    def __init__(self) -> None:
        from hexa_bringup.rosenv import apply_defaults

        apply_defaults()
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context)
        import os

        self.node = rclpy.create_node(f"hexa_cli_{os.getpid()}", context=self.context,
                                      start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def close(self) -> None:
        try:
            self.executor.shutdown()
            self.node.destroy_node()
        finally:
            if self.context.ok():
                self.rclpy.shutdown(context=self.context)

    def __enter__(self) -> "_Cli":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _resolve(cli: _Cli, topic: str, type_name: str | None, timeout: float) -> tuple[str, str]:
    """Fully qualified topic name and its type, waiting for discovery up to `timeout` (0 = forever)."""
    name = topic if topic.startswith("/") else "/" + topic
    if type_name:
        return name, type_name
    start = time.monotonic()
    while True:
        types = dict(cli.node.get_topic_names_and_types())
        if name in types and types[name]:
            if len(types[name]) > 1:
                print(f"hexa topic: {name} has several types {types[name]}; using {types[name][0]}", file=sys.stderr)
            return name, types[name][0]
        if timeout and time.monotonic() - start > timeout:
            raise SystemExit(f"hexa topic: no publisher of {name} found within {timeout:g} s "
                             f"(check ROS_DOMAIN_ID and that the node runs; `hexa topic list`)")
        cli.spin_for(0.1)


def _qos_for(cli: _Cli, topic: str):
    """A subscription QoS compatible with every current publisher (best effort if any publisher is)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    infos = cli.node.get_publishers_info_by_topic(topic)
    reliable = bool(infos) and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
    latched = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def run_list(args: argparse.Namespace) -> int:
    with _Cli() as cli:
        cli.spin_for(args.wait)
        topics = sorted(cli.node.get_topic_names_and_types())
    if args.json:
        print(json.dumps({name: types for name, types in topics}))
    else:
        for name, types in topics:
            print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def run_echo(args: argparse.Namespace) -> int:
    from hexa_bringup.msgutil import get_message_class, message_to_dict

    wanted = 1 if args.once else max(0, args.count)
    received = 0
    with _Cli() as cli:
        deadline = time.monotonic() + args.timeout if args.timeout else math.inf
        name, type_name = _resolve(cli, args.topic, args.type, args.timeout)
        cls = get_message_class(type_name)
        cli.spin_for(0.2)  # let publishers' QoS be discovered
        max_array = args.max_array or None

        def on_msg(msg) -> None:
            nonlocal received
            if wanted and received >= wanted:
                return
            received += 1
            data = message_to_dict(msg, max_array)
            if args.json:
                print(json.dumps(data), flush=True)
            else:
                print(_yaml_like(data) + "---", flush=True)

        cli.node.create_subscription(cls, name, on_msg, _qos_for(cli, name))
        while cli.context.ok() and (not wanted or received < wanted):
            if time.monotonic() > deadline:
                print(f"hexa topic echo: {received} of {wanted or 'any'} messages on {name} within "
                      f"{args.timeout:g} s", file=sys.stderr)
                return 1
            cli.executor.spin_once(timeout_sec=0.05)
    return 0


def _yaml_like(data: dict, indent: int = 0) -> str:
    lines = []
    pad = "  " * indent
    for key, value in data.items():
        if isinstance(value, dict):
            lines.append(f"{pad}{key}:")
            lines.append(_yaml_like(value, indent + 1).rstrip("\n"))
        else:
            lines.append(f"{pad}{key}: {json.dumps(value)}")
    return "\n".join(lines) + "\n"


def run_hz(args: argparse.Namespace) -> int:
    from hexa_bringup.msgutil import get_message_class

    stamps: deque[float] = deque(maxlen=max(2, args.window))
    total = 0
    with _Cli() as cli:
        name, type_name = _resolve(cli, args.topic, args.type, args.duration)
        cls = get_message_class(type_name)
        cli.spin_for(0.2)

        def on_msg(_msg) -> None:
            nonlocal total
            total += 1
            stamps.append(time.monotonic())

        cli.node.create_subscription(cls, name, on_msg, _qos_for(cli, name))
        start = time.monotonic()
        next_print = start + 1.0
        summary: dict = {}
        while cli.context.ok():
            cli.executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            if now >= next_print:
                next_print += 1.0
                summary = _rate_summary(name, stamps, total)
                if not args.json:
                    if summary["rate_hz"] is None:
                        print(f"{name}: no new messages", flush=True)
                    else:
                        print(f"{name}: average rate {summary['rate_hz']:.3f} Hz  min {summary['min_s']:.4f} s  "
                              f"max {summary['max_s']:.4f} s  std {summary['std_s']:.5f} s  window {summary['window']}",
                              flush=True)
            if args.duration and now - start >= args.duration:
                break
        summary = _rate_summary(name, stamps, total)
    if args.json:
        print(json.dumps(summary))
    return 0


def _rate_summary(name: str, stamps: deque, total: int) -> dict:
    if len(stamps) < 2:
        return {"topic": name, "rate_hz": None, "min_s": None, "max_s": None, "std_s": None, "window": len(stamps),
                "count": total}
    ts = list(stamps)
    gaps = [b - a for a, b in zip(ts, ts[1:])]
    mean = sum(gaps) / len(gaps)
    std = math.sqrt(sum((g - mean) ** 2 for g in gaps) / len(gaps))
    return {"topic": name, "rate_hz": 1.0 / mean if mean > 0 else None, "min_s": min(gaps), "max_s": max(gaps),
            "std_s": std, "window": len(stamps), "count": total}
