"""hexa.estimation.SampleSequencer: the output order depends on stamps and contents only, not on how the three
topics interleave on delivery (deterministic replay)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexa.estimation import EstimationError, SampleSequencer


def _streams(n: int = 60):
    """A driver-like run: per 5 ms sample one motor_currents and one joint_states with the same (sometimes repeated)
    host stamp, commands changing every 10 ms, 30 Hz poses stamped up to 0.3 s before they arrive."""
    cur, js, poses = [], [], []
    for k in range(n):
        t = 0.005 * k
        stamp = round(t + 0.004, 3) if k % 7 else round(t + 0.001, 3)
        cmd = np.full(6, 0.01 * (k // 2))
        cur.append(("cur", stamp, t, np.full(6, 0.1 * k)))
        js.append(("js", stamp, cmd, None, np.zeros(6)))
    for j in range(10):
        poses.append(("pose", 0.033 * j, np.full(6, float(j))))
    return cur, js, poses


def _feed(seq: SampleSequencer, order: list) -> list:
    out = []
    for item in order:
        if item[0] == "cur":
            out += seq.push_currents(*item[1:])
        elif item[0] == "js":
            out += seq.push_states(*item[1:])
        else:
            out += seq.push_pose(*item[1:])
    return [(o[0], o[1], tuple(np.round(o[2], 9)) if o[0] == "pose" else (tuple(o[2]), tuple(o[3]))) for o in out]


def _interleave(streams: list[list], picks: list[int]) -> list:
    idx = [0] * len(streams)
    out = []
    for p in picks:
        live = [k for k in range(len(streams)) if idx[k] < len(streams[k])]
        if not live:
            break
        k = live[p % len(live)]
        out.append(streams[k][idx[k]])
        idx[k] += 1
    for k, s in enumerate(streams):
        out += s[idx[k]:]
    return out


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 2), min_size=0, max_size=200))
def test_any_interleaving_of_the_topics_gives_the_same_sample_and_pose_sequence(picks):
    cur, js, poses = _streams()
    # poses arrive 0.1-0.3 s after their stamp: within pose_delay, so each is applied at the same sample every time
    reference = _feed(SampleSequencer(pose_delay=0.35), cur + js + poses)
    shuffled = _interleave([cur, js, poses], picks)
    assert _feed(SampleSequencer(pose_delay=0.35), shuffled) == reference


def test_samples_carry_their_own_joint_states_command_and_poses_wait_for_their_slot():
    cur, js, poses = _streams(80)
    out = _feed(SampleSequencer(pose_delay=0.1), poses + cur + js)
    samples = [o for o in out if o[0] == "sample"]
    assert len(samples) == 80
    assert [o[1] for o in samples] == sorted(o[1] for o in samples)
    # each sample at board time t carries the command of its own joint_states (k = 4: t = 0.02 s, command 0.02),
    # whatever the host stamps (0.024 here, 0.019 for k = 3)
    assert [o[2][0][0] for o in samples] == pytest.approx([0.01 * (k // 2) for k in range(80)])
    # each pose comes right before the first sample at or after its stamp + pose_delay
    for k, o in enumerate(out):
        if o[0] == "pose":
            nxt = next(s for s in out[k:] if s[0] == "sample")
            prev = [s for s in out[:k] if s[0] == "sample"]
            assert nxt[1] >= o[1] + 0.1 - 1e-12
            assert not prev or prev[-1][1] < o[1] + 0.1


def test_a_lost_partner_drops_only_its_own_sample_and_a_pose_later_than_its_slot_is_counted():
    cur, js, poses = _streams(20)
    seq = SampleSequencer(pose_delay=0.01)
    out = _feed(seq, cur[:5] + cur[6:] + js)  # motor_currents 5 lost
    assert len([o for o in out if o[0] == "sample"]) == 19
    assert seq.unpaired == 1
    assert _feed(seq, [("pose", 0.0, np.zeros(6))]) and seq.late_poses == 1


def test_without_motor_currents_each_joint_states_is_a_sample_at_its_stamp():
    _, js, _ = _streams(32)
    seq = SampleSequencer(mode="auto", auto_wait=5)
    out = _feed(seq, js[:5])
    assert [o[1] for o in out] == [j[1] for j in js[:5]]  # decided after auto_wait joint_states
    for j in js[5:]:  # then every joint_states is a sample at once
        assert [o[1] for o in _feed(seq, [j])] == [j[1]]
    assert not seq.board


def test_bad_settings_are_refused_naming_them():
    with pytest.raises(EstimationError, match="mode"):
        SampleSequencer(mode="fast")
    with pytest.raises(EstimationError, match="pose_delay"):
        SampleSequencer(pose_delay=-1.0)
