"""`hexa record`, `hexa play`, `hexa bag info` and `hexa bag recover`: MCAP rosbag2 recording of live topics (raw
CDR), playback, what a bag holds, and the rebuilding of a bag whose recorder was killed."""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time

from hexa_bringup.commands._ros import absolute

SKIP_BY_DEFAULT = {"/rosout", "/parameter_events"}


def register(sub: argparse._SubParsersAction) -> None:
    pr = sub.add_parser("record", help="record live topics to an MCAP rosbag2 (closed cleanly on Ctrl-C; killed, "
                                       "it loses at most the last 0.5 s: `hexa bag recover`)")
    pr.add_argument("topics", nargs="*", help="topics to record (default: every topic, discovered continuously)")
    pr.add_argument("--sensor-inputs", action="store_true",
                    help="also record the graph's sensor inputs (both cameras' colour, aligned depth and camera_info, "
                         "motor_currents, joint_states in --ns): a bag `hexa bringup replay` plays")
    pr.add_argument("--ns", default="/hexa", help="namespace of --sensor-inputs (default /hexa)")
    pr.add_argument("-o", "--output", required=True, help="bag directory to create (must not exist)")
    pr.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0 = until Ctrl-C)")
    pr.add_argument("--use-sim-time", action="store_true", help="stamp messages with /clock time")
    pr.add_argument("--json", action="store_true", help="print a JSON summary at the end")
    pr.set_defaults(func=run_record)

    pp = sub.add_parser("play", help="publish the messages of a bag")
    pp.add_argument("bag")
    pp.add_argument("--rate", type=float, default=1.0, help="playback speed factor (0 = as fast as possible)")
    pp.add_argument("--clock", action="store_true", help="publish /clock from the bag's time (for sim-time nodes)")
    pp.add_argument("--clock-rate", type=float, default=40.0, metavar="HZ",
                    help="with --clock: /clock messages per second of bag time (default 40, as `ros2 bag play "
                         "--clock`; every sim-time node wakes for each one, ≈ 0.45 ms of CPU per message on the "
                         "2-core robot PC, so 100 Hz costs a five-node graph about a fifth of a core; 0 = one per "
                         "message)")
    pp.add_argument("--topics", nargs="*", help="only these topics")
    pp.add_argument("--exclude", nargs="+", default=[], metavar="TOPIC", help="not these topics")
    pp.add_argument("--wait", type=float, default=1.0, help="seconds to let subscribers connect before playing")
    pp.add_argument("--json", action="store_true", help="print a JSON summary at the end")
    pp.add_argument("--wait-subscribers", action="store_true",
                    help="end the --wait early once every topic (and /clock) has a matched subscriber and the "
                         "number of matches held still for 0.5 s; when --wait runs out first, name the topics "
                         "without a subscriber and play anyway")
    pp.add_argument("--subscribers", nargs="+", default=[], metavar="TOPIC=N",
                    help="with --wait-subscribers: wait also until TOPIC has at least N matched subscribers (a "
                         "topic read by several nodes: one matched reader alone does not end the wait)")
    pp.add_argument("--log", metavar="FILE",
                    help="write one line per published message: monotonic ns just before publishing, the message's "
                         "bag timestamp (ns) and its topic")
    pp.set_defaults(func=run_play)

    pb = sub.add_parser("bag", help="bag maintenance")
    bag_sub = pb.add_subparsers(dest="bag_command", required=True)
    bi = bag_sub.add_parser("info", help="what a bag holds: duration, start and end, and per topic its type, "
                                         "message count and QoS (like `ros2 bag info`)")
    bi.add_argument("bag", help="the bag directory")
    bi.add_argument("--json", action="store_true")
    bi.set_defaults(func=run_info)
    rv = bag_sub.add_parser("recover", help="rebuild a readable bag (MCAP + metadata.yaml) from what a killed "
                                            "`hexa record` left, and say what was lost")
    rv.add_argument("bag", help="the damaged bag directory (or its .mcap file)")
    rv.add_argument("-o", "--output", help="write the recovered bag here (default: in place, the damaged one kept "
                                           "as BAG.damaged)")
    rv.add_argument("--json", action="store_true", help="print a JSON summary")
    rv.set_defaults(func=run_recover)


