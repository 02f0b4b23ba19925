"""Several hexa nodes in one process on one executor: `python -m hexa_ros.compose NAME=MODULE:CLASS ... --ros-args ...`.

Each NAME=MODULE:CLASS builds MODULE.CLASS as a node named NAME (a node-local `__node` remap); the `--ros-args` that
follow (namespace, parameters file, `-p` overrides) are global, as for a single-node process, so a node reads the
same parameters composed or alone. Every node keeps its own entry point too (`python -m MODULE`).

One process shares one Python interpreter: composed nodes never run their callbacks at the same time, so compose
nodes whose work is short beside the latency their outputs need (docs/node_layer.md, "Composition").
"""
from __future__ import annotations

import importlib
import inspect
import re
import sys
from collections.abc import Callable
from typing import Any

_SPEC = re.compile(r"^(?P<name>[A-Za-z_][A-Za-z0-9_]*)=(?P<module>[A-Za-z_][\w.]*):(?P<cls>[A-Za-z_]\w*)$")


class ComposeError(ValueError):
    """A node spec that cannot be loaded (naming it)."""


def parse_specs(argv: list[str]) -> tuple[list[tuple[str, str, str]], list[str]]:
    """(name, module, class) per NAME=MODULE:CLASS before `--ros-args`, and the ROS arguments from there on.

    Raises:
        ComposeError: a malformed spec, a repeated name, or no spec at all.
    """
    cut = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    specs, names = [], set()
    for arg in argv[:cut]:
        m = _SPEC.match(arg)
        if m is None:
            raise ComposeError(f"node spec {arg!r} is not NAME=MODULE:CLASS (e.g. observer=hexa_dynamics."
                               f"observer_node:ObserverNode)")
        if m["name"] in names:
            raise ComposeError(f"node name {m['name']!r} given twice")
        names.add(m["name"])
        specs.append((m["name"], m["module"], m["cls"]))
    if not specs:
        raise ComposeError("no node to compose: give NAME=MODULE:CLASS ...")
    return specs, argv[cut:]


def load(module: str, cls: str) -> Callable[..., Any]:
    """The node class `cls` of `module`.

    Raises:
        ComposeError: the module or the class does not exist.
    """
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        raise ComposeError(f"cannot import node module {module!r}: {exc}") from exc
    factory = getattr(mod, cls, None)
    if not callable(factory):
        raise ComposeError(f"module {module!r} has no node class {cls!r}")
    params = inspect.signature(factory).parameters.values()
    if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        raise ComposeError(f"{module}.{cls} cannot be composed: its __init__ takes no **kwargs for rclpy's Node")
    return factory


def main(argv: list[str] | None = None) -> int:
    from hexa_ros.node import install_signal_handlers, run, stop_requested

    args = list(sys.argv[1:] if argv is None else argv)
    install_signal_handlers()     # Ctrl-C while the node modules import: rc 0, no traceback (hexa_ros.start)
    try:
        specs, ros_args = parse_specs(args)
        factories = [load(module, cls) for _name, module, cls in specs]
    except ComposeError as exc:
        print(f"hexa compose: {exc}", file=sys.stderr)
        return 2
    except BaseException:  # noqa: BLE001 - stopped while importing (an ImportError may wrap the interrupt)
        if stop_requested():
            return 0
        raise
    kwargs = [{"cli_args": ["--ros-args", "-r", f"__node:={name}"]} for name, _m, _c in specs]
    return run(factories, "+".join(name for name, _m, _c in specs), [sys.argv[0], *ros_args], kwargs)


if __name__ == "__main__":
    sys.exit(main())
