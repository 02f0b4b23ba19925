"""Cross-process ROS tests of the workspace: every hexa_msgs type round-trips; `hexa topic` sees other processes."""
from __future__ import annotations

import json
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")
import hexa_msgs.msg as hm  # noqa: E402

from msg_samples import sample_message  # noqa: E402
from roundtrip_peer import MESSAGES  # noqa: E402
from hexa_bringup.msgutil import message_to_dict  # noqa: E402

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

PY = sys.executable


def _json_roundtrip(d: dict) -> dict:
    return json.loads(json.dumps(d))


def test_every_hexa_msgs_message_type_is_exchanged_between_two_processes_with_every_field_intact(procs, ros_env):
    pub = procs.start([PY, "test/roundtrip_peer.py", "pub"], ros_env)
    assert pub.stdout.readline().strip() == "published"
    sub = procs.start([PY, "test/roundtrip_peer.py", "sub", "30"], ros_env)
    out, err = sub.communicate(timeout=60)
    received = json.loads(out.strip().splitlines()[-1])
    assert sorted(received) == sorted(MESSAGES), err
    for k, name in enumerate(MESSAGES):
        expected = _json_roundtrip(message_to_dict(sample_message(getattr(hm, name), k + 1)))
        assert received[name] == expected, f"{name} changed on the way"
        defaults = _json_roundtrip(message_to_dict(getattr(hm, name)()))
        for field, value in expected.items():
            assert value != defaults[field], f"sample {name}.{field} equals its default: the test would prove nothing"


def test_hexa_topic_echo_once_json_prints_a_collision_event_published_by_another_process(procs, ros_env):
    procs.start([PY, "test/roundtrip_peer.py", "collision"], ros_env)
    echo = procs.start([PY, "-m", "hexa_bringup.cli", "topic", "echo", "/hexa/collision", "--once", "--json",
                        "--timeout", "30"], ros_env)
    out, err = echo.communicate(timeout=60)
    assert echo.returncode == 0, err
    msg = json.loads(out.strip().splitlines()[-1])
    assert msg["event"] == hm.CollisionEvent.START
    assert msg["id"] == 7 and msg["axis"] == 2 and msg["axis_name"] == "z"
    assert msg["value"] == 3.5 and msg["onset"] == {"sec": 12, "nanosec": 340_000_000}
    assert msg["header"]["frame_id"] == "base"


def test_hexa_topic_list_shows_another_process_topic_with_its_type(procs, ros_env):
    procs.start([PY, "test/roundtrip_peer.py", "collision"], ros_env)
    lst = procs.start([PY, "-m", "hexa_bringup.cli", "topic", "list", "--json", "--wait", "3"], ros_env)
    out, err = lst.communicate(timeout=60)
    assert lst.returncode == 0, err
    topics = json.loads(out)
    assert topics.get("/hexa/collision") == ["hexa_msgs/msg/CollisionEvent"]


def test_hexa_topic_hz_measures_the_rate_of_another_process(procs, ros_env):
    procs.start([PY, "test/roundtrip_peer.py", "collision"], ros_env)  # publishes at ~10 Hz
    hz = procs.start([PY, "-m", "hexa_bringup.cli", "topic", "hz", "/hexa/collision", "--duration", "4", "--json"],
                     ros_env)
    out, err = hz.communicate(timeout=60)
    assert hz.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["count"] >= 10
    assert 5.0 < summary["rate_hz"] < 12.0


def test_hexa_topic_echo_times_out_with_a_clear_message_when_nobody_publishes(procs, ros_env):
    echo = procs.start([PY, "-m", "hexa_bringup.cli", "topic", "echo", "/hexa/nothing_here", "--once",
                        "--timeout", "2"], ros_env)
    out, err = echo.communicate(timeout=60)
    assert echo.returncode != 0
    assert "no publisher of /hexa/nothing_here" in err
