"""`hexa bench graph`: the analysis helpers, the user's mistakes, and one end-to-end run on the simulated bag (replay
at a slow rate, both robot-mode runs, sim mode), shared by the tests of this module. No timing is asserted."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

PY = sys.executable
REPO = Path(__file__).resolve().parents[1]
INPUT_SUFFIXES = ("cam_top/color/image_raw", "cam_top/aligned_depth_to_color/image_raw", "cam_top/color/camera_info",
                  "cam_side/color/image_raw", "cam_side/aligned_depth_to_color/image_raw",
                  "cam_side/color/camera_info", "motor_currents", "joint_states")


# ----------------------------------------------------------------------------------------------------- no ROS


def test_nearest_matching_takes_only_samples_within_the_tolerance():
    from hexa_bringup.bench_graph_analysis import match_nearest

    board = np.array([0.001, 0.002, 0.003, np.nan, 0.010])
    idx = match_nearest([0.00205, 0.0025, 0.010, 0.020], board, tol=1e-4)
    assert idx.tolist() == [1, -1, 4, -1]


def test_residuals_stamped_by_the_observers_tracked_offset_are_matched_to_their_samples():
    """The observer stamps a residual with its sample's board time plus the host offset SampleClock tracks; the
    bench finds each residual's sample from the offset the observer said at one residual (good to a fraction of a
    period), across lost residuals, with evenly spaced and with jittered board times, at 1 kHz and at 200 Hz, also
    while the offset still settles after a first sample that came 80 ms late (it then moves ≈ 8 µs per sample)."""
    from hexa.dynamics.monitor import SampleClock
    from hexa_bringup.bench_graph_analysis import match_tracked_offset

    rng = np.random.default_rng(4)
    for period in (1e-3, 5e-3):
        n = 3000
        stamps = 1.8e9 + np.arange(n) * period + 0.8e-3 + rng.exponential(1.5e-3, n)   # the driver's host stamps
        stamps[0] += 0.08                                               # the first one late: the offset settles
        keep = np.ones(n, bool)
        keep[[0, 1, 500, 501, 502, 2999]] = False                      # residuals the subscriber never got
        for even, board in ((True, np.arange(n) * period), (False, np.cumsum(period + rng.normal(0.0, 2e-5, n)))):
            board = np.round(board * 1e6) * 1e-6                       # the Mega's sample instants (its clock)
            clock = SampleClock()
            res, said = [], {}
            for k, (st, b) in enumerate(zip(stamps, board)):
                res.append(clock.time(st, int(round(b * 1e6))))
                said[k] = clock.board_offset                           # the observer's diagnostics after sample k
            res_kept, kept = np.array(res)[keep], np.flatnonzero(keep)
            for anchor in (len(kept) - 1, len(kept) // 2):
                for err in (0.3 * period, -0.3 * period):
                    idx = match_tracked_offset(res_kept, board, said[kept[anchor]] + err, anchor)
                    assert idx.tolist() == kept.tolist(), (period, anchor, err)
            if even:   # evenly spaced samples fit every whole-period shift: the guess decides
                shifted = match_tracked_offset(res_kept, board, said[kept[-1]] + period, -1)
                assert (shifted - kept).tolist() == [-1] * len(kept)


def test_the_bench_helpers_run_at_the_observers_configured_priority(tmp_path):
    """The player, the emulated boards and the measuring subscriber take the observer's realtime_priority from the
    parameters file (wildcards and namespaces as rcl matches them), else the node's default (normal scheduling)."""
    from hexa_bringup.bench_graph import safety_priority
    from hexa_bringup.graphs import DEFAULT_PARAMS
    from hexa_ros.realtime import REALTIME_PRIORITY_PARAM

    assert safety_priority(DEFAULT_PARAMS) == REALTIME_PRIORITY_PARAM.default == 0
    own = tmp_path / "p.yaml"
    own.write_text("/**/observer:\n  ros__parameters:\n    realtime_priority: 50\n")
    assert safety_priority(own) == 50
    assert safety_priority(own, "/robot2") == 50
    own.write_text("/hexa/observer:\n  ros__parameters:\n    realtime_priority: 30\n")
    assert safety_priority(own, "/hexa") == 30 and safety_priority(own, "/other") == 0
    assert safety_priority(tmp_path / "none.yaml") == 0


