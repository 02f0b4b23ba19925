"""`python -m hexa_ros.start MODULE [ARGS ...]`: a node module's `main(argv)` with Ctrl-C handled from its first import.

A node module imports for seconds before its `main` runs (MuJoCo, the detector's backend, pinocchio), and Python's
default SIGINT handler would end such an import with a KeyboardInterrupt traceback. Here SIGINT/SIGTERM record the
stop first (hexa_ros.node), so a signal during the import ends the process with rc 0 and no traceback, as one during
the node's construction or spin does. `hexa bringup` starts every node this way.
"""
from __future__ import annotations

import importlib
import sys

from hexa_ros.env import apply_defaults

apply_defaults()            # before numpy and cv2 load: their thread pools read it (hexa_ros.env.defaults)

from hexa_ros import node  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """Import MODULE (argv[0]) and return its `main([MODULE, *rest])`; 0 when stopped before `main` handles signals
    itself (hexa_ros.node.run)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args:
        print("usage: python -m hexa_ros.start MODULE [ARGS ...]", file=sys.stderr)
        return 2
    node.install_signal_handlers()
    try:
        return importlib.import_module(args[0]).main([args[0], *args[1:]])
    except BaseException:  # noqa: BLE001 - stopped while importing (an ImportError may wrap the interrupt) or
        if node.stop_requested():   # before `run` took the signals over
            return 0
        raise


if __name__ == "__main__":
    sys.exit(main())
