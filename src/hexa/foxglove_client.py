"""A small client of the Foxglove WebSocket protocol: channel list, subscriptions, messages decoded by their schema.

It reads what `hexa view` (foxglove-sdk) serves, as the Foxglove app would: JSON channels as dicts, protobuf channels
(the foxglove.* schemas) decoded with the FileDescriptorSet the server advertises.
"""
from __future__ import annotations

import base64
import json
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from google.protobuf.message import Message as ProtobufMessage

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
#: binary opcode of a message on a subscription (server → client)
MESSAGE_DATA = 0x01


class FoxgloveClientError(RuntimeError):
    """The server cannot be reached, or sent something this client does not understand (the message says what)."""


@dataclass(frozen=True)
class Message:
    topic: str
    log_time_ns: int
    schema_name: str
    data: Any           #: dict (JSON channels) or a protobuf message (protobuf channels)


class FoxgloveClient:
    """Connects to `url` (ws://host:port) and collects the server's channel advertisements.

    Raises:
        FoxgloveClientError: no server answers at `url` within `timeout` seconds.
    """

    def __init__(self, url: str, timeout: float = 10.0) -> None:
        from websockets.sync.client import connect
        from websockets.typing import Subprotocol

        try:
            self._cm = connect(url, subprotocols=[Subprotocol(p) for p in SUBPROTOCOLS], open_timeout=timeout,
                               max_size=None)
            self._ws = self._cm.__enter__()
        except (OSError, TimeoutError) as exc:
            raise FoxgloveClientError(f"no Foxglove server at {url}: {exc}") from exc
        self.channels: dict[int, dict[str, Any]] = {}
        self._subs: dict[int, int] = {}
        self._classes: dict[int, type[ProtobufMessage]] = {}
        self._next = 1

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._cm.__exit__(None, None, None)

    def _recv(self, timeout: float) -> bytes | None:
        """The next binary frame within `timeout` s (text frames update the channel list), None when none came."""
        try:
            m = self._ws.recv(timeout=timeout)
        except TimeoutError:
            return None
        if isinstance(m, str):
            self._handle_text(m)
            return None
        return m

    def _handle_text(self, text: str) -> None:
        msg = json.loads(text)
        if msg.get("op") == "advertise":
            for ch in msg["channels"]:
                self.channels[int(ch["id"])] = ch
        elif msg.get("op") == "unadvertise":
            for cid in msg["channelIds"]:
                self.channels.pop(int(cid), None)

    def wait_for_topics(self, topics: set[str], timeout: float = 10.0) -> dict[str, dict[str, Any]]:
        """The advertised channels by topic once all of `topics` are advertised.

        Raises:
            FoxgloveClientError: some are still missing after `timeout` seconds (names them).
        """
        deadline = time.monotonic() + timeout
        while True:
            have = {c["topic"]: c for c in self.channels.values()}
            if topics <= set(have):
                return have
            left = deadline - time.monotonic()
            if left <= 0:
                raise FoxgloveClientError(f"channels not advertised: {sorted(topics - set(have))}")
            self._recv(left)

    def subscribe(self, topics: list[str]) -> None:
        """Subscribe to the advertised channels of `topics`."""
        by_topic = {c["topic"]: cid for cid, c in self.channels.items()}
        subs = []
        for t in topics:
            sid, self._next = self._next, self._next + 1
            self._subs[sid] = by_topic[t]
            subs.append({"id": sid, "channelId": by_topic[t]})
        self._ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def _decode(self, channel_id: int, payload: bytes) -> Any:
        ch = self.channels[channel_id]
        if ch["encoding"] == "json":
            return json.loads(payload)
        if ch["encoding"] != "protobuf":
            raise FoxgloveClientError(f"channel {ch['topic']}: encoding {ch['encoding']!r} is not decoded here")
        cls = self._classes.get(channel_id)
        if cls is None:
            from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

            fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
            pool = descriptor_pool.DescriptorPool()
            for fd in fds.file:
                pool.Add(fd)
            cls = self._classes[channel_id] = message_factory.GetMessageClass(
                pool.FindMessageTypeByName(ch["schemaName"]))
        return cls.FromString(payload)

    def messages(self, duration: float, until: Callable[[list[Message]], bool] | None = None) -> list[Message]:
        """Messages received on the subscriptions for `duration` seconds, or until `until(messages)` is true."""
        out: list[Message] = []
        deadline = time.monotonic() + duration
        while (left := deadline - time.monotonic()) > 0 and not (until and until(out)):
            m = self._recv(left)
            if m is None or len(m) < 13 or m[0] != MESSAGE_DATA:
                continue
            sid, log_time = struct.unpack_from("<IQ", m, 1)
            cid = self._subs.get(sid)
            if cid is None or cid not in self.channels:
                continue
            ch = self.channels[cid]
            out.append(Message(ch["topic"], log_time, ch.get("schemaName", ""), self._decode(cid, bytes(m[13:]))))
        return out
