"""The live collision monitor of the Hexa: board-clocked current samples → ζ estimator → residual observer (seed 000
§3.1, eqs 23-26) → residual and collision events, with the camera's plate pose folded in.

One object holds the whole per-sample pipeline the observer node runs, so that it can be tested, replayed and
benchmarked without ROS: `push_currents`, `push_states` and `push_pose` take the three input streams in any
delivery order and return the samples they complete, each already through the estimator and the observer.
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hexa.dynamics.cusum import CusumConfig, make_detector
from hexa.dynamics.observer import ObserverConfig, ObserverError, ResidualObserver, ResidualSample
from hexa.estimation import EstimatorConfig, InputCheck, SampleSequencer, ServoModel, ZetaEstimator
from hexa.pose_check import PoseCheck
from hexa.rotations import pose6_from_transform
from hexa.stream_gate import ACCEPTED, StreamGate

if TYPE_CHECKING:
    from collections.abc import Sequence

    from hexa.robots.hexa_description import HexaDescription

ZETA_SOURCES = ("estimator", "measured")
#: estimator settings the monitor takes at run time
ESTIMATOR_KEYS = ("accel_sigma", "torque_sigma", "camera_sigma", "bias_walk", "saturation", "stall_sigma")


class SampleClock:
    """Sample times from the current board's microsecond clock (wraps at 2³²) on the ROS time axis.

    `fixed_offset` given (the simulator's boards run on sim time): t = unwrapped board time + fixed_offset. Otherwise
    t = offset + unwrapped board time, the offset following the mean of (stamp − board time) with time constant `tau`
    (receive latency, host/board clock drift), re-anchored when they disagree by more than `jump` s (board reset).
    Host receive stamps jitter by milliseconds (USB, scheduling; in sim mode they are quantized by /clock), which at
    200-1000 Hz would corrupt the observer's Δt; the board's clock does not.

    Board times pass a hexa.stream_gate.StreamGate: a repeated or older board time, or one more than `jump` s after the
    last accepted one beyond the host time between their stamps (a board that was silent for a while comes back that
    much later), returns None and is counted by reason in `rejected` (older or repeated ones also in `backwards`),
    leaving the clock as it was — one board time 2·10⁹ µs ahead costs that one sample. A board clock that really
    jumped (a reset) is adopted after `adopt_after` consistent samples."""

    def __init__(self, tau: float = 10.0, jump: float = 0.5, fixed_offset: float | None = None,
                 adopt_after: int = 5) -> None:
        self.tau, self.jump, self.fixed_offset = tau, jump, fixed_offset
        self.gate: StreamGate[tuple[float, float]] = StreamGate(self._follows, adopt_after)
        self._raw: int | None = None
        self._raw0 = 0                   # the first accepted board time (µs): `board` counts from it
        self._board = 0.0
        self._offset = 0.0
        self.backwards = 0

    @property
    def board_offset(self) -> float | None:
        """Sample time − the board's own clock (s; the board's µs counter unwrapped from the first accepted value):
        what a subscriber adds to a sample's board_time_us to get the time this clock gives it now (None before the
        first sample). It moves by less than 1 µs per sample, so consecutive sample times can be traced back to
        their samples."""
        if self._raw is None:
            return None
        if self.fixed_offset is not None:
            return self.fixed_offset
        return self._offset - self._raw0 * 1e-6

    @property
    def rejected(self) -> dict[str, int]:
        """Rejected board times by reason (time_past, time_future)."""
        return dict(self.gate.rejected)

    def _follows(self, prev: tuple[float, float], new: tuple[float, float]) -> str | None:
        """(board time, stamp) `new` may follow `prev`: later on the board, by at most `jump` + the stamps' step."""
        step = new[0] - prev[0]
        if step <= 0.0:
            return "time_past"
        return "time_future" if step > self.jump + max(new[1] - prev[1], 0.0) else None

    def time(self, stamp: float, board_us: int) -> float | None:
        """The sample time (s) of a sample received at host time `stamp` with board time `board_us` (µs)."""
        raw = int(board_us) & 0xFFFFFFFF
        if self._raw is None:
            board = raw * 1e-6 if self.fixed_offset is not None else 0.0
        else:   # the signed step from the last accepted board time, across the 2³² µs wrap
            board = self._board + ((((raw - self._raw) + (1 << 31)) & 0xFFFFFFFF) - (1 << 31)) * 1e-6
        verdict = self.gate.check((board, float(stamp)))
        if verdict not in ACCEPTED:
            self.backwards += verdict == "time_past"
            return None
        first, dt = self._raw is None, board - self._board
        if first:
            self._raw0 = raw
        self._raw, self._board = raw, board
        if self.fixed_offset is not None:
            return board + self.fixed_offset
        if first or verdict == "adopted":
            self._offset = stamp - board
            return stamp
        err = stamp - (self._offset + board)
        if abs(err) > self.jump:
            self._offset = stamp - board
        else:
            self._offset += err * min(1.0, dt / self.tau)
        return self._offset + board


