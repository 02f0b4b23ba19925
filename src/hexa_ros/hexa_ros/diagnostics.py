"""/diagnostics for every node: a status from a node's counters, published as one DiagnosticArray."""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

OK, WARN, ERROR, STALE = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR, DiagnosticStatus.STALE


def status(name: str, level: int, message: str, values: Mapping[str, Any], hardware_id: str = "") -> DiagnosticStatus:
    """A DiagnosticStatus with `values` as key/value strings (sorted by key when `values` is not ordered)."""
    st = DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id)
    st.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    return st


def values_of(st: Any) -> dict[str, str]:
    """A received DiagnosticStatus's key/value pairs as a dict (any message class with `values` of key/value)."""
    return {kv.key: kv.value for kv in st.values}


def rejects(counters: Mapping[str, Any]) -> int:
    """The number of rejected inputs among `counters`: the values of keys that name a reject."""
    return int(sum(v for k, v in counters.items() if "reject" in k and isinstance(v, (int, float))))


def counter_status(name: str, counters: Mapping[str, Any], ok_message: str, hardware_id: str = "") -> DiagnosticStatus:
    """OK with `ok_message`, or WARN "n input(s) rejected" when a counter named `…reject…` is above zero."""
    n = rejects(counters)
    level, msg = (WARN, f"{n} input(s) rejected") if n else (OK, ok_message)
    return status(name, level, msg, dict(sorted(counters.items())), hardware_id)


def array(node: Any, statuses: list[DiagnosticStatus]) -> DiagnosticArray:
    """A DiagnosticArray stamped with the node's clock."""
    arr = DiagnosticArray()
    arr.header.stamp = node.get_clock().now().to_msg()
    arr.status = statuses
    return arr
