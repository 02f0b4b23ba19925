"""Rosbag2 (MCAP) recording, playback and crash recovery of raw CDR messages with rosbags, with hexa_msgs types.

A recording survives a crash (SIGKILL, power cut of the process) up to its last flushed chunk: `BagRecorder` closes
an MCAP chunk and flushes the file at least every `chunk_period` s, and `recover_bag` rebuilds a readable bag (MCAP
with its index and footer, metadata.yaml) from what a killed recorder left.
"""
from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from hexa.bags import BagError, paced, read_bag, salvage_mcap

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["BagError", "BagRecorder", "Recovery", "bag_topics", "paced", "read_bag", "recover_bag", "typestore"]

#: s of messages a recorder holds in memory at most before they are on disk (one MCAP chunk)
CHUNK_PERIOD = 0.5


def _hexa_msgs_dir() -> Path | None:
    try:
        from ament_index_python.packages import get_package_share_directory

        share = Path(get_package_share_directory("hexa_msgs")) / "msg"
        if share.is_dir():
            return share
    except Exception:  # noqa: BLE001 - ament index absent: fall back to the source tree
        pass
    src = Path(__file__).resolve().parents[2] / "hexa_msgs" / "msg"
    return src if src.is_dir() else None


def typestore() -> "Typestore":
    """rosbags typestore of ROS 2 Jazzy plus every hexa_msgs message (from the installed .msg files)."""
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    store = get_typestore(Stores.ROS2_JAZZY)
    folder = _hexa_msgs_dir()
    if folder is not None:
        types = {}
        for f in sorted(folder.glob("*.msg")):
            types.update(get_types_from_msg(f.read_text(), f"hexa_msgs/msg/{f.stem}"))
        store.register(types)
    return store


def _qos_yaml(reliable: bool, transient_local: bool) -> list:
    from rosbags.rosbag2.metadata import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    zero = QosTime(sec=0, nsec=0)
    return [Qos(history=QosHistory.KEEP_LAST, depth=10,
                reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
                durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
                deadline=zero, lifespan=zero, liveliness=QosLiveliness.AUTOMATIC,
                liveliness_lease_duration=zero, avoid_ros_namespace_conventions=False)]


class BagRecorder:
    """Writes raw CDR messages to a new MCAP rosbag2; a context manager that closes (finalises) the bag.

    Args:
        path: bag directory to create.
        chunk_period: the messages of the last `chunk_period` s at most are held in memory: then the MCAP chunk is
            closed and the file flushed (`write`, `tick`), so that a killed recorder loses no more.
    """

    def __init__(self, path: str | Path, chunk_period: float = CHUNK_PERIOD) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already, not overwriting")
        if not chunk_period > 0:
            raise BagError(f"chunk_period must be > 0 s, got {chunk_period}")
        self.chunk_period = float(chunk_period)
        self._store = typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._connections: dict[str, object] = {}
        self._chunk_start = time.monotonic()
        self.counts: dict[str, int] = {}

    def __enter__(self) -> "BagRecorder":
        self._writer.open()
        self._writer.storage.bio.flush()         # the MCAP header on disk: a killed recorder leaves an MCAP file
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def add_topic(self, topic: str, msgtype: str, reliable: bool = True, transient_local: bool = False) -> None:
        """Declare `topic` of ROS type `msgtype` ("pkg/msg/Name") before writing to it.

        Raises:
            BagError: the type is unknown to the typestore.
        """
        if topic in self._connections:
            return
        if msgtype not in self._store.fielddefs:
            raise BagError(f"cannot record {topic}: message type {msgtype} is unknown (not Jazzy nor hexa_msgs)")
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self._store, offered_qos_profiles=_qos_yaml(reliable, transient_local))
        self.counts[topic] = 0

    def write(self, topic: str, stamp_ns: int, cdr: bytes) -> None:
        """Append one serialized message received at `stamp_ns` (ns since the epoch, or sim time)."""
        self._writer.write(self._connections[topic], stamp_ns, cdr)
        self.counts[topic] += 1
        self.tick()

    def tick(self, now: float | None = None) -> None:
        """Close the pending chunk and flush the file when it is `chunk_period` s old (host monotonic `now`)."""
        now = time.monotonic() if now is None else now
        if now - self._chunk_start < self.chunk_period:
            return
        self._chunk_start = now
        storage = self._writer.storage           # rosbags' McapWriter: its pending chunk and file
        if storage is not None and storage.chunk.msgs:
            storage.close_chunk()
            storage.bio.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None  # type: ignore[assignment]


