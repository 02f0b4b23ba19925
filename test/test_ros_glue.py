"""hexa_ros: the shared node layer — stamps, composition of several nodes in one process (each keeps its name and its
parameters from the shared file), clean Ctrl-C, configuration errors in one line."""
from __future__ import annotations

import signal
import sys
import time

import pytest

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable


def test_stamps_round_trip_and_never_carry_a_billion_nanoseconds():
    from hexa_ros.stamps import to_sec, to_stamp

    for t in (0.0, 1.5, 12.999_999_999_7, 1e9 + 0.25):
        s = to_stamp(t)
        assert 0 <= s.nanosec < 1_000_000_000
        assert to_sec(s) == pytest.approx(t, abs=1e-9 * max(1.0, t) * 1e-6 + 1e-9)
    with pytest.raises(ValueError, match="non-finite"):
        to_stamp(float("nan"))


def test_counters_with_rejects_warn_and_their_values_read_back_as_strings():
    from hexa_ros.diagnostics import OK, WARN, counter_status, rejects, status, values_of

    counters = {"frames": 12, "reject: nan": 2, "reject: size": 1, "note": "x"}
    assert rejects(counters) == 3
    st = counter_status("pose", counters, "tracking")
    assert (st.level, st.message) == (WARN, "3 input(s) rejected")
    assert values_of(st) == {"frames": "12", "note": "x", "reject: nan": "2", "reject: size": "1"}
    assert [kv.key for kv in st.values] == sorted(counters)          # sorted: a stable display
    clean = counter_status("pose", {"frames": 3}, "tracking", hardware_id="cam_top")
    assert (clean.level, clean.message, clean.hardware_id) == (OK, "tracking", "cam_top")
    assert values_of(status("n", OK, "", {})) == {}


def test_malloc_thresholds_are_in_the_child_environment_and_applied_in_process():
    from hexa_ros.env import MALLOC_THRESHOLDS, ros_env, tune_malloc

    env = ros_env(base={})
    assert env["MALLOC_MMAP_THRESHOLD_"] == str(MALLOC_THRESHOLDS["MMAP_THRESHOLD"])
    assert env["MALLOC_TRIM_THRESHOLD_"] == str(MALLOC_THRESHOLDS["TRIM_THRESHOLD"])
    assert ros_env(base={"MALLOC_MMAP_THRESHOLD_": "1"})["MALLOC_MMAP_THRESHOLD_"] == "1"   # the user's value stays
    assert tune_malloc() is sys.platform.startswith("linux")


def test_compose_refuses_a_malformed_spec_naming_it():
    from hexa_ros.compose import ComposeError, parse_specs

    specs, ros = parse_specs(["a=m.x:A", "b=m.y:B", "--ros-args", "-p", "x:=1"])
    assert specs == [("a", "m.x", "A"), ("b", "m.y", "B")] and ros == ["--ros-args", "-p", "x:=1"]
    for bad, words in ((["observer"], "NAME=MODULE:CLASS"), (["a=m:A", "a=n:B"], "twice"), ([], "no node")):
        with pytest.raises(ComposeError, match=words):
            parse_specs(bad)


def test_composed_nodes_keep_their_names_and_parameters_and_stop_on_ctrl_c(procs, ros_env, tmp_path):
    import subprocess

    params = tmp_path / "p.yaml"
    params.write_text("/**/observer:\n  ros__parameters:\n    min_duration: 0.03\n"
                      "/**/singularity:\n  ros__parameters:\n    omega_limit: 0.075\n")
    p = procs.start([PY, "-m", "hexa_ros.compose", "observer=hexa_dynamics.observer_node:ObserverNode",
                     "singularity=hexa_dynamics.singularity_node:SingularityNode", "--ros-args", "-r",
                     "__ns:=/glue", "--params-file", str(params)], ros_env)
    got = {}
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(got) < 2:
        for node, key in (("/glue/observer", "min_duration"), ("/glue/singularity", "omega_limit")):
            r = subprocess.run([PY, "-m", "hexa_bringup.cli", "param", "get", node, key], env=ros_env,
                               capture_output=True, text=True, timeout=60)
            if r.returncode == 0 and r.stdout.strip():
                got[node] = r.stdout.strip()
        time.sleep(0.5)
    assert "0.03" in got.get("/glue/observer", ""), got
    assert "0.075" in got.get("/glue/singularity", ""), got
    assert p.poll() is None
    p.send_signal(signal.SIGINT)
    _out, err = p.communicate(timeout=15)
    assert p.returncode == 0 and "Traceback" not in err, err
    # each node logs once when built, so the first log call's inspect cost is not paid in a callback
    assert "[glue.observer]: ready" in err and "[glue.singularity]: ready" in err, err


