"""`hexa view`: the running graph live in Foxglove (foxglove-sdk WebSocket server; layout shipped with it)."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="serve the running graph to Foxglove over WebSocket (ws://HOST:PORT)",
                       description="Subscribes to the graph's images (sent as JPEG), /tf, markers, residual and "
                                   "thresholds, collision, contact, wrenches, singularity and /diagnostics, and "
                                   "serves them with foxglove-sdk. In Foxglove: Open connection → Foxglove "
                                   "WebSocket → ws://HOST:PORT, then import the layout that --layout prints.")
    p.add_argument("--ns", default="/hexa", help="namespace of the graph (default /hexa)")
    p.add_argument("--port", type=int, default=8765, help="WebSocket port (default 8765; 0 = any free port)")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (0.0.0.0 for the network)")
    p.add_argument("--image-rate", type=float, default=10.0, metavar="HZ", help="JPEG frames per camera per second")
    p.add_argument("--layout", action="store_true", help="print the path of the Foxglove layout JSON and exit")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hexa_bringup import view_node

    if args.layout:
        print(view_node.LAYOUT)
        return 0
    if not 0 <= args.port <= 65535:
        print(f"hexa view: --port must be 0..65535, got {args.port}")
        return 2
    return view_node.main(["hexa-view", "--ros-args", "-r", f"__ns:={args.ns}", "-p", f"port:={args.port}",
                           "-p", f"host:={args.host}", "-p", f"image_rate_hz:={float(args.image_rate)}"])
