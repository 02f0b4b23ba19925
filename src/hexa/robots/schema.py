"""Reading robot-description YAML with validation that names the offending key."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

DESCRIPTION_DIR = Path(__file__).resolve().parent


class RobotDescriptionError(ValueError):
    """A robot description is missing a key, has a wrong shape, or a value out of range."""


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping from `path`.

    Raises:
        RobotDescriptionError: the file is missing, unreadable, or not a mapping.
    """
    p = Path(path)
    if not p.is_file():
        raise RobotDescriptionError(f"robot description {p} does not exist")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise RobotDescriptionError(f"robot description {p} is not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise RobotDescriptionError(f"robot description {p} must be a mapping at top level")
    return data


def _get(data: dict[str, Any], key: str) -> Any:
    node: Any = data
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise RobotDescriptionError(f"missing key '{key}' in robot description")
        node = node[part]
    return node


def require_float(data: dict[str, Any], key: str, *, positive: bool = False, nonneg: bool = False,
                  lo: float | None = None, hi: float | None = None) -> float:
    """The float at dotted `key`, checked finite and within the given bounds.

    Raises:
        RobotDescriptionError: naming `key` and the bad value.
    """
    raw = _get(data, key)
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise RobotDescriptionError(f"key '{key}' must be a number (SI units), got {raw!r}")
    v = float(raw)
    if not np.isfinite(v):
        raise RobotDescriptionError(f"key '{key}' must be finite, got {v}")
    if positive and v <= 0:
        raise RobotDescriptionError(f"key '{key}' must be > 0, got {v}")
    if nonneg and v < 0:
        raise RobotDescriptionError(f"key '{key}' must be >= 0, got {v}")
    if lo is not None and v < lo:
        raise RobotDescriptionError(f"key '{key}' must be >= {lo}, got {v}")
    if hi is not None and v > hi:
        raise RobotDescriptionError(f"key '{key}' must be <= {hi}, got {v}")
    return v


def require_array(data: dict[str, Any], key: str, shape: tuple[int, ...]) -> np.ndarray:
    """The numeric array at dotted `key` with exactly `shape` (read-only float64 copy).

    Raises:
        RobotDescriptionError: naming `key`, the expected and the actual shape.
    """
    raw = _get(data, key)
    try:
        arr = np.array(raw, dtype=float)
    except (TypeError, ValueError) as exc:
        raise RobotDescriptionError(f"key '{key}' must be numeric, got {raw!r}") from exc
    if arr.shape != shape:
        raise RobotDescriptionError(f"key '{key}' must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise RobotDescriptionError(f"key '{key}' must be finite, got {arr.tolist()}")
    arr.setflags(write=False)
    return arr


def require_str(data: dict[str, Any], key: str, choices: tuple[str, ...] | None = None) -> str:
    """The string at dotted `key`, optionally one of `choices`."""
    raw = _get(data, key)
    if not isinstance(raw, str):
        raise RobotDescriptionError(f"key '{key}' must be a string, got {raw!r}")
    if choices is not None and raw not in choices:
        raise RobotDescriptionError(f"key '{key}' must be one of {choices}, got {raw!r}")
    return raw
