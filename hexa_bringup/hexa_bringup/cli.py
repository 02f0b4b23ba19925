"""The `hexa` command: one entry point, subcommands discovered from hexa_bringup.commands."""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from hexa_bringup import commands


def build_parser() -> argparse.ArgumentParser:
    """Parser with every subcommand module's `register(subparsers)` applied, in name order."""
    parser = argparse.ArgumentParser(prog="hexa", description="hexa: collision detection and singularity release "
                                     "for parallel robots (ROS 2 Jazzy). SI units; --json for machine output.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for mod in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if mod.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{mod.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the `hexa` command; each subcommand sets `func(args) -> int` on its parser."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