def _init(name: str, sim_time: bool = False):
    from hexa_bringup.rosenv import apply_defaults

    apply_defaults()
    import os

    import rclpy
    from rclpy.parameter import Parameter

    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node(f"{name}_{os.getpid()}", start_parameter_services=False,
                             parameter_overrides=[Parameter("use_sim_time", value=sim_time)])
    return rclpy, node


def run_record(args: argparse.Namespace) -> int:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from hexa_bringup.bag import BagError, BagRecorder
    from hexa_bringup.msgutil import get_message_class

    stop = False

    def on_signal(_sig, _frm) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    rclpy, node = _init("hexa_record", args.use_sim_time)
    wanted = {absolute(t) for t in args.topics}
    if args.sensor_inputs:
        from hexa_bringup.graphs import SENSOR_INPUTS

        wanted |= {f"{args.ns.rstrip('/')}/{t}" for t in SENSOR_INPUTS}
    try:
        recorder = BagRecorder(args.output)
    except BagError as exc:
        print(f"hexa record: {exc}", file=sys.stderr)
        return 2
    subs = {}
    from hexa_ros.node import executor_kind, make_executor

    executor = make_executor(executor_kind())   # the nodes' EventsExecutor: a fraction of the per-message cost
    executor.add_node(node)
    with recorder:
        start = time.monotonic()
        next_scan = 0.0
        try:
            while not stop and rclpy.ok():
                now = time.monotonic()
                if now >= next_scan:
                    next_scan = now + 0.5
                    for topic, types in node.get_topic_names_and_types():
                        skipped = (wanted and topic not in wanted) or (not wanted and topic in SKIP_BY_DEFAULT)
                        if topic in subs or skipped:
                            continue
                        infos = node.get_publishers_info_by_topic(topic)
                        if not infos:
                            continue
                        reliable = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
                        latched = all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
                        try:
                            cls = get_message_class(types[0])
                            recorder.add_topic(topic, types[0], reliable, latched)
                        except Exception as exc:  # noqa: BLE001 - keep recording the rest, say why
                            print(f"hexa record: skipping {topic}: {exc}", file=sys.stderr)
                            subs[topic] = None
                            continue
                        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE if reliable
                                         else ReliabilityPolicy.BEST_EFFORT,
                                         durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                                         else DurabilityPolicy.VOLATILE)

                        def on_raw(data: bytes, t=topic) -> None:
                            recorder.write(t, node.get_clock().now().nanoseconds, data)

                        subs[topic] = node.create_subscription(cls, topic, on_raw, qos, raw=True)
                        print(f"hexa record: recording {topic} [{types[0]}]", file=sys.stderr, flush=True)
                executor.spin_once(timeout_sec=0.05)
                recorder.tick()
                if args.duration and now - start >= args.duration:
                    break
        finally:
            counts = dict(recorder.counts)
            executor.shutdown()
    node.destroy_node()
    if rclpy.ok():
        rclpy.shutdown()
    if args.json:
        print(json.dumps({"bag": args.output, "counts": counts}))
    else:
        print(f"hexa record: wrote {sum(counts.values())} messages on {len(counts)} topics to {args.output}")
    return 0


