"""Node main/spin/shutdown for every hexa node: one executor, clean Ctrl-C, configuration errors named, not traced.

Every node module has `main(argv) = hexa_ros.node.main(NodeClass, "name", argv)`; `hexa_ros.compose` runs several
node classes in one process on one executor the same way.

The executor is rclpy's EventsExecutor (C++ event queue): a 1 kHz JointState subscription costs ≈ 110-160 µs of CPU
per message with it against ≈ 640 µs with the SingleThreadedExecutor on the 2-core robot PC (docs/node_layer.md).
Its `spin()` does not return on SIGINT, so the loop below spins in bounded steps and SIGINT/SIGTERM set a flag
that ends the loop after the callback in progress (while nodes are built, they raise KeyboardInterrupt; from the
executor's set-up on, they only set the flag). rclpy's
signal handler stays off: it would invalidate the context while a callback is still publishing. The bounded step
also ends the wait when /clock stops (sim time, the simulator gone), where an unbounded wait would never return.

Once its nodes are built, each logs "ready": the first log call of a process costs ≈ 25 ms of CPU (rclpy names the
caller's module through `inspect`, which resolves the path of every loaded module once), spent here rather than in
the first callback that logs (the isolation node's collision START).
"""
from __future__ import annotations

import signal
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

#: exceptions a node's constructor raises for a user's configuration mistake (a bad parameter value, a missing
#: file): reported in one line, exit code 2
CONFIG_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError, KeyError)
#: seconds one executor step waits at most
SPIN_STEP = 0.2
#: the node attribute hexa_ros.realtime.request_realtime_priority keeps a node's asked-for priority in; `run` raises
#: the process only when one is set (hexa_ros.realtime stays unimported otherwise)
REQUESTED_PRIORITY = "_hexa_realtime_priority"
EXECUTORS = ("events", "single")
#: the signal that makes a hexa node write its threads' stacks to stderr (`install_signal_handlers`)
DUMP_STACKS_SIGNAL = signal.SIGUSR1


def _raise_keyboard_interrupt(_signum: int, _frame: Any) -> None:
    _StopRequest.requested = True
    raise KeyboardInterrupt


def install_signal_handlers() -> None:
    """SIGINT and SIGTERM raise KeyboardInterrupt in the main thread (rclpy's own handler stays off) and record the
    stop request (`stop_requested`): an import interrupted by it raises ImportError, not KeyboardInterrupt.

    SIGUSR1 writes every thread's Python stack to stderr (the node's log under `hexa bringup`), also while the main
    thread is blocked in C: the supervisor sends it to a node that does not stop before it kills the node, so the log
    says where it hung."""
    import faulthandler

    signal.signal(signal.SIGINT, _raise_keyboard_interrupt)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    faulthandler.register(DUMP_STACKS_SIGNAL, all_threads=True)


def make_executor(kind: str, context: Any = None) -> Any:
    """An executor of `kind` ("events": rclpy.experimental.EventsExecutor; "single": SingleThreadedExecutor).

    Raises:
        ValueError: an unknown kind.
    """
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == "single":
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)
    raise ValueError(f"executor must be one of {EXECUTORS}, got {kind!r}")


def executor_kind() -> str:
    """The executor hexa nodes use: HEXA_EXECUTOR ("events" by default, "single" for comparison)."""
    import os

    return os.environ.get("HEXA_EXECUTOR", "events")


class _StopRequest:
    """Set by SIGINT/SIGTERM while an executor spins: the loop ends after the callback in progress (a
    KeyboardInterrupt raised inside a callback would be logged by the executor as a FATAL callback failure)."""

    requested = False

    @classmethod
    def handler(cls, _signum: int, _frame: Any) -> None:
        cls.requested = True


def stop_requested() -> bool:
    """SIGINT or SIGTERM arrived since `install_signal_handlers` (first called by hexa_ros.start or `run`)."""
    return _StopRequest.requested


def stop_on_signal() -> None:
    """From now on SIGINT/SIGTERM only request the stop (`_StopRequest`): no KeyboardInterrupt can interrupt the
    executor's set-up or a message being taken and converted."""
    signal.signal(signal.SIGINT, _StopRequest.handler)
    signal.signal(signal.SIGTERM, _StopRequest.handler)


