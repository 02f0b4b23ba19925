"""`hexa node list|info`: the graph's nodes and what each publishes, subscribes, serves and calls (like
`ros2 node`)."""
from __future__ import annotations

import argparse
import json

from hexa_bringup.commands._ros import RosCli, graph_completer


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("node", help="list the graph's nodes, show one's endpoints (like `ros2 node`)")
    nsub = p.add_subparsers(dest="node_command", metavar="ACTION")
    nsub.required = True
    pl = nsub.add_parser("list", help="fully qualified names of the nodes in the graph")
    pl.add_argument("--json", action="store_true")
    pl.add_argument("--wait", type=float, default=1.5,
                    help="seconds of discovery before listing (default 1.5; up to 5 s more while the graph shows "
                         "nothing yet)")
    pl.set_defaults(func=run_list)
    pi = nsub.add_parser("info", help="a node's publishers, subscribers, service servers and clients")
    pi.add_argument("node", help="fully qualified node name, e.g. /hexa/observer"
                    ).completer = graph_completer("nodes")
    pi.add_argument("--json", action="store_true")
    pi.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for the node to be discovered")
    pi.set_defaults(func=run_info)


def run_list(args: argparse.Namespace) -> int:
    with RosCli("hexa_node") as cli:
        cli.discover(args.wait, cli.nodes)
        nodes = cli.nodes()
    print(json.dumps(nodes) if args.json else "\n".join(nodes))
    return 0


def run_info(args: argparse.Namespace) -> int:
    with RosCli("hexa_node") as cli:
        ns, name = cli.wait_node(args.node, args.timeout)
        cli.spin_for(0.5)                     # the node's endpoints are discovered after the node itself
        g = cli.node
        info = {"node": f"{ns.rstrip('/')}/{name}",
                "subscribers": dict(g.get_subscriber_names_and_types_by_node(name, ns)),
                "publishers": dict(g.get_publisher_names_and_types_by_node(name, ns)),
                "service_servers": dict(g.get_service_names_and_types_by_node(name, ns)),
                "service_clients": dict(g.get_client_names_and_types_by_node(name, ns))}
    if args.json:
        print(json.dumps(info))
        return 0
    print(info["node"])
    for key, title in (("subscribers", "Subscribers"), ("publishers", "Publishers"),
                       ("service_servers", "Service Servers"), ("service_clients", "Service Clients")):
        print(f"  {title}:")
        for topic, types in sorted(info[key].items()):
            print(f"    {topic}: {', '.join(types)}")
    return 0
