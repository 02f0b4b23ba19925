"""`hexa interface show|list`: the definition of a message or service type, and the installed types (like
`ros2 interface`)."""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from hexa_bringup.commands._ros import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("interface", help="show a message/service definition, list installed types "
                                         "(like `ros2 interface`)")
    isub = p.add_subparsers(dest="interface_command", metavar="ACTION")
    isub.required = True
    ps = isub.add_parser("show", help="the .msg/.srv text of a type, e.g. hexa_msgs/msg/Residual")
    ps.add_argument("type", help="pkg/msg/Name, pkg/srv/Name or pkg/Name")
    ps.set_defaults(func=run_show)
    pl = isub.add_parser("list", help="every installed message and service type")
    pl.add_argument("package", nargs="?", help="only this package's types")
    pl.add_argument("--json", action="store_true")
    pl.set_defaults(func=run_list)


def _ament_prefix() -> None:
    """The venv is an ament prefix (the ROS wheels and hexa_msgs install there): search it when no workspace has
    been sourced."""
    if not os.environ.get("AMENT_PREFIX_PATH") and (Path(sys.prefix) / "share" / "ament_index").is_dir():
        os.environ["AMENT_PREFIX_PATH"] = sys.prefix


def _interfaces() -> dict[str, list[str]]:
    """package → its interface files ("msg/Name.msg", "srv/Name.srv") from the ament index."""
    from ament_index_python import get_resource, get_resources

    _ament_prefix()
    out = {}
    for pkg in get_resources("rosidl_interfaces"):
        content, _prefix = get_resource("rosidl_interfaces", pkg)
        out[pkg] = sorted({line.rsplit(".", 1)[0] for line in content.splitlines()
                           if line.endswith((".msg", ".srv", ".action"))})
    return out


def definition(type_name: str) -> str:
    """The text of `type_name`'s .msg/.srv/.action file.

    Raises:
        CliError: a malformed name, or a type that is not installed (naming the package's types).
    """
    from ament_index_python import PackageNotFoundError, get_package_share_directory

    _ament_prefix()
    parts = type_name.strip("/").split("/")
    if len(parts) not in (2, 3) or not all(parts):
        raise CliError(f"malformed type {type_name!r}; expected pkg/msg/Name or pkg/srv/Name")
    pkg, name = parts[0], parts[-1]
    kinds = [parts[1]] if len(parts) == 3 else ["msg", "srv", "action"]
    try:
        share = Path(get_package_share_directory(pkg))
    except (PackageNotFoundError, ValueError) as exc:
        raise CliError(f"no interface package {pkg!r} is installed (`hexa interface list`)") from exc
    for kind in kinds:
        f = share / kind / f"{name}.{kind}"
        if f.is_file():
            return f.read_text(encoding="utf-8")
    known = ", ".join(_interfaces().get(pkg, [])) or "none"
    raise CliError(f"{pkg} has no interface {'/'.join(parts[1:])}; it has: {known}")


def run_show(args: argparse.Namespace) -> int:
    print(definition(args.type).rstrip("\n"))
    return 0


def run_list(args: argparse.Namespace) -> int:
    found = _interfaces()
    if args.package:
        if args.package not in found:
            raise CliError(f"no interface package {args.package!r} is installed")
        found = {args.package: found[args.package]}
    names = [f"{pkg}/{i}" for pkg in sorted(found) for i in found[pkg]]
    print(json.dumps(names) if args.json else "\n".join(names))
    return 0
