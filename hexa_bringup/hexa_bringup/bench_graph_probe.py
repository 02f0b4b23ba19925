"""Helper processes of `hexa bench graph`: the measuring subscriber and the emulated boards.

`python -m hexa_bringup.bench_graph_probe probe SPEC.json OUT.pickle` subscribes (raw CDR, no deserialization) to
the topics SPEC names and notes the monotonic time each message arrives; it prints `READY` on stdout once every
node SPEC expects is in the ROS graph, every topic of `ready_publishers` has a publisher and every topic of
`ready_messages` has delivered a message, then `RX <n>` every 0.5 s (messages received on the `count` topics).
On SIGINT/SIGTERM it writes {topic: [(monotonic ns, bytes)], ...} to OUT and exits. With `hold_command` it
publishes that joint_commands vector at 20 Hz (robot mode without a trajectory node).

`python -m hexa_bringup.bench_graph_probe boards UNO_LINK MEGA_LINK --amps I1..I6` runs hexa.protocol.emulator's
Uno and Mega emulators on pseudo-terminals (symlinked to the two paths), the Mega streaming `--amps` at whatever rate
the driver asks for; it prints `READY {"mega_clock_zero": s}` (the monotonic time at which the Mega's board clock
read 0) and, when stopped, `STATS {...}`.

Both run in their own process so that neither shares an interpreter lock with the nodes they measure or feed.
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import signal
import sys
import time
from typing import Any


class _Stop:
    def __init__(self) -> None:
        self.requested = False

    def __call__(self, _sig: int, _frame: Any) -> None:
        self.requested = True


def _say(line: str) -> None:
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def run_probe(spec_path: str, out_path: str) -> int:
    """The measuring subscriber (see the module docstring); SPEC: {ns, topics: [{topic, type, qos: reliable |
    sensor, keep: bytes kept per message (0 = all), count: bool}], nodes, ready_publishers, ready_messages,
    hold_command: [6 floats] or null}."""
    stop = _Stop()
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    with open(spec_path, encoding="utf-8") as f:
        spec = json.load(f)
    from hexa_bringup.rosenv import apply_defaults

    apply_defaults()
    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from rclpy.signals import SignalHandlerOptions

    from hexa_bringup.msgutil import get_message_class

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(f"hexa_bench_probe_{os.getpid()}", start_parameter_services=False)
    reliable = QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
    received: dict[str, list[tuple[int, bytes]]] = {}
    counted = {"n": 0}
    subs = []
    for t in spec["topics"]:
        topic, keep, count = t["topic"], int(t.get("keep", 0)), bool(t.get("count", False))
        store = received.setdefault(topic, [])
        qos = qos_profile_sensor_data if t.get("qos") == "sensor" else reliable

        def on_raw(data: bytes, store: list = store, keep: int = keep, count: bool = count) -> None:
            store.append((time.monotonic_ns(), data[:keep] if keep else data))
            if count:
                counted["n"] += 1

        subs.append(node.create_subscription(get_message_class(t["type"]), topic, on_raw, qos, raw=True))
    hold = spec.get("hold_command")
    if hold:
        from sensor_msgs.msg import JointState

        pub = node.create_publisher(JointState, f"{spec['ns']}/joint_commands", 10)

        def on_hold() -> None:
            m = JointState()
            m.header.stamp = node.get_clock().now().to_msg()
            m.name = [f"arm_{i}" for i in range(1, 7)]
            m.position = [float(v) for v in hold]
            pub.publish(m)

        node.create_timer(0.05, on_hold)
    try:
        from rclpy.experimental import EventsExecutor

        executor = EventsExecutor()
    except ImportError:  # older rclpy: the default executor
        from rclpy.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor()
    executor.add_node(node)
    want_nodes = {(spec["ns"].rstrip("/") or "/", n) for n in spec.get("nodes", [])}
    ready = False
    last_counts: dict[str, int] | None = None
    next_check = 0.0
    try:
        while not stop.requested:
            executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            if now < next_check:
                continue
            if ready:
                _say(f"RX {counted['n']}")
                next_check = now + 0.5
                continue
            next_check = now + 0.2
            have = {(ns, name) for name, ns in node.get_node_names_and_namespaces()}
            missing = [f"node {n}" for _, n in sorted(want_nodes - have)]
            missing += [f"publisher of {t}" for t in spec.get("ready_publishers", []) if node.count_publishers(t) == 0]
            missing += [f"a message on {t}" for t in spec.get("ready_messages", []) if not received.get(t)]
            counts = {t: node.count_subscribers(t) for t in spec.get("subscribers_of", [])}
            if not missing and counts != last_counts:      # the readers of the inputs: unchanged for 1 s
                missing, last_counts = ["steady subscriber counts"], counts
            if not missing:
                ready = True
                if counts:
                    _say("SUBSCRIBERS " + json.dumps(counts))
                _say("READY")
            else:
                _say("WAITING " + json.dumps(missing))
                next_check = now + 1.0
    finally:
        with open(out_path + ".tmp", "wb") as f:
            pickle.dump(received, f, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(out_path + ".tmp", out_path)
        try:
            executor.shutdown()
        except Exception:  # noqa: BLE001 - shutting down anyway
            pass
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def run_boards(uno_link: str, mega_link: str, amps: list[float]) -> int:
    """The two emulated boards (see the module docstring) until SIGINT/SIGTERM."""
    stop = _Stop()
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    from hexa.protocol.emulator import MegaEmulator, UnoEmulator

    currents = [float(a) for a in amps]
    uno = UnoEmulator(link=uno_link)
    mega = MegaEmulator(current_source=lambda _t: currents, link=mega_link)
    with uno, mega:
        _say("READY " + json.dumps({"mega_clock_zero": mega.clock_zero}))
        while not stop.requested:
            time.sleep(0.1)
        stats = {"mega_tx_frames": mega.tx_frames, "mega_overruns": mega.overruns,
                 "mega_tx_dropped_bytes": mega.tx_dropped_bytes, "mega_samples": mega.sample_seq,
                 "uno_rx_frames": uno.rx_frames, "rx_crc_errors": mega.rx_crc_errors + uno.rx_crc_errors}
    _say("STATS " + json.dumps(stats))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hexa_bringup.bench_graph_probe")
    sub = ap.add_subparsers(dest="what", required=True)
    p = sub.add_parser("probe")
    p.add_argument("spec")
    p.add_argument("out")
    b = sub.add_parser("boards")
    b.add_argument("uno")
    b.add_argument("mega")
    b.add_argument("--amps", type=float, nargs=6, default=[0.0] * 6)
    args = ap.parse_args(argv)
    if args.what == "probe":
        return run_probe(args.spec, args.out)
    return run_boards(args.uno, args.mega, args.amps)


if __name__ == "__main__":
    sys.exit(main())