@dataclass(frozen=True)
class MonitorConfig:
    """Settings of the monitor beside the observer's and the estimator's.

    zeta_source: "estimator" (hobby servos: the arm samples carry the commanded angle) or "measured" (they carry the
    measured angle and velocity); time_source: "auto" | "board" | "stamp" (hexa.estimation.SampleSequencer);
    sim_clock: board time is sim time (the simulator's virtual boards); pose_delay (s): camera poses enter at sample
    time image stamp + pose_delay; reseed_distance (m): a camera pose re-seeds the observer's pose tracking when this
    far from it; command_delay (s): the servo model's command latency."""

    zeta_source: str = "estimator"
    time_source: str = "auto"
    sim_clock: bool = False
    pose_delay: float = 0.5
    reseed_distance: float = 0.005
    command_delay: float = 0.0

    @staticmethod
    def sim_clock_of(board_clock: str, use_sim_time: bool) -> bool:
        """Whether board time is sim time: "sim", "track" (follow the host stamps), or "auto" (sim under sim time).

        Raises:
            ValueError: another mode, named.
        """
        if board_clock not in ("auto", "sim", "track"):
            raise ValueError(f"board_clock must be 'auto', 'sim' or 'track', got {board_clock!r}")
        return board_clock == "sim" or (board_clock == "auto" and use_sim_time)

    def __post_init__(self) -> None:
        if self.zeta_source not in ZETA_SOURCES:
            raise ValueError(f"zeta_source must be 'estimator' or 'measured', got {self.zeta_source!r}")
        if self.time_source not in ("auto", "board", "stamp"):
            raise ValueError(f"time_source must be 'auto', 'board' or 'stamp', got {self.time_source!r}")
        if not (math.isfinite(self.pose_delay) and 0.0 <= self.pose_delay <= 0.9):
            raise ValueError(f"pose_delay must be in [0, 0.9] s (estimator history 1 s), got {self.pose_delay!r}")
        if not (math.isfinite(self.reseed_distance) and self.reseed_distance > 0):
            raise ValueError(f"reseed_distance must be > 0 m, got {self.reseed_distance!r}")


@dataclass(frozen=True)
class MonitorSample:
    """One monitored sample: the observer's output, ζ and ζ̇ it used (rad, rad/s) and the measured τ (N·m)."""

    time: float
    residual: ResidualSample
    zeta: NDArray
    zeta_dot: NDArray | None
    tau: NDArray


