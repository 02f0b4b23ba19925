# PYTHON_ARGCOMPLETE_OK
"""The `hexa` command: one entry point, subcommands discovered from hexa_bringup.commands.

A user's mistake (a wrong name, type, value or file, a node or service that is not there) ends with one line on
stderr and exit 2, never a traceback. Shell completion: `eval "$(register-python-argcomplete hexa)"` (argcomplete).
"""
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


def _user_errors() -> tuple[type[BaseException], ...]:
    """Exception types that mean the user asked for something wrong or absent (not a bug in hexa)."""
    import yaml

    from hexa_bringup.commands._ros import CliError
    from hexa_bringup.msgutil import MessageTypeError
    from hexa_bringup.supervisor import SupervisorError

    found: list[type[BaseException]] = [CliError, MessageTypeError, SupervisorError, yaml.YAMLError]
    try:
        from hexa.bags import BagError

        found.append(BagError)
    except ImportError:
        pass
    try:
        from rclpy.exceptions import (InvalidNamespaceException, InvalidNodeNameException,
                                      InvalidServiceNameException, InvalidTopicNameException)

        found += [InvalidNamespaceException, InvalidNodeNameException, InvalidServiceNameException,
                  InvalidTopicNameException]
    except ImportError:
        pass
    return tuple(found)


def main(argv: list[str] | None = None) -> int:
    """Run the `hexa` command; each subcommand sets `func(args) -> int` on its parser."""
    parser = build_parser()
    try:
        import argcomplete

        argcomplete.autocomplete(parser)
    except ImportError:
        pass
    args = parser.parse_args(argv)
    import signal

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        # started in the background of a non-interactive shell, which ignores SIGINT for its jobs: Ctrl-C and
        # `kill -INT` still stop every verb cleanly
        signal.signal(signal.SIGINT, signal.default_int_handler)
    where = " ".join([args.command] + [str(v) for k, v in sorted(vars(args).items())
                                       if k.endswith("_command") and isinstance(v, str)])
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:                     # `hexa … | head`: the reader left; stop writing, quietly
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except SystemExit as exc:
        if isinstance(exc.code, str):           # a command's own "raise SystemExit('message')": a user error
            print(exc.code if exc.code.startswith("hexa") else f"hexa {where}: {exc.code}", file=sys.stderr)
            return 2
        raise
    except _user_errors() as exc:
        from hexa_bringup.commands._ros import reason

        print(f"hexa {where}: {reason(exc)}", file=sys.stderr)
        return 2
    except Exception as exc:
        if _interrupted(exc):                   # Ctrl-C inside an import (rclpy's C library) re-raised as another error
            return 130
        raise


def _interrupted(exc: BaseException) -> bool:
    """True when a KeyboardInterrupt is among the causes of `exc`."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


if __name__ == "__main__":
    sys.exit(main())
