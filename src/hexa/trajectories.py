"""Plate trajectories of the Hexa in SI units, with derivatives: the test trajectories of seed 000 (circle eq 37,
helix eq 40, ellipse eq 41), periodic Fourier series (`FourierTrajectory`: the calibration's excitation and the
random trajectories of `hexa.random_trajectory`), and pose files.

Each trajectory maps time t (s, scalar or array) to `(pose, pose_dot, pose_ddot)`, each (…, 6): x y z (m) and the
Z-Y-X Tait–Bryan angles α β γ (rad) of eq 38, then their first and second time derivatives. The paper gives the
formulas in mm and degrees; they are converted here. All three share ω = 0.4π rad/s (period 5 s) and start at
(x, y) = (a, 0) with non-zero velocity, as in the paper; `DURATIONS` is the run length used by the demo (two turns).
`trajectory_named` resolves a name: the paper's three, "random:SEED" (the random trajectory of SEED), "file", or
names joined by "+" (a `sequence`: "circle+helix+ellipse" plays the three in turn).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

OMEGA = 0.4 * math.pi          # rad/s (eqs 37, 40, 41)
Z0 = -0.550                    # m
ALPHA = math.radians(-6.0)     # rad
OFFSET = math.radians(1.0)     # rad, the "1 +" / "1 −" of β and γ

Trajectory = Callable[[float | np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


def _planar(t: float | np.ndarray, ax: float, ay: float, z_rate: float,
            tilt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.asarray(t, dtype=float)
    w = OMEGA
    c, s = np.cos(w * t), np.sin(w * t)
    zero, one = np.zeros_like(t), np.ones_like(t)
    pose = np.stack([ax * c, ay * s, Z0 + z_rate * t, ALPHA * one, OFFSET - tilt * c, OFFSET + tilt * s], -1)
    vel = np.stack([-ax * w * s, ay * w * c, z_rate * one, zero, tilt * w * s, tilt * w * c], -1)
    acc = np.stack([-ax * w * w * c, -ay * w * w * s, zero, zero, tilt * w * w * c, -tilt * w * w * s], -1)
    return pose, vel, acc


def circle(t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Circle of radius 0.1 m at z = −0.55 m, β = 1° − 30° cos ωt, γ = 1° + 30° sin ωt (seed 000, eq 37)."""
    return _planar(t, 0.100, 0.100, 0.0, math.radians(30.0))


