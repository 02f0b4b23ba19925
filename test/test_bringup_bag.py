"""`hexa record` writes MCAP bags other tools can open; `hexa play` publishes them back."""
from __future__ import annotations

import json
import signal
import sys
import time

import pytest

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable


def test_record_writes_an_mcap_bag_whose_messages_deserialize_with_rosbags(procs, ros_env, tmp_path):
    from rosbags.rosbag2 import Reader

    from hexa_bringup.bag import typestore

    procs.start([PY, "test/roundtrip_peer.py", "collision"], ros_env)
    bag = tmp_path / "b1"
    rec = procs.start([PY, "-m", "hexa_bringup.cli", "record", "/hexa/collision", "-o", str(bag), "--duration", "4",
                       "--json"], ros_env)
    out, err = rec.communicate(timeout=60)
    assert rec.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["counts"]["/hexa/collision"] >= 10
    assert list(bag.glob("*.mcap")), "no .mcap file written"
    store = typestore()
    with Reader(bag) as reader:
        [conn] = reader.connections
        assert conn.msgtype == "hexa_msgs/msg/CollisionEvent"
        assert "uint8 START=0" in conn.msgdef.data  # the definition travels with the bag
        n = 0
        for c, _t, data in reader.messages():
            msg = store.deserialize_cdr(data, c.msgtype)
            assert (msg.id, msg.axis_name, msg.value) == (7, "z", 3.5)
            n += 1
        assert n == summary["counts"]["/hexa/collision"]


def test_record_is_closed_cleanly_on_ctrl_c(procs, ros_env, tmp_path):
    from rosbags.rosbag2 import Reader

    procs.start([PY, "test/roundtrip_peer.py", "collision"], ros_env)
    bag = tmp_path / "b2"
    rec = procs.start([PY, "-m", "hexa_bringup.cli", "record", "-o", str(bag)], ros_env)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:  # wait until it subscribed
        line = rec.stderr.readline()
        if "recording /hexa/collision" in line:
            break
    time.sleep(1.5)
    rec.send_signal(signal.SIGINT)
    out, _err = rec.communicate(timeout=30)
    assert rec.returncode == 0
    assert (bag / "metadata.yaml").exists(), "bag not finalised (metadata.yaml missing)"
    with Reader(bag) as reader:
        assert reader.message_count > 0


def test_record_refuses_to_overwrite_an_existing_bag(procs, ros_env, tmp_path):
    (tmp_path / "exists").mkdir()
    rec = procs.start([PY, "-m", "hexa_bringup.cli", "record", "-o", str(tmp_path / "exists"), "--duration", "1"],
                      ros_env)
    _out, err = rec.communicate(timeout=60)
    assert rec.returncode == 2 and "exists already" in err


def _collision_bag(procs, ros_env, bag):
    """Two seconds of the peer's /hexa/collision recorded into `bag`; every process stopped after."""
    procs.start([PY, "test/roundtrip_peer.py", "collision"], ros_env)
    rec = procs.start([PY, "-m", "hexa_bringup.cli", "record", "/hexa/collision", "-o", str(bag),
                       "--duration", "2"], ros_env)
    rec.communicate(timeout=60)
    procs.stop_all()
    procs.procs.clear()
    return bag


def test_play_publishes_the_recorded_messages_to_a_subscriber(procs, ros_env, tmp_path):
    bag = _collision_bag(procs, ros_env, tmp_path / "b3")
    echo = procs.start([PY, "-m", "hexa_bringup.cli", "topic", "echo", "/hexa/collision",
                        "hexa_msgs/msg/CollisionEvent", "-n", "3", "--json", "--timeout", "40"], ros_env)
    time.sleep(2.0)
    play = procs.start([PY, "-m", "hexa_bringup.cli", "play", str(bag), "--rate", "1", "--wait", "2", "--json"],
                       ros_env)
    pout, perr = play.communicate(timeout=60)
    assert play.returncode == 0, perr
    assert json.loads(pout.strip().splitlines()[-1])["published"] >= 5
    out, err = echo.communicate(timeout=60)
    assert echo.returncode == 0, err
    msgs = [json.loads(line) for line in out.strip().splitlines()]
    assert len(msgs) == 3 and all(m["id"] == 7 and m["axis_name"] == "z" for m in msgs)