def spin_until_shutdown(executor: Any, step: float = SPIN_STEP) -> None:
    """Spin `executor` in bounded steps until the context shuts down or SIGINT/SIGTERM arrives (also one that
    arrived since `stop_on_signal`). An error the executor raises once the stop was requested (a message taken
    while the process is being stopped) ends the spin like the stop itself; before, it propagates."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    stop_on_signal()
    try:
        while rclpy.ok() and not _StopRequest.requested:
            executor.spin_once(timeout_sec=step)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if not _StopRequest.requested:
            raise


def run(factories: Sequence[Callable[..., Any]], name: str, argv: list[str] | None = None,
        node_kwargs: Sequence[dict[str, Any]] | None = None) -> int:
    """Init ROS, build the nodes, spin them on one executor, shut down cleanly; the process's exit code.

    Args:
        factories: node classes (or callables returning a node), built in order.
        name: the program's name in error messages ("hexa <name>: ...").
        argv: command line with `--ros-args ...` (default sys.argv).
        node_kwargs: per factory, keyword arguments for the node (e.g. `cli_args` of a composed node).

    Returns:
        0 after a clean shutdown, 2 when a node's configuration is invalid (the message names it).
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from hexa_ros.env import apply_defaults

    apply_defaults()
    install_signal_handlers()     # a stop requested earlier (hexa_ros.start, while importing) still counts
    nodes: list[Any] = []
    try:
        rclpy.init(args=argv if argv is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO)
        for k, factory in enumerate(factories):
            nodes.append(factory(**(node_kwargs[k] if node_kwargs else {})))
        stop_on_signal()  # built: a signal from here on only requests the stop (logging "ready" walks every module)
    except BaseException as exc:  # noqa: BLE001 - stopped while starting ROS or building (whatever the signal
        _teardown(nodes)          # interrupted), or a configuration error
        if _StopRequest.requested:
            return 0
        if isinstance(exc, CONFIG_ERRORS):
            print(f"hexa {name}: {exc}", file=sys.stderr)
            return 2
        raise
    if any(getattr(node, REQUESTED_PRIORITY, 0) for node in nodes):   # hexa_ros.realtime.request_realtime_priority
        from hexa_ros.realtime import apply_requested_priority

        apply_requested_priority(nodes)     # this process is the nodes' own: SCHED_FIFO when one asked for it
    for node in nodes:
        node.get_logger().info("ready")
    loop = getattr(nodes[0], "run_loop", None) if len(nodes) == 1 else None
    if callable(loop):   # a node that steps its own loop (the simulator) and spins itself between steps
        try:
            loop(lambda: rclpy.ok() and not _StopRequest.requested)
        except KeyboardInterrupt:
            pass
        finally:
            _teardown(nodes)
        return 0
    try:
        executor = make_executor(executor_kind())
    except ValueError as exc:
        print(f"hexa {name}: HEXA_EXECUTOR: {exc}", file=sys.stderr)
        _teardown(nodes)
        return 2
    for node in nodes:
        executor.add_node(node)
    spin_until_shutdown(executor)
    _teardown(nodes, executor)
    return 0


def _teardown(nodes: list[Any], executor: Any = None) -> None:
    import rclpy

    signal.signal(signal.SIGINT, signal.SIG_IGN)     # a second Ctrl-C must not interrupt the teardown
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    for node in reversed(nodes):
        close = getattr(node, "close", None)
        if callable(close):
            close()
        if executor is not None:
            executor.remove_node(node)
        node.destroy_node()
    if executor is not None:
        executor.shutdown()
    rclpy.try_shutdown()


def main(factory: Callable[..., Any], name: str, argv: list[str] | None = None) -> int:
    """The entry point of a single-node module: `def main(argv=None): return hexa_ros.node.main(Node, "x", argv)`."""
    return run([factory], name, argv)


# ------------------------------------------------------------------------------------------ parameters
#: the robot-YAML parameter of every node (in ROS `robot_description` is URDF XML, which this is not)
DESCRIPTION = "description"


@dataclass(frozen=True)
class Param:
    """A node parameter: its default, what it means (with its unit), and how it may change.

    runtime: False (the default) marks it read-only, so a set on the running node is refused with rclpy's reason
    ("read-only parameter"); True when the node applies a new value at once. range: (low, high) inclusive for a
    number; choices: the accepted strings.
    """

    default: Any
    description: str
    runtime: bool = False
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    dynamic_typing: bool = False


#: the robot-YAML parameter's declaration, the same on every node
DESCRIPTION_PARAM = Param("", "robot description YAML path (SI units); empty = the packaged one")


def descriptor(p: Param) -> Any:
    """The rcl_interfaces/ParameterDescriptor of `p` (description, read_only, range, choices)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    d = ParameterDescriptor(description=p.description, read_only=not p.runtime, dynamic_typing=p.dynamic_typing)
    if p.choices:
        d.additional_constraints = "one of: " + ", ".join(p.choices)
    if p.range is not None:
        lo, hi = p.range
        if isinstance(p.default, bool) or not isinstance(p.default, (int, float)):
            d.additional_constraints = f"each value in [{lo:g}, {hi:g}]"
        elif isinstance(p.default, int):
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    return d


def declare_parameters(node: Any, params: Mapping[str, Param]) -> dict[str, Any]:
    """Declare `params` on `node` with their descriptors; their values (defaults overridden by the command line or
    the parameters file).

    Raises:
        ValueError: a value has the wrong type, is out of its range or not one of its choices (names it).
    """
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

    values = {}
    for name, p in params.items():
        try:
            v = node.declare_parameter(name, p.default, descriptor(p)).value
        except (InvalidParameterTypeException, InvalidParameterValueException, TypeError) as exc:
            raise ValueError(f"parameter {name}: {exc}") from None
        if p.choices and v not in p.choices:
            raise ValueError(f"parameter {name} must be one of {', '.join(p.choices)}; got {v!r}")
        if p.range is not None and isinstance(v, (list, tuple)) and not all(p.range[0] <= x <= p.range[1] for x in v):
            raise ValueError(f"parameter {name}: each value must be in [{p.range[0]:g}, {p.range[1]:g}]; got {v}")
        values[name] = v
    return values
