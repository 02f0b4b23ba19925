"""Bags survive a crash: BagRecorder keeps at most one chunk period in memory, and recover_bag rebuilds a readable
bag from an MCAP cut anywhere (what a SIGKILLed recorder leaves), saying what was lost."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from hexa.bags import BagError, read_bag, salvage_mcap
from hexa_bringup.bag import BagRecorder, bag_topics, recover_bag, typestore

def _record(path, n=300, dt_ns=10_000_000, chunk_every=50):
    """`n` messages 10 ms apart alternating between two topics, a chunk closed every `chunk_every` messages (as
    `chunk_period` does in time); returns the stamps and the file's size after each chunk was flushed."""
    store = typestore()
    js = store.types["sensor_msgs/msg/JointState"]
    header = store.types["std_msgs/msg/Header"]
    stamp = store.types["builtin_interfaces/msg/Time"]
    flushed = []
    with BagRecorder(path, chunk_period=1e9) as rec:
        rec.add_topic("/hexa/joint_states", "sensor_msgs/msg/JointState", reliable=False)
        rec.add_topic("/hexa/diag", "std_msgs/msg/String")
        string = store.types["std_msgs/msg/String"]
        for k in range(n):
            t = 1_000_000_000 + k * dt_ns
            if k % 2:
                msg = string(data=f"m{k}")
                rec.write("/hexa/diag", t, bytes(store.serialize_cdr(msg, "std_msgs/msg/String")))
            else:
                msg = js(header=header(stamp=stamp(sec=k, nanosec=0), frame_id="base"), name=["arm_1"],
                         position=np.array([float(k)]), velocity=np.zeros(0), effort=np.zeros(0))
                rec.write("/hexa/joint_states", t, bytes(store.serialize_cdr(msg, "sensor_msgs/msg/JointState")))
            if (k + 1) % chunk_every == 0:
                rec.tick(now=float("inf"))
                flushed.append((k, (path / f"{path.name}.mcap").stat().st_size))
    return flushed


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    path = tmp_path_factory.mktemp("bags") / "whole"
    return path, _record(path)


def test_a_recorder_flushes_each_chunk_so_the_file_holds_it_before_close(whole):
    path, flushed = whole
    sizes = [s for _, s in flushed]
    assert sizes == sorted(sizes) and len(set(sizes)) == len(sizes)   # each chunk reached the file when closed
    assert sum(bag_topics(path)[t][1] for t in ("/hexa/joint_states", "/hexa/diag")) == 300


@pytest.mark.parametrize("cut", ["after_chunk_3", "inside_chunk_4", "header_only", "mid_record"])
def test_a_cut_mcap_is_rebuilt_into_a_readable_bag_up_to_its_last_complete_record(whole, tmp_path, cut):
    path, flushed = whole
    src = path / f"{path.name}.mcap"
    data = src.read_bytes()
    size = {"after_chunk_3": flushed[2][1], "inside_chunk_4": (flushed[2][1] + flushed[3][1]) // 2,
            "header_only": 8 + 9 + 40, "mid_record": flushed[0][1] + 5}[cut]
    bag = tmp_path / "killed"
    bag.mkdir()
    (bag / "killed.mcap").write_bytes(data[:size])           # what a SIGKILLed recorder leaves: no footer, no yaml
    with pytest.raises(BagError):
        list(read_bag(bag))
    if cut == "header_only":
        r = recover_bag(bag)
        assert sum(r.counts.values()) == 0 and r.chunks == 0
        return
    r = recover_bag(bag)
    assert r.output == bag and r.damaged == tmp_path / "killed.damaged" and (r.damaged / "killed.mcap").exists()
    msgs = list(read_bag(bag))                               # rosbags reads it (metadata.yaml, index, footer)
    got = len(msgs)
    whole_chunks = {"after_chunk_3": 3, "inside_chunk_4": 3, "mid_record": 1}[cut]
    assert r.chunks == whole_chunks
    expected = whole_chunks * 50 + r.partial_messages
    assert got == sum(r.counts.values()) == expected
    if cut == "inside_chunk_4":
        assert 0 < r.partial_messages < 50                   # the complete messages of the cut chunk are kept
    stamps = [m[2] for m in msgs]
    assert stamps == [1_000_000_000 + k * 10_000_000 for k in range(got)]   # in order, none missing before the cut
    assert (r.start_ns, r.end_ns) == (stamps[0], stamps[-1])
    store = typestore()
    js = [store.deserialize_cdr(m[3], m[1]) for m in msgs if m[0] == "/hexa/joint_states"]
    assert [j.position[0] for j in js] == [float(k) for k in range(0, got, 2)]
    assert bag_topics(bag)["/hexa/joint_states"][2] is False  # its QoS (best effort) survives


def test_recover_refuses_a_readable_bag_and_a_non_mcap_naming_it(whole, tmp_path):
    path, _ = whole
    with pytest.raises(BagError, match="readable bag already"):
        recover_bag(path)
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "bad.mcap").write_bytes(b"")
    with pytest.raises(BagError, match="not an MCAP file"):
        recover_bag(bad)
    with pytest.raises(BagError, match="no MCAP file"):
        recover_bag(tmp_path / "missing")
    copy = tmp_path / "copy"
    shutil.copytree(path, copy)
    (copy / "metadata.yaml").unlink()
    r = recover_bag(copy, tmp_path / "out")                  # footer intact, yaml lost: all of it, elsewhere
    assert sum(r.counts.values()) == 300 and r.damaged is None and (copy / "whole.mcap").exists()
    assert salvage_mcap(copy / "whole.mcap").chunks == 6
