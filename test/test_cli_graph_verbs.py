"""The `hexa` graph verbs with ros2cli's habits, each against a real observer node in another process: service call
with the type from the graph, topic pub / info -v, node list / info, interface show, bag info, param describe / dump /
load, doctor, shell completion; a user's mistake ends with one line and exit 2, never a traceback."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest
import yaml

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable
HEXA = [PY, "-m", "hexa_bringup.cli"]


@pytest.fixture(scope="module")
def graph(module_ros_domain_id, tmp_path_factory):
    """An observer node in /hexa (its own process) and the environment to reach it."""
    from hexa_bringup.rosenv import ros_env

    env = ros_env(module_ros_domain_id)
    log = open(tmp_path_factory.mktemp("cli") / "observer.log", "w")  # noqa: SIM115 - closed at teardown
    node = subprocess.Popen([PY, "-m", "hexa_dynamics.observer_node", "--ros-args", "-r", "__ns:=/hexa"], env=env,
                            start_new_session=True, stdout=log, stderr=subprocess.STDOUT)
    try:
        r = hexa(env, "node", "info", "/hexa/observer", "--timeout", "60")
        assert r.returncode == 0, r.stderr
        yield env
    finally:
        try:
            os.killpg(node.pid, signal.SIGINT)
            node.wait(timeout=15)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            os.killpg(node.pid, signal.SIGKILL)
            node.wait(timeout=5)
        log.close()


def hexa(env, *args, timeout: float = 120.0, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([*HEXA, *args], env=env, capture_output=True, text=True, timeout=timeout, **kw)


def user_error(r: subprocess.CompletedProcess) -> str:
    """The one-line message of a command that failed on a user's mistake (asserting the form)."""
    assert r.returncode == 2, (r.returncode, r.stdout[-1000:], r.stderr[-2000:])
    assert "Traceback" not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hexa "), r.stderr
    return lines[0]


