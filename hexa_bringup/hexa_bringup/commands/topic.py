"""`hexa topic list|echo|hz|pub|info`: what operators would use `ros2 topic` for (no ros2 CLI wheel exists)."""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import deque

from hexa_bringup.commands._ros import (CliError, RosCli, absolute, graph_completer, load_yaml_mapping,
                                        looks_like_type, qos_dict, reason)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("topic", help="list topics, print messages, measure rates (like `ros2 topic`)")
    tsub = p.add_subparsers(dest="topic_command", metavar="ACTION")
    tsub.required = True

    pl = tsub.add_parser("list", help="topics in the graph with their types")
    pl.add_argument("-t", "--show-types", action="store_true", help="also print each topic's type")
    pl.add_argument("--json", action="store_true")
    pl.add_argument("--wait", type=float, default=1.5,
                    help="seconds of discovery before listing (default 1.5; up to 5 s more while the graph shows "
                         "nothing yet)")
    pl.set_defaults(func=run_list)

    pe = tsub.add_parser("echo", help="print messages of a topic (type resolved from the graph)")
    pe.add_argument("topic").completer = graph_completer("topics")
    pe.add_argument("type", nargs="?", help="message type pkg/msg/Name (default: from the graph)")
    pe.add_argument("--once", action="store_true", help="exit after the first message")
    pe.add_argument("-n", "--count", type=int, default=0, help="exit after N messages")
    pe.add_argument("--json", action="store_true", help="one JSON object per line")
    pe.add_argument("--timeout", type=float, default=0.0,
                    help="give up (exit 1) after this many seconds without the wanted messages; 0 = wait forever")
    pe.add_argument("--max-array", type=int, default=32, help="cut arrays longer than this (images); 0 = no cut")
    pe.set_defaults(func=run_echo)

    ph = tsub.add_parser("hz", help="measure the publishing rate of a topic")
    ph.add_argument("topic").completer = graph_completer("topics")
    ph.add_argument("type", nargs="?")
    ph.add_argument("--window", type=int, default=100, help="samples in the moving window")
    ph.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0 = until Ctrl-C)")
    ph.add_argument("--json", action="store_true", help="print one JSON summary at the end")
    ph.set_defaults(func=run_hz)

    pp = tsub.add_parser("pub", help="publish a message (type from the graph when omitted), e.g. "
                                     "hexa topic pub /chatter std_msgs/msg/String '{data: hi}' --once")
    pp.add_argument("topic").completer = graph_completer("topics")
    pp.add_argument("type", nargs="?", help="message type pkg/msg/Name (default: from the graph's publishers or "
                                            "subscribers of the topic)")
    pp.add_argument("values", nargs="?", default="{}", help="message fields as YAML (default {})")
    pp.add_argument("-r", "--rate", type=float, default=1.0, help="messages per second (default 1)")
    pp.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    pp.add_argument("-t", "--times", type=int, default=0, help="publish this many messages and exit (0 = until "
                                                               "Ctrl-C)")
    pp.add_argument("-w", "--wait-matching-subscriptions", type=int, default=None, metavar="N",
                    help="wait until N subscriptions match before publishing (default 1 with --once/--times, else 0)")
    pp.add_argument("--timeout", type=float, default=10.0, help="give up waiting for the type or the subscriptions "
                                                                "after this many seconds")
    pp.add_argument("--qos-reliability", choices=["reliable", "best_effort"], default="reliable")
    pp.add_argument("--qos-durability", choices=["volatile", "transient_local"], default="volatile")
    pp.add_argument("--qos-depth", type=int, default=10)
    pp.set_defaults(func=run_pub)

    pi = tsub.add_parser("info", help="type and endpoints of a topic; -v: each endpoint's node and QoS")
    pi.add_argument("topic").completer = graph_completer("topics")
    pi.add_argument("-v", "--verbose", action="store_true", help="every publisher and subscription with its QoS")
    pi.add_argument("--json", action="store_true")
    pi.add_argument("--wait", type=float, default=1.0, help="seconds of discovery before answering (default 1)")
    pi.add_argument("--timeout", type=float, default=5.0,
                    help="seconds to wait for the topic to be discovered (default 5)")
    pi.set_defaults(func=run_info)