class CollisionMonitor:
    """Estimator + residual observer + collision detector on the driver's sample streams (module docstring).

    Usage:
        mon = CollisionMonitor(desc)
        for s in mon.push_currents(stamp, board_time_us, currents): publish(s.residual, ...)
        for s in mon.push_states(stamp, commanded, velocity, effort): ...
        for s in mon.push_pose(image_stamp, pose): ...

    `detector`: "threshold" (the paper's criterion and the servo-torque one, `CollisionDetector`) or "cusum"
    (`hexa.dynamics.cusum.CusumDetector` with `cusum`, fed ζ̂̇ before each sample).

    Raises (constructor, configure):
        ValueError (ObserverError, EstimationError): a setting out of range, naming it.
    """

    def __init__(self, desc: HexaDescription, config: MonitorConfig | None = None,
                 observer: ObserverConfig | None = None, estimator: EstimatorConfig | None = None,
                 detector: str = "threshold", cusum: CusumConfig | None = None) -> None:
        from hexa.dynamics.lagrange import HexaDynamicParameters

        self.desc = desc
        self.config = config or MonitorConfig()
        from hexa.calibration.overlay import ServoTorqueModel

        self.k_t = float(desc.K_t)
        self.torque = ServoTorqueModel(desc)   # per-servo K_t, current offset, friction of a calibration overlay
        self.observer = ResidualObserver(HexaDynamicParameters.from_description(desc), observer or ObserverConfig())
        self.estimator = ZetaEstimator(desc, ServoModel.from_description(desc, command_delay=self.config.command_delay),
                                       estimator or EstimatorConfig())
        self.observer.detector = make_detector(detector, self.observer.config, cusum)
        self._motion = getattr(self.observer.detector, "motion", None)   # the CUSUM follows ζ̂̇
        self.clock = SampleClock(fixed_offset=0.0 if self.config.sim_clock else None)
        self.sequencer = SampleSequencer(self.config.time_source, pose_delay=self.config.pose_delay)
        self.rejects = {"bad_currents": 0, "board_time": 0, "bad_joint_names": 0, "bad_pose": 0, "estimator": 0,
                        "observer": 0, "bad_states": 0}
        self.inputs = InputCheck(desc)
        self.pose_check = PoseCheck.for_hexa(desc)
        self.settling = 0
        self.carries_setpoint = False   # the newest motor_currents carried its set-points
        self.log: list[str] = []   # what the owner should log (calibration results)
        self._tracking = False
        self._pose_hist: deque[tuple[float, NDArray]] = deque()   # (t, tracked plate pose) for the re-seed test
        self._calib_until: float | None = None
        self.t = -math.inf

    # ------------------------------------------------------------------ settings and control
    def configure(self, observer: ObserverConfig | None = None, estimator: EstimatorConfig | None = None,
                  reseed_distance: float | None = None, cusum: CusumConfig | None = None) -> None:
        """Apply new settings at run time (the detector's thresholds take effect at the next sample; `cusum` only
        with the CUSUM detector)."""
        if cusum is not None:
            if not hasattr(self.observer.detector, "set_cusum"):
                raise ValueError("cusum settings need detector 'cusum' (the detector is chosen at start-up)")
            self.observer.detector.set_cusum(cusum)
        if reseed_distance is not None:
            self.config = dataclasses.replace(self.config, reseed_distance=float(reseed_distance))
        if observer is not None:
            self.observer.set_config(observer)
        if estimator is not None:
            self.estimator.config = estimator

    def reset(self, recalibrate: bool = False, duration: float = 1.0) -> str:
        """Re-zero the observer and restart the estimator; with `recalibrate`, average the rest offset over the next
        `duration` s of samples (robot at rest, untouched). Returns what was done."""
        self.observer.reset()
        self.estimator.reset()
        self._tracking = False
        self._pose_hist.clear()
        if not recalibrate:
            return "reset"
        self.observer.start_calibration()
        self._calib_until = (self.t if math.isfinite(self.t) else 0.0) + float(duration)
        return f"reset; recalibrating the rest offset over {float(duration):g} s"

    @property
    def board_seen(self) -> bool:
        """True once the sample times come from the current board's clock."""
        return self.sequencer.board

    # ------------------------------------------------------------------ inputs
    def push_currents(self, stamp: float, board_us: int, currents: ArrayLike,
                      setpoint: Sequence[float] | NDArray | None = None) -> list[MonitorSample]:
        """A current sample (A) received at host time `stamp` with board time `board_us` (µs); `setpoint`: the servo
        set-points in effect when it was measured (rad), when the message carries them (None or empty: they come
        on joint_states, paired by stamp). A stream that carries them makes joint_states unneeded
        (`carries_setpoint`): push_states then ignores its messages."""
        cur = self.inputs.currents(currents)
        if cur is None:
            self.rejects["bad_currents"] += 1
            return []
        carried = setpoint is not None and len(setpoint) > 0
        self.carries_setpoint = carried
        if carried and not self.inputs.states(setpoint, None, None, "setpoint"):
            return []
        seq = self.sequencer
        if not seq.takes_currents or not seq.admit("currents", stamp):   # a bad stamp never moves the board clock
            return []
        t = self.clock.time(stamp, board_us)
        if t is None:
            self.rejects["board_time"] += 1
            return []
        tau = self.torque.from_currents(cur)
        if carried:
            return self._run(seq.push_sample(stamp, t, tau, np.asarray(setpoint, float), admitted=True))
        return self._run(seq.push_currents(stamp, t, tau, admitted=True))

    def push_states(self, stamp: float, position: NDArray | None, velocity: NDArray | None,
                    effort: NDArray | None) -> list[MonitorSample]:
        """A joint_states sample: commanded (or measured) ζ, velocity and effort (None when absent); ignored while
        the current samples carry their set-points."""
        if self.carries_setpoint:
            return []
        if position is None:
            self.rejects["bad_joint_names"] += 1
            return []
        if not self.inputs.states(position, velocity, effort):
            self.rejects["bad_states"] += 1
            return []
        if effort is None and not self.sequencer.board:
            self.rejects["bad_joint_names"] += 1
        return self._run(self.sequencer.push_states(stamp, position, velocity, effort))

    def push_pose(self, stamp: float, pose: NDArray) -> list[MonitorSample]:
        """A camera plate pose at image time `stamp`: [x y z α β γ] (Z-Y-X, m, rad) or, as the message carries it,
        [x y z qx qy qz qw]; one that fails hexa.pose_check (a non-unit quaternion, off the workspace, a jump) is
        dropped and counted."""
        T = self.pose_check.check_pose6(stamp, pose) if np.size(pose) != 7 else self.pose_check.check(
            stamp, np.ravel(pose)[:3], np.ravel(pose)[3:])
        if T is None:
            self.rejects["bad_pose"] += 1
            return []
        return self._run(self.sequencer.push_pose(stamp, pose6_from_transform(T)))

    # ------------------------------------------------------------------ the pipeline
    def _run(self, items: list[tuple]) -> list[MonitorSample]:
        out = []
        for item in items:
            if item[0] == "sample":
                s = self._sample(*item[1:])
                if s is not None:
                    out.append(s)
            else:
                self._camera(item[1], item[2])
        return out

    def _camera(self, t: float, pose: NDArray) -> None:
        """A camera pose (image time t), released by the sequencer at sample time t + pose_delay."""
        if self.config.zeta_source == "estimator":
            self.estimator.update_camera(t, pose)
        tracked = self._tracked_pose_at(t)
        if tracked is None or float(np.max(np.abs(tracked[:3] - pose[:3]))) > self.config.reseed_distance:
            # the observer takes a camera seed only when it is not older than its tracked pose
            self.observer.update_pose(max(t, self.t), pose)

    def _tracked_pose_at(self, t: float) -> NDArray | None:
        if not self._tracking:
            return None
        for ts, p in reversed(self._pose_hist):
            if ts <= t:
                return p
        return None

    def _sample(self, t: float, pos: NDArray, tau: NDArray, vel: NDArray | None) -> MonitorSample | None:
        zeta_dot: NDArray | None
        if self.config.zeta_source == "estimator":
            e = self.estimator.step(t, pos, tau)
            if e is None:
                self.rejects["estimator"] += 1
                return None
            if not e[2]:  # ζ̇ still converging after a (re)start: the observer restarts after it
                self.settling += 1
                return None
            zeta, zeta_dot = np.array(e[0]), np.array(e[1])
        else:
            zeta, zeta_dot = pos, vel    # measured: the rate the sample carries, or None
        if self._motion is not None:
            self._motion(t, zeta_dot)
        tau = self.torque.correct(tau, zeta, zeta_dot)
        out = self.observer.update_arm(t, zeta, tau, zeta_dot)
        self._tracking = out is not None
        if out is None:
            self.rejects["observer"] += 1
            return None
        self.t = t
        self._pose_hist.append((t, np.asarray(out.pose, dtype=float)))
        while self._pose_hist and self._pose_hist[0][0] < t - 1.0:
            self._pose_hist.popleft()
        if self._calib_until is not None and t >= self._calib_until:
            self._calib_until = None
            try:
                off = self.observer.finish_calibration()
                self.log.append(f"observer offset recalibrated: {np.round(off, 4).tolist()}")
            except ObserverError as exc:
                self.log.append(f"recalibration failed: {exc}")
        return MonitorSample(t, out, zeta, zeta_dot, tau)

    def health(self) -> tuple[str, str]:
        """("OK" | "WARN", message) for diagnostics: WARN before the first accepted sample and while in collision."""
        if self.observer.accepted == 0:
            return "WARN", "no accepted joint_states yet"
        return ("WARN", "in collision") if self.observer.detector.active else ("OK", "ok")

    def counters(self) -> dict[str, Any]:
        """Counters for diagnostics: accepted samples, events, rejects by reason of each stage."""
        obs, est, seq = self.observer, self.estimator, self.sequencer
        values: dict[str, Any] = {"accepted": obs.accepted, "collisions": obs.detector.count,
                                  "in_collision": obs.detector.active, "servo_saturated_samples": est.saturated,
                                  "camera_accepted": est.camera_accepted, "late_poses": seq.late_poses,
                                  "unpaired_samples": seq.unpaired,
                                  "time_source": "board" if seq.board else "stamp",
                                  "estimator_settling_samples": self.settling}
        values.update({f"reject_node_{k}": v for k, v in self.rejects.items()})
        values.update(self.input_counters())
        offset = self.clock.board_offset     # a subscriber traces residual stamps back to their samples with it
        values["board_clock_offset_s"] = "" if offset is None else f"{offset:.6f}"
        values.update({f"reject_observer_{k}": v for k, v in obs.rejected.items()})
        values.update({f"reject_estimator_{k}": v for k, v in est.rejected.items()})
        return values

    def input_counters(self) -> dict[str, int]:
        """Rejects by reason of the input checks (values, board clock, stamps, poses) and the clock jumps adopted."""
        values = {f"reject_input_{k}": v for k, v in self.inputs.rejected.items()}
        values.update({f"reject_board_{k}": v for k, v in self.clock.rejected.items()})
        values.update({f"reject_stamp_{k}": v for k, v in self.sequencer.rejected.items()})
        values.update(self.pose_check.counters())
        values["clock_jumps_adopted"] = (self.clock.gate.adopted + self.estimator.clock_jumps
                                         + self.observer.clock_jumps + self.sequencer.adopted)
        return values
