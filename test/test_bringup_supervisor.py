"""The bringup supervisor: status table, respawn with back-off, signal forwarding, failure of required nodes."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest
import yaml

# ROS processes that only need the graph to answer, not to keep up with time: `make test` runs these on two
# workers beside the ROS-free tests (scripts/run_tests.sh)
pytestmark = pytest.mark.ros_parallel

PY = sys.executable


def _graph(tmp_path, nodes) -> str:
    path = tmp_path / "graph.yaml"
    path.write_text(yaml.safe_dump(nodes))
    return str(path)


def _bringup(procs, tmp_path, nodes, *extra):
    env = dict(__import__("os").environ)
    return procs.start([PY, "-m", "hexa_bringup.cli", "bringup", "sim", "--graph", _graph(tmp_path, nodes),
                        "--log-dir", str(tmp_path / "logs"), "--status-every", "1", *extra], env)


def test_crashing_node_is_respawned_with_growing_backoff_and_logged(procs, tmp_path):
    nodes = [{"name": "steady", "cmd": [PY, "-c", "import time; time.sleep(60)"]},
             {"name": "crashy", "cmd": [PY, "-c", "import time; time.sleep(0.2); raise SystemExit(3)"],
              "required": False}]
    sup = _bringup(procs, tmp_path, nodes, "--duration", "5")
    out, err = sup.communicate(timeout=60)
    assert sup.returncode == 0, out + err
    respawns = [line for line in out.splitlines() if "crashy: exited with code 3" in line]
    assert len(respawns) >= 3
    delays = [float(line.rsplit("respawning in ", 1)[1].split()[0]) for line in respawns]
    assert delays[:3] == [0.5, 1.0, 2.0]
    assert "steady" in out and "running" in out  # status table
    assert (tmp_path / "logs" / "crashy.log").exists()


def test_required_node_that_cannot_start_makes_bringup_exit_nonzero_naming_it(procs, tmp_path):
    nodes = [{"name": "steady", "cmd": [PY, "-c", "import time; time.sleep(60)"]},
             {"name": "broken", "cmd": [PY, "-c", "raise SystemExit(1)"]}]
    sup = _bringup(procs, tmp_path, nodes, "--duration", "30")
    out, err = sup.communicate(timeout=60)
    assert sup.returncode == 1
    assert "FAILED: required node broken exited with code 1 3 times" in out


def test_missing_executable_of_a_required_node_fails_with_its_name(procs, tmp_path):
    nodes = [{"name": "ghost", "cmd": ["/nonexistent/hexa-node"]}]
    sup = _bringup(procs, tmp_path, nodes, "--duration", "10")
    out, _err = sup.communicate(timeout=60)
    assert sup.returncode == 1 and "ghost" in out and "cannot start" in out


def test_sigint_is_forwarded_to_every_node_which_stops_cleanly(procs, tmp_path):
    marker = tmp_path / "stopped"
    code = ("import signal, sys, time, pathlib\n"
            "def h(s, f):\n"
            f"    pathlib.Path({str(marker)!r} + sys.argv[1]).write_text('ok'); sys.exit(0)\n"
            "signal.signal(signal.SIGINT, h)\n"
            "time.sleep(60)\n")
    nodes = [{"name": f"n{i}", "cmd": [PY, "-c", code, str(i)]} for i in range(3)]
    sup = _bringup(procs, tmp_path, nodes)
    time.sleep(3)
    sup.send_signal(signal.SIGINT)
    out, _err = sup.communicate(timeout=30)
    assert sup.returncode == 0, out
    assert all((tmp_path / f"stopped{i}").exists() for i in range(3))
    assert "stopping 3 nodes (signal SIGINT)" in out


def test_a_node_that_does_not_stop_writes_where_it_hangs_to_its_log_before_it_is_killed(tmp_path):
    import io

    from hexa_bringup.supervisor import NodeSpec, Supervisor

    # a hexa node's signal handling (hexa_ros.node), then a stop request that never ends the main thread's wait in C
    code = ("import threading, sys\n"
            "from hexa_ros import node\n"
            "node.install_signal_handlers(); node.stop_on_signal()\n"
            "def wait_for_a_lock_nobody_releases():\n"
            "    print('waiting', flush=True); threading.Event().wait()\n"
            "wait_for_a_lock_nobody_releases()\n")
    out = io.StringIO()
    sup = Supervisor([NodeSpec("stuck", [PY, "-c", code])], dict(__import__("os").environ),
                     log_dir=str(tmp_path / "logs"), out=out)
    sup._start(sup.nodes[0])
    log = tmp_path / "logs" / "stuck.log"
    t_end = time.monotonic() + 30
    while "waiting" not in (log.read_text() if log.exists() else "") and time.monotonic() < t_end:
        time.sleep(0.05)
    sup.stop_all(timeout=1.0)
    assert sup.nodes[0].last_rc == -signal.SIGKILL
    assert "stuck: did not stop within 1 s" in out.getvalue()
    text = log.read_text()
    assert "most recent call first" in text and "wait_for_a_lock_nobody_releases" in text, text


def test_bringup_without_installed_nodes_or_with_a_bad_graph_file_says_why(tmp_path):
    bad = tmp_path / "g.yaml"
    bad.write_text("- {name: x}\n")
    r = subprocess.run([PY, "-m", "hexa_bringup.cli", "bringup", "sim", "--graph", str(bad)], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and "needs 'name' and 'cmd'" in r.stderr
    r = subprocess.run([PY, "-m", "hexa_bringup.cli", "bringup", "robot"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and ("--uno" in r.stderr or "not installed" in r.stderr)


def test_robot_mode_approaches_the_start_slowly_by_default_and_sim_only_when_asked():
    import argparse

    from hexa_bringup.commands.bringup import ROBOT_APPROACH_SPEED, mode_node_args
    from hexa_bringup.supervisor import SupervisorError

    def args(mode, speed=None):
        return argparse.Namespace(mode=mode, uno="/dev/ttyACM0", mega="/dev/ttyACM1", cameras=["1", "2"],
                                  approach_speed=speed)

    assert mode_node_args(args("robot"))["trajectory"] == ["-p", f"approach_speed:={ROBOT_APPROACH_SPEED}"]
    assert ROBOT_APPROACH_SPEED > 0
    assert mode_node_args(args("robot", 0.0))["trajectory"] == ["-p", "approach_speed:=0.0"]   # operator's choice
    assert "trajectory" not in mode_node_args(args("sim"))       # the simulator starts at the start pose
    assert mode_node_args(args("sim", 0.5))["trajectory"] == ["-p", "approach_speed:=0.5"]
    with pytest.raises(SupervisorError, match="approach-speed"):
        mode_node_args(args("robot", -1.0))
    with pytest.raises(SupervisorError, match="approach-speed"):
        mode_node_args(args("robot", float("nan")))


def test_realtime_priority_raises_the_safety_path_in_the_graph_bringup_builds(tmp_path):
    import argparse

    from hexa_bringup.commands.bringup import mode_node_args
    from hexa_bringup.graphs import DEFAULT_PARAMS, build_graph
    from hexa_bringup.supervisor import SupervisorError

    def args(priority):
        return argparse.Namespace(mode="robot", uno="/dev/ttyACM0", mega="/dev/ttyACM1", cameras=[],
                                  approach_speed=None, realtime_priority=priority)

    node_args = mode_node_args(args(50))
    specs = {s.name: s.cmd for s in build_graph("robot", "/hexa", DEFAULT_PARAMS, node_args)}
    raised = {name for name, cmd in specs.items() if "realtime_priority:=50" in cmd}
    assert raised == {"driver", "observer"}, specs
    assert "uno_port:=/dev/ttyACM0" in specs["driver"]           # beside the mode's own arguments
    assert not any("realtime_priority" in a for a in mode_node_args(args(None)).get("observer", []))
    for bad in (-1, 100):
        with pytest.raises(SupervisorError, match="--realtime-priority must be 0"):
            mode_node_args(args(bad))
    r = subprocess.run([PY, "-m", "hexa_bringup.cli", "bringup", "robot", "--uno", "u", "--mega", "m",
                        "--realtime-priority", "120"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--realtime-priority must be 0" in r.stderr and "Traceback" not in r.stderr


def test_realism_reaches_the_simulator_in_sim_mode_and_is_refused_elsewhere():
    import argparse

    from hexa_bringup.commands.bringup import mode_node_args
    from hexa_bringup.supervisor import SupervisorError

    def args(mode, realism):
        return argparse.Namespace(mode=mode, uno="/dev/ttyACM0", mega="/dev/ttyACM1", cameras=[],
                                  approach_speed=None, realism=realism)

    assert mode_node_args(args("sim", "realistic"))["sim"] == ["-p", "realism:=realistic"]
    assert "sim" not in mode_node_args(args("sim", None))        # the sim node's own default (realistic)
    with pytest.raises(SupervisorError, match="realism"):
        mode_node_args(args("robot", "realistic"))


def test_sim_mode_knows_the_simulated_robot_from_its_overrides_the_parameters_file_and_the_default(tmp_path):
    from hexa_bringup.commands.bringup import sim_robot
    from hexa_bringup.graphs import DEFAULT_PARAMS, DEFAULT_REALISM
    from hexa_bringup.sim_params import PARAMETERS
    from hexa_bringup.supervisor import SupervisorError

    assert PARAMETERS["realism"].default == DEFAULT_REALISM
    assert sim_robot(DEFAULT_PARAMS, {}) == (DEFAULT_REALISM, 0)                   # the shipped parameters
    assert sim_robot(tmp_path / "none.yaml", {}) == (DEFAULT_REALISM, 0)           # no file: the node's defaults
    own = tmp_path / "p.yaml"
    own.write_text("/**/sim:\n  ros__parameters:\n    seed: 7\n    realism: ideal\n")
    assert sim_robot(own, {}) == ("ideal", 7)
    assert sim_robot(own, {"sim": ["-p", "realism:=realistic", "-p", "seed:=3"]}) == ("realistic", 3)
    own.write_text("/**:\n  ros__parameters:\n    seed: 4\n/robot2:\n  sim:\n    ros__parameters:\n      seed: 5\n")
    assert sim_robot(own, {}) == (DEFAULT_REALISM, 4)                              # the wildcard section
    assert sim_robot(own, {}, "/robot2") == (DEFAULT_REALISM, 5)                   # a later, nested namespace one
    own.write_text("/**/sim:\n  ros__parameters:\n    seed: seven\n")
    with pytest.raises(SupervisorError, match="seed"):
        sim_robot(own, {})


def test_a_signal_stops_the_graph_while_it_runs_and_reaches_the_caller_again_after(tmp_path):
    """`run` takes SIGINT/SIGTERM only while the graph runs (`stopped_by` names the signal) and gives the process's
    own handlers back when it returns: `hexa demo` sees a Ctrl-C between cases or while writing its report."""
    import io
    import os
    import threading

    from hexa_bringup.supervisor import NodeSpec, Supervisor

    mine, mine_term = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    spec = NodeSpec("sleeper", [PY, "-c", "import time; time.sleep(60)"])
    sup = Supervisor([spec], dict(os.environ), log_dir=str(tmp_path / "a"), out=io.StringIO())
    assert sup.run(duration=0.3) == 0 and sup.stopped_by is None
    assert signal.getsignal(signal.SIGINT) is mine
    sup = Supervisor([spec], dict(os.environ), log_dir=str(tmp_path / "b"), out=io.StringIO())
    threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()
    assert sup.run() == 0 and sup.stopped_by == signal.SIGTERM
    assert signal.getsignal(signal.SIGINT) is mine and signal.getsignal(signal.SIGTERM) is mine_term
    assert sup.nodes[0].state == "exited"
