"""Benchmark registry for `hexa bench`: each area registers functions that return measured rows."""
from __future__ import annotations

import importlib
import pkgutil
import time
from dataclasses import dataclass, asdict
from typing import Callable

_REGISTRY: dict[str, Callable[[bool], list["BenchRow"]]] = {}


@dataclass
class BenchRow:
    """One measured figure beside its target.

    Args are the benchmark's name, the measured value, its unit, the target as text (e.g. "<= 20 us"),
    and whether the target is met (None when there is no target).
    """

    name: str
    value: float
    unit: str
    target: str = ""
    met: bool | None = None
    note: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


def register(area: str) -> Callable:
    """Decorator registering `fn(quick: bool) -> list[BenchRow]` under `area` (e.g. "kinematics")."""

    def deco(fn: Callable[[bool], list[BenchRow]]) -> Callable[[bool], list[BenchRow]]:
        _REGISTRY[area] = fn
        return fn

    return deco


def discover() -> dict[str, Callable[[bool], list[BenchRow]]]:
    """Import every module of this package so their @register calls run; return the registry."""
    for mod in pkgutil.iter_modules(__path__):
        importlib.import_module(f"{__name__}.{mod.name}")
    return dict(_REGISTRY)


def time_per_call(fn: Callable[[], object], min_time: float = 0.3, repeat: int = 3) -> float:
    """Best-of-`repeat` seconds per call of `fn`, each trial running at least `min_time` seconds."""
    n = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        dt = time.perf_counter() - t0
        if dt >= min_time / 4 or n > 1_000_000:
            break
        n *= 4
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best