def _resolve(cli: RosCli, topic: str, type_name: str | None, timeout: float) -> tuple[str, str]:
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
            raise CliError(f"no publisher of {name} found within {timeout:g} s "
                           f"(check ROS_DOMAIN_ID and that the node runs; `hexa topic list`)")
        cli.spin_for(0.1)


def _qos_for(cli: RosCli, topic: str):
    """A subscription QoS compatible with every current publisher (best effort if any publisher is)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    infos = cli.node.get_publishers_info_by_topic(topic)
    reliable = bool(infos) and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
    latched = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def run_list(args: argparse.Namespace) -> int:
    with RosCli() as cli:
        cli.discover(args.wait, cli.foreign_topics)
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
    with RosCli() as cli:
        deadline = time.monotonic() + args.timeout if args.timeout else math.inf
        name, type_name = _resolve(cli, args.topic, args.type, args.timeout)
        cls = get_message_class(type_name)
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

        # the subscription's QoS follows the publishers (_qos_for), so it is made once the first one is there: a
        # best-effort subscription made before a reliable publisher appears would take a message sent once, unresent
        sub = None
        while cli.context.ok() and (not wanted or received < wanted):
            if sub is None and cli.node.get_publishers_info_by_topic(name):
                cli.spin_for(0.2)  # let the other publishers' QoS be discovered
                sub = cli.node.create_subscription(cls, name, on_msg, _qos_for(cli, name))
            if time.monotonic() > deadline:
                print(f"hexa topic echo: {received} of {wanted or 'any'} messages on {name} within "
                      f"{args.timeout:g} s{' (no publisher appeared)' if sub is None else ''}", file=sys.stderr)
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
    with RosCli() as cli:
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


def _graph_type(cli: RosCli, name: str, timeout: float) -> str:
    """The type of `name` from the graph (publishers or subscriptions), waiting up to `timeout` s.

    Raises:
        CliError: nobody in the graph uses the topic.
    """
    def probe() -> str | None:
        types = dict(cli.node.get_topic_names_and_types()).get(name)
        return types[0] if types else None

    return cli.wait_for(probe, timeout, f"{name} is not in the graph within {timeout:g} s: give its type "
                                        f"(hexa topic pub {name} pkg/msg/Name '{{...}}')")


def run_pub(args: argparse.Namespace) -> int:
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from hexa_bringup.msgutil import get_message_class, set_message_fields

    name = absolute(args.topic)
    type_name, values = args.type, args.values
    if type_name is not None and not looks_like_type(type_name):
        if args.values != "{}":
            raise CliError(f"{type_name!r} is not a message type (pkg/msg/Name)")
        type_name, values = None, type_name          # `pub TOPIC '{yaml}'`: the type comes from the graph
    fields = load_yaml_mapping(values, "the message")
    if not args.rate > 0:
        raise CliError(f"--rate must be > 0, got {args.rate:g}")
    count = 1 if args.once else max(0, args.times)
    wait_subs = args.wait_matching_subscriptions
    if wait_subs is None:
        wait_subs = 1 if count else 0
    with RosCli("hexa_pub") as cli:
        if type_name is None:
            type_name = _graph_type(cli, name, args.timeout)
        cls = get_message_class(type_name)
        try:
            msg = set_message_fields(cls(), fields)
        except (KeyError, TypeError, AssertionError, ValueError, AttributeError) as exc:
            raise CliError(f"bad message for {type_name}: {reason(exc)}") from exc
        qos = QoSProfile(depth=max(1, args.qos_depth),
                         reliability=ReliabilityPolicy.RELIABLE if args.qos_reliability == "reliable"
                         else ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if args.qos_durability == "transient_local"
                         else DurabilityPolicy.VOLATILE)
        pub = cli.node.create_publisher(cls, name, qos)
        if wait_subs:
            cli.wait_for(lambda: pub.get_subscription_count() >= wait_subs, args.timeout,
                         f"{pub.get_subscription_count()} of {wait_subs} subscriptions of {name} matched within "
                         f"{args.timeout:g} s")
            cli.spin_for(0.5)       # matched here first: the subscriber's side matches this publisher a moment later
        sent = 0
        period = 1.0 / args.rate
        next_t = time.monotonic()
        while cli.context.ok():
            pub.publish(msg)
            sent += 1
            print(f"publishing #{sent}: {json.dumps(message_dict(msg))}", flush=True)
            if count and sent >= count:
                break
            next_t += period
            cli.spin_for(max(0.0, next_t - time.monotonic()))
        cli.spin_for(0.3)                              # a best-effort message leaves before the node does
        # a reliable one is acknowledged first: the publisher matched the subscriber before publishing, but that side
        # may match this publisher only after the sample went out once (a loaded host), and gets it on a resend
        deadline = time.monotonic() + min(5.0, args.timeout)
        step = Duration(nanoseconds=100_000_000)
        while not pub.wait_for_all_acked(step) and cli.context.ok():
            if time.monotonic() >= deadline:
                print(f"hexa topic pub: not every subscription of {name} acknowledged the last message within "
                      f"{min(5.0, args.timeout):g} s", file=sys.stderr)
                break
    return 0


def message_dict(msg) -> dict:
    from hexa_bringup.msgutil import message_to_dict

    return message_to_dict(msg, 32)


def run_info(args: argparse.Namespace) -> int:
    name = absolute(args.topic)
    with RosCli("hexa_info") as cli:
        cli.spin_for(args.wait)
        types = cli.wait_for(lambda: dict(cli.node.get_topic_names_and_types()).get(name),
                             max(0.0, args.timeout - args.wait) or 1e-3,
                             f"no topic {name} in the graph within {args.timeout:g} s (check ROS_DOMAIN_ID; "
                             f"`hexa topic list`)")

        def endpoints() -> tuple[list, list] | None:
            """Both lists once every endpoint's node is known (a node's name arrives after its endpoints)."""
            pubs = [_endpoint(i) for i in cli.node.get_publishers_info_by_topic(name)]
            subs = [_endpoint(i) for i in cli.node.get_subscriptions_info_by_topic(name) if i.node_name != cli.name]
            return None if any(e["node"] == UNKNOWN_NODE for e in pubs + subs) else (pubs, subs)

        try:
            pubs, subs = cli.wait_for(endpoints, 2.0, "")
        except CliError:                               # still unnamed: show them as they are
            pubs = [_endpoint(i) for i in cli.node.get_publishers_info_by_topic(name)]
            subs = [_endpoint(i) for i in cli.node.get_subscriptions_info_by_topic(name) if i.node_name != cli.name]
    if args.json:
        info = {"topic": name, "types": list(types), "publishers": len(pubs), "subscriptions": len(subs)}
        if args.verbose:
            info.update(publisher_endpoints=pubs, subscription_endpoints=subs)
        print(json.dumps(info))
        return 0
    print(f"Type: {', '.join(types)}")
    for title, eps in (("Publisher count", pubs), ("Subscription count", subs)):
        print(f"\n{title}: {len(eps)}" if args.verbose else f"{title}: {len(eps)}")
        if not args.verbose:
            continue
        for e in eps:
            q = e["qos"]
            print(f"\nNode name: {e['node']}\nNode namespace: {e['namespace']}\nTopic type: {e['type']}\n"
                  f"Endpoint type: {e['endpoint']}\nGID: {e['gid']}\nQoS profile:\n"
                  f"  Reliability: {q['reliability'].upper()}\n  History (Depth): {q['history'].upper()} "
                  f"({q['depth']})\n  Durability: {q['durability'].upper()}\n"
                  f"  Lifespan: {_dur(q['lifespan_s'])}\n  Deadline: {_dur(q['deadline_s'])}\n"
                  f"  Liveliness: {q['liveliness'].upper()}\n"
                  f"  Liveliness lease duration: {_dur(q['liveliness_lease_s'])}")
    return 0


#: the node name of an endpoint whose node has not been discovered yet
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


def _dur(seconds: float | None) -> str:
    return "Infinite" if seconds is None else f"{seconds:g} s"


def _endpoint(info) -> dict:
    return {"node": info.node_name, "namespace": info.node_namespace, "type": info.topic_type,
            "endpoint": info.endpoint_type.name, "gid": ".".join(f"{b:02x}" for b in info.endpoint_gid),
            "qos": qos_dict(info.qos_profile)}
