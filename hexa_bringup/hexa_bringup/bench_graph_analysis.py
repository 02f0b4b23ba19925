"""ROS-free analysis of `hexa bench graph` runs: stamps from raw CDR, latency statistics, matching of residuals to
current samples, and the comparison of a replay's outputs with a slow reference replay."""
from __future__ import annotations

from collections import Counter, defaultdict, deque
from typing import Iterable, Sequence

import numpy as np


def cdr_stamp_ns(data: bytes) -> int:
    """Header stamp (ns) of a serialized message whose first field is a std_msgs/Header (CDR, either endianness)."""
    order = "little" if data[1] & 1 else "big"
    sec = int.from_bytes(data[4:8], order, signed=True)
    nsec = int.from_bytes(data[8:12], order)
    return sec * 1_000_000_000 + nsec


def latency_stats(values: Iterable[float]) -> dict:
    """{n, p50, p95, max} of latencies (s); the statistics are None when there is no value."""
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if v.size == 0:
        return {"n": 0, "p50": None, "p95": None, "max": None}
    return {"n": int(v.size), "p50": float(np.percentile(v, 50)), "p95": float(np.percentile(v, 95)),
            "max": float(v.max())}


def unwrap_board_us(values: Sequence[int]) -> np.ndarray:
    """Board times (µs, a 32-bit counter) unwrapped and converted to seconds."""
    raw = np.asarray(values, dtype=np.int64)
    if raw.size == 0:
        return np.zeros(0)
    d = np.diff(raw)
    d = np.where(d < -(1 << 31), d + (1 << 32), d)
    return (raw[0] + np.concatenate([[0], np.cumsum(d)])) * 1e-6


def match_nearest(stamps: Sequence[float], times: Sequence[float], tol: float = 1e-4) -> np.ndarray:
    """For each stamp (s), the index of the nearest of `times` (s) when it is within `tol`, else -1."""
    s = np.asarray(stamps, dtype=float)
    t = np.asarray(times, dtype=float)
    idx = np.full(s.size, -1, dtype=np.int64)
    ok_t = np.isfinite(t)
    if s.size == 0 or not ok_t.any():
        return idx
    where = np.flatnonzero(ok_t)
    order = where[np.argsort(t[where], kind="stable")]
    ts = t[order]
    k = np.searchsorted(ts, s)
    lo = np.clip(k - 1, 0, ts.size - 1)
    hi = np.clip(k, 0, ts.size - 1)
    pick = np.where(np.abs(ts[lo] - s) <= np.abs(ts[hi] - s), lo, hi)
    good = np.abs(ts[pick] - s) <= tol
    idx[good] = order[pick[good]]
    return idx


def match_tracked_offset(stamps: Sequence[float], times: Sequence[float], guess: float, anchor: int = -1,
                         tol: float | None = None, probe: int = 200) -> np.ndarray:
    """For each stamp (s, in arrival order) the index of the time (s, increasing) it was made from, where each stamp
    is its time plus an offset that moves slowly from sample to sample (the observer's residual stamps: the sample's
    board time plus the host offset hexa.dynamics.monitor.SampleClock tracks; it follows the host stamps with a 10 s
    time constant, so it moves by microseconds per sample, by tens of them while it settles after a start with a late
    first sample); -1 where no time fits.

    `guess` (s) is the offset at stamp `anchor` (the observer's `board_clock_offset_s` diagnostics value and the
    residual that arrived just before it), good to a fraction of the sample period. The samples around
    `stamps[anchor] − guess` are tried there, each scored by how many of the `probe` stamps either side it then
    follows; of those that score (nearly) best — with evenly spaced samples every shift by whole periods does — the
    one nearest the guess wins. From there the offset is followed stamp by stamp in both directions, each match
    re-anchoring it (within `tol` of the next time, default a quarter of the median sample period: what the offset
    moves over a few lost stamps stays inside it); 20 stamps in a row without a match end the following.
    """
    s = np.asarray(stamps, dtype=float)
    t = np.asarray(times, dtype=float)
    idx = np.full(s.size, -1, dtype=np.int64)
    if s.size == 0 or t.size == 0:
        return idx
    k0 = anchor % s.size
    if tol is None:
        tol = 0.25 * float(np.median(np.diff(t))) if t.size > 1 else 1e-4

    def nearest(x: float) -> int:
        k = int(np.searchsorted(t, x))
        if k <= 0:
            return 0
        if k >= t.size:
            return t.size - 1
        return k if abs(t[k] - x) < abs(t[k - 1] - x) else k - 1

    def follow(off: float, step: int, limit: int, out: np.ndarray | None) -> int:
        """Follow the offset from stamp k0 + step on, at most `limit` stamps; how many matched."""
        n, misses, k = 0, 0, k0 + step
        while 0 <= k < s.size and abs(k - k0) <= limit and misses < 20:
            x = s[k] - off
            i = nearest(x)
            if abs(t[i] - x) <= tol:
                n, misses, off = n + 1, 0, s[k] - t[i]
                if out is not None:
                    out[k] = i
            else:
                misses += 1
            k += step
        return n

    centre = nearest(s[k0] - guess)
    scored = []
    for j in range(max(0, centre - 20), min(t.size, centre + 21)):
        off = s[k0] - t[j]
        scored.append((follow(off, 1, probe, None) + follow(off, -1, probe, None), j))
    best_n = max(n for n, _ in scored)
    if best_n < 0.5 * min(2 * probe, s.size - 1):
        return idx
    near = [j for n, j in scored if n >= best_n - max(2, 0.02 * best_n)]
    j0 = min(near, key=lambda j: abs(s[k0] - t[j] - guess))
    idx[k0] = j0
    follow(s[k0] - t[j0], 1, s.size, idx)
    follow(s[k0] - t[j0], -1, s.size, idx)
    return idx