def test_service_call_takes_the_type_from_the_graph_when_the_request_comes_second(graph):
    r = hexa(graph, "service", "call", "/hexa/observer/reset", "{recalibrate: false}", "--json")
    assert r.returncode == 0 and json.loads(r.stdout) == {"success": True, "message": "reset"}, r.stderr
    r = hexa(graph, "service", "call", "/hexa/observer/reset", "hexa_msgs/srv/ResetObserver",
             "{recalibrate: false}", "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["success"] is True, r.stderr
    assert "no field 'bogus'" in user_error(hexa(graph, "service", "call", "/hexa/observer/reset", "{bogus: 1}"))
    assert "no service /hexa/nope" in user_error(hexa(graph, "service", "call", "/hexa/nope", "{a: 1}",
                                                      "--timeout", "2"))


def test_topic_info_verbose_gives_each_endpoints_qos(graph):
    r = hexa(graph, "topic", "info", "-v", "/hexa/collision_state", "--json")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["types"] == ["hexa_msgs/msg/CollisionEvent"] and info["publishers"] == 1
    [pub] = info["publisher_endpoints"]
    assert (pub["node"], pub["namespace"], pub["endpoint"]) == ("observer", "/hexa", "PUBLISHER")
    assert (pub["qos"]["reliability"], pub["qos"]["durability"]) == ("reliable", "transient_local")
    r = hexa(graph, "topic", "info", "-v", "/hexa/joint_states")      # the observer subscribes: best effort stream
    assert r.returncode == 0 and "Subscription count: 1" in r.stdout and "Node name: observer" in r.stdout, r.stdout
    assert "no topic /hexa/nothing" in user_error(hexa(graph, "topic", "info", "/hexa/nothing", "--wait", "0.5",
                                                                "--timeout", "1"))


def test_topic_pub_reaches_a_subscriber_and_infers_the_type(graph):
    echo = subprocess.Popen([*HEXA, "topic", "echo", "/hexa/cli_note", "std_msgs/msg/String", "--once", "--json",
                             "--timeout", "60"], env=graph, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        r = hexa(graph, "topic", "pub", "/hexa/cli_note", "std_msgs/msg/String", "{data: hello}", "--once",
                 "--timeout", "60")
        assert r.returncode == 0, r.stderr
        out, err = echo.communicate(timeout=60)
    finally:
        if echo.poll() is None:
            echo.kill()
    assert echo.returncode == 0 and json.loads(out) == {"data": "hello"}, err
    # no type given: the graph's (the observer subscribes to plate_pose); --once waits for that subscription
    r = hexa(graph, "topic", "pub", "/hexa/plate_pose", "{header: {frame_id: base}, pose: {orientation: {w: 1.0}}}",
             "--once", "--timeout", "30")
    assert r.returncode == 0 and "publishing #1" in r.stdout, r.stderr
    assert "not in the graph" in user_error(hexa(graph, "topic", "pub", "/hexa/unknown", "{data: 1}", "--once",
                                                 "--timeout", "1"))


def test_node_list_and_info_show_the_observer(graph):
    r = hexa(graph, "node", "list", "--json")
    assert r.returncode == 0 and "/hexa/observer" in json.loads(r.stdout), r.stderr
    r = hexa(graph, "node", "info", "/hexa/observer", "--json")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["publishers"]["/hexa/residual"] == ["hexa_msgs/msg/Residual"]
    assert info["subscribers"]["/hexa/joint_states"] == ["sensor_msgs/msg/JointState"]
    assert info["service_servers"]["/hexa/observer/reset"] == ["hexa_msgs/srv/ResetObserver"]
    assert "no node /hexa/nope" in user_error(hexa(graph, "node", "info", "/hexa/nope", "--timeout", "1"))


def test_interface_show_prints_the_definition(graph):
    r = hexa(graph, "interface", "show", "hexa_msgs/msg/CollisionEvent")
    assert r.returncode == 0 and "uint8 START=0" in r.stdout, r.stderr
    r = hexa(graph, "interface", "show", "hexa_msgs/ResetObserver")
    assert r.returncode == 0 and "---" in r.stdout and "recalibrate" in r.stdout, r.stderr
    assert "has no interface msg/Nope" in user_error(hexa(graph, "interface", "show", "hexa_msgs/msg/Nope"))
    r = hexa(graph, "interface", "list", "hexa_msgs", "--json")
    assert "hexa_msgs/srv/CalibrateCurrents" in json.loads(r.stdout)


def test_bag_info_of_a_recording_of_the_latched_collision_state(graph, tmp_path):
    bag = tmp_path / "state_bag"
    r = hexa(graph, "record", "/hexa/collision_state", "-o", str(bag), "--duration", "3")
    assert r.returncode == 0, r.stderr
    r = hexa(graph, "bag", "info", str(bag), "--json")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    t = info["topics"]["/hexa/collision_state"]
    assert t["type"] == "hexa_msgs/msg/CollisionEvent" and t["count"] == info["messages"] >= 1
    assert t["qos"][0]["durability"] == "transient_local" and info["storage"] == "mcap"
    r = hexa(graph, "bag", "info", str(bag))
    assert "/hexa/collision_state" in r.stdout and "Duration:" in r.stdout
    assert "does not exist" in user_error(hexa(graph, "bag", "info", str(tmp_path / "nope")))


def test_param_describe_dump_and_load(graph, tmp_path):
    r = hexa(graph, "param", "describe", "/hexa/observer", "frame_id", "marker_scale", "--json")
    assert r.returncode == 0, r.stderr
    d = {x["name"]: x for x in json.loads(r.stdout)}
    assert d["frame_id"]["read_only"] is True and d["frame_id"]["description"]
    assert d["marker_scale"]["read_only"] is False and d["marker_scale"]["range"]["max"] > 0
    assert "no parameter 'nope'" in user_error(hexa(graph, "param", "describe", "/hexa/observer", "nope"))
    r = hexa(graph, "param", "dump", "/hexa/observer")
    assert r.returncode == 0, r.stderr
    dump = yaml.safe_load(r.stdout)
    params = dump["/hexa/observer"]["ros__parameters"]
    assert params["frame_id"] == "base" and isinstance(params["thresholds"], list)
    f = tmp_path / "observer.yaml"
    r = hexa(graph, "param", "dump", "/hexa/observer", "-o", str(f))
    assert r.returncode == 0 and yaml.safe_load(f.read_text()) == dump, r.stderr
    r = hexa(graph, "param", "load", "/hexa/observer", str(f))       # everything already in effect
    assert r.returncode == 0 and "set 0" in r.stdout and "refused 0" in r.stdout, (r.stdout, r.stderr)
    params.update(marker_scale=params["marker_scale"] * 2, frame_id="elsewhere")
    f.write_text(yaml.safe_dump(dump))
    r = hexa(graph, "param", "load", "/hexa/observer", str(f))
    assert r.returncode == 1 and "set 1" in r.stdout and "refused 1" in r.stdout, (r.stdout, r.stderr)
    assert "frame_id refused" in r.stderr and "read-only" in r.stderr
    r = hexa(graph, "param", "get", "/hexa/observer", "marker_scale")
    assert json.loads(r.stdout) == pytest.approx(params["marker_scale"])
    r = hexa(graph, "param", "get", "/hexa/observer", "frame_id")
    assert json.loads(r.stdout) == "base"
    assert "no node /hexa/nope" in user_error(hexa(graph, "param", "dump", "/hexa/nope", "--timeout", "1"))


def test_doctor_reports_the_middleware_the_graph_and_the_firmware(graph):
    r = hexa(graph, "doctor", "--json", "--wait", "8")    # discovery of the node: seconds on a loaded machine
    assert r.stdout, r.stderr
    report = json.loads(r.stdout)
    checks = {c["name"]: c for c in report["checks"]}
    assert r.returncode == (1 if report["failed"] else 0)
    assert checks["rmw"]["state"] == "ok" and checks["rmw loaded"]["detail"] == "rmw_fastrtps_cpp"
    assert "segment 32 MB" in checks["dds profile"]["detail"]
    assert checks["domain"]["detail"].startswith(f"ROS_DOMAIN_ID={graph['ROS_DOMAIN_ID']}")
    assert "LOCALHOST" in checks["discovery"]["detail"]
    assert "/hexa/observer" in checks["graph"]["detail"]
    assert {"firmware uno", "firmware mega"} <= set(checks)
    assert "cameras" in checks or "camera" in checks
    assert any(name.startswith("serial port") for name in checks)
    r = hexa(dict(graph, ROS_DOMAIN_ID="500"), "doctor", "--json", "--wait", "0")
    assert r.stdout, r.stderr
    bad = {c["name"]: c for c in json.loads(r.stdout)["checks"]}
    assert r.returncode == 1 and bad["domain"]["state"] == "fail"


def test_user_mistakes_end_with_one_line_and_exit_2(graph, tmp_path):
    cases = [
        (["topic", "echo", "/hexa/residual", "not/a/Type", "--once", "--timeout", "2"], "not/a/Type"),
        (["topic", "pub", "/hexa/x", "std_msgs/msg/String", "{data: [1"], "not valid YAML"),
        (["topic", "pub", "/hexa/x", "std_msgs/msg/String", "{nope: 1}", "--once", "-w", "0"], "no field 'nope'"),
        (["service", "call", "/hexa/observer/reset", "[1, 2]"], "must be a mapping"),
        (["service", "call", "/hexa/observer/reset", "std_srvs/srv/Nope", "{}"], "std_srvs/srv/Nope"),
        (["interface", "show", "nonsense"], "malformed type"),
        (["bringup", "replay", str(tmp_path / "no_bag")], "does not exist"),
        (["param", "load", "/hexa/observer", str(tmp_path / "none.yaml")], "cannot read"),
        (["node", "info", "bad name!", "--timeout", "1"], "bad name!"),
        (["demo", "--rtf", "-1"], "--rtf must be > 0"),
        (["demo", "--rtf", "nan"], "--rtf must be > 0"),
    ]
    for args, words in cases:
        line = user_error(hexa(graph, *args))
        assert words in line, (args, line)


def test_shell_completion_completes_verbs(tmp_path):
    """argcomplete's protocol as bash's completion function drives it."""
    from hexa_bringup.rosenv import ros_env

    out = tmp_path / "completions"
    env = dict(ros_env(None), _ARGCOMPLETE="1", _ARGCOMPLETE_IFS="\n", COMP_LINE="hexa topic p", COMP_POINT="12",
               _ARGCOMPLETE_STDOUT_FILENAME=str(out))
    t0 = time.monotonic()
    r = subprocess.run([*HEXA], env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert [w.strip() for w in out.read_text().split("\n")] == ["pub"], out.read_text()
    env.update(COMP_LINE="hexa param d", COMP_POINT="12")
    subprocess.run([*HEXA], env=env, capture_output=True, text=True, timeout=60)
    assert sorted(w.strip() for w in out.read_text().split("\n")) == ["describe", "dump"]
    print(f"two completions in {time.monotonic() - t0:.1f} s")


def test_demo_prints_its_domain_and_the_line_that_watches_it_from_a_second_shell(graph, tmp_path):
    """The printed line, run as printed from a shell with the default discovery range, finds the observer's
    /hexa/collision (the demo's graph is on this host only)."""
    import re
    import shlex

    r = hexa(graph, "demo", "--params", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "demo"))
    assert r.returncode == 2 and "parameter file" in r.stderr      # stops before any graph starts
    m = re.search(r"^\s+(ROS_DOMAIN_ID=(\d+) hexa topic echo /hexa/collision)$", r.stdout, re.M)
    assert m and m.group(2) == graph["ROS_DOMAIN_ID"], r.stdout
    shell = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "RMW_", "FAST"))}
    assign, *argv = shlex.split(m.group(1))
    shell[assign.split("=")[0]] = assign.split("=")[1]
    watch = subprocess.run([*HEXA, *argv[1:], "--timeout", "6"], env=shell, capture_output=True, text=True,
                           timeout=90)
    # no collision happens here: it found the publisher and waited for messages (exit 1), it did not miss the node
    assert watch.returncode == 1 and "0 of any messages on /hexa/collision" in watch.stderr, watch.stderr


