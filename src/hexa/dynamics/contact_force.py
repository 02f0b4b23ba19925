"""Contact force over a whole collision from a stream of arm states (seed 000 §3.3, eqs 27–36): the stateful side of
`hexa.dynamics.identification.identify_contact_force`.

Each sample (t, ζ, ζ̇, τ) gives a state with ζ̈ from a first-order low-pass derivative of ζ̇ (time constant
`accel_tau`) and τ averaged over `torque_window`; the states of the last `history` seconds are kept. The plate pose
of a state is forward kinematics of ζ (seed 000 §2.2.2), warm-started from the previous solution and seeded by the
last camera pose; a camera pose that disagrees with FK of ζ at its image time by more than `BRANCH_TOLERANCE`
restarts the tracking from the camera (the tracking left the camera's assembly branch).

Contacts and collision events arrive on their own (isolation takes two camera frames and the detector, up to ~1 s on
a loaded host), so the forces of a collision are identified on a grid of sample times anchored at its START, and the
same states give the same forces however late the messages arrive (a replay at 1× and one at 0.3× agree):
- the first contact of a recent collision is identified retroactively on the kept states, from its image time (not
  before the START) to the END or the newest state, at the grid's slots every 1/`rate_hz` (spacing at most 0.05 s)
  (`backfilled` results): a contact that arrives late, even after the END, still gives the force over the whole
  contact;
- then, while the states run up to the END (also after the END message, which can overtake the last states), each
  slot START + k/`rate_hz` is identified on the first state at or after it, with the latest contact of the collision;
  with `rate_hz` 0 a contact is identified once, on the newest state, when it arrives;
- a contact whose collision has not STARTed yet (a newer id) is kept until its START;
- with `require_collision`, any other contact is rejected (`not_in_collision`).
An arm contact without a measured push direction takes the collision's last measured one. A force identified while
some servo's torque was at its stall torque within `torque_window` is flagged `servo_stalled`: a stalled servo is
back-driven and reports no angle, so ζ and its rates are estimates from the cameras and the force is unreliable.
Rejected inputs are counted by reason in `ContactForceTracker.rejects`.
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.dynamics.identification import ARM_FORCE_MODELS, LINKS, identify_contact_force
from hexa.dynamics.lagrange import DynamicsError, HexaDynamicParameters, motion_from_joint_rates
from hexa.estimation import EstimatorConfig
from hexa.kinematics.hexa6rus import forward_kinematics
from hexa.stream_gate import TimeGate

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from hexa.robots.hexa_description import HexaDescription

REJECT_REASONS = ("non_finite", "repeated_time", "time_past", "time_jump", "bad_pose", "unknown_link", "bad_chain",
                  "no_state", "not_in_collision", "pose_tracking", "identification")
#: m: a camera pose this far (position) from FK of ζ at its image time means the tracking is on another branch
BRANCH_TOLERANCE = 0.02
#: s: states are kept at least this long for the camera's branch check (the vision's latency is below 0.5 s)
POSE_LOOKBACK = 1.0
#: s: the longest spacing of backfilled identifications
BACKFILL_SPACING = 0.05
#: s: sample times this close to a due identification count as due (stamps are rounded to nanoseconds)
TIME_EPS = 1e-6
RECENT_COLLISIONS = 10   # collisions whose late contacts can still be backfilled
EARLY_CONTACTS = 20      # contacts kept while their START is on its way
PENDING_POSES = 64       # camera poses newer than the newest state, waiting for it


class ContactForceError(ValueError):
    """Bad tracker configuration or call; the message names the offending value."""


@dataclass(frozen=True)
class ContactForceConfig:
    """Settings of a ContactForceTracker (the rnea node's parameters of the same names).

    rate_hz: identifications per second of sample time while a collision is in progress (0: on contacts only);
    torque_window: s over which τ is averaged; accel_tau: s, time constant of the low-pass derivative giving ζ̈;
    require_collision: contacts outside a START..END are rejected; history: s of states kept for late contacts
    (0: no backfill); arm_force_model, arm_friction: what an arm force's unobservable directions get and μ of
    "friction_cone" (hexa.dynamics.identification); saturation: a servo whose |τ| exceeds saturation·τ_max is
    stalled (the ζ estimator's criterion, its `saturation`: that servo's angle is not measured).
    """

    rate_hz: float = 100.0
    torque_window: float = 0.02
    accel_tau: float = 0.02
    require_collision: bool = True
    history: float = 3.0
    arm_force_model: str = "friction_cone"
    arm_friction: float = 0.2
    saturation: float = EstimatorConfig().saturation

    def __post_init__(self) -> None:
        checks = (("rate_hz", self.rate_hz >= 0, "a rate >= 0 Hz"),
                  ("saturation", 0 < self.saturation <= 1, "a fraction in (0, 1]"),
                  ("torque_window", self.torque_window >= 0, "a window >= 0 s"),
                  ("accel_tau", self.accel_tau > 0, "a time constant > 0 s"),
                  ("history", self.history >= 0, "a duration >= 0 s"),
                  ("arm_friction", self.arm_friction >= 0, "a finite coefficient >= 0"))
        for name, ok, what in checks:
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ContactForceError(f"{name} must be {what}, got {value!r}")
        if self.arm_force_model not in ARM_FORCE_MODELS:
            raise ContactForceError(f"arm_force_model must be one of {ARM_FORCE_MODELS}, "
                                    f"got {self.arm_force_model!r}")


@dataclass(frozen=True)
class LocatedContact:
    """A contact the vision located: image time (s), collision id, link ("plate", "arm", "rod"), chain 1..6 (any for
    the plate), point (3,) in `base` (m), and the pushing object's axis (3,) when measured (None or zero: not)."""

    time: float
    collision_id: int
    link: str
    chain: int
    point: NDArray
    push_direction: NDArray | None = None


@dataclass(frozen=True)
class ArmState:
    """One sample as identified: ζ (rad), ζ̇ (rad/s), ζ̈ (rad/s², filtered), τ (N·m, averaged) at `time` (s);
    `stalled`: some servo's torque reached its stall torque in the averaging window."""

    time: float
    zeta: NDArray
    zeta_dot: NDArray
    zeta_ddot: NDArray
    tau: NDArray
    stalled: bool = False


@dataclass(frozen=True)
class ContactForce:
    """The identified force (N, `base`) of a contact at sample `time` (s): the fields of
    `ContactForceEstimate` (chain 0 for the plate), whether it was identified retroactively (`backfilled`) and whether
    a servo was at its stall torque then (`servo_stalled`: the force is unreliable)."""

    time: float
    collision_id: int
    link: str
    chain: int
    point: NDArray
    force: NDArray
    rank: int
    condition: float
    observable: bool
    residual_norm: float
    force_model: str
    backfilled: bool
    servo_stalled: bool = False


class ContactForceTracker:
    """Arm states, camera poses, collision events and located contacts → the contact force of each collision.

    Args:
        desc: the robot description (kinematics and mass properties).
        config: settings (ContactForceConfig defaults when None).
        params: dynamic parameters (from `desc` when None).
    """

    def __init__(self, desc: HexaDescription, config: ContactForceConfig | None = None,
                 params: HexaDynamicParameters | None = None) -> None:
        self.desc = desc
        self.config = config or ContactForceConfig()
        self.params = params or HexaDynamicParameters.from_description(desc)
        #: N·m: a servo torque this large is a stalled servo (the ζ estimator's criterion: its angle is not measured)
        self.stall_torque = self.config.saturation * float(desc.torque_max)
        self.period = 1.0 / self.config.rate_hz if self.config.rate_hz > 0 else math.inf
        self.rejects = {k: 0 for k in REJECT_REASONS}
        self.forces = 0          # ContactForce results returned
        self.backfilled = 0      # of which identified retroactively
        self.restarts = 0        # sample time went back (or jumped ahead) for good: the stream started again
        # one sample time before the newest or more than 1 s after it is rejected; 5 in a row that follow one another
        # are a stream that started again (hexa.stream_gate)
        self._time_gate = TimeGate(1.0, adopt_after=5)
        self.last_error = ""     # message of the last failed identification
        self._states: deque[ArmState] = deque()      # the last max(history, POSE_LOOKBACK) s
        self._tau: deque[tuple[float, NDArray, bool]] = deque()   # the samples of the last torque_window s
        self._tau_sum = np.zeros(6)
        self._stalled = 0                            # of which with a servo at its stall torque
        self._zd_prev: tuple[float, NDArray] | None = None
        self._zdd = np.zeros(6)
        self._pose: NDArray | None = None            # plate pose tracked from ζ
        self._camera: NDArray | None = None          # last camera pose, the FK seed when tracking is lost
        self._pending: list[tuple[float, NDArray]] = []  # camera poses newer than the newest state
        self._started = 0                            # newest collision id STARTed
        self._live: int | None = None                # collision whose slots the states still reach (to its END)
        self._due = math.inf                         # its next slot (s of sample time)
        self._contacts: dict[int, LocatedContact] = {}   # latest contact per collision id (the active one's is used)
        self._early: dict[int, LocatedContact] = {}
        self._spans: dict[int, list[float]] = {}     # recent collision id -> [START t, END t or inf]
        self._identified: set[int] = set()           # collisions with at least one force identified
        self._push: dict[int, NDArray] = {}          # last measured push direction per collision id
        from hexa.dynamics.identification import _kernel_of

        _kernel_of(self.params)   # the identification kernel (and LAPACK's import) now, not at the first contact

    @property
    def state(self) -> ArmState | None:
        """The newest state (None before the first sample)."""
        return self._states[-1] if self._states else None

    @property
    def plate_pose(self) -> NDArray | None:
        """The plate pose tracked from ζ at the last identification (None: the next one starts from the camera)."""
        return self._pose

    @property
    def active(self) -> int | None:
        """Id of the collision in progress: STARTed, its END not received (None between collisions)."""
        cid = self._live
        return cid if cid is not None and math.isinf(self._spans[cid][1]) else None

    # ------------------------------------------------------------------ inputs
    def step_state(self, t: float, zeta: NDArray, zeta_dot: NDArray, tau: NDArray) -> list[ContactForce]:
        """Take one sample: ζ (rad), ζ̇ (rad/s), τ (N·m) at time t (s); the forces identified at `rate_hz`."""
        x = np.concatenate([np.asarray(v, dtype=float).reshape(6) for v in (zeta, zeta_dot, tau)])
        if not (math.isfinite(t) and np.isfinite(x).all()):
            self.rejects["non_finite"] += 1
            return []
        zeta, zeta_dot, tau = x[:6], x[6:12], x[12:]
        newest = self.state
        verdict = self._time_gate.check(t)
        if verdict == "time_past":
            self.rejects["repeated_time" if newest is not None and t == newest.time else "time_past"] += 1
            return []
        if verdict == "time_future":
            self.rejects["time_jump"] += 1
            return []
        if verdict == "adopted":
            self._restart()
        if self._zd_prev is not None:
            h = t - self._zd_prev[0]
            a = math.exp(-h / self.config.accel_tau)
            self._zdd = a * self._zdd + (1.0 - a) * (zeta_dot - self._zd_prev[1]) / h
        self._zd_prev = (t, zeta_dot)
        stalled = bool(np.max(np.abs(tau)) >= self.stall_torque)
        self._tau.append((t, tau, stalled))
        self._tau_sum += tau
        self._stalled += stalled
        while self._tau[0][0] < t - self.config.torque_window:
            _, old, was = self._tau.popleft()
            self._tau_sum -= old
            self._stalled -= was
        state = ArmState(t, zeta, zeta_dot, self._zdd.copy(), self._tau_sum / len(self._tau), self._stalled > 0)
        self._states.append(state)
        keep = max(self.config.history, POSE_LOOKBACK)
        while self._states[0].time < t - keep:
            self._states.popleft()
        if self._pending:
            due = [p for p in self._pending if p[0] <= t]
            self._pending = [p for p in self._pending if p[0] > t]
            for tp, pose in due:
                self._check_branch(tp, pose)
        cid = self._live
        if cid is None or t < self._due - TIME_EPS:
            return []
        start, end = self._spans.get(cid, (math.inf, -math.inf))
        if t > end + TIME_EPS:
            self._live = None          # the states passed its END: the collision's forces are complete
            return []
        self._due = _slot(start, self.period, t + 2.0 * TIME_EPS)
        if cid not in self._contacts:
            return []
        out = self._identify_now(self._contacts[cid])
        return [out] if out is not None else []

    def on_pose(self, t: float, pose: NDArray) -> None:
        """A camera plate pose [x y z α β γ] at image time t: the FK seed, and the check of the tracking's branch."""
        pose = np.asarray(pose, dtype=float).reshape(-1)
        if pose.shape != (6,) or not (math.isfinite(t) and np.all(np.isfinite(pose))):
            self.rejects["bad_pose"] += 1
            return
        self._camera = pose
        newest = self.state
        if newest is not None and t <= newest.time:
            self._check_branch(t, pose)
        elif len(self._pending) < PENDING_POSES:
            self._pending.append((t, pose))

    def on_collision(self, kind: str, collision_id: int, t: float) -> list[ContactForce]:
        """A collision event ("START" or "END") at time t; a START releases the contact that arrived before it.

        Raises:
            ContactForceError: an unknown kind.
        """
        cid = int(collision_id)
        if kind == "START":
            self._spans[cid] = [t, math.inf]
            for old in sorted(self._spans)[:-RECENT_COLLISIONS]:
                self._spans.pop(old)
                self._identified.discard(old)
                self._push.pop(old, None)
            self._live = cid
            self._due = t if math.isfinite(self.period) else math.inf      # rate_hz 0: no live slots
            self._started = max(self._started, cid)
            early = self._early.pop(cid, None)
            self._early = {k: c for k, c in self._early.items() if k > cid}
            return self._accept(early) if early is not None else []
        if kind != "END":
            raise ContactForceError(f"collision event must be 'START' or 'END', got {kind!r}")
        if cid in self._spans:
            self._spans[cid][1] = t    # its contacts stay until the states reach its END (step_state)
        return []

    def on_contact(self, contact: LocatedContact, emit: Callable[[ContactForce], Any] | None = None
                   ) -> list[ContactForce]:
        """A located contact: its forces now and, for the first contact of a collision, over the kept states.
        `emit`, when given, gets each force as soon as it is identified (a backfill runs tens of identifications
        of several ms each: the caller publishes the first one at once, not after the last)."""
        point = np.asarray(contact.point, dtype=float).reshape(-1)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            self.rejects["non_finite"] += 1
            return []
        if contact.link not in LINKS:
            self.rejects["unknown_link"] += 1
            return []
        if contact.link != "plate" and not 1 <= int(contact.chain) <= 6:
            self.rejects["bad_chain"] += 1
            return []
        cid = int(contact.collision_id)
        if self.config.require_collision and cid != self._live:
            if cid in self._spans and cid not in self._identified:
                self._remember_push(cid, contact.push_direction)
                out = self._backfill(contact, emit)
                if out is not None:      # a collision that ended before its contact arrived
                    return out
            if cid > self._started:      # its START is still on its way
                if len(self._early) < EARLY_CONTACTS or cid in self._early:
                    self._early[cid] = contact
                return []
            self.rejects["not_in_collision"] += 1
            return []
        return self._accept(contact, emit)

    # ------------------------------------------------------------------ identification
    def _restart(self) -> None:
        self.restarts += 1
        self._states.clear()
        self._tau.clear()
        self._tau_sum = np.zeros(6)
        self._stalled = 0
        self._pending.clear()
        self._zd_prev, self._pose = None, None
        self._zdd = np.zeros(6)

    def _remember_push(self, cid: int, push: NDArray | None) -> None:
        if push is None:
            return
        push = np.asarray(push, dtype=float).reshape(3)
        if np.all(np.isfinite(push)) and np.any(push != 0.0):
            self._push[cid] = push
            for old in sorted(self._push)[:-2 * RECENT_COLLISIONS]:
                self._push.pop(old)

    def _state_at(self, t: float) -> ArmState | None:
        """The newest kept state not after t (None when t precedes them all)."""
        for s in reversed(self._states):
            if s.time <= t:
                return s
        return None

    def _check_branch(self, t: float, pose: NDArray) -> None:
        then = self._state_at(t)
        if self._pose is None or then is None:
            return
        fk = self._forward_kinematics(then.zeta, self._pose)
        if fk is None or float(np.max(np.abs(fk[:3] - pose[:3]))) > BRANCH_TOLERANCE:
            self._pose = None          # the next identification starts again from the camera

    def _forward_kinematics(self, zeta: NDArray, guess: NDArray | None) -> NDArray | None:
        if guess is None:
            return None
        try:
            pose = np.asarray(forward_kinematics(self.desc, zeta, guess=guess), dtype=float)
        except (ValueError, ArithmeticError):
            return None
        return pose if np.all(np.isfinite(pose)) else None

    def _accept(self, contact: LocatedContact, emit: Callable[[ContactForce], Any] | None = None
                ) -> list[ContactForce]:
        """A contact of the collision in progress (or any, without require_collision)."""
        cid = int(contact.collision_id)
        self._remember_push(cid, contact.push_direction)
        self._contacts[cid] = contact
        for old in sorted(self._contacts)[:-RECENT_COLLISIONS]:
            self._contacts.pop(old)
        out: list[ContactForce] = []
        if cid in self._spans and cid not in self._identified:
            out.extend(self._backfill(contact, emit) or [])   # the slots between its image time and now
        newest = self.state
        done = bool(out) and newest is not None and out[-1].time == newest.time    # the backfill reached it
        if (math.isinf(self.period) or cid != self._live) and not done:   # no grid: once, on the newest state
            now = self._identify_now(contact)
            if now is not None:
                out.append(now)
                if emit is not None:
                    emit(now)
        return out

    def _identify_now(self, contact: LocatedContact) -> ContactForce | None:
        state = self.state
        if state is None:
            self.rejects["no_state"] += 1
            return None
        pose = self._forward_kinematics(state.zeta, self._camera if self._pose is None else self._pose)
        if pose is None:
            self.rejects["pose_tracking"] += 1
            return None
        self._pose = pose
        return self._identify(contact, state, pose, backfilled=False)

    def _backfill(self, contact: LocatedContact, emit: Callable[[ContactForce], Any] | None = None
                  ) -> list[ContactForce] | None:
        """`contact` identified on the kept states from its image time (not before its collision's START, not older
        than `history`) to the END or the newest state (included), at the collision's grid slots (the first state at
        or after each); the live slots then go on after the newest state. None when no state lies in that span."""
        cid = int(contact.collision_id)
        if self.config.history <= 0 or not self._states:
            return None
        start, end = self._spans[cid]
        newest = self._states[-1].time
        t0 = max(start, contact.time, newest - self.config.history)
        span = [s for s in self._states if t0 - TIME_EPS <= s.time <= end + TIME_EPS]
        if not span:
            return None
        spacing = self.period / math.ceil(self.period / BACKFILL_SPACING) if math.isfinite(self.period) \
            else BACKFILL_SPACING          # divides the live grid's period, so both grids share their slots
        out: list[ContactForce] = []
        guess = self._camera if self._pose is None else self._pose
        due = _slot(start, spacing, t0)
        for s in span:
            if s.time < due - TIME_EPS:
                continue
            due = _slot(start, spacing, s.time + 2.0 * TIME_EPS)
            pose = self._forward_kinematics(s.zeta, guess)
            if pose is None:
                self.rejects["pose_tracking"] += 1
                continue
            guess = pose
            f = self._identify(contact, s, pose, backfilled=True)
            if f is not None:
                out.append(f)
                if emit is not None:
                    emit(f)
        if cid == self._live and math.isfinite(self.period):
            self._due = max(self._due, _slot(start, self.period, newest + 2.0 * TIME_EPS))
            if span[-1].time == newest:
                self._pose = guess         # the live identifications go on from the newest state's pose
        return out

    def _identify(self, contact: LocatedContact, s: ArmState, pose: NDArray, backfilled: bool
                  ) -> ContactForce | None:
        """identify_contact_force (seed 000 eqs 27–36) of `contact` on state `s` with plate pose `pose`."""
        cid = int(contact.collision_id)
        chain = 0 if contact.link == "plate" else int(contact.chain)
        point = np.asarray(contact.point, dtype=float).reshape(3)
        try:
            motion = motion_from_joint_rates(self.params, s.zeta[None], s.zeta_dot[None], pose[None],
                                             s.zeta_ddot[None])
            est = identify_contact_force(self.params, motion, s.tau, contact.link, chain, point,
                                         arm_force_model=self.config.arm_force_model,
                                         push_direction=self._push.get(cid), friction=self.config.arm_friction)
        except (ValueError, DynamicsError, np.linalg.LinAlgError) as exc:
            self.rejects["identification"] += 1
            self.last_error = str(exc)
            return None
        self._identified.add(cid)
        self.forces += 1
        self.backfilled += int(backfilled)
        return ContactForce(time=s.time, collision_id=cid, link=contact.link, chain=chain, point=point,
                            force=np.asarray(est.force, dtype=float), rank=int(est.rank),
                            condition=float(est.condition), observable=bool(est.observable),
                            residual_norm=float(est.residual_norm), force_model=est.force_model,
                            backfilled=backfilled, servo_stalled=s.stalled)


def _slot(start: float, spacing: float, t: float) -> float:
    """The first slot start + k·spacing (k ≥ 0) at or after t (within TIME_EPS)."""
    return start + max(0, math.ceil((t - TIME_EPS - start) / spacing)) * spacing