def fifo_pairs(keys_a: Sequence, keys_b: Sequence) -> list[tuple[int, int]]:
    """(i, j) pairs with keys_a[i] == keys_b[j], the k-th occurrence of a key in `a` paired with its k-th
    occurrence in `b` (frames that share a stamp)."""
    slots: dict = defaultdict(deque)
    for j, k in enumerate(keys_b):
        slots[k].append(j)
    out = []
    for i, k in enumerate(keys_a):
        if slots[k]:
            out.append((i, slots[k].popleft()))
    return out


def compare_events(run: list[dict], ref: list[dict], sample_period: float) -> tuple[bool, str]:
    """Same collision events as the reference: the same START/END sequence with each onset within one sample.

    Events are dicts {kind: "START" | "END", id, onset (s), stamp (s)}."""
    kinds_run = [e["kind"] for e in sorted(run, key=lambda e: (e["stamp"], e["kind"] != "START"))]
    kinds_ref = [e["kind"] for e in sorted(ref, key=lambda e: (e["stamp"], e["kind"] != "START"))]
    if kinds_run != kinds_ref:
        return False, f"events {'/'.join(kinds_run) or 'none'} vs reference {'/'.join(kinds_ref) or 'none'}"
    a = sorted(run, key=lambda e: (e["stamp"], e["kind"] != "START"))
    b = sorted(ref, key=lambda e: (e["stamp"], e["kind"] != "START"))
    d_onset = max((abs(x["onset"] - y["onset"]) for x, y in zip(a, b)), default=0.0)
    d_stamp = max((abs(x["stamp"] - y["stamp"]) for x, y in zip(a, b)), default=0.0)
    ok = d_onset <= sample_period * 1.001 + 1e-9
    return ok, (f"{len(a)} events; max |onset difference| {d_onset * 1e3:.1f} ms, max |event time difference| "
                f"{d_stamp * 1e3:.1f} ms (1 sample = {sample_period * 1e3:.1f} ms)")


def compare_contacts(run: list[dict], ref: list[dict]) -> tuple[bool, str]:
    """Same contacts as the reference: count and (link, chain) of each, in stamp order; dicts {stamp, id, link,
    chain}."""
    names = {0: "plate", 1: "arm", 2: "rod", 255: "unknown"}

    def seq(cs: list[dict]) -> list[tuple[int, int]]:
        return [(int(c["link"]), int(c["chain"])) for c in sorted(cs, key=lambda c: c["stamp"])]

    a, b = seq(run), seq(ref)
    ok = a == b

    def text(s: list[tuple[int, int]]) -> str:
        c = Counter(s)
        return ", ".join(f"{n}x {names.get(k[0], k[0])}" + (f" {k[1]}" if k[1] else "") for k, n in c.items()) or "none"

    return ok, f"{len(a)} contacts ({text(a)}) vs reference {len(b)} ({text(b)})"


def within_percent(value: int, ref: int, percent: float) -> bool:
    """|value - ref| <= percent % of ref (equal counts when ref is 0)."""
    return abs(value - ref) <= percent / 100.0 * ref if ref else value == 0
