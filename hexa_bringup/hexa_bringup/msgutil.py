"""Message helpers the missing rosidl_runtime_py would give: type lookup and message ↔ plain-Python conversion."""
from __future__ import annotations

import array
import importlib
from typing import Any

import numpy as np


class MessageTypeError(LookupError):
    """A message type name cannot be resolved to an importable class."""


def get_message_class(type_name: str) -> type:
    """Class of `type_name` ("pkg/msg/Name" or "pkg/Name"), e.g. "hexa_msgs/msg/CollisionEvent".

    Raises:
        MessageTypeError: the name is malformed or its package is not installed.
    """
    parts = type_name.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts):
        raise MessageTypeError(f"malformed message type {type_name!r}; expected 'pkg/msg/Name'")
    pkg, kind, name = parts
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise MessageTypeError(f"message type {type_name!r} is not installed ({exc})") from exc


def _is_message(value: Any) -> bool:
    return hasattr(value, "get_fields_and_field_types")


def message_to_dict(msg: Any, max_array: int | None = None) -> dict[str, Any]:
    """Plain dict of `msg` (nested messages as dicts, arrays as lists).

    Args:
        msg: a ROS message instance.
        max_array: if given, longer arrays are cut to this many items and a note "...(N items)" appended.
    """
    out: dict[str, Any] = {}
    for field in msg.get_fields_and_field_types():
        out[field] = _to_plain(getattr(msg, field), max_array)
    return out


def _to_plain(value: Any, max_array: int | None) -> Any:
    if _is_message(value):
        return message_to_dict(value, max_array)
    if isinstance(value, (list, tuple, array.array, np.ndarray)):
        items = list(value)
        n = len(items)
        if max_array is not None and n > max_array:
            items = items[:max_array]
            return [_to_plain(v, max_array) for v in items] + [f"...({n} items)"]
        return [_to_plain(v, max_array) for v in items]
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, np.generic):
        return value.item()
    return value


def set_message_fields(msg: Any, values: dict[str, Any]) -> Any:
    """Fill `msg` from a plain dict (the inverse of message_to_dict); returns `msg`.

    Raises:
        KeyError: a key that is not a field of the message (naming it).
    """
    fields = msg.get_fields_and_field_types()
    for key, value in values.items():
        if key not in fields:
            raise KeyError(f"{type(msg).__name__} has no field {key!r}; fields: {list(fields)}")
        current = getattr(msg, key)
        if _is_message(current) and isinstance(value, dict):
            set_message_fields(current, value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            slot_type = fields[key]
            inner = slot_type.split("<", 1)[1].rstrip(">") if "<" in slot_type else slot_type.rstrip("[]")
            inner = inner.split("[", 1)[0]
            cls = get_message_class(inner)
            setattr(msg, key, [set_message_fields(cls(), v) for v in value])
        else:
            setattr(msg, key, value)
    return msg
