"""What the graph verbs of the `hexa` CLI share: a short-lived rclpy node, name resolution, waiting for discovery,
and the error type that ends a command with one line and exit 2."""
from __future__ import annotations

import os
import re
import time
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")

#: "pkg/msg/Name", "pkg/srv/Name" or "pkg/Name": how a type differs from a YAML request on the command line
TYPE_NAME = re.compile(r"^[A-Za-z_]\w*/(?:(?:msg|srv|action)/)?[A-Z]\w*$")


class CliError(Exception):
    """A user's mistake or an absent graph resource: `hexa` prints the message on one line and exits 2."""


def reason(exc: BaseException) -> str:
    """An exception's message on one line (a KeyError's without the quotes its str() adds)."""
    text = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
    return " ".join(str(text).split()) or type(exc).__name__


def absolute(name: str) -> str:
    """`name` made absolute ("hexa/observer" → "/hexa/observer")."""
    return name if name.startswith("/") else "/" + name


def split_node_name(name: str) -> tuple[str, str]:
    """("/hexa", "observer") of "/hexa/observer"; ("/", "sim") of "sim"."""
    full = absolute(name).rstrip("/")
    ns, _, base = full.rpartition("/")
    if not base:
        raise CliError(f"{name!r} is not a node name (e.g. /hexa/observer; `hexa node list`)")
    return ns or "/", base


def looks_like_type(text: str | None) -> bool:
    """True when `text` has the shape of an interface type rather than a YAML request ('{duration: 2.0}')."""
    return bool(text) and TYPE_NAME.match(text.strip()) is not None


def load_yaml_mapping(text: str, what: str) -> dict[str, Any]:
    """A YAML/JSON mapping from the command line ('' or None → {}).

    Raises:
        CliError: not YAML, or not a mapping (naming the text).
    """
    import yaml

    try:
        value = yaml.safe_load(text) if text else {}
    except yaml.YAMLError as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CliError(f"{what} is not valid YAML ({first}): {text!r}") from exc
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise CliError(f"{what} must be a mapping such as '{{field: value}}', got {text!r}")
    return value


class RosCli:
    """An rclpy context + node for one CLI call; a context manager that closes both."""

    def __init__(self, name: str = "hexa_cli") -> None:
        from hexa_bringup.rosenv import apply_defaults

        apply_defaults()
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context)
        self.name = f"{name}_{os.getpid()}"
        self.node = rclpy.create_node(self.name, context=self.context, start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def wait_for(self, probe: Callable[[], T | None], timeout: float, error: str) -> T:
        """Spin until `probe()` returns something other than None/empty, at most `timeout` s (0 = forever).

        Raises:
            CliError: `error`, when the time runs out.
        """
        start = time.monotonic()
        while True:
            value = probe()
            if value:
                return value
            if timeout and time.monotonic() - start > timeout:
                raise CliError(error)
            self.spin_for(0.1)

    def discover(self, wait: float, others: Callable[[], Any], patience: float = 5.0) -> None:
        """Spin `wait` s of discovery, then on (up to `patience` s more) while `others()` finds nothing of the graph
        yet or what it finds still changes within 0.5 s (discovery is slower on a loaded host)."""
        self.spin_for(wait)
        end = time.monotonic() + patience
        last, still = others(), time.monotonic()
        while time.monotonic() < end and not (last and time.monotonic() - still >= 0.5):
            self.spin_for(0.1)
            now = others()
            if now != last:
                last, still = now, time.monotonic()

    def foreign_topics(self) -> list[str]:
        """Topics other than the ones every node (this one too) has."""
        return sorted(t for t, _ in self.node.get_topic_names_and_types() if t not in ("/rosout", "/parameter_events"))

    def nodes(self) -> list[str]:
        """Fully qualified names of the graph's nodes, without this CLI's own node."""
        out = []
        for name, ns in self.node.get_node_names_and_namespaces():
            if name == self.name:
                continue
            out.append(f"{ns.rstrip('/')}/{name}")
        return sorted(set(out))

    def wait_node(self, name: str, timeout: float) -> tuple[str, str]:
        """(namespace, name) of node `name` once discovered.

        Raises:
            CliError: not discovered within `timeout` s.
        """
        ns, base = split_node_name(name)
        full = f"{ns.rstrip('/')}/{base}"
        self.wait_for(lambda: full in self.nodes(), timeout,
                      f"no node {full} found within {timeout:g} s (check ROS_DOMAIN_ID; `hexa node list`)")
        return ns, base

    def call(self, name: str, cls: type, request: Any, timeout: float) -> Any:
        """The response of service `name` to `request`.

        Raises:
            CliError: the service is not available, or does not answer, within `timeout` s.
        """
        client = self.node.create_client(cls, name)
        end = time.monotonic() + timeout
        while not client.service_is_ready():
            if time.monotonic() > end:
                raise CliError(f"service {name} not available within {timeout:g} s (`hexa service list`)")
            self.spin_for(0.1)
        future = client.call_async(request)
        while not future.done():
            if time.monotonic() > end:
                raise CliError(f"no response from {name} within {timeout:g} s")
            self.executor.spin_once(timeout_sec=0.05)
        return future.result()

    def close(self) -> None:
        try:
            self.executor.shutdown()
            self.node.destroy_node()
        finally:
            if self.context.ok():
                self.rclpy.shutdown(context=self.context)

    def __enter__(self) -> "RosCli":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def qos_dict(qos: Any) -> dict[str, Any]:
    """The QoS policies of an endpoint as plain values (reliability, durability, history, depth, deadline, lifespan,
    liveliness, lease duration; durations in s, None = infinite)."""
    def seconds(d: Any) -> float | None:
        ns = d.nanoseconds
        return None if ns >= 0x7FFFFFFFFFFFFFFF or ns == 0x7FFFFFFF * 10**9 + 0x7FFFFFFF else ns * 1e-9

    def name(policy: Any) -> str:
        return policy.name.lower()

    return {"reliability": name(qos.reliability), "durability": name(qos.durability), "history": name(qos.history),
            "depth": int(qos.depth), "deadline_s": seconds(qos.deadline), "lifespan_s": seconds(qos.lifespan),
            "liveliness": name(qos.liveliness), "liveliness_lease_s": seconds(qos.liveliness_lease_duration)}


def graph_completer(kind: str) -> Callable[..., list[str]]:
    """An argcomplete completer of the graph's `kind` names ("topics" | "nodes" | "services"), discovered for about a
    second at each TAB (there is no ros2 daemon to ask)."""
    def complete(prefix: str, **_kw: Any) -> list[str]:
        try:
            with RosCli("hexa_complete") as cli:
                if kind == "nodes":
                    cli.discover(1.0, cli.nodes, patience=3.0)
                    names = cli.nodes()
                elif kind == "services":
                    cli.discover(1.0, cli.nodes, patience=3.0)
                    names = [n for n, _ in cli.node.get_service_names_and_types()]
                else:
                    cli.discover(1.0, cli.foreign_topics, patience=3.0)
                    names = cli.foreign_topics()
        except Exception:  # noqa: BLE001 - a completion must never print an error into the user's command line
            return []
        return sorted(n for n in set(names) if n.startswith(prefix))

    return complete
