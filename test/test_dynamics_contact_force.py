"""ContactForceTracker: the ζ̈ filter and the τ window, identification at rate_hz while a collision is in progress, the
backfill of late contacts over START..END, early contacts kept until their START, rejects by reason; every force is
identify_contact_force's answer on the tracker's state."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hexa.dynamics.contact_force import (ContactForceConfig, ContactForceError, ContactForceTracker,
                                         LocatedContact)
from hexa.dynamics.identification import identify_contact_force
from hexa.dynamics.lagrange import motion_from_joint_rates
from hexa.kinematics import hexa6rus
from hexa.robots.hexa_description import load_hexa
from hexa.trajectories import TRAJECTORIES

DESC = load_hexa()
DT = 0.001
T = np.arange(0.0, 2.0, DT)
POSE, POSE_DOT, POSE_DDOT = (np.asarray(v, dtype=float) for v in TRAJECTORIES["circle"](T))
ZETA, ZETA_DOT, _ = hexa6rus.inverse_kinematics_derivatives(DESC, POSE, POSE_DOT, POSE_DDOT)
TAU = np.tile([0.3, -0.2, 0.25, -0.3, 0.2, -0.25], (len(T), 1))


def _tracker(**cfg) -> ContactForceTracker:
    tr = ContactForceTracker(DESC, ContactForceConfig(**cfg))
    tr.on_pose(0.0, POSE[0])
    return tr


def _run(tr: ContactForceTracker, t0: float, t1: float, events: dict | None = None) -> list:
    """Samples with t0 <= t < t1; events {k: callable} run before sample k; all forces returned."""
    out = []
    for k in np.flatnonzero((T >= t0 - 1e-9) & (T < t1 - 1e-9)):
        if events and k in events:
            out += events[k]()
        out += tr.step_state(T[k], ZETA[k], ZETA_DOT[k], TAU[k])
    return out


def _k(t: float) -> int:
    return int(round(t / DT))


def _plate_contact(cid: int, t: float, **kw) -> LocatedContact:
    return LocatedContact(time=t, collision_id=cid, link="plate", chain=0,
                          point=POSE[_k(t), :3] + np.array([0.02, 0.01, 0.0]), **kw)


def test_zeta_ddot_is_a_first_order_low_pass_derivative_with_time_constant_accel_tau():
    tr = ContactForceTracker(DESC, ContactForceConfig(accel_tau=0.02))
    a = np.array([1.0, -2.0, 0.5, 0.0, 3.0, -1.0])      # rad/s², constant from the first sample on
    for n in range(101):
        tr.step_state(n * DT, ZETA[0], a * n * DT, TAU[0])
        if n in (20, 100):   # after one and five time constants
            assert tr.state.zeta_ddot == pytest.approx(a * (1 - math.exp(-n * DT / 0.02)), rel=1e-9, abs=1e-12)
    assert tr.state.zeta_ddot == pytest.approx(a, rel=0.01)


def test_tau_is_the_average_over_torque_window():
    tr = ContactForceTracker(DESC, ContactForceConfig(torque_window=0.02))
    for n in range(100):
        tr.step_state(n * DT, ZETA[0], ZETA_DOT[0], np.full(6, float(n)))
    assert tr.state.tau == pytest.approx(np.full(6, np.mean(np.arange(79, 100))))  # t - 0.02 <= t_i <= t
    tr = ContactForceTracker(DESC, ContactForceConfig(torque_window=0.0))
    for n in range(5):
        tr.step_state(n * DT, ZETA[0], ZETA_DOT[0], np.full(6, float(n)))
    assert tr.state.tau == pytest.approx(np.full(6, 4.0))


def test_a_force_is_identify_contact_force_on_the_trackers_state_and_fk_pose():
    tr = _tracker()
    _run(tr, 0.0, 0.5)
    tr.on_collision("START", 1, 0.5)
    c = _plate_contact(1, 0.5)
    assert tr.on_contact(c) == []          # no state at or after the START yet: the first slot is the next sample
    (f,) = _run(tr, 0.5, 0.501)
    s = tr.state
    pose = hexa6rus.forward_kinematics(DESC, s.zeta, guess=POSE[0])
    assert pose == pytest.approx(POSE[_k(s.time)], abs=1e-9)
    motion = motion_from_joint_rates(tr.params, s.zeta[None], s.zeta_dot[None], pose[None], s.zeta_ddot[None])
    est = identify_contact_force(tr.params, motion, s.tau, "plate", 0, c.point, arm_force_model="friction_cone",
                                 friction=0.2)
    assert f.time == s.time and f.collision_id == 1 and f.link == "plate" and f.chain == 0 and not f.backfilled
    assert f.force == pytest.approx(est.force, abs=1e-9)
    assert (f.rank, f.observable, f.force_model) == (est.rank, est.observable, est.force_model) == (3, True,
                                                                                                       "measured")
    assert f.condition == pytest.approx(est.condition) and f.residual_norm == pytest.approx(est.residual_norm)


def test_an_arm_contact_without_a_push_direction_takes_the_collisions_last_measured_one():
    tr = _tracker(arm_force_model="object_axis")
    _run(tr, 0.0, 0.5)
    tr.on_collision("START", 1, 0.5)
    A, B = DESC.A[0], hexa6rus.elbows(DESC, ZETA[_k(0.499)])[0]
    point = A + 0.6 * (B - A)
    push = np.array([0.0, 0.0, 1.0])
    tr.on_contact(LocatedContact(0.5, 1, "arm", 1, point, push_direction=push))
    (first,) = _run(tr, 0.5, 0.501)
    tr.on_contact(LocatedContact(0.5, 1, "arm", 1, point, push_direction=np.zeros(3)))
    (later,) = _run(tr, 0.501, 0.511)     # the next slot, 0.51 s, with the latest contact
    s = tr.state
    pose = hexa6rus.forward_kinematics(DESC, s.zeta, guess=POSE[0])
    motion = motion_from_joint_rates(tr.params, s.zeta[None], s.zeta_dot[None], pose[None], s.zeta_ddot[None])
    est = identify_contact_force(tr.params, motion, s.tau, "arm", 1, point, arm_force_model="object_axis",
                                 push_direction=push)
    assert later.force == pytest.approx(est.force, abs=1e-9) and later.force_model == est.force_model
    assert first.rank == later.rank == 1 and not later.observable


def test_a_collision_in_progress_is_identified_at_rate_hz_until_its_end():
    tr = _tracker(rate_hz=100.0)
    forces = _run(tr, 0.0, 1.5, {_k(0.5): lambda: tr.on_collision("START", 1, 0.5),
                                 _k(0.6): lambda: tr.on_contact(_plate_contact(1, 0.6)),
                                 _k(1.0): lambda: tr.on_collision("END", 1, 1.0)})
    times = np.array([f.time for f in forces])
    assert {f.collision_id for f in forces} == {1}
    assert times[0] == pytest.approx(0.6) and times[-1] == pytest.approx(1.0)   # the slots to the END, none after
    assert np.diff(times) == pytest.approx(0.01, abs=1e-9)
    assert tr.active is None


def test_a_contact_arriving_after_the_end_is_backfilled_from_its_image_time_to_the_end_at_rate_hz():
    tr = _tracker(rate_hz=100.0, history=3.0)
    live = _run(tr, 0.0, 1.5, {_k(0.5): lambda: tr.on_collision("START", 7, 0.5),
                               _k(1.0): lambda: tr.on_collision("END", 7, 1.0)})
    assert live == [] and tr.rejects["not_in_collision"] == 0
    forces = tr.on_contact(_plate_contact(7, 0.55))
    times = np.array([f.time for f in forces])
    assert all(f.backfilled and f.collision_id == 7 for f in forces) and tr.backfilled == len(forces)
    assert times[0] == pytest.approx(0.55, abs=1e-9) and 1.0 - 0.01 < times[-1] <= 1.0
    assert np.diff(times) == pytest.approx(0.01, abs=1e-9) and len(forces) == 46
    assert tr.on_contact(_plate_contact(7, 0.6)) == [] and tr.rejects["not_in_collision"] == 1  # identified already
    # a contact seen before its START is backfilled from the START
    tr = _tracker(rate_hz=50.0)
    _run(tr, 0.0, 1.2, {_k(0.5): lambda: tr.on_collision("START", 2, 0.5),
                        _k(0.8): lambda: tr.on_collision("END", 2, 0.8)})
    times = [f.time for f in tr.on_contact(_plate_contact(2, 0.4))]
    assert times[0] == pytest.approx(0.5) and times[-1] == pytest.approx(0.8) and len(times) == 16


def test_a_late_contact_of_the_collision_in_progress_is_backfilled_then_goes_on_at_the_next_slot():
    tr = _tracker(rate_hz=100.0)
    _run(tr, 0.0, 0.9, {_k(0.5): lambda: tr.on_collision("START", 3, 0.5)})
    emitted = []      # (force, identifications done when it was handed over)
    forces = tr.on_contact(_plate_contact(3, 0.6), emit=lambda f: emitted.append((f, tr.forces)))
    assert [f.backfilled for f in forces] == [True] * 30     # the slots 0.60 ... 0.89 s of the START's grid
    assert forces[0].time == pytest.approx(0.6) and forces[-1].time == pytest.approx(0.89)
    # each force is handed to `emit` as soon as it is identified, in the order returned: the first one before the
    # other 29 identifications are done
    assert [f for f, _ in emitted] == forces and [n for _, n in emitted] == list(range(1, 31))
    (live,) = _run(tr, 0.9, 0.91)
    assert live.time == pytest.approx(0.9) and not live.backfilled


@pytest.mark.parametrize("delay", [0.0155, 0.05, 0.0812, 0.3])
@pytest.mark.parametrize("end_early", [0.0, 0.0065])
def test_the_forces_do_not_depend_on_when_contacts_and_events_arrive(delay, end_early):
    # a contact every 0.1 s of image time, arriving `delay` s of sample time later (the isolation's latency; a
    # replay at 1x takes more sample time than one at 0.3x), the END message up to a batch of states ahead of them
    def forces(delay: float, end_early: float) -> list:
        tr = _tracker(rate_hz=100.0)
        events = {_k(0.5): [lambda: tr.on_collision("START", 1, 0.5)],
                  _k(1.0 - end_early): [lambda: tr.on_collision("END", 1, 1.0)]}
        for image in (0.5, 0.6, 0.7, 0.8, 0.9):
            events.setdefault(_k(image + delay), []).append(lambda image=image: tr.on_contact(_plate_contact(1, image)))
        return _run(tr, 0.0, 1.5, {k: (lambda fs=fs: [f for fn in fs for f in fn()]) for k, fs in events.items()})

    times = [f.time for f in forces(delay, end_early)]
    assert times == pytest.approx(np.arange(0.5, 1.0 + 1e-9, 0.01), abs=1e-9)   # the grid START..END, nothing else


def test_no_backfill_without_history_nor_beyond_it():
    tr = _tracker(history=0.0)
    _run(tr, 0.0, 1.5, {_k(0.5): lambda: tr.on_collision("START", 1, 0.5),
                        _k(1.0): lambda: tr.on_collision("END", 1, 1.0)})
    assert tr.on_contact(_plate_contact(1, 0.55)) == [] and tr.rejects["not_in_collision"] == 1
    tr = _tracker(history=0.7)
    _run(tr, 0.0, 1.5, {_k(0.5): lambda: tr.on_collision("START", 1, 0.5),
                        _k(1.0): lambda: tr.on_collision("END", 1, 1.0)})
    times = [f.time for f in tr.on_contact(_plate_contact(1, 0.55))]
    assert times[0] >= 1.499 - 0.7 - 1e-9 and times[-1] <= 1.0


def test_a_contact_before_its_start_is_kept_until_the_start_arrives():
    tr = _tracker()
    _run(tr, 0.0, 0.5)
    assert tr.on_contact(_plate_contact(4, 0.45)) == []
    assert sum(tr.rejects.values()) == 0
    forces = _run(tr, 0.5, 0.7, {_k(0.55): lambda: tr.on_collision("START", 4, 0.55)})
    assert forces[0].collision_id == 4 and forces[0].time == pytest.approx(0.55)
    assert len(forces) == 15 and not any(f.backfilled for f in forces)   # from the START at 100 Hz


def test_a_contact_outside_a_collision_is_rejected_unless_collisions_are_not_required():
    tr = _tracker()
    _run(tr, 0.0, 0.5, {_k(0.1): lambda: tr.on_collision("START", 1, 0.1),
                        _k(0.2): lambda: tr.on_collision("END", 1, 0.2)})
    assert tr.on_contact(_plate_contact(1, 0.3)) == []   # after the END, not in START..END: nothing to backfill
    assert tr.on_contact(_plate_contact(0, 0.3)) == []   # an older collision
    assert tr.rejects["not_in_collision"] == 2
    tr = _tracker(require_collision=False)
    _run(tr, 0.0, 0.5)
    (f,) = tr.on_contact(_plate_contact(0, 0.3))
    assert f.collision_id == 0 and not f.backfilled


def test_bad_inputs_are_counted_by_reason():
    tr = _tracker()
    _run(tr, 0.0, 0.1)
    tr.on_collision("START", 1, 0.1)
    bad = [LocatedContact(0.1, 1, "plate", 0, np.array([np.nan, 0.0, 0.0])),
           LocatedContact(0.1, 1, "foot", 0, np.zeros(3)), LocatedContact(0.1, 1, "rod", 9, np.zeros(3))]
    assert all(tr.on_contact(c) == [] for c in bad)
    assert tr.step_state(0.2, ZETA[0] * np.nan, ZETA_DOT[0], TAU[0]) == []
    assert tr.step_state(T[99], ZETA[99], ZETA_DOT[99], TAU[99]) == []
    tr.on_pose(0.2, np.full(6, np.inf))
    assert {k: v for k, v in tr.rejects.items() if v} == {"non_finite": 2, "unknown_link": 1, "bad_chain": 1,
                                                          "repeated_time": 1, "bad_pose": 1}
    with pytest.raises(ContactForceError, match="'BEGIN'"):
        tr.on_collision("BEGIN", 2, 0.2)


def test_no_state_and_no_pose_are_rejected_not_raised():
    tr = ContactForceTracker(DESC, ContactForceConfig(require_collision=False))
    assert tr.on_contact(_plate_contact(1, 0.0)) == [] and tr.rejects["no_state"] == 1
    tr = ContactForceTracker(DESC)
    tr.on_collision("START", 1, 0.0)
    assert tr.on_contact(_plate_contact(1, 0.0)) == [] and sum(tr.rejects.values()) == 0   # its slots come later
    assert tr.step_state(0.0, ZETA[0], ZETA_DOT[0], TAU[0]) == []      # no camera pose yet: no FK seed
    assert tr.rejects["pose_tracking"] == 1


def test_a_camera_pose_on_another_branch_restarts_the_tracking_from_the_camera():
    tr = _tracker()
    _run(tr, 0.0, 0.3, {_k(0.1): lambda: tr.on_collision("START", 1, 0.1),
                        _k(0.15): lambda: tr.on_contact(_plate_contact(1, 0.15)),
                        _k(0.2): lambda: tr.on_collision("END", 1, 0.2)})
    assert tr.plate_pose == pytest.approx(POSE[_k(0.2)], abs=1e-9)      # the last slot, at the END
    tr.on_pose(0.25, POSE[_k(0.25)])          # agrees with FK of ζ at its image time: tracking kept
    assert tr.plate_pose is not None
    wrong = POSE[_k(0.25)] + np.array([0.0, 0.0, 0.05, 0.0, 0.0, 0.0])
    tr.on_pose(0.4, wrong)                     # newer than the newest state: checked when the samples reach it
    _run(tr, 0.3, 0.4)
    assert tr.plate_pose is not None
    _run(tr, 0.4, 0.41)
    assert tr.plate_pose is None


def test_one_sample_time_far_off_is_rejected_and_a_stream_that_went_back_restarts():
    tr = _tracker()
    _run(tr, 0.0, 0.5)
    newest = tr.state.time
    assert tr.step_state(newest - 100.0, ZETA[100], ZETA_DOT[100], TAU[100]) == []    # one stamp in the past
    assert tr.step_state(newest + 1e6, ZETA[100], ZETA_DOT[100], TAU[100]) == []      # one far in the future
    assert tr.restarts == 0 and tr.state.time == newest
    assert (tr.rejects["time_past"], tr.rejects["time_jump"]) == (1, 1)
    for k in range(5):                                   # the stream started again at 0.1 s: adopted at the 5th
        tr.step_state(0.1 + 0.001 * k, ZETA[100], ZETA_DOT[100], TAU[100])
    assert tr.restarts == 1 and tr.state.time == pytest.approx(0.104) and np.all(tr.state.zeta_ddot == 0)


@pytest.mark.parametrize("field, value", [("arm_friction", -0.5), ("arm_force_model", "guess"), ("accel_tau", 0.0),
                                          ("history", math.inf), ("torque_window", -0.01), ("rate_hz", math.nan),
                                          ("saturation", 0.0), ("saturation", 1.5)])
def test_a_bad_setting_is_refused_naming_it(field, value):
    with pytest.raises(ContactForceError, match=field) as exc:
        ContactForceConfig(**{field: value})
    assert repr(value) in str(exc.value)


def test_a_force_identified_while_a_servo_is_at_its_stall_torque_is_flagged_for_the_torque_window():
    tr = _tracker(rate_hz=100.0, torque_window=0.02)
    assert tr.stall_torque == pytest.approx(0.97 * DESC.torque_max)
    tau = TAU.copy()
    tau[_k(0.6):_k(0.65), 2] = DESC.torque_max        # servo 3 stalls from 0.600 to 0.649 s
    forces = _forces_with(tr, tau)
    flagged = [round(f.time, 3) for f in forces if f.servo_stalled]
    # a force is flagged while a stalled sample lies in its 20 ms torque window: 0.60 ... 0.66 s (0.649 + 0.02)
    assert flagged == pytest.approx([0.6, 0.61, 0.62, 0.63, 0.64, 0.65, 0.66])
    assert len(forces) == 30 and not any(f.servo_stalled for f in forces if f.time < 0.6 or f.time > 0.67)


def test_the_stall_criterion_follows_the_saturation_setting():
    """At saturation 0.5 a servo at 60 % of its stall torque is stalled; at the default 0.97 it is not."""
    tau = TAU.copy()
    tau[_k(0.6):_k(0.65), 2] = 0.6 * DESC.torque_max
    for saturation, stalled in ((0.5, True), (0.97, False)):
        tr = _tracker(rate_hz=100.0, torque_window=0.02, saturation=saturation)
        assert tr.stall_torque == pytest.approx(saturation * DESC.torque_max)
        assert any(f.servo_stalled for f in _forces_with(tr, tau)) == stalled


def _forces_with(tr: ContactForceTracker, tau: np.ndarray) -> list:
    """The forces of a plate contact from 0.5 s (collision START then) over 0.8 s of samples with torques `tau`."""
    forces = []
    for k in range(_k(0.8)):
        if k == _k(0.5):
            tr.on_collision("START", 1, 0.5)
            tr.on_contact(_plate_contact(1, 0.5))
        forces += tr.step_state(T[k], ZETA[k], ZETA_DOT[k], tau[k])
    return forces


def test_without_a_grid_a_contact_is_identified_once_on_arrival():
    tr = _tracker(rate_hz=0.0)
    _run(tr, 0.0, 0.7, {_k(0.5): lambda: tr.on_collision("START", 1, 0.5)})
    forces = tr.on_contact(_plate_contact(1, 0.6))       # backfilled at 0.60, 0.65 (50 ms slots), then the newest
    assert [round(f.time, 3) for f in forces] == [0.6, 0.65, 0.699]
    assert [f.backfilled for f in forces] == [True, True, False]
    assert _run(tr, 0.7, 0.8) == []                        # no slots without a rate
    (f,) = tr.on_contact(_plate_contact(1, 0.7))           # a later contact: once, on the newest state
    assert f.time == pytest.approx(0.799) and not f.backfilled
