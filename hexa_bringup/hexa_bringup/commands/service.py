"""`hexa service list|call` and `hexa param list|get|set`: what operators would use `ros2 service` / `ros2 param`
for (resume after a collision, reset the observer, calibrate currents, change thresholds at runtime)."""
from __future__ import annotations

import argparse
import json
import sys
import time

import yaml


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("service", help="list services, call one (like `ros2 service`)")
    ssub = p.add_subparsers(dest="service_command", metavar="ACTION")
    ssub.required = True
    pl = ssub.add_parser("list", help="services in the graph with their types")
    pl.add_argument("--json", action="store_true")
    pl.add_argument("--wait", type=float, default=1.5)
    pl.set_defaults(func=run_list)
    pc = ssub.add_parser("call", help="call a service; the request as YAML/JSON, e.g. '{recalibrate: true}'")
    pc.add_argument("name")
    pc.add_argument("type", nargs="?", help="pkg/srv/Name (default: from the graph)")
    pc.add_argument("request", nargs="?", default="{}", help="request fields as YAML (default {})")
    pc.add_argument("--timeout", type=float, default=10.0)
    pc.add_argument("--json", action="store_true")
    pc.set_defaults(func=run_call)

    q = sub.add_parser("param", help="list, get or set node parameters (like `ros2 param`)")
    qsub = q.add_subparsers(dest="param_command", metavar="ACTION")
    qsub.required = True
    ql = qsub.add_parser("list", help="parameter names of a node")
    ql.add_argument("node", help="fully qualified node name, e.g. /hexa/observer")
    ql.set_defaults(func=run_param_list)
    qg = qsub.add_parser("get", help="a parameter's value")
    qg.add_argument("node")
    qg.add_argument("name")
    qg.set_defaults(func=run_param_get)
    qs = qsub.add_parser("set", help="set a parameter (value as YAML: 2.5, true, [2, 2, 2, 0.2, 0.2, 0.2])")
    qs.add_argument("node")
    qs.add_argument("name")
    qs.add_argument("value")
    qs.set_defaults(func=run_param_set)
    for sp in (ql, qg, qs):
        sp.add_argument("--timeout", type=float, default=10.0)


def _cli():
    from hexa_bringup.commands.topic import _Cli

    return _Cli()


def run_list(args: argparse.Namespace) -> int:
    with _cli() as cli:
        cli.spin_for(args.wait)
        services = sorted(cli.node.get_service_names_and_types())
    if args.json:
        print(json.dumps({n: t for n, t in services}))
    else:
        for n, t in services:
            print(f"{n} [{', '.join(t)}]")
    return 0


def _service_class(type_name: str):
    from hexa_bringup.msgutil import get_message_class

    parts = type_name.split("/")
    if len(parts) == 2:
        type_name = f"{parts[0]}/srv/{parts[1]}"
    return get_message_class(type_name)


def _call(cli, name: str, cls, request, timeout: float):
    client = cli.node.create_client(cls, name)
    end = time.monotonic() + timeout
    while not client.service_is_ready():
        if time.monotonic() > end:
            raise SystemExit(f"hexa: service {name} not available within {timeout:g} s")
        cli.spin_for(0.1)
    future = client.call_async(request)
    while not future.done():
        if time.monotonic() > end:
            raise SystemExit(f"hexa: no response from {name} within {timeout:g} s")
        cli.executor.spin_once(timeout_sec=0.05)
    return future.result()


def run_call(args: argparse.Namespace) -> int:
    from hexa_bringup.msgutil import message_to_dict, set_message_fields

    name = args.name if args.name.startswith("/") else "/" + args.name
    try:
        fields = yaml.safe_load(args.request) or {}
    except yaml.YAMLError as exc:
        raise SystemExit(f"hexa service call: request is not valid YAML: {exc}") from exc
    if not isinstance(fields, dict):
        raise SystemExit(f"hexa service call: request must be a mapping, got {args.request!r}")
    with _cli() as cli:
        type_name = args.type
        end = time.monotonic() + args.timeout
        while type_name is None:
            found = dict(cli.node.get_service_names_and_types()).get(name)
            if found:
                type_name = found[0]
            elif time.monotonic() > end:
                raise SystemExit(f"hexa service call: no service {name} found (hexa service list)")
            else:
                cli.spin_for(0.1)
        cls = _service_class(type_name)
        try:
            request = set_message_fields(cls.Request(), fields)
        except (KeyError, TypeError, AssertionError, ValueError) as exc:
            raise SystemExit(f"hexa service call: bad request for {type_name}: {exc}") from exc
        response = _call(cli, name, cls, request, args.timeout)
    data = message_to_dict(response)
    print(json.dumps(data) if args.json else yaml.safe_dump(data, sort_keys=False).rstrip())
    return 0


def _param_value(value):
    from rcl_interfaces.msg import ParameterType

    kinds = {ParameterType.PARAMETER_BOOL: "bool_value", ParameterType.PARAMETER_INTEGER: "integer_value",
             ParameterType.PARAMETER_DOUBLE: "double_value", ParameterType.PARAMETER_STRING: "string_value",
             ParameterType.PARAMETER_BOOL_ARRAY: "bool_array_value",
             ParameterType.PARAMETER_INTEGER_ARRAY: "integer_array_value",
             ParameterType.PARAMETER_DOUBLE_ARRAY: "double_array_value",
             ParameterType.PARAMETER_STRING_ARRAY: "string_array_value"}
    field = kinds.get(value.type)
    if field is None:
        return None
    v = getattr(value, field)
    return list(v) if "array" in field else v


def run_param_list(args: argparse.Namespace) -> int:
    from rcl_interfaces.srv import ListParameters

    with _cli() as cli:
        resp = _call(cli, f"{args.node}/list_parameters", ListParameters, ListParameters.Request(), args.timeout)
    for n in sorted(resp.result.names):
        print(n)
    return 0


def run_param_get(args: argparse.Namespace) -> int:
    from rcl_interfaces.srv import GetParameters

    with _cli() as cli:
        resp = _call(cli, f"{args.node}/get_parameters", GetParameters, GetParameters.Request(names=[args.name]),
                     args.timeout)
    if not resp.values or resp.values[0].type == 0:
        print(f"hexa param get: {args.node} has no parameter {args.name!r}", file=sys.stderr)
        return 1
    print(json.dumps(_param_value(resp.values[0])))
    return 0


def run_param_set(args: argparse.Namespace) -> int:
    from rclpy.parameter import Parameter
    from rcl_interfaces.srv import SetParameters

    value = yaml.safe_load(args.value)
    if isinstance(value, list) and value and all(isinstance(v, (int, float)) for v in value):
        value = [float(v) for v in value]
    try:
        param = Parameter(args.name, value=value).to_parameter_msg()
    except (TypeError, ValueError) as exc:
        raise SystemExit(f"hexa param set: unsupported value {args.value!r}: {exc}") from exc
    with _cli() as cli:
        resp = _call(cli, f"{args.node}/set_parameters", SetParameters, SetParameters.Request(parameters=[param]),
                     args.timeout)
    result = resp.results[0]
    if not result.successful:
        print(f"hexa param set: refused: {result.reason}", file=sys.stderr)
        return 1
    print(f"set {args.node} {args.name} = {value!r}")
    return 0