def run_play(args: argparse.Namespace) -> int:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    from hexa_bringup.bag import BagError, bag_topics, paced, read_bag
    from hexa_bringup.msgutil import get_message_class
    from hexa_ros.cdr import motor_currents_with_setpoint_field

    try:
        least = _subscriber_counts(args.subscribers)
    except ValueError as exc:
        print(f"hexa play: {exc}", file=sys.stderr)
        return 2
    try:
        topics = bag_topics(args.bag)
    except Exception as exc:  # noqa: BLE001
        print(f"hexa play: cannot open bag {args.bag}: {exc}", file=sys.stderr)
        return 2
    try:
        log = open(args.log, "w", encoding="utf-8") if args.log else None  # noqa: SIM115 - closed below
    except OSError as exc:
        print(f"hexa play: cannot write the log {args.log}: {exc}", file=sys.stderr)
        return 2
    stop = False

    def on_signal(_sig, _frm) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    rclpy, node = _init("hexa_play")
    excluded = {absolute(t) for t in args.exclude}
    wanted = {absolute(t) for t in args.topics or []}
    selected = [t for t in topics if (not wanted or t in wanted) and t not in excluded]
    absent = sorted(wanted - set(topics))
    if absent:
        print(f"hexa play: the bag has no topic {', '.join(absent)}; playing the others", file=sys.stderr)
    pubs = {}
    for topic in selected:
        msgtype, _count, reliable = topics[topic]
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE if reliable else
                         ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
        pubs[topic] = node.create_publisher(get_message_class(msgtype), topic, qos)
    clock_pub = node.create_publisher(Clock, "/clock", 10) if args.clock else None
    end = time.monotonic() + args.wait
    watched = list(pubs.items()) + ([("/clock", clock_pub)] if clock_pub is not None else [])
    wanted_n = {**dict.fromkeys((t for t, _p in watched), 1), **least}
    unplayed = sorted(set(least) - {t for t, _p in watched})
    if unplayed:
        print(f"hexa play: --subscribers names {', '.join(unplayed)}, which is not played; ignored", file=sys.stderr)
    matches, steady_since = -1, time.monotonic()
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
        if args.wait_subscribers:
            counts = [p.get_subscription_count() for _t, p in watched]
            if sum(counts) != matches:
                matches, steady_since = sum(counts), time.monotonic()
            elif all(c >= wanted_n[t] for (t, _p), c in zip(watched, counts)) and \
                    time.monotonic() - steady_since >= 0.5:
                break
    if args.wait_subscribers:
        lonely = [f"{t} ({p.get_subscription_count()} of {wanted_n[t]})" for t, p in watched
                  if p.get_subscription_count() < wanted_n[t]]
        if lonely:
            print(f"hexa play: too few subscribers after {args.wait:g} s on {', '.join(lonely)}; playing anyway",
                  file=sys.stderr)
    sent = 0
    counts = dict.fromkeys(selected, 0)
    currents = {t for t in selected if topics[t][0] == "hexa_msgs/msg/MotorCurrents"}   # older bags: set-point field
    clock_step = int(1e9 / args.clock_rate) if args.clock_rate > 0 else 0
    next_clock = -1
    try:
        for topic, _msgtype, stamp, data in paced(read_bag(args.bag, selected), args.rate):
            if stop:
                break
            if clock_pub is not None and stamp >= next_clock:
                msg = Clock()
                msg.clock.sec, msg.clock.nanosec = divmod(stamp, 1_000_000_000)
                clock_pub.publish(msg)
                next_clock = stamp + clock_step
            if log is not None:
                log.write(f"{time.monotonic_ns()} {stamp} {topic}\n")
            pubs[topic].publish(motor_currents_with_setpoint_field(data) if topic in currents else data)
            sent += 1
            counts[topic] += 1
    except BagError as exc:
        print(f"hexa play: {exc}", file=sys.stderr)
        return 2
    finally:
        if log is not None:
            log.close()
        time.sleep(0.3)  # let the last reliable messages go out
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    if args.json:
        print(json.dumps({"bag": args.bag, "published": sent, "counts": counts}))
    else:
        print(f"hexa play: published {sent} messages from {args.bag}")
    return 0


def _subscriber_counts(items: list[str]) -> dict[str, int]:
    """`--subscribers` TOPIC=N items as {"/topic": N}.

    Raises:
        ValueError: an item that is not TOPIC=N with N >= 1.
    """
    out = {}
    for item in items:
        topic, sep, n = item.rpartition("=")
        if not sep or not topic or not n.isdigit() or int(n) < 1:
            raise ValueError(f"--subscribers takes TOPIC=N with N >= 1, got {item!r}")
        out[absolute(topic)] = int(n)
    return out