def bag_topics(path: str | Path) -> dict[str, tuple[str, int, bool]]:
    """topic → (msgtype, message count, reliable) of a bag."""
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.metadata import QosReliability

    with Reader(Path(path)) as reader:
        out = {}
        for c in reader.connections:
            qos = getattr(c.ext, "offered_qos_profiles", []) or []
            reliable = not qos or all(getattr(q, "reliability", None) != QosReliability.BEST_EFFORT for q in qos)
            out[c.topic] = (c.msgtype, c.msgcount, reliable)
        return out


class Recovery(NamedTuple):
    """What `recover_bag` rebuilt: messages per topic, their time span (ns), and what was lost."""

    output: Path
    counts: dict[str, int]
    start_ns: int
    end_ns: int
    chunks: int
    partial_messages: int
    discarded_bytes: int
    damaged: Path | None


def recover_bag(path: str | Path, output: str | Path | None = None) -> Recovery:
    """Rebuild a readable bag from the MCAP a killed recorder left (no footer, no metadata.yaml).

    Every complete record is kept: whole chunks, and the complete messages of a last chunk cut short; the bytes
    after the last complete record are lost (the messages recorded after `end_ns`).

    Args:
        path: the damaged bag directory (holding one .mcap file) or the .mcap file.
        output: bag directory to write (must not exist); None: in place, the damaged directory moved to
            `<path>.damaged`.

    Returns:
        The Recovery: output bag, counts per topic, time span, what was discarded, where the damaged file went.

    Raises:
        BagError: nothing to recover (no .mcap, a readable bag already), a type unknown to the typestore, or the
            output exists.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.storage_mcap import get_qos

    src = Path(path)
    files = sorted(src.glob("*.mcap")) if src.is_dir() else [src]
    if not files or not files[0].is_file():
        raise BagError(f"no MCAP file in {src}")
    if len(files) > 1:
        raise BagError(f"{src} holds {len(files)} MCAP files: recover one at a time ({files[0].name}, ...)")
    bag_dir = src if src.is_dir() else src.parent
    if (bag_dir / "metadata.yaml").exists():
        try:
            bag_topics(bag_dir)
        except Exception:  # noqa: BLE001 - unreadable despite its metadata: recover it
            pass
        else:
            raise BagError(f"{bag_dir} is a readable bag already: nothing to recover")
    salvage = salvage_mcap(files[0])
    store = typestore()
    damaged = None
    if output is None:
        damaged = bag_dir.with_name(bag_dir.name + ".damaged")
        if damaged.exists():
            raise BagError(f"{damaged} exists already, not overwriting")
        out = bag_dir
    else:
        out = Path(output)
        if out.exists():
            raise BagError(f"{out} exists already, not overwriting")
    for _schema, _topic, _enc, _meta in salvage.channels.values():
        name = salvage.schemas.get(_schema, ("?",))[0]
        if name not in store.fielddefs:
            raise BagError(f"cannot recover {_topic}: message type {name} is unknown (not Jazzy nor hexa_msgs)")
    if damaged is not None:
        bag_dir.rename(damaged)
    writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
    try:
        writer.open()
        conns, topics = {}, {}
        for cid, (schema_id, topic, encoding, meta) in sorted(salvage.channels.items()):
            qos = get_qos(_metadata_bytes(meta))
            conns[cid] = writer.add_connection(topic, salvage.schemas[schema_id][0], typestore=store,
                                               serialization_format=encoding, offered_qos_profiles=qos)
            topics[cid] = topic
        counts = {t: 0 for t in topics.values()}
        stamps = []
        for cid, stamp, data in sorted(salvage.messages, key=lambda m: m[1]):
            if cid in conns:
                writer.write(conns[cid], stamp, data)
                counts[topics[cid]] += 1
                stamps.append(stamp)
        writer.close()
    except Exception:
        if writer.storage is not None:
            writer.abort()
        shutil.rmtree(out, ignore_errors=True)
        if damaged is not None:
            damaged.rename(bag_dir)
        raise
    return Recovery(out, counts, min(stamps, default=0), max(stamps, default=0), salvage.chunks,
                    salvage.partial_messages, salvage.discarded, damaged)


def _metadata_bytes(meta: dict[str, str]) -> bytes:
    """An MCAP channel's metadata map as its record encodes it (for rosbags' QoS parser)."""
    out = b""
    for key, value in meta.items():
        for text in (key, value):
            raw = text.encode()
            out += len(raw).to_bytes(4, "little") + raw
    return out
