"""Subscriptions read on demand: messages wait in their DDS reader (keep last `depth`) until the node takes them.

A node that needs only some of a heavy stream (the isolation node: camera frames around a collision) subscribes
through `PolledSubscriptions`: the subscriptions belong to a second node of the process (`<owner>_<suffix>`) that no
executor spins, so no callback runs per message and the owner's executor queue holds only its own (light) messages.
`take(sub)` returns what the reader holds, oldest first: the last `depth` messages, as serialized bytes for a raw
subscription. Topic names resolve through the owner, so its remaps apply, the node-local ones of a composed node
included (the polled node itself ignores the process's arguments, which would remap a resolved name twice).
"""
from __future__ import annotations

from typing import Any


class PolledSubscriptions:
    """A node whose subscriptions are read with `take`, never spun (module docstring).

    Args:
        owner: the node the subscriptions work for (name, namespace and context are taken from it).
        suffix: the polled node is named `<owner>_<suffix>`.
    """

    def __init__(self, owner: Any, suffix: str) -> None:
        from rclpy.node import Node
        from rclpy.parameter import Parameter

        name = f"{owner.get_name()}_{suffix}"
        self.owner = owner
        self.node = Node(name, namespace=owner.get_namespace(), context=owner.context,
                         cli_args=["--ros-args", "-r", f"__node:={name}"], use_global_arguments=False,
                         start_parameter_services=False,
                         enable_rosout=False,
                         parameter_overrides=[Parameter("use_sim_time", value=False)])   # no /clock to take

    def subscribe(self, msg_type: Any, topic: str, qos: Any, raw: bool = True) -> Any:
        """A subscription whose reader keeps the last `qos.depth` messages until `take`, on `topic` as the owner
        resolves it (its namespace and remaps)."""
        return self.node.create_subscription(msg_type, self.owner.resolve_topic_name(topic), _never_called, qos,
                                             raw=raw)

    @staticmethod
    def take(sub: Any) -> list[Any]:
        """Every message the reader holds, oldest first (bytes for a raw subscription)."""
        out = []
        with sub.handle:
            while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                out.append(taken[0])
        return out

    def close(self) -> None:
        """Destroy the polled node (from the owner's `close()`)."""
        self.node.destroy_node()


def _never_called(_msg: Any) -> None:    # pragma: no cover - the node is never spun
    raise AssertionError("a polled subscription is read with take(), not spun")
