"""Ctrl-C of `hexa bringup sim`: every node exits with rc 0 and no traceback once the nodes are up (at once, while the
circle runs). Each node runs through hexa_ros.start, so a Ctrl-C while it still imports or builds is clean too, but
for the interpreter's own start (its first fraction of a second), which no Python code covers (docs/node_layer.md)."""
from __future__ import annotations

import re
import signal
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PARAMS = Path(__file__).resolve().parents[1] / "hexa_bringup" / "hexa_bringup" / "config" / "hexa_params.yaml"
ROW = re.compile(r"^(\w+)\s+(exited|running|waiting|failed)\s+\S+\s+(\d+)\s+\S+\s+(\S+)\s*$")


def _params(tmp: Path) -> Path:
    """The shipped parameters with this run's own serial links (the simulator's ptys and the driver's ports)."""
    links = tmp / "links"
    text = PARAMS.read_text()
    assert "link_dir: /tmp/hexa_sim" in text and '/**/driver:\n  ros__parameters:\n' in text
    text = text.replace("link_dir: /tmp/hexa_sim", f"link_dir: {links}")
    text = text.replace("/**/driver:\n  ros__parameters:\n",
                        f"/**/driver:\n  ros__parameters:\n    uno_port: {links}/uno\n    mega_port: {links}/mega\n")
    out = tmp / "params.yaml"
    out.write_text(text)
    return out


NODES = {"sim", "driver", "pose", "observer", "isolation", "rnea", "singularity", "trajectory"}


def _wait_for_nodes(env: dict[str, str], names: set[str], timeout: float, monkeypatch) -> bool:
    """True once every node of `names` is on the ROS graph of `env`'s domain."""
    for key in ("RMW_IMPLEMENTATION", "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
                "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        if key in env:
            monkeypatch.setenv(key, env[key])
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("sigint_probe", context=ctx)
    try:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            if names <= set(node.get_node_names()):
                return True
            time.sleep(0.2)
        return False
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize("after", [0.0, 5.0])
def test_sigint_stops_every_node_of_the_sim_graph_with_rc_0_and_no_traceback(procs, ros_env, tmp_path, after,
                                                                             monkeypatch):
    logs = tmp_path / "logs"
    sup = procs.start([sys.executable, "-m", "hexa_bringup.cli", "bringup", "sim", "--params", str(_params(tmp_path)),
                       "--log-dir", str(logs), "--status-every", "1000"], ros_env)
    assert _wait_for_nodes(ros_env, NODES, 60.0, monkeypatch), "the graph's nodes did not come up"
    time.sleep(after)
    assert sup.poll() is None, sup.communicate()[0]
    sup.send_signal(signal.SIGINT)
    out, err = sup.communicate(timeout=60)
    assert sup.returncode == 0, out + err
    rows = [m.groups() for line in out.splitlines() if (m := ROW.match(line))][-8:]   # the table after the stop
    assert len(rows) == 8, out
    assert all(state == "exited" and restarts == "0" and rc == "0" for _n, state, restarts, rc in rows), \
        f"{rows}\n{out[-3000:]}\n{err[-3000:]}"
    for log in logs.glob("*.log"):
        text = log.read_text(errors="replace")
        assert "Traceback" not in text, f"{log.name}:\n{text[-3000:]}"
    assert "did not stop" not in out


def test_ctrl_c_during_a_demo_case_stops_the_graph_writes_no_report_and_exits_130(procs, ros_env, tmp_path,
                                                                                monkeypatch):
    """A case cut short has no result: `hexa demo` says where its bag and logs are and exits 130, with no report
    built from the partial case, every node stopped cleanly."""
    out = tmp_path / "demo"
    demo = procs.start([sys.executable, "-m", "hexa_bringup.cli", "demo", "--case", "plate", "--out", str(out)],
                       ros_env)
    # the calibration of the default robot comes first (cached after the first run): up to minutes on a fresh clone
    assert _wait_for_nodes(ros_env, NODES, 300.0, monkeypatch), "the demo's graph did not come up"
    record_log, t_end = out / "plate" / "logs" / "record.log", time.monotonic() + 60.0
    while time.monotonic() < t_end and "hexa record: recording" not in (
            record_log.read_text(errors="replace") if record_log.exists() else ""):
        time.sleep(0.2)   # the recorder too has set up its own Ctrl-C handling and subscribed
    time.sleep(1.0)
    assert demo.poll() is None, demo.communicate()[0]
    demo.send_signal(signal.SIGINT)
    stdout, stderr = demo.communicate(timeout=60)
    assert demo.returncode == 130, (demo.returncode, stdout[-2000:], stderr[-2000:])
    assert "stopped during case plate" in stderr and "no report" in stderr, stderr
    assert not (out / "report.md").exists()
    assert "Traceback" not in stdout + stderr
    rows = [m.groups() for line in stdout.splitlines() if (m := ROW.match(line))][-9:]   # 8 nodes and the recorder
    assert len(rows) == 9 and all(state == "exited" and rc == "0" for _n, state, _r, rc in rows), rows
    for log in (out / "plate" / "logs").glob("*.log"):
        assert "Traceback" not in log.read_text(errors="replace"), log.name