SIGNAL_AT_READY = """
import os, signal, sys
from rclpy.node import Node
from hexa_ros import node

class SignalledWhenBuilt(Node):
    built = False

    def __init__(self):
        super().__init__("signalled_when_built")
        self.built = True

    def get_logger(self):   # the "ready" line: the signal arrives between the build and the spin
        if self.built:
            os.kill(os.getpid(), signal.%s)
        return super().get_logger()

sys.exit(node.main(SignalledWhenBuilt, "probe", ["probe"]))
"""


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_signal_between_the_build_and_the_spin_stops_with_rc_0_and_no_traceback(procs, ros_env, sig):
    p = procs.start([PY, "-c", SIGNAL_AT_READY % sig], ros_env)
    _out, err = p.communicate(timeout=60)
    assert p.returncode == 0 and "Traceback" not in err, (p.returncode, err)


def test_compose_with_an_unknown_class_exits_2_in_one_line(procs, ros_env):
    p = procs.start([PY, "-m", "hexa_ros.compose", "x=hexa_dynamics.observer_node:NoSuchNode"], ros_env)
    _out, err = p.communicate(timeout=60)
    assert p.returncode == 2 and "NoSuchNode" in err and "Traceback" not in err, err


def test_polled_subscriptions_keep_the_last_depth_messages_until_taken(ros_env, monkeypatch):
    """hexa_ros.polled: no executor spins the polled node; `take` returns the reader's last `depth` messages (raw
    bytes, oldest first), then nothing until new ones arrive; the owner's node-local remaps (a composed node's)
    apply."""
    import time

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import UInt32

    from hexa_ros.polled import PolledSubscriptions

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    owner = rclpy.create_node("polled_owner", namespace="/t", context=ctx,
                              cli_args=["--ros-args", "-r", "numbers:=renamed"])
    polled = PolledSubscriptions(owner, "images")
    try:
        assert (polled.node.get_name(), polled.node.get_namespace()) == ("polled_owner_images", "/t")
        sub = polled.subscribe(UInt32, "numbers", QoSProfile(depth=3, reliability=ReliabilityPolicy.BEST_EFFORT))
        assert sub.topic_name == "/t/renamed"
        pub = owner.create_publisher(UInt32, "numbers", 10)
        deadline = time.monotonic() + 20.0
        while (pub.get_subscription_count() < 1 or polled.node.count_publishers("/t/renamed") < 1) \
                and time.monotonic() < deadline:       # publisher and reader have matched
            time.sleep(0.05)
        assert pub.get_subscription_count() == 1, "the polled subscription was not discovered"
        taken: list[int] = []
        n = 0
        while len(taken) < 3 and time.monotonic() < deadline:
            for _ in range(5):                     # five new messages between takes: the reader keeps three
                pub.publish(UInt32(data=n))
                n += 1
            time.sleep(0.1)
            batch = polled.take(sub)
            assert len(batch) <= 3 and all(isinstance(b, bytes) for b in batch)
            taken += [deserialize_message(b, UInt32).data for b in batch]
        assert len(taken) >= 3 and taken == sorted(set(taken)), taken     # oldest first, each once
        assert polled.take(sub) == []
    finally:
        polled.close()
        owner.destroy_node()
        rclpy.shutdown(context=ctx)


def test_a_deferred_service_answers_later_while_the_executor_serves_other_requests(ros_env, monkeypatch):
    """hexa_ros.deferred: a request whose callback returns Later(delay, finish) is answered `delay` s later with what
    `finish` filled in; one answered at once meanwhile is not held behind it; close() cancels answers to come."""
    import threading
    import time

    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    from hexa_ros.deferred import DeferredService, Later

    def start(req, resp):
        if not starts:                       # the first request: answered 0.6 s later
            starts.append(time.monotonic())
            return Later(0.6, lambda r: setattr(r, "message", "late"))
        resp.success, resp.message = True, "now"
        return resp

    starts: list[float] = []
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    server = rclpy.create_node("deferred_server", context=ctx)
    client_node = rclpy.create_node("deferred_client", context=ctx)
    srv = DeferredService(server, Trigger, "job", start)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(server)
    ex.add_node(client_node)
    spin = threading.Thread(target=ex.spin, daemon=True)
    spin.start()
    try:
        cli = client_node.create_client(Trigger, "job")
        assert cli.wait_for_service(timeout_sec=20.0)
        slow = cli.call_async(Trigger.Request())
        deadline = time.monotonic() + 10.0
        while not starts and time.monotonic() < deadline:
            time.sleep(0.01)
        fast = cli.call_async(Trigger.Request())
        while not fast.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert fast.done() and fast.result().message == "now" and not slow.done()   # not held behind the slow one
        while not slow.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert slow.done() and slow.result().message == "late"
        assert time.monotonic() - starts[0] >= 0.6
        starts.clear()                       # one more slow request, then close(): it is never answered
        never = cli.call_async(Trigger.Request())
        while not starts and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.1)
        srv.close()
        time.sleep(0.8)
        assert not never.done()
    finally:
        ex.shutdown()
        server.destroy_node()
        client_node.destroy_node()
        rclpy.shutdown(context=ctx)


def test_a_deferred_answer_refuses_a_delay_no_timer_can_wait():
    from hexa_ros.deferred import Later

    assert Later(0.5, print).delay == 0.5
    for bad in (-1.0, float("nan"), float("inf"), 1e300):
        with pytest.raises(ValueError, match="delay"):
            Later(bad, print)
