"""rosbag2 reading without ROS (rosbags): recorded CDR messages in time order, replayed at their recorded pace."""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path


class BagError(RuntimeError):
    """A bag cannot be written or read (path exists, unknown type, corrupt file)."""


def read_bag(path: str | Path, topics: list[str] | None = None) -> Iterator[tuple[str, str, int, bytes]]:
    """Yield (topic, msgtype, timestamp_ns, cdr) in time order.

    Raises:
        BagError: the bag is missing or unreadable.
    """
    from rosbags.rosbag2 import Reader

    p = Path(path)
    if not p.exists():
        raise BagError(f"bag {p} does not exist")
    try:
        with Reader(p) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            for conn, stamp, data in reader.messages(connections=conns):
                yield conn.topic, conn.msgtype, stamp, bytes(data)
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types; name the bag
        if isinstance(exc, BagError):
            raise
        raise BagError(f"cannot read bag {p}: {exc}") from exc


def paced(messages: Iterator[tuple[str, str, int, bytes]], rate: float,
          sleep: Callable[[float], None] = time.sleep) -> Iterator[tuple[str, str, int, bytes]]:
    """Re-yield `messages` at `rate` times their recorded pace (rate <= 0: as fast as possible)."""
    t_wall0: float | None = None
    t_bag0 = 0
    for item in messages:
        stamp = item[2]
        if rate > 0:
            if t_wall0 is None:
                t_wall0, t_bag0 = time.monotonic(), stamp
            due = t_wall0 + (stamp - t_bag0) / 1e9 / rate
            delay = due - time.monotonic()
            if delay > 0:
                sleep(delay)
        yield item



MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 0x03, 0x04, 0x05, 0x06


@dataclass
class McapSalvage:
    """What a damaged MCAP file still holds, read record by record up to the first incomplete one.

    schemas: id → (name, encoding, data); channels: id → (schema id, topic, message encoding, metadata map);
    messages: (channel id, log time ns, payload) in file order; chunks: complete chunk records read;
    partial_messages: messages taken from an incomplete uncompressed chunk at the end (its complete records);
    size: bytes of the file; discarded: bytes at its end that hold no complete record.
    """

    schemas: dict[int, tuple[str, str, bytes]] = field(default_factory=dict)
    channels: dict[int, tuple[int, str, str, dict[str, str]]] = field(default_factory=dict)
    messages: list[tuple[int, int, bytes]] = field(default_factory=list)
    chunks: int = 0
    partial_messages: int = 0
    size: int = 0
    discarded: int = 0


def salvage_mcap(path: str | Path) -> McapSalvage:
    """The complete records of an MCAP file that may end anywhere (a writer killed before its footer).

    Raises:
        BagError: the file is missing or does not start with the MCAP magic.
    """
    p = Path(path)
    try:
        data = memoryview(p.read_bytes())
    except OSError as exc:
        raise BagError(f"cannot read {p}: {exc}") from exc
    if bytes(data[:len(MCAP_MAGIC)]) != MCAP_MAGIC:
        raise BagError(f"{p} is not an MCAP file ({len(data)} bytes, no MCAP magic)")
    out = McapSalvage(size=len(data))
    out.discarded = len(data) - len(MCAP_MAGIC) - _scan(data[len(MCAP_MAGIC):], out, top=True)
    return out


def _string(buf: memoryview, at: int) -> tuple[str, int]:
    n = int.from_bytes(buf[at:at + 4], "little")
    if at + 4 + n > len(buf):
        raise IndexError("string beyond its record")
    return bytes(buf[at + 4:at + 4 + n]).decode(), at + 4 + n


def _scan(buf: memoryview, out: McapSalvage, top: bool = False) -> int:
    """Read the schema, channel and message records of `buf` (and those inside its chunks) into `out`; the offset
    just past the last complete record. The footer's magic (8 bytes, no record) ends a top-level scan."""
    at = 0
    while at + 9 <= len(buf):
        op, size = buf[at], int.from_bytes(buf[at + 1:at + 9], "little")
        body = buf[at + 9:at + 9 + size]
        try:
            if op == _OP_CHUNK and top:
                if not _chunk(body, size, out):
                    return at
            elif len(body) < size:
                return at
            else:
                _record(op, body, out)
        except (IndexError, ValueError):   # a record cut short inside (or garbage): stop before it
            return at
        at += 9 + size
    return at


def _chunk(body: memoryview, size: int, out: McapSalvage) -> bool:
    """One chunk record: True when complete. An incomplete one written uncompressed gives its complete records."""
    compression, pos = _string(body, 28)
    length = int.from_bytes(body[pos:pos + 8], "little")
    data = body[pos + 8:pos + 8 + length]
    if len(body) == size and len(data) == length:
        size_raw = int.from_bytes(body[16:24], "little")
        _scan(memoryview(_decompress(bytes(data), compression, size_raw)), out)
        out.chunks += 1
        return True
    if compression == "":
        n = len(out.messages)
        _scan(data, out)
        out.partial_messages = len(out.messages) - n
    return False


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    """A chunk's records (rosbags' decompressors: none, lz4, zstd)."""
    from rosbags.rosbag2.storage_mcap import decompress

    try:
        return decompress(data, compression, size, 0)
    except Exception as exc:  # noqa: BLE001 - rosbags' ReaderError or a codec's error: a damaged chunk
        raise ValueError(f"chunk does not decompress: {exc}") from exc


def _record(op: int, body: memoryview, out: McapSalvage) -> None:
    if op == _OP_SCHEMA:
        name, pos = _string(body, 2)
        encoding, pos = _string(body, pos)
        n = int.from_bytes(body[pos:pos + 4], "little")
        out.schemas[int.from_bytes(body[0:2], "little")] = (name, encoding, bytes(body[pos + 4:pos + 4 + n]))
    elif op == _OP_CHANNEL:
        topic, pos = _string(body, 4)
        encoding, pos = _string(body, pos)
        end = pos + 4 + int.from_bytes(body[pos:pos + 4], "little")
        pos, meta = pos + 4, {}
        while pos < end:
            key, pos = _string(body, pos)
            meta[key], pos = _string(body, pos)
        out.channels[int.from_bytes(body[0:2], "little")] = (int.from_bytes(body[2:4], "little"), topic, encoding,
                                                             meta)
    elif op == _OP_MESSAGE:
        if len(body) < 22:
            raise ValueError("message record shorter than its header")
        out.messages.append((int.from_bytes(body[0:2], "little"), int.from_bytes(body[6:14], "little"),
                             bytes(body[22:])))