def test_completion_offers_the_graphs_topic_and_node_names(graph, tmp_path):
    out = tmp_path / "completions"
    env = dict(graph, _ARGCOMPLETE="1", _ARGCOMPLETE_IFS="\n", _ARGCOMPLETE_STDOUT_FILENAME=str(out))
    for line, wanted in (("hexa topic info /hexa/coll", {"/hexa/collision", "/hexa/collision_state"}),
                         ("hexa param dump /hexa/obs", {"/hexa/observer"})):
        env.update(COMP_LINE=line, COMP_POINT=str(len(line)))
        r = subprocess.run([*HEXA], env=env, capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        assert {w.strip() for w in out.read_text().split("\n")} == wanted, out.read_text()


def test_doctor_reads_the_firmware_version_a_running_driver_reports(tmp_path, procs, ros_env):
    """The driver against the board emulators on ptys (the firmware's protocol): doctor names both boards."""
    from hexa.protocol.emulator import MegaEmulator, UnoEmulator
    from test_driver_helpers import driver_args

    with UnoEmulator(link=tmp_path / "uno") as uno, MegaEmulator(link=tmp_path / "mega") as mega:
        procs.start(driver_args(uno.port, mega.port, "stream_rate_hz:=200", "diagnostics_period:=0.2"), ros_env)
        boards: list = []
        deadline = time.monotonic() + 60
        while not len(boards) == 2 and time.monotonic() < deadline:
            r = hexa(ros_env, "doctor", "--json", "--wait", "3")
            boards = [c for c in json.loads(r.stdout)["checks"] if c["name"] == "board"]
    assert len(boards) == 2, boards
    assert all(c["state"] == "ok" and "firmware 0x100 (" in c["detail"] for c in boards), boards   # the emulators'
    assert any("(Mega)" in c["detail"] for c in boards) and any("(Uno)" in c["detail"] for c in boards), boards


def test_param_load_reads_the_sections_and_wildcards_of_a_ros_parameters_file():
    from hexa_bringup.commands._ros import CliError
    from hexa_bringup.commands.service import file_parameters
    from hexa_bringup.graphs import DEFAULT_PARAMS

    shipped = file_parameters(yaml.safe_load(DEFAULT_PARAMS.read_text()), "/hexa/observer", "hexa_params.yaml")
    assert "thresholds" in shipped and "approach_speed" not in shipped          # /**/observer, not /**/trajectory
    data = {"/**": {"ros__parameters": {"use_sim_time": True, "a": 1}},
            "/hexa": {"observer": {"ros__parameters": {"a": 2, "gains": {"k": 3}}}},
            "/*/rnea": {"ros__parameters": {"a": 4}}}
    assert file_parameters(data, "/hexa/observer", "f") == {"use_sim_time": True, "a": 2, "gains.k": 3}
    assert file_parameters(data, "/hexa/rnea", "f") == {"use_sim_time": True, "a": 4}
    with pytest.raises(CliError, match="no ros__parameters for /hexa/pose"):
        file_parameters({"/hexa/observer": {"ros__parameters": {"a": 1}}}, "/hexa/pose", "f")


def test_a_verb_started_with_sigint_ignored_still_stops_on_sigint(graph):
    """A background job of a non-interactive shell inherits SIGINT ignored; `hexa` restores it, so Ctrl-C or
    `kill -INT` ends a waiting verb with 130 instead of leaving it running."""
    echo = subprocess.Popen([*HEXA, "topic", "echo", "/hexa/cli_quiet", "std_msgs/msg/String"], env=graph,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:       # the echo is up once its subscription is in the graph
            r = hexa(graph, "topic", "info", "/hexa/cli_quiet")
            if r.returncode == 0 and "Subscription count: 1" in r.stdout:
                break
            time.sleep(0.5)
        echo.send_signal(signal.SIGINT)
        out, err = echo.communicate(timeout=30)
    finally:
        if echo.poll() is None:
            echo.kill()
            echo.wait()
    assert echo.returncode == 130, (echo.returncode, err[-2000:])
    assert "Traceback" not in err, err
