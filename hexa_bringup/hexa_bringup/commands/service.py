"""`hexa service list|call` and `hexa param list|get|set|describe|dump|load`: what operators would use
`ros2 service` / `ros2 param` for (resume after a collision, reset the observer, calibrate currents, change thresholds
at runtime, keep a node's settings in a file)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import yaml

from hexa_bringup.commands._ros import (CliError, RosCli, absolute, graph_completer, load_yaml_mapping,
                                        looks_like_type, reason)

NODES = graph_completer("nodes")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("service", help="list services, call one (like `ros2 service`)")
    ssub = p.add_subparsers(dest="service_command", metavar="ACTION")
    ssub.required = True
    pl = ssub.add_parser("list", help="services in the graph with their types")
    pl.add_argument("--json", action="store_true")
    pl.add_argument("--wait", type=float, default=1.5)
    pl.set_defaults(func=run_list)
    pc = ssub.add_parser("call", help="call a service: call NAME [TYPE] [REQUEST]; the type comes from the graph "
                                      "when omitted, e.g. hexa service call /hexa/observer/reset "
                                      "'{recalibrate: true}'")
    pc.add_argument("name").completer = graph_completer("services")
    pc.add_argument("type", nargs="?", metavar="TYPE_OR_REQUEST",
                    help="pkg/srv/Name, or the request when the type is omitted (told apart by shape)")
    pc.add_argument("request", nargs="?", default=None, help="request fields as YAML (default {})")
    pc.add_argument("--timeout", type=float, default=10.0)
    pc.add_argument("--json", action="store_true")
    pc.set_defaults(func=run_call)

    q = sub.add_parser("param", help="list, get or set node parameters (like `ros2 param`)")
    qsub = q.add_subparsers(dest="param_command", metavar="ACTION")
    qsub.required = True
    ql = qsub.add_parser("list", help="parameter names of a node")
    ql.add_argument("node", help="fully qualified node name, e.g. /hexa/observer").completer = NODES
    ql.set_defaults(func=run_param_list)
    qg = qsub.add_parser("get", help="a parameter's value")
    qg.add_argument("node").completer = NODES
    qg.add_argument("name")
    qg.set_defaults(func=run_param_get)
    qs = qsub.add_parser("set", help="set a parameter (value as YAML: 2.5, true, [2, 2, 2, 0.2, 0.2, 0.2])")
    qs.add_argument("node").completer = NODES
    qs.add_argument("name")
    qs.add_argument("value")
    qs.set_defaults(func=run_param_set)
    qd = qsub.add_parser("describe", help="parameters' descriptors: type, description, range, read-only")
    qd.add_argument("node").completer = NODES
    qd.add_argument("names", nargs="*", help="parameter names (default: all)")
    qd.add_argument("--json", action="store_true")
    qd.set_defaults(func=run_param_describe)
    qm = qsub.add_parser("dump", help="every parameter of a node as a ROS parameters YAML (`--params` / "
                                      "`hexa param load` read it)")
    qm.add_argument("node").completer = NODES
    qm.add_argument("-o", "--output", help="write to this file instead of stdout")
    qm.set_defaults(func=run_param_dump)
    qo = qsub.add_parser("load", help="set a node's parameters from a ROS parameters YAML (as `hexa param dump` "
                                      "writes); values already in effect are skipped, refusals named")
    qo.add_argument("node").completer = NODES
    qo.add_argument("file")
    qo.set_defaults(func=run_param_load)
    for sp in (ql, qg, qs, qd, qm, qo):
        sp.add_argument("--timeout", type=float, default=10.0)


def _cli() -> RosCli:
    return RosCli()


def run_list(args: argparse.Namespace) -> int:
    with _cli() as cli:
        cli.discover(args.wait, cli.nodes)
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
    cls = get_message_class(type_name)
    if not hasattr(cls, "Request"):
        raise CliError(f"{type_name} is not a service type")
    return cls


def _call(cli: RosCli, name: str, cls, request, timeout: float):
    """The response of a node's parameter service `name` ("/ns/node/get_parameters").

    Raises:
        CliError: the node is not in the graph (naming it), or does not answer.
    """
    try:
        return cli.call(name, cls, request, timeout)
    except CliError:
        node = name.rsplit("/", 1)[0]
        if node not in cli.nodes():
            raise CliError(f"no node {node} in the graph within {timeout:g} s (check ROS_DOMAIN_ID; "
                           f"`hexa node list`)") from None
        raise


def run_call(args: argparse.Namespace) -> int:
    from hexa_bringup.msgutil import message_to_dict, set_message_fields

    name = absolute(args.name)
    type_name, request = args.type, args.request
    if request is None and type_name is not None and not looks_like_type(type_name):
        type_name, request = None, type_name           # `call NAME '{yaml}'`: the type comes from the graph
    elif type_name is not None and not looks_like_type(type_name):
        raise CliError(f"{type_name!r} is not a service type (pkg/srv/Name)")
    fields = load_yaml_mapping(request or "", "the request")
    with _cli() as cli:
        if type_name is None:
            def probe() -> str | None:
                found = dict(cli.node.get_service_names_and_types()).get(name)
                return found[0] if found else None

            type_name = cli.wait_for(probe, args.timeout, f"no service {name} found within {args.timeout:g} s "
                                                          f"(`hexa service list`)")
        cls = _service_class(type_name)
        try:
            req = set_message_fields(cls.Request(), fields)
        except (KeyError, TypeError, AssertionError, ValueError, AttributeError) as exc:
            raise CliError(f"bad request for {type_name}: {reason(exc)}") from exc
        response = cli.call(name, cls, req, args.timeout)
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

    node = absolute(args.node)
    with _cli() as cli:
        resp = _call(cli, f"{node}/list_parameters", ListParameters, ListParameters.Request(), args.timeout)
    for n in sorted(resp.result.names):
        print(n)
    return 0


def run_param_get(args: argparse.Namespace) -> int:
    from rcl_interfaces.srv import GetParameters

    node = absolute(args.node)
    with _cli() as cli:
        resp = _call(cli, f"{node}/get_parameters", GetParameters, GetParameters.Request(names=[args.name]),
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
        raise CliError(f"unsupported value {args.value!r}: {exc}") from exc
    node = absolute(args.node)
    with _cli() as cli:
        resp = _call(cli, f"{node}/set_parameters", SetParameters, SetParameters.Request(parameters=[param]),
                     args.timeout)
    result = resp.results[0]
    if not result.successful:
        print(f"hexa param set: refused: {result.reason}", file=sys.stderr)
        return 1
    print(f"set {args.node} {args.name} = {value!r}")
    return 0


_TYPE_NAMES = {0: "not set", 1: "bool", 2: "integer", 3: "double", 4: "string", 5: "byte array", 6: "bool array",
               7: "integer array", 8: "double array", 9: "string array"}


def _descriptor_dict(d) -> dict:
    out = {"name": d.name, "type": _TYPE_NAMES.get(d.type, str(d.type)), "description": d.description,
           "read_only": bool(d.read_only), "dynamic_typing": bool(d.dynamic_typing)}
    if d.additional_constraints:
        out["constraints"] = d.additional_constraints
    if d.floating_point_range:
        r = d.floating_point_range[0]
        out["range"] = {"min": r.from_value, "max": r.to_value, "step": r.step}
    if d.integer_range:
        r = d.integer_range[0]
        out["range"] = {"min": r.from_value, "max": r.to_value, "step": r.step}
    return out


def _param_names(cli: RosCli, node: str, timeout: float) -> list[str]:
    from rcl_interfaces.srv import ListParameters

    return sorted(_call(cli, f"{node}/list_parameters", ListParameters, ListParameters.Request(), timeout)
                  .result.names)


def run_param_describe(args: argparse.Namespace) -> int:
    from rcl_interfaces.srv import DescribeParameters

    node = absolute(args.node)
    with _cli() as cli:
        names = list(args.names) or _param_names(cli, node, args.timeout)
        resp = _call(cli, f"{node}/describe_parameters", DescribeParameters, DescribeParameters.Request(names=names),
                     args.timeout)
    found = [_descriptor_dict(d) for d in resp.descriptors]
    unknown = [d["name"] for d in found if d["type"] == "not set"]
    if len(found) != len(names) or unknown:
        raise CliError(f"{node} has no parameter {', '.join(repr(n) for n in unknown or names)} "
                       f"(`hexa param list {node}`)")
    if args.json:
        print(json.dumps(found))
        return 0
    for d in found:
        print(f"Parameter name: {d['name']}\n  Type: {d['type']}")
        if d["description"]:
            print(f"  Description: {d['description']}")
        print("  Constraints:")
        if d["read_only"]:
            print("    Read only: true")
        if "range" in d:
            r = d["range"]
            print(f"    Min value: {r['min']}\n    Max value: {r['max']}" + (f"\n    Step: {r['step']}"
                                                                           if r["step"] else ""))
        if d.get("constraints"):
            print(f"    {d['constraints']}")
    return 0


def _values(cli: RosCli, node: str, names: list[str], timeout: float) -> dict:
    from rcl_interfaces.srv import GetParameters

    resp = _call(cli, f"{node}/get_parameters", GetParameters, GetParameters.Request(names=names), timeout)
    return {n: _param_value(v) for n, v in zip(names, resp.values)}


def run_param_dump(args: argparse.Namespace) -> int:
    node = absolute(args.node)
    with _cli() as cli:
        values = _values(cli, node, _param_names(cli, node, args.timeout), args.timeout)
    text = yaml.safe_dump({node: {"ros__parameters": _nested(values)}}, sort_keys=True, default_flow_style=None)
    if args.output:
        try:
            Path(args.output).write_text(text, encoding="utf-8")
        except OSError as exc:
            raise CliError(f"cannot write {args.output}: {exc.strerror}") from exc
        print(f"wrote {len(values)} parameters of {node} to {args.output}")
    else:
        print(text, end="")
    return 0


def _nested(values: dict) -> dict:
    """{"a.b": 1} → {"a": {"b": 1}} (the ROS parameters YAML layout)."""
    out: dict = {}
    for name, value in values.items():
        if value is None:
            continue
        *path, last = name.split(".")
        d = out
        for part in path:
            d = d.setdefault(part, {})
        d[last] = value
    return out


def _flat(tree: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flat(value, name + "."))
        else:
            out[name] = value
    return out


def _node_sections(data: dict, prefix: str = "") -> list[tuple[str, dict]]:
    """(node key, ros__parameters) of a ROS parameters YAML in file order; namespaces may nest as mappings."""
    out = []
    for key, value in data.items():
        if not isinstance(value, dict):
            continue
        name = f"{prefix}/{str(key).strip('/')}" if prefix else str(key)
        if isinstance(value.get("ros__parameters"), dict):
            out.append((name, value["ros__parameters"]))
        out += _node_sections({k: v for k, v in value.items() if k != "ros__parameters"}, name)
    return out


def _matches(key: str, node: str) -> bool:
    """True when the node-name key of a parameters file (`/hexa/observer`, `observer`, `/**`, `/**/observer`,
    `/*/observer`) applies to the fully qualified `node`."""
    import re

    pattern = re.escape(key if key.startswith("/") else "/" + key)
    pattern = pattern.replace(r"/\*\*", "(?:/[^/]+)*").replace(r"\*", "[^/]+")
    return re.fullmatch(pattern, node) is not None


def node_parameters(data: dict, node: str) -> dict:
    """The parameters the loaded ROS parameters YAML `data` gives the fully qualified `node` (every section whose
    name or wildcard matches it, later ones over earlier ones, as rcl applies them), flattened to dotted names."""
    found: dict = {}
    for key, params in _node_sections(data):
        if _matches(key, node):
            found.update(_flat(params))
    return found


def file_parameters(data, node: str, path: str) -> dict:
    """`node_parameters` of a ROS parameters YAML.

    Raises:
        CliError: the file is not a parameters YAML or has nothing for `node`.
    """
    if not isinstance(data, dict):
        raise CliError(f"{path} is not a ROS parameters YAML (a mapping of node names to ros__parameters)")
    found = node_parameters(data, node)
    if not found:
        raise CliError(f"{path} has no ros__parameters for {node}")
    return found


def run_param_load(args: argparse.Namespace) -> int:
    from rclpy.parameter import Parameter
    from rcl_interfaces.srv import SetParameters

    node = absolute(args.node)
    try:
        text = Path(args.file).read_text(encoding="utf-8")
    except OSError as exc:
        raise CliError(f"cannot read {args.file}: {exc.strerror}") from exc
    wanted = file_parameters(yaml.safe_load(text), node, args.file)
    with _cli() as cli:
        existing = set(_param_names(cli, node, args.timeout))
        unknown = sorted(set(wanted) - existing)
        current = _values(cli, node, sorted(set(wanted) & existing), args.timeout)
        changes = {n: v for n, v in wanted.items() if n in current and current[n] != v}
        msgs = []
        for n, v in changes.items():
            if isinstance(v, list) and v and all(isinstance(x, (int, float)) for x in v) \
                    and isinstance(current[n], list) and any(isinstance(x, float) for x in current[n]):
                v = [float(x) for x in v]
            try:
                msgs.append(Parameter(n, value=v).to_parameter_msg())
            except (TypeError, ValueError) as exc:
                raise CliError(f"{args.file}: unsupported value of {n}: {v!r} ({exc})") from exc
        results = _call(cli, f"{node}/set_parameters", SetParameters, SetParameters.Request(parameters=msgs),
                        args.timeout).results if msgs else []
    refused = [(m.name, r.reason) for m, r in zip(msgs, results) if not r.successful]
    for n in unknown:
        print(f"hexa param load: {node} has no parameter {n!r}: skipped", file=sys.stderr)
    for n, why in refused:
        print(f"hexa param load: {n} refused: {why}", file=sys.stderr)
    print(f"{node}: set {len(msgs) - len(refused)}, unchanged {len(current) - len(changes)}, "
          f"refused {len(refused)}, unknown {len(unknown)}")
    return 1 if refused or unknown else 0
