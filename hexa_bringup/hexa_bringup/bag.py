"""Rosbag2 (MCAP) recording and playback of raw CDR messages with rosbags, including hexa_msgs types."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from hexa.bags import BagError, paced, read_bag

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["BagError", "BagRecorder", "bag_topics", "paced", "read_bag", "typestore"]


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
    """Writes raw CDR messages to a new MCAP rosbag2; a context manager that closes (finalises) the bag."""

    def __init__(self, path: str | Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already, not overwriting")
        self._store = typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._connections: dict[str, object] = {}
        self.counts: dict[str, int] = {}

    def __enter__(self) -> "BagRecorder":
        self._writer.open()
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