def bag_summary(path: str) -> dict:
    """Files, size, storage, time span and per-topic type, count and offered QoS of the bag at `path`.

    Raises:
        hexa_bringup.commands._ros.CliError: missing or unreadable (a killed recording: `hexa bag recover`).
    """
    from pathlib import Path

    import yaml
    from rosbags.rosbag2 import Reader

    from hexa_bringup.commands._ros import CliError

    bag = Path(path)
    if not bag.exists():
        raise CliError(f"bag {path} does not exist")
    try:
        reader = Reader(bag)
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types; all mean "not a readable bag"
        hint = " (a killed recording? `hexa bag recover`)" if bag.is_dir() and list(bag.glob("*.mcap")) else ""
        raise CliError(f"cannot read bag {path}: {' '.join(str(exc).split())}{hint}") from exc
    try:
        files = sorted(p for p in (bag.iterdir() if bag.is_dir() else [bag]) if p.is_file())
        meta = {}
        if bag.is_dir() and (bag / "metadata.yaml").is_file():
            meta = (yaml.safe_load((bag / "metadata.yaml").read_text()) or {}).get("rosbag2_bagfile_information", {})
        topics = {}
        for c in reader.connections:
            qos = [{"reliability": q.reliability.name.lower(), "durability": q.durability.name.lower(),
                    "history": q.history.name.lower(), "depth": int(q.depth)}
                   for q in getattr(c.ext, "offered_qos_profiles", []) or []]
            t = topics.setdefault(c.topic, {"type": c.msgtype, "count": 0, "serialization": c.ext.serialization_format,
                                            "qos": qos})
            t["count"] += c.msgcount
        start, end = (reader.start_time, reader.end_time) if reader.message_count else (0, 0)
        return {"bag": str(bag), "files": [str(f) for f in files], "size_bytes": sum(f.stat().st_size for f in files),
                "storage": meta.get("storage_identifier", files[0].suffix.lstrip(".") if files else "?"),
                "duration_s": (end - start) * 1e-9, "start_ns": start, "end_ns": end,
                "messages": reader.message_count, "topics": topics}
    finally:
        reader.close()


def run_info(args: argparse.Namespace) -> int:
    import datetime

    info = bag_summary(args.bag)
    if args.json:
        print(json.dumps(info))
        return 0

    def when(ns: int) -> str:
        return f"{datetime.datetime.fromtimestamp(ns * 1e-9, datetime.timezone.utc):%Y-%m-%d %H:%M:%S.%f} UTC " \
               f"({ns * 1e-9:.9f})"

    print(f"Files:             {', '.join(info['files'])}")
    print(f"Bag size:          {info['size_bytes'] / 1e6:.3f} MB")
    print(f"Storage id:        {info['storage']}")
    print(f"Duration:          {info['duration_s']:.3f} s")
    print(f"Start:             {when(info['start_ns'])}")
    print(f"End:               {when(info['end_ns'])}")
    print(f"Messages:          {info['messages']}")
    print(f"Topic information: {len(info['topics'])} topics")
    width = max((len(t) for t in info["topics"]), default=0)
    for topic, t in sorted(info["topics"].items()):
        qos = ", ".join(f"{q['reliability']}/{q['durability']}" for q in t["qos"]) or "-"
        print(f"  {topic:<{width}}  {t['type']}  count {t['count']}  {t['serialization']}  QoS {qos}")
    return 0


def run_recover(args: argparse.Namespace) -> int:
    from hexa_bringup.bag import BagError, recover_bag

    try:
        r = recover_bag(args.bag, args.output)
    except BagError as exc:
        print(f"hexa bag recover: {exc}", file=sys.stderr)
        return 2
    total = sum(r.counts.values())
    span = (r.end_ns - r.start_ns) / 1e9 if total else 0.0
    if args.json:
        print(json.dumps({"bag": str(r.output), "damaged": str(r.damaged) if r.damaged else None,
                          "counts": r.counts, "start_ns": r.start_ns, "end_ns": r.end_ns, "chunks": r.chunks,
                          "partial_chunk_messages": r.partial_messages, "discarded_bytes": r.discarded_bytes}))
        return 0
    print(f"hexa bag recover: {total} messages on {len(r.counts)} topics, {span:.3f} s "
          f"(stamps {r.start_ns} .. {r.end_ns} ns) from {r.chunks} whole chunks and {r.partial_messages} messages "
          f"of a cut chunk -> {r.output}")
    for topic, n in sorted(r.counts.items()):
        print(f"  {topic}: {n}")
    kept = f"; the damaged bag is kept as {r.damaged}" if r.damaged else ""
    print(f"lost: what was recorded after {r.end_ns} ns ({r.discarded_bytes} bytes of an incomplete record at "
          f"the end of the file){kept}")
    return 0