def helix(t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Helix: the circle rising 5 mm/s from z = −0.55 m, tilts of 25° (seed 000, eq 40)."""
    return _planar(t, 0.100, 0.100, 0.005, math.radians(25.0))


def ellipse(t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ellipse with semi-axes 0.08 m (x) and 0.11 m (y) at z = −0.55 m, tilts of 30° (seed 000, eq 41)."""
    return _planar(t, 0.080, 0.110, 0.0, math.radians(30.0))


TRAJECTORIES: dict[str, Trajectory] = {"circle": circle, "helix": helix, "ellipse": ellipse}

#: Run length (s) of each trajectory: two periods; covers the paper's collision instants (3.4–5.6 s).
DURATIONS: dict[str, float] = {"circle": 10.0, "helix": 10.0, "ellipse": 10.0}
#: a trajectory name "random:SEED" is the random smooth reachable trajectory of SEED (hexa.random_trajectory)
RANDOM_PREFIX = "random:"


@dataclass
class FourierTrajectory:
    """A periodic plate trajectory: per DOF k (x y z α β γ)

        q_k(t) = q0_k + Σ_{l=1..L} a_kl sin(l ω t) + b_kl (cos(l ω t) − 1),      ω = 2π / period,

    so q(0) = q0 and the motion repeats every `period` s; `cycles` periods make its `duration`. a, b: (6, L)."""

    q0: np.ndarray
    a: np.ndarray
    b: np.ndarray
    period: float
    cycles: int = 1

    @property
    def duration(self) -> float:
        return self.period * self.cycles

    def evaluate(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(pose, pose_dot, pose_ddot), each (…, 6), at times t (s)."""
        t = np.asarray(t, dtype=float)
        L = self.a.shape[1]
        w = 2.0 * math.pi / self.period * np.arange(1, L + 1)
        ph = t[..., None] * w                                    # (…, L)
        s, c = np.sin(ph), np.cos(ph)
        pose = self.q0 + s @ self.a.T + (c - 1.0) @ self.b.T
        vel = (c * w) @ self.a.T - (s * w) @ self.b.T
        acc = -(s * w * w) @ self.a.T - (c * w * w) @ self.b.T
        return pose, vel, acc

    def __call__(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.evaluate(t)

    def pose_function(self) -> Callable[[float], np.ndarray]:
        return lambda t: self.evaluate(t)[0]

    def write(self, path: str | Path, rate_hz: float = 100.0, title: Sequence[str] = ()) -> Path:
        """Write the pose file the trajectory node plays (`hexa bringup sim|robot --trajectory FILE`: CSV rows
        t x y z α β γ, SI, at `rate_hz`), `cycles` periods long; `title` lines and the series (period, q0, a, b,
        read back by `read_design`) go in `#` comment lines."""
        head = [*title, "period " + repr(float(self.period)), "q0 " + " ".join(repr(float(v)) for v in self.q0),
                "a " + " ".join(repr(float(v)) for v in self.a.ravel()),
                "b " + " ".join(repr(float(v)) for v in self.b.ravel())]
        return write_pose_file(path, self.evaluate, self.duration, rate_hz, head)

    @classmethod
    def read_design(cls, path: str | Path) -> "FourierTrajectory | None":
        """The series in a file written by `write` (None when the file has no series lines)."""
        vals: dict[str, list[float]] = {}
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if not line.startswith("#"):
                    break
                key, _, rest = line[1:].strip().partition(" ")
                if key in ("period", "q0", "a", "b"):
                    vals[key] = [float(v) for v in rest.split()]
        if set(vals) != {"period", "q0", "a", "b"}:
            return None
        return cls(q0=np.asarray(vals["q0"]), a=np.asarray(vals["a"]).reshape(6, -1),
                   b=np.asarray(vals["b"]).reshape(6, -1), period=vals["period"][0])


def sample(name: str, rate_hz: float = 100.0,
           duration: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Times (N,) and pose, pose_dot, pose_ddot (N, 6) of trajectory `name` (one of TRAJECTORIES or "random:SEED")
    sampled at `rate_hz`.

    Raises:
        KeyError: unknown trajectory name (the message lists the known ones).
    """
    try:
        fn, T = trajectory_named(name)
    except ValueError as exc:
        raise KeyError(str(exc)) from None
    T = T if duration is None else float(duration)
    t = np.arange(int(round(T * rate_hz)) + 1) / rate_hz
    return (t, *fn(t))


def write_pose_file(path: str | Path, trajectory: Trajectory, duration: float, rate_hz: float = 100.0,
                    title: Sequence[str] = ()) -> Path:
    """Write `duration` s of `trajectory` at `rate_hz` as the pose file `load_pose_file` reads and the trajectory
    node plays (CSV rows t x y z α β γ, SI), with `title` lines as `#` comments."""
    p = Path(path)
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    pose = np.asarray(trajectory(t)[0], dtype=float)
    np.savetxt(p, np.column_stack([t, pose]), delimiter=",", fmt="%.9g",
               header="\n".join([*title, "t x y z alpha beta gamma (s, m, rad)"]))
    return p


def load_pose_file(path: str | Path) -> tuple[Trajectory, float]:
    """A trajectory from a CSV file of rows t x y z α β γ (SI), linearly interpolated, and its duration (s).

    The rates are the file's finite differences (np.gradient), the accelerations zero.

    Raises:
        ValueError: the file has the wrong number of columns, non-finite values or non-increasing time.
        OSError: the file cannot be read.
    """
    data = np.loadtxt(path, delimiter=",", ndmin=2, comments="#")
    if data.shape[1] != 7:
        raise ValueError(f"{path}: expected 7 columns (t x y z alpha beta gamma), got {data.shape[1]}")
    if not np.all(np.isfinite(data)):
        raise ValueError(f"{path}: non-finite values")
    t = data[:, 0]
    if np.any(np.diff(t) <= 0):
        raise ValueError(f"{path}: time must increase strictly")
    poses = data[:, 1:]
    rates = np.gradient(poses, t, axis=0) if len(t) > 1 else np.zeros_like(poses)

    def traj(tt: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pose = np.array([np.interp(tt, t, poses[:, k]) for k in range(6)])
        rate = np.array([np.interp(tt, t, rates[:, k]) for k in range(6)])
        return pose, rate, np.zeros(6)

    return traj, float(t[-1] - t[0]) if len(t) > 1 else 0.0


def random_seed_of(name: str) -> int | None:
    """SEED of a trajectory name "random:SEED", None for any other name.

    Raises:
        ValueError: "random:" followed by something other than a non-negative integer.
    """
    if not name.startswith(RANDOM_PREFIX):
        return None
    tail = name[len(RANDOM_PREFIX):]
    if not tail.isdigit():
        raise ValueError(f"a random trajectory is named random:SEED with SEED an integer >= 0, got {name!r}")
    return int(tail)


#: s: the cross-fade from one trajectory of a sequence onto the next (as the trajectory player's loop blend)
SEQUENCE_BLEND = 2.0
#: joins the names of a sequence: "circle+helix+ellipse" plays the three in turn
SEQUENCE_SEPARATOR = "+"


def smoothstep(u: float | np.ndarray) -> float | np.ndarray:
    """s = 3u² − 2u³ of u clipped to 0..1 (a float for a scalar u): a blend from 0 to 1 that starts and ends at
    rest, the trajectory player's and a sequence's cross-fade."""
    v = np.clip(u, 0.0, 1.0)
    s = v * v * (3.0 - 2.0 * v)
    return float(s) if np.ndim(u) == 0 else s


def smoothstep_rate(u: float | np.ndarray, duration: float) -> float | np.ndarray:
    """d/dt of smoothstep(t / duration) at u = t / duration (0 outside 0..1)."""
    v = np.clip(u, 0.0, 1.0)
    d = np.where((v > 0.0) & (v < 1.0), 6.0 * v * (1.0 - v) / duration, 0.0)
    return float(d) if np.ndim(u) == 0 else d


def smoothstep_accel(u: float | np.ndarray, duration: float) -> float | np.ndarray:
    """d²/dt² of smoothstep(t / duration) at u = t / duration (0 outside 0..1, where it steps)."""
    v = np.clip(u, 0.0, 1.0)
    d = np.where((v > 0.0) & (v < 1.0), (6.0 - 12.0 * v) / (duration * duration), 0.0)
    return float(d) if np.ndim(u) == 0 else d


def cross_fade(a: Sequence[np.ndarray], b: Sequence[np.ndarray], x: float | np.ndarray,
               blend: float) -> list[np.ndarray]:
    """Cross-fade from motion `a` onto motion `b` (each [pose, rate] or [pose, rate, acceleration], the same
    instants) `x` s into a `blend` s fade, with a smoothstep s = smoothstep(x / blend): pose (1 − s)·a + s·b, its
    rate and acceleration by the product rule, so pose and rate stay continuous from `a` to `b`. Arrays of x run
    along the first axis of each motion."""
    u = np.asarray(x, dtype=float) / blend
    s, ds, dds = smoothstep(u), smoothstep_rate(u, blend), smoothstep_accel(u, blend)
    if np.ndim(u):
        s, ds, dds = (np.asarray(v)[:, None] for v in (s, ds, dds))
    out = [(1 - s) * a[0] + s * b[0], (1 - s) * a[1] + s * b[1] + ds * (b[0] - a[0])]
    if len(a) > 2:
        out.append((1 - s) * a[2] + s * b[2] + 2 * ds * (b[1] - a[1]) + dds * (b[0] - a[0]))
    return out


def sequence(parts: Sequence[tuple[Trajectory, float]], blend: float = SEQUENCE_BLEND) -> tuple[Trajectory, float]:
    """The trajectories `parts` ((trajectory, duration s) each) played in turn, and the total duration (s).

    Part k starts at the sum of the earlier durations. Over its first `blend` seconds it cross-fades from part k−1
    continued past its end onto part k with a smoothstep s: pose (1 − s)·a + s·b, its rate and acceleration the
    product rule's (`cross_fade`, which the trajectory player's loop restart uses too), so pose and rate stay
    continuous across each junction. Away from the junctions each part is played as it is.

    Raises:
        ValueError: no part, a duration not > blend (the cross-fade must end inside its part), a blend < 0.
    """
    if not parts:
        raise ValueError("a sequence needs at least one trajectory")
    if not (math.isfinite(blend) and blend >= 0):
        raise ValueError(f"blend must be >= 0 s, got {blend}")
    durations = [float(d) for _, d in parts]
    if any(not (d > blend) for d in durations):
        raise ValueError(f"every trajectory of a sequence must last longer than its {blend:g} s blend: {durations}")
    starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
    fns = [fn for fn, _ in parts]

    def traj(t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        tt = np.asarray(t, dtype=float)
        flat = tt.reshape(-1)
        k = np.clip(np.searchsorted(starts, flat, side="right") - 1, 0, len(fns) - 1)
        out = [np.zeros((flat.size, 6)) for _ in range(3)]
        for i, fn in enumerate(fns):
            idx = np.flatnonzero(k == i)
            if not idx.size:
                continue
            x = flat[idx] - starts[i]
            b = [np.asarray(v, dtype=float).reshape(-1, 6) for v in fn(x)]
            if i > 0 and blend > 0:
                a = [np.asarray(v, dtype=float).reshape(-1, 6) for v in fns[i - 1](x + durations[i - 1])]
                b = cross_fade(a, b, x, blend)
            for o, v in zip(out, b):
                o[idx] = v
        shape = tt.shape + (6,)
        pose, vel, acc = (o.reshape(shape) for o in out)
        return pose, vel, acc

    return traj, float(sum(durations))


def trajectory_named(name: str, path: str | Path = "") -> tuple[Trajectory, float]:
    """(trajectory, duration s) of `name`: one of TRAJECTORIES, "random:SEED" (hexa.random_trajectory, for the
    packaged description), "file" for the pose file at `path`, or such names (not "file") joined by "+", played in
    turn (`sequence`).

    Raises:
        ValueError: an unknown name, or a bad file (see load_pose_file).
        OSError: the file cannot be read.
    """
    if name == "file":
        return load_pose_file(path)
    if SEQUENCE_SEPARATOR in name:
        names = name.split(SEQUENCE_SEPARATOR)
        if "file" in names:
            raise ValueError(f"a sequence names trajectories, not 'file': {name!r}")
        return sequence([trajectory_named(n) for n in names])
    seed = random_seed_of(name)
    if seed is not None:
        from hexa.random_trajectory import random_trajectory

        traj = random_trajectory(seed)
        return traj, traj.duration
    if name not in TRAJECTORIES:
        raise ValueError(f"trajectory must be one of {sorted(TRAJECTORIES)}, 'random:SEED', 'file' or such names "
                         f"joined by '+', got {name!r}")
    return TRAJECTORIES[name], DURATIONS[name]
