"""Deterministic, non-default sample values for any ROS message type (for round-trip tests)."""
from __future__ import annotations

from typing import Any

from rosidl_parser.definition import (AbstractNestedType, Array, BasicType, BoundedSequence,
                                      NamespacedType, AbstractString)

_INT_RANGES = {"int8": (-128, 127), "uint8": (0, 255), "byte": (0, 255), "char": (0, 255),
               "int16": (-32768, 32767), "uint16": (0, 65535), "int32": (-2**31, 2**31 - 1),
               "uint32": (0, 2**32 - 1), "int64": (-2**63, 2**63 - 1), "uint64": (0, 2**64 - 1)}


def _basic(typename: str, k: int) -> Any:
    if typename == "boolean":
        return k % 2 == 1
    if typename in ("float", "double"):
        return (k + 1) * 0.25 + (0.5 if typename == "double" else 0.0)
    if typename == "octet":
        return bytes([(k * 37 + 11) % 256])
    lo, hi = _INT_RANGES[typename]
    return lo + (k * 7919 + 13) % (hi - lo + 1) if lo < 0 else (k * 7919 + 13) % (hi + 1)


def _value(slot, k: int, in_array: bool = False) -> Any:
    if isinstance(slot, BasicType):
        if slot.typename == "boolean" and not in_array:
            return True
        return _basic(slot.typename, k)
    if isinstance(slot, AbstractString):
        return f"sample-{k}"
    if isinstance(slot, NamespacedType):
        import importlib

        cls = getattr(importlib.import_module(".".join(slot.namespaces)), slot.name)
        return sample_message(cls, k)
    if isinstance(slot, AbstractNestedType):
        if isinstance(slot, Array):
            n = slot.size
        elif isinstance(slot, BoundedSequence):
            n = min(2, slot.maximum_size)
        else:
            n = 3
        return [_value(slot.value_type, k + i + 1, True) for i in range(n)]
    raise TypeError(f"unsupported slot {slot!r}")


def sample_message(cls: type, k: int = 1) -> Any:
    """An instance of `cls` with every field set to a value that differs from its default (seeded by k)."""
    msg = cls()
    for i, (name, slot) in enumerate(zip(msg.get_fields_and_field_types(), cls.SLOT_TYPES)):
        setattr(msg, name, _value(slot, k * 31 + i))
    return msg