def test_the_realtime_priority_option_raises_the_safety_path_as_bringup_does(tmp_path):
    from hexa_bringup.bench_graph import graph_specs, safety_priority
    from hexa_bringup.graphs import DEFAULT_PARAMS

    assert safety_priority(DEFAULT_PARAMS, priority=50) == 50 and safety_priority(DEFAULT_PARAMS) == 0
    replay = {s.name: s.cmd for s in graph_specs("replay", "/hexa", DEFAULT_PARAMS, priority=50)}
    assert {n for n, cmd in replay.items() if "realtime_priority:=50" in cmd} == {"observer"}
    robot = {s.name: s.cmd for s in graph_specs("robot", "/hexa", DEFAULT_PARAMS, {"driver": ["-p", "x:=1"]},
                                                priority=50)}
    assert {n for n, cmd in robot.items() if "realtime_priority:=50" in cmd} == {"driver", "observer"}
    assert "x:=1" in robot["driver"]
    # composed, the observer keeps a process of its own at that priority (a node with arguments is not composed)
    composed = graph_specs("replay", "/hexa", DEFAULT_PARAMS, compose=True, priority=50)
    [observer] = [s for s in composed if "realtime_priority:=50" in s.cmd]
    assert observer.name == "observer"
    r = subprocess.run([PY, "-m", "hexa_bringup.cli", "bench", "graph", "--realtime-priority", "120", "--no-robot",
                        "--no-sim", "--cache", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert r.returncode != 0 and "--realtime-priority must be 0" in r.stderr and "Traceback" not in r.stderr


def test_frames_sharing_a_stamp_pair_in_order():
    from hexa_bringup.bench_graph_analysis import fifo_pairs

    assert fifo_pairs([0, 0, 5, 7], [0, 5, 0, 9]) == [(0, 0), (1, 2), (2, 1)]


def test_header_stamps_come_from_raw_cdr():
    pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import serialize_message

    from hexa_bringup.bench_graph_analysis import cdr_stamp_ns

    m = PoseStamped()
    m.header.stamp = Time(sec=12, nanosec=345)
    m.header.frame_id = "base"
    assert cdr_stamp_ns(serialize_message(m)) == 12_000_000_345


def test_board_time_unwraps_past_the_32_bit_counter():
    from hexa_bringup.bench_graph_analysis import unwrap_board_us

    t = unwrap_board_us([2**32 - 1000, 2**32 - 1, 999])
    assert np.allclose(np.diff(t), [999e-6, 1000e-6])


def test_events_compare_by_kind_and_onset_within_one_sample():
    from hexa_bringup.bench_graph_analysis import compare_events

    ref = [{"kind": "START", "id": 1, "onset": 4.581, "stamp": 4.601},
           {"kind": "END", "id": 1, "onset": 4.581, "stamp": 5.063}]
    near = [dict(e, onset=e["onset"] + 0.001) for e in ref]
    far = [dict(e, onset=e["onset"] + 0.003) for e in ref]
    assert compare_events(near, ref, 0.001)[0]
    assert not compare_events(far, ref, 0.001)[0]
    assert not compare_events(ref[:1], ref, 0.001)[0]
    assert compare_events([], [], 0.001)[0]


def test_contacts_compare_by_count_link_and_chain():
    from hexa_bringup.bench_graph_analysis import compare_contacts, within_percent

    ref = [{"stamp": 1.0, "id": 1, "link": 0, "chain": 0}, {"stamp": 1.1, "id": 1, "link": 1, "chain": 4}]
    assert compare_contacts(list(reversed(ref)), ref)[0]
    assert not compare_contacts([dict(ref[0]), dict(ref[1], chain=5)], ref)[0]
    assert not compare_contacts(ref[:1], ref)[0]
    assert within_percent(31, 32, 5.0) and not within_percent(30, 32, 5.0) and within_percent(0, 0, 5.0)



def test_cpu_sampler_reads_this_process():
    from hexa_bringup.bench_graph import CpuSampler

    with CpuSampler({"me": os.getpid()}, period=0.05) as cpu:
        t0, c0 = time.monotonic(), time.process_time()
        while time.process_time() - c0 < 0.2 and time.monotonic() - t0 < 20:
            sum(range(1000))
        t1, c1 = time.monotonic(), time.process_time()
    assert abs(cpu.seconds("me", t0, t1) - (c1 - c0)) < 0.1     # /proc ticks are 10 ms; samples every 50 ms


# ----------------------------------------------------------------------------------------------------- mistakes


def _hexa(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([PY, "-m", "hexa_bringup.cli", *args], capture_output=True, text=True, timeout=timeout,
                          cwd=str(REPO))


def test_a_missing_bag_is_named_without_a_traceback(tmp_path):
    r = _hexa("bench", "graph", str(tmp_path / "nope"), "--cache", str(tmp_path / "cache"))
    assert r.returncode == 2
    assert "does not exist" in r.stderr and "Traceback" not in r.stderr


def test_a_bag_without_the_inputs_names_what_is_missing(tmp_path):
    from hexa_bringup.bag import BagRecorder

    bag = tmp_path / "bag"
    with BagRecorder(bag) as rec:
        rec.add_topic("/hexa/residual", "hexa_msgs/msg/Residual")
    r = _hexa("bench", "graph", str(bag), "--cache", str(tmp_path / "cache"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "motor_currents" in r.stderr


def test_graph_options_are_refused_for_the_ros_free_areas():
    r = _hexa("bench", "kinematics", "--rate", "2")
    assert r.returncode != 0 and "only apply to `hexa bench graph`" in r.stderr


# ----------------------------------------------------------------------------------------------------- end to end


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory):
    """The plate case made by the simulator alone, as `hexa bench graph` makes its default bag (currents at 1 kHz)."""
    pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")
    from hexa_bringup.bench_bag import synthesize
    from hexa_bringup.bench_graph import bag_inputs

    bag = synthesize(tmp_path_factory.mktemp("bench_graph_bag") / "bag", "plate", stream_rate_hz=1000)
    info = bag_inputs(bag)
    assert info.duration > 6.0 and info.board_coverage > 0.999, (info.duration, info.board_coverage)
    return bag


@pytest.fixture(scope="module")
def bench_run(short_bag, tmp_path_factory, module_ros_domain_id):
    cache = tmp_path_factory.mktemp("bench_graph_cache")
    out = cache / "result.json"
    proc = subprocess.run([PY, "-m", "hexa_bringup.cli", "bench", "graph", str(short_bag), "--rate", "0.5",
                           "--no-reference", "--robot-duration", "1.5", "--cache", str(cache), "--json",
                           "--out", str(out), "--domain-id", str(module_ros_domain_id)],
                          capture_output=True, text=True, timeout=900, cwd=str(REPO))
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout)
    assert json.loads(out.read_text()) == result
    return {"result": result, "stderr": proc.stderr, "cache": cache}


def _rows(result: dict, prefix: str) -> dict[str, dict]:
    [section] = [k for k in result if k.startswith(prefix)]
    return {r["name"]: r for r in result[section]}


def test_the_replay_reports_every_figure_with_counts(bench_run):
    res = bench_run["result"]
    [machine] = res["graph machine"]            # the machine's speed at the time of the run, beside the figures
    assert machine["unit"] == "us" and 5.0 < machine["value"] < 5000.0
    rows = _rows(res, "graph replay")
    info = res["info"]["replay"]
    for name in ("pose", "observer", "isolation", "rnea", "singularity"):
        assert any(n == f"CPU {name}" for n in rows), name   # one process per node today
    for name in ("CPU processing nodes, total", "CPU player (hexa play)", "player: achieved rate",
                 "pose: plate_pose per top frame", "observer: current samples without a residual",
                 "observer: collision events", "isolation: contacts", "rnea: contact_wrench",
                 "singularity: indices per plate_pose", "vs slow replay"):
        assert name in rows, name
    for what in ("frame -> plate_pose", "sample -> residual", "START -> contact", "START -> contact_wrench"):
        for stat in ("p50", "p95", "max"):
            assert f"latency {what} {stat}" in rows
    assert rows["CPU processing nodes, total"]["value"] > 0 and rows["CPU player (hexa play)"]["value"] > 0
    assert rows["latency frame -> plate_pose p95"]["target"] == "<= 0.04 s"
    assert rows["latency sample -> residual p95"]["target"] == "<= 0.005 s"
    counts = info["counts"]
    assert counts["top_frames"] > 50 and counts["plate_pose"] > 0 and counts["singularity"] > 0
    assert counts["currents"] > 1000 and counts["residual"] > 0
    assert counts["collision"] >= 1, "the plate push was not detected in the replay"
    assert info["latency"]["sample_residual"]["n"] > 0 and info["latency"]["frame_pose"]["n"] > 0


def test_at_a_slow_rate_nearly_every_current_sample_gets_its_residual(bench_run):
    """Counted from the observer's first residual, which waits for the first camera pose. The pose node's
    best-effort image readers can miss the first frames of a replay (the player waits for every reader of a topic,
    but a reader that matches late on its own side is not covered by that wait), and the first residual waits for
    them; half the samples is the floor
    for the whole count."""
    rows = _rows(bench_run["result"], "graph replay")
    info = bench_run["result"]["info"]["replay"]
    missing = rows["observer: current samples without a residual"]["value"]
    assert info["counts"]["residual"] >= 0.5 * info["counts"]["currents"], info["counts"]
    assert missing <= 0.1 * info["counts"]["currents"], rows["observer: current samples without a residual"]


def test_the_player_publishes_only_the_sensor_inputs(bench_run):
    published = bench_run["result"]["info"]["replay"]["published"]
    assert published, "the player logged nothing"
    for topic in published:
        assert topic.endswith(INPUT_SUFFIXES), topic
    assert not any(t.endswith(("residual", "contact", "contact_wrench", "collision", "plate_pose")) for t in published)
    assert sum(1 for t in published if t.endswith(INPUT_SUFFIXES)) == len(INPUT_SUFFIXES)


def test_robot_mode_reports_rates_cpu_and_latencies_at_both_stream_rates(bench_run):
    res = bench_run["result"]
    for hz in (1000, 200):
        rows = _rows(res, f"graph robot {hz} Hz")
        for name in ("CPU driver", "CPU camera_top", "CPU camera_side", "CPU observer", "CPU processing nodes, total",
                     "rate joint_states", "rate motor_currents", "rate residual", "rate plate_pose",
                     "observer: residuals per current sample", "latency frame -> plate_pose p95",
                     "latency sample -> motor_currents p95", "observer: collision STARTs at rest",
                     "CPU board emulators"):
            assert name in rows, (hz, name)
        assert "latency sample -> residual p95" in rows
        info = res["info"][f"robot_{hz}hz"]
        assert info["counts"]["motor_currents"] > 0 and info["counts"]["residual"] > 0, info["counts"]
        assert info["counts"]["plate_pose"] > 0, info["counts"]
        assert info["boards"].get("mega_samples", 0) > 0, info["boards"]


def test_sim_mode_reports_the_real_time_factor_the_simulator_reached(bench_run):
    res = bench_run["result"]
    rows = _rows(res, "graph sim")
    rtf = rows["sim: real-time factor reached"]
    assert rtf["target"] == ">= 0.5x" and 0.05 < rtf["value"] <= 1.1, rtf
    for name in ("CPU sim", "CPU driver", "CPU trajectory", "CPU observer", "CPU processing nodes, total",
                 "sim: residuals per sim second", "sim: plate_pose per sim second"):
        assert name in rows, name
    assert res["info"]["sim"]["counts"]["clock"] > 10 and res["info"]["sim"]["counts"]["residual"] > 0


def test_no_child_process_outlives_the_bench(bench_run):
    res = bench_run["result"]["info"]
    pids = list(res["replay"]["pids"].values()) + list(res["sim"]["pids"].values())
    for hz in (1000, 200):
        pids += list(res[f"robot_{hz}hz"]["pids"].values())
    alive = []
    for pid in pids:
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            continue
        if b"hexa" in cmd:
            alive.append((pid, cmd))
    assert not alive, alive


def _children_of(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / "stat").read_bytes().rsplit(b")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(d.name))
    return out


def test_ctrl_c_while_playing_stops_every_child(short_bag, tmp_path, ros_domain_id):
    proc = subprocess.Popen([PY, "-m", "hexa_bringup.cli", "bench", "graph", str(short_bag), "--rate", "0.25",
                             "--no-reference", "--no-robot", "--no-sim", "--cache", str(tmp_path), "--domain-id",
                             str(ros_domain_id)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=str(REPO), start_new_session=True)
    try:
        assert proc.stderr is not None
        deadline = time.monotonic() + 180
        seen = []
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line:
                break
            seen.append(line)
            if "playing" in line:
                break
        assert any("playing" in s for s in seen), "".join(seen)
        time.sleep(2.0)
        children = _children_of(proc.pid)
        assert len(children) >= 7, children          # probe, five nodes, player
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err
        assert "Traceback" not in err
        assert not [p for p in children if Path(f"/proc/{p}").exists()]
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