def test_play_names_a_missing_bag(procs, ros_env, tmp_path):
    play = procs.start([PY, "-m", "hexa_bringup.cli", "play", str(tmp_path / "nope")], ros_env)
    _out, err = play.communicate(timeout=60)
    assert play.returncode == 2 and "nope" in err


def test_a_sigkilled_recording_is_recovered_losing_at_most_the_last_second(procs, ros_env, tmp_path):
    from rosbags.rosbag2 import Reader

    from hexa_bringup.bag import typestore

    procs.start([PY, "test/roundtrip_peer.py", "stream"], ros_env)     # CollisionEvent id 0, 1, ... at 100 Hz
    bag = tmp_path / "killed"
    rec = procs.start([PY, "-m", "hexa_bringup.cli", "record", "/hexa/collision", "-o", str(bag)], ros_env)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if "recording /hexa/collision" in rec.stderr.readline():
            break
    time.sleep(3.45)        # the recorder flushes every 0.5 s from its start: killed just before a flush (worst case)
    t_kill = time.time_ns()
    rec.send_signal(signal.SIGKILL)
    rec.wait(timeout=10)
    assert not (bag / "metadata.yaml").exists()
    fix = procs.start([PY, "-m", "hexa_bringup.cli", "bag", "recover", str(bag), "--json"], ros_env)
    out, err = fix.communicate(timeout=60)
    assert fix.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    lost = (t_kill - summary["end_ns"]) / 1e9
    print(f"SIGKILLed recording: {summary['counts']} recovered, last {lost:.3f} s lost")
    assert lost <= 1.0 and summary["counts"]["/hexa/collision"] >= 150
    store = typestore()
    with Reader(bag) as reader:                                      # rosbags opens it: metadata, index, footer
        ids = [store.deserialize_cdr(d, c.msgtype).id for c, _t, d in reader.messages()]
    assert ids == list(range(ids[0], ids[0] + len(ids)))             # none missing up to the cut
    play = procs.start([PY, "-m", "hexa_bringup.cli", "play", str(bag), "--rate", "0", "--wait", "0", "--json"],
                       ros_env)
    pout, perr = play.communicate(timeout=60)
    assert play.returncode == 0, perr
    assert json.loads(pout.strip().splitlines()[-1])["published"] == len(ids)


def test_play_waits_for_as_many_subscribers_as_asked_and_says_which_topic_had_too_few(procs, ros_env, tmp_path):
    bag = _collision_bag(procs, ros_env, tmp_path / "b4")
    bad = procs.start([PY, "-m", "hexa_bringup.cli", "play", str(bag), "--subscribers", "/hexa/collision=0"],
                      ros_env)
    _out, err = bad.communicate(timeout=60)
    assert bad.returncode == 2 and "TOPIC=N" in err and "Traceback" not in err
    procs.start([PY, "-m", "hexa_bringup.cli", "topic", "echo", "/hexa/collision", "hexa_msgs/msg/CollisionEvent",
                 "-n", "1", "--timeout", "40"], ros_env)
    t0 = time.monotonic()
    play = procs.start([PY, "-m", "hexa_bringup.cli", "play", str(bag), "--wait", "6", "--wait-subscribers",
                        "--subscribers", "hexa/collision=2"], ros_env)
    _out, err = play.communicate(timeout=60)
    assert play.returncode == 0, err
    assert "too few subscribers after 6 s on /hexa/collision (1 of 2)" in err
    assert time.monotonic() - t0 >= 6.0       # one matched reader did not end the wait
