"""`hexa eval`: the campaign through the nodes' core classes on the simulator (ROS-free), its parallel pool, the
report's structure — and behaviour that could fail: a strong plate push is detected quickly, ideal free motion raises
no false alarm, lower thresholds never detect less."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from hexa.eval import CampaignConfig, ProgressBar, jobs_of, run_campaign
from hexa.eval.campaign import (DETECTOR_NAMES, GRID_MIN_DURATIONS, GRID_SCALES, THRESHOLD_SCALES, draw_contact,
                                run_contact_job)
from hexa.eval.report import matched_delay, summarize, write_report

pytestmark = pytest.mark.slow   # a campaign on worker processes: left out of `make check`


def test_contacts_are_drawn_reproducibly_within_their_ranges_and_feasible():
    """Contacts are reproducible per (seed, index), within their ranges, on the paper's and random trajectories in
    turn, and feasible: an infeasible first draw (the pushing object within 3 mm of another link) is redrawn with
    the same link and chain."""
    from hexa.eval.campaign import _draw, draw_contact_counted, kinds_of
    from hexa.robots.hexa_description import load_hexa
    from hexa.vision.evaluation import MIN_CLEARANCE, contact_clearance

    drawn = [draw_contact_counted(3, i) for i in range(24)]
    cs = [c for c, _ in drawn]
    assert [dataclasses.asdict(c) for c in cs[:3]] == [dataclasses.asdict(draw_contact(3, i)) for i in range(3)]
    assert dataclasses.asdict(draw_contact(4, 0)) != dataclasses.asdict(cs[0])
    assert {c.link for c in cs} == {"plate", "arm", "rod"}
    desc = load_hexa()
    assert any(n > 0 for _, n in drawn)
    for i, (c, n) in enumerate(drawn):
        assert contact_clearance(desc, c) >= MIN_CLEARANCE
        first = _draw(3, i, kinds_of("all"), 0)
        assert (c.link, c.chain) == (first.link, first.chain)
        assert (n == 0) == (c == first)
        if n:
            assert contact_clearance(desc, first) < MIN_CLEARANCE
    # the paper's trajectories and random ones, alternating; every other first draw is the same with either kind
    paper = [draw_contact(3, i, "paper") for i in range(12)]
    assert {c.trajectory for c in paper} == {"circle", "helix", "ellipse"}
    assert [c.trajectory for c in cs[1::2]] == [f"random:{3 * 100003 + i}" for i in range(1, 24, 2)]
    assert [c.trajectory for c in cs[:12:2]] == [c.trajectory for c in paper[::2]]
    firsts = [dataclasses.replace(_draw(3, i, kinds_of(k), 0), trajectory="") for k in ("all", "paper")
              for i in range(12)]
    assert firsts[:12] == firsts[12:]
    assert all(c.trajectory.startswith("random:") for c in (draw_contact(3, i, "random") for i in range(2)))
    for c in cs:
        assert 1.0 <= c.peak_force <= 10.0 and 1.5 <= c.onset <= 8.0
        assert (c.chain == 0) == (c.link == "plate") and 0 <= c.chain <= 6
        assert c.force_magnitude(c.peak_time + c.hold_time / 2) == pytest.approx(c.peak_force)
        assert c.force_magnitude(c.end_time) == 0.0


def test_a_strong_plate_push_is_detected_within_100_ms_and_its_force_identified():
    plate = {"name": "push", "trajectory": "circle", "link": "plate", "chain": 0, "onset": 2.0, "rise_time": 0.2,
             "release_time": 0.2, "peak_force": 8.0, "position": -1.75, "elevation": -1.2, "azimuth": 0.0,
             "approach_time": 0.6, "approach_distance": 0.25, "hold_time": 0.2}
    r = run_contact_job({"collision": plate, "sim_seed": 1, "realism": "ideal", "index": 0})
    m = r["metrics"]
    assert m["true_link"] == "plate" and m["false_starts"] == 0
    assert np.isfinite(m["exceed_time"]) and 0.0 <= m["delay_ms"] <= 100.0
    rmse = np.asarray(m["force_rmse"])
    assert np.all(np.isfinite(rmse)) and np.all(rmse < 2.0)        # the identification ran on the contact
    assert r["rejected_draws"] == 0 and 0.0 <= r["servo_saturated_s"] <= 0.6   # stalled s within the contact
    assert r["type2_crossings"] == 0     # its servos stall for a while, but the plate stays clear of a type II pose
    # the replays at scale 1 see what the live detector (the node's default, the threshold detector) saw
    assert r["detector"] == "threshold"
    node = {row["scale"]: row for row in r["detect"]["threshold"]}
    assert node[1.0]["detect_time"] == pytest.approx(m["detect_time"], abs=1e-9)
    # and so does the CUSUM's replay when the CUSUM runs live
    r = run_contact_job({"collision": plate, "sim_seed": 1, "realism": "ideal", "index": 0, "identify": False,
                         "detector": "cusum"})
    m = r["metrics"]
    assert r["detector"] == "cusum" and m["false_starts"] == 0 and 0.0 <= m["delay_ms"] <= 100.0
    node = {row["scale"]: row for row in r["detect"]["cusum"]}
    assert node[1.0]["detect_time"] == pytest.approx(m["detect_time"], abs=1e-9)



def test_a_push_that_stalls_the_servos_can_drive_the_robot_through_a_type_II_singularity():
    # campaign case 24 (seed 0): a plate push that back-drives the stalled servos until det J_D changes sign
    r = run_contact_job({"campaign_seed": 0, "index": 24, "sim_seed": 24, "realism": "ideal", "trajectories": "all",
                         "isolation": "oracle", "identify": False})
    assert r["link"] == "plate" and r["servo_saturated_s"] > 0.2
    assert r["type2_crossings"] >= 1

def test_smoke_campaign_on_two_worker_processes_writes_the_report(tmp_path):
    cfg = CampaignConfig(cases=6, free_seconds=20.0, realisms=("ideal",), seed=5, workers=2)
    assert cfg.trajectories == "all" and len(jobs_of(cfg)) == 8     # free motion: 10 s paper + 10 s random
    seen: list[float] = []
    result = run_campaign(cfg, progress=seen.append)
    assert len(seen) == 8 and result["workers"] == 2
    assert len(result["contacts"]) == 6 and all("metrics" in c for c in result["contacts"])
    assert sum(f["seconds"] for f in result["free"]) == pytest.approx(20.0)
    # contacts and free motion ran over both kinds of trajectory, and the report says per kind
    assert [c["trajectory_kind"] for c in result["contacts"]] == ["paper", "random"] * 3
    assert sorted(f["trajectory_kind"] for f in result["free"]) == ["paper", "random"]
    md = write_report(result, tmp_path)
    text = md.read_text()
    for name in ("det_curve.png", "detection_vs_force.png", "delay_per_link.png", "rmse.png"):
        assert (tmp_path / name).stat().st_size > 5000 and f"]({name})" in text
    data = json.loads((tmp_path / "report.json").read_text())
    s = data["summary"]["ideal"]
    assert s["cases"] == 6 and all(len(s["det"][n]) == len(THRESHOLD_SCALES) for n in DETECTOR_NAMES)
    assert set(s["targets"]) >= {"fa_per_10h", "det_plate_3n", "delay_median_ms", "rmse_below_paper"}
    split = s["rmse_by_servos"]          # every case with an RMSE counted once: servos held or some stalled
    assert split["held"]["cases"] + split["stalled"]["cases"] == s["rmse_cases"]
    assert 0 <= split["stalled_type2"]["below"] <= split["stalled_type2"]["cases"] <= split["stalled"]["cases"]
    assert s["rmse_cases"] > 0 and (split["held"]["below"] + split["stalled"]["below"]
                                    == pytest.approx(s["targets"]["rmse_below_paper"] * s["rmse_cases"]))
    assert s["live_false_starts_free"] == 0                    # ideal free motion raises no false alarm
    assert sum(f["starts"]["threshold"][THRESHOLD_SCALES.index(1.0)] for f in result["free"]) == 0
    assert s["vs_paper"]["detector"] == "cusum" and "delay_vs_paper" in s["targets"]
    kinds = s["kinds"]
    assert set(kinds) == {"paper", "random"} and all(k["cases"] == 3 for k in kinds.values())
    assert all(k["free_hours"] == pytest.approx(10.0 / 3600) and k["live_false_starts_free"] == 0
               for k in kinds.values())                            # ideal free motion, random too: no false alarm
    assert sum(k["detected"] for k in kinds.values()) == sum(pl["detected"] for pl in s["links"].values())
    assert all(k["detectors"][n]["false_alarms"] == 0 for k in kinds.values() for n in ("threshold", "paper"))
    assert "| random | 3 |" in text and "| paper | 3 |" in text
    # a lower threshold never detects fewer contacts nor raises fewer false alarms
    for name in DETECTOR_NAMES:
        rows = s["det"][name]
        det = [sum(1 for c in result["contacts"] for row in c["detect"][name]
                   if row["scale"] == r["scale"] and np.isfinite(row["detect_time"])) for r in rows]
        assert det == sorted(det, reverse=True)
        fa = [r["false_alarms"] for r in rows]
        assert fa == sorted(fa, reverse=True)
    # the minimum-duration grid: every minimum duration at every grid scale, the node's own from its DET rows; a
    # shorter wait never STARTs later on a contact without an earlier START (the same run over the threshold)
    grid = s["min_duration_grid"]
    assert [(r["min_duration"], r["scale"]) for r in grid] == [
        (md, sc) for md in (*GRID_MIN_DURATIONS, 0.02) for sc in GRID_SCALES]
    node = {r["scale"]: r for r in s["det"]["threshold"]}
    assert all(r["false_alarms"] == node[r["scale"]]["false_alarms"] for r in grid if r["min_duration"] == 0.02)
    for c in result["contacts"]:
        for k, scale in enumerate(GRID_SCALES):
            times = [c["detect_grid"][f"{md:g}"][k] for md in GRID_MIN_DURATIONS]
            times.append(next(r for r in c["detect"]["threshold"] if r["scale"] == scale))
            if all(r["false_starts"] == 0 for r in times):
                t = [r["detect_time"] if np.isfinite(r["detect_time"]) else np.inf for r in times]
                assert t == sorted(t), (c["index"], scale, t)
    assert "minimum duration and threshold scale" in text
    # the campaign's contacts: the drawn ones, so the summary counts them per link
    links = [draw_contact(5, i).link for i in range(6)]
    assert {k: v["cases"] for k, v in s["links"].items()} == {k: links.count(k) for k in ("plate", "arm", "rod")}
    assert summarize(result)["ideal"]["targets"] == pytest.approx(s["targets"], nan_ok=True)
    # the isolation ran on rendered frames in every contact, and the report shows it beside its targets
    assert result["isolation_note"] == "" and all(c["isolation"]["mode"] == "rendered" for c in result["contacts"])
    iso = s["isolation"]
    assert iso["rendered_cases"] == 6 and iso["detected"] == sum(pl["detected"] for pl in s["links"].values())
    assert "Isolation on rendered frames" in text and "isolation: right link + chain" in text


def test_the_detectors_are_compared_at_the_papers_false_alarms_and_not_without_free_motion():
    def row(scale, fa, delay):
        return {"scale": scale, "false_alarms": fa, "delay_median_ms": delay, "detection_arm_strong": 0.5}

    paper1 = row(1.0, 23, 56.5)
    cusum = [row(1.0, 122, 18.7), row(1.3, 37, 34.8), row(1.5, 15, 45.4), row(2.0, 0, 76.2)]
    m = matched_delay(cusum, paper1, hours=1.0)     # the first scale with no more false alarms than the paper's
    assert m["scale"] == 1.5 and m["ratio"] == pytest.approx(45.4 / 56.5) and m["false_alarms"] == 15
    assert matched_delay(cusum, paper1, hours=0.0)["scale"] is None       # no free motion: rates unknown
    assert np.isnan(matched_delay(cusum, paper1, hours=0.0)["ratio"])
    assert matched_delay(cusum[:2], row(1.0, 0, 56.5), hours=1.0)["scale"] is None   # never as quiet


def test_progress_bar_counts_jobs_and_simulated_time():
    import io

    buf = io.StringIO()
    bar = ProgressBar(2, 20.0, stream=buf, width=10)
    assert "[####      ]" in bar.update(8.0) and "1/2 jobs" in buf.getvalue()   # 8 of 20 s: the bar follows time
    line = bar.update(12.0)
    assert "2/2 jobs" in line and "20 s simulated" in line and "[##########]" in line
    assert buf.getvalue().endswith("\n")


def test_bad_campaign_settings_are_refused_with_their_name():
    with pytest.raises(ValueError, match="realism must be one of"):
        CampaignConfig(realisms=("kind",))
    with pytest.raises(ValueError, match="nothing to run"):
        CampaignConfig(cases=0, free_seconds=0.0)
    with pytest.raises(ValueError, match="workers"):
        CampaignConfig(workers=0)
    with pytest.raises(ValueError, match="local:N"):
        CampaignConfig(scheduler="local:0")
    with pytest.raises(ValueError, match="detector"):
        CampaignConfig(detector="bayes")
    with pytest.raises(ValueError, match="alarm"):
        CampaignConfig(cusum={"alarm": 0.0})
    with pytest.raises(ValueError, match="trajectories must be one of"):
        CampaignConfig(trajectories="spiral")
    with pytest.raises(ValueError, match="isolation must be one of"):
        CampaignConfig(isolation="magic")


def test_campaign_runs_on_a_local_dask_cluster_of_two_workers():
    import os

    cfg = CampaignConfig(cases=0, free_seconds=1.0, realisms=("ideal", "realistic"), seed=2, scheduler="local:2",
                         trajectories="random")
    seen: list[float] = []
    result = run_campaign(cfg, progress=seen.append)
    assert result["engine"] == "dask local:2" and result["workers"] == 2
    assert len(seen) == 2 and {f["realism"] for f in result["free"]} == {"ideal", "realistic"}
    assert all(f["sim_seconds"] == pytest.approx(2.0) and f["pid"] != os.getpid() for f in result["free"])
    assert {f["trajectory"] for f in result["free"]} == {f"random:{2 * 100003 + 50000}"}
    assert set(result["free"][0]["starts"]) == set(DETECTOR_NAMES)


def test_cli_writes_the_report_and_refuses_bad_sizes(tmp_path, capsys):
    """Bad sizes are refused in one line; without a headless renderer (an EGL vendor list that names no driver) the
    rendered isolation falls back to the oracle, says so on stderr and names the oracle in the report."""
    import os
    import subprocess
    import sys

    from hexa_bringup.cli import main

    assert main(["eval", "--cases", "-1", "--realism", "ideal"]) == 2
    assert "cases (-1)" in capsys.readouterr().err
    env = dict(os.environ, MUJOCO_GL="egl", __EGL_VENDOR_LIBRARY_FILENAMES=str(tmp_path / "no_vendor.json"))
    p = subprocess.run([sys.executable, "-m", "hexa_bringup.cli", "eval", "--cases", "1", "--minutes", "0",
                        "--realism", "ideal", "--workers", "1", "--no-identify", "--trajectories", "paper", "--out",
                        str(tmp_path), "--json"], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert list(summary) == ["ideal"] and summary["ideal"]["cases"] == 1
    assert list(summary["ideal"]["kinds"]) == ["paper"]            # --trajectories paper
    assert "1/1 jobs" in p.stderr                                  # the progress bar
    assert "needs a headless renderer" in p.stderr and "the oracle isolation runs" in p.stderr
    iso = summary["ideal"]["isolation"]
    assert iso["oracle_cases"] == 1 and iso["rendered_cases"] == 0
    report = (tmp_path / "report.md").read_text()
    assert "an **oracle**" in report and "— (oracle isolation)" in report and "needs a headless renderer" in report
    assert (tmp_path / "det_curve.png").exists()


def test_free_motion_starts_on_the_first_monitoring_ok_and_moves_the_arms():
    """The runner waits for the monitoring contract's first OK, as the live trajectory node does, then moves."""
    import numpy as np

    from hexa.eval.campaign import simulate
    from hexa.sim.realism import RealismConfig

    rec = simulate(None, "circle", 4.0, RealismConfig.ideal(), 1)
    swing = rec.truth_zeta.max(axis=0) - rec.truth_zeta.min(axis=0)
    assert np.all(swing > 0.2), swing              # the circle moves every arm by tenths of a radian
    assert rec.counters["monitoring_lost"] == 0
    early = rec.truth_t < 0.5                      # before the monitor settles, the start pose is held at rest
    assert np.ptp(rec.truth_zeta[early], axis=0).max() < 0.01


def test_a_contact_run_follows_the_trajectory_until_its_contact():
    """With the hold policy of the contact runs, the runner keeps moving after the monitoring's first OK: it gets the
    monitoring state at every tick, as the node's 50 ms heartbeat gives it (silence would count as LOST and hold)."""
    from hexa.eval.campaign import LEAD_IN, simulate
    from hexa.sim.realism import RealismConfig

    late = draw_contact(5, 1, "random")                        # a contact long after the 3 s simulated here
    late = dataclasses.replace(late, onset=6.0)
    rec = simulate(late, late.trajectory, 3.0, RealismConfig.ideal(), 1, identify=False)
    assert not rec.events and np.abs(rec.truth_force).max() == 0.0
    moving = rec.truth_t > LEAD_IN + 1.0                       # well past the runner's 0.25 s silence timeout
    path = rec.truth_pose[moving, :3]
    assert np.linalg.norm(np.diff(path, axis=0), axis=1).sum() > 0.02, "the trajectory was held"


def test_rendered_isolation_runs_the_isolation_node_with_its_parameter_defaults():
    """The eval's scheduler and locator take their classes' defaults: they are the isolation node's parameters."""
    import inspect

    from hexa.vision.isolation_scheduler import ContactLocator, IsolationScheduler
    from hexa_vision.isolation_params import PARAMETERS, SCHEDULER

    sched = inspect.signature(IsolationScheduler).parameters
    assert {k: sched[k].default for k in SCHEDULER} == {k: p.default for k, p in SCHEDULER.items()}
    assert inspect.signature(ContactLocator).parameters["coarse_margin"].default == PARAMETERS["coarse_margin"].default


#: draw_contact(2, index, "paper") of a plate, an arm and a rod contact, each detected on the ideal robot
RENDERED_CASES = ((8, "plate", 0), (33, "arm", 6), (44, "rod", 5))


def test_rendered_isolation_finds_the_link_chain_and_point_of_a_plate_arm_and_rod_contact():
    """The isolation node's scheduler and locator on the frames rendered from the run's simulator find each contact's
    link and chain within 10 mm, rendering only the frames they are handed (backgrounds and pairs from the onset);
    the force is identified at the isolated point, not the true one."""
    from hexa.eval.campaign import R_LOW, TAIL, case_data, simulate
    from hexa.report.collision_demo import compute_metrics
    from hexa.sim.realism import RealismConfig

    for index, link, chain in RENDERED_CASES:
        c = draw_contact(2, index, "paper")
        assert (c.link, c.chain) == (link, chain)
        identify = link == "plate"
        rec = simulate(c, c.trajectory, c.end_time + TAIL, RealismConfig.ideal(), 2 * 100003 + index,
                       identify=identify)
        assert rec.isolation == "rendered"
        m = compute_metrics(case_data(c.name, rec, rec.events, (2.0,) * 3 + (0.2,) * 3, (0.0,) * 6), r_low=R_LOW)
        assert np.isfinite(m.detect_time) and m.detect_time <= c.end_time + 1.0      # a START during the contact
        assert (m.found_link, m.found_chain) == (link, chain), rec.evaluations
        assert m.point_error_median_mm <= 10.0, m
        onset = [e for e in rec.evaluations if e.onset]
        assert len(onset) == 1 and (onset[0].link, onset[0].chain) == ({"plate": 0, "arm": 1, "rod": 2}[link], chain)
        # two backgrounds and the pairs handed out: a small part of the 30 frames per second of both cameras
        frames = rec.isolation_cost["frames_rendered"]
        assert 2 + 2 * len(rec.evaluations) >= frames >= 4 and frames < 0.2 * 2 * 30 * rec.sim_seconds
        if identify:
            assert len(rec.wrench_t) > 10 and np.all(np.isfinite(m.force_rmse))
            isolated = np.array([e.point for e in rec.evaluations if e.link != 255])
            gap = np.linalg.norm(rec.wrench_point[:, None, :] - isolated[None], axis=2).min(axis=1)
            assert np.all(gap < 1e-12)                       # every force at a point the isolation handed over
            truth = rec.truth_point[np.clip(np.searchsorted(rec.truth_t, rec.wrench_t), 0, len(rec.truth_t) - 1)]
            assert np.linalg.norm(rec.wrench_point - truth, axis=1).min() > 1e-4   # not the oracle's true point


def test_the_nodes_model_of_a_run_is_its_own_description_the_simulated_robot_stays(tmp_path):
    """`nodes_desc` (what `--calibrate` gives each job: a calibration overlay) is the model the observer runs; the
    simulated robot stays the description's. A model with twice the plate's mass sees its missing weight in free
    motion's Fz residual; a campaign config carries the excitation file and the currents' rate into every job."""
    import numpy as np

    from hexa.eval.campaign import simulate
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim.realism import RealismConfig

    desc = load_hexa()
    overlay = tmp_path / "heavy.yaml"
    overlay.write_text(f"calibration_of: ''\ninertia:\n  plate:\n    mass: {2.0 * desc.plate.mass}\n",
                       encoding="utf-8")
    runs = {name: simulate(None, "circle", 2.0, RealismConfig.ideal(), 1, identify=False, nodes_desc=d,
                           stream_rate_hz=143.0)
            for name, d in (("same", None), ("heavy", load_hexa(overlay)))}
    fz = {k: float(np.median(r.residual[r.t > 1.5, 2])) for k, r in runs.items()}
    weight = desc.plate.mass * 9.81
    assert abs(fz["same"]) < 0.2 * weight, fz
    assert abs(abs(fz["heavy"]) - weight) < 0.3 * weight, fz
    dt = np.median(np.diff(runs["same"].t))
    assert dt == pytest.approx(0.007, abs=5e-4)     # 143 Hz: one sample every 7 physics steps
    exc = tmp_path / "excitation.csv"
    exc.write_text("0,0,0,-0.55,0,0,0\n", encoding="utf-8")
    jobs = jobs_of(CampaignConfig(cases=1, free_seconds=10.0, calibrate=str(exc), stream_rate_hz=143.0))
    assert all(j["calibrate"] == str(exc) and j["stream_rate_hz"] == 143.0 for _, j in jobs)
    with pytest.raises(ValueError, match="no excitation file"):
        CampaignConfig(calibrate=str(tmp_path / "missing.csv"))


def test_a_terminated_campaign_stops_its_worker_processes(tmp_path):
    """`kill` (SIGTERM) on `hexa eval` ends it with 130 like Ctrl-C and takes its pool's workers with it: a worker
    left behind would go on simulating on cores the next job needs."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    def workers(pid: int) -> set[int]:
        out = set()
        for entry in os.listdir("/proc"):
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
                cmd = Path(f"/proc/{entry}/cmdline").read_bytes()
            except (OSError, ValueError):
                continue
            if entry.isdigit() and int(stat.rpartition(")")[2].split()[1]) == pid and b"spawn_main" in cmd:
                out.add(int(entry))
        return out

    hexa = str(Path(sys.executable).parent / "hexa")
    proc = subprocess.Popen([hexa, "eval", "--cases", "0", "--minutes", "4", "--workers", "2", "--realism", "ideal",
                             "--no-plots", "--out", str(tmp_path)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and len(workers(proc.pid)) < 2 and proc.poll() is None:
            time.sleep(0.2)
        started = workers(proc.pid)
        assert len(started) == 2, f"the pool's two workers did not start: {started}"
        time.sleep(2.0)                           # the workers are simulating
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 130
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(Path(f"/proc/{p}").exists() for p in started):
            time.sleep(0.1)
        assert not [p for p in started if Path(f"/proc/{p}").exists()], "workers outlived the campaign"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def test_a_campaign_on_a_few_robots_calibrates_each_once_and_runs_its_jobs_on_it(tmp_path, monkeypatch):
    """`robots` N: the jobs run on N simulated robots in turn (the simulator's truth from the robot's seed, its noise
    from the job's), each robot calibrated once before the jobs, and every job's nodes run its robot's overlay.
    The identification is replaced by a recorder here (it is tested in test_calibration.py): what is tested is
    which robot each job simulates and which model its nodes get."""
    from hexa.calibration import simulated
    from hexa.eval import campaign
    from hexa.robots.hexa_description import load_hexa
    from hexa.sim import Simulator
    from hexa.sim.realism import RealismConfig, draw_truth

    desc = load_hexa()
    realistic = RealismConfig.realistic()
    sim = Simulator(desc, seed=5, robot_seed=9, cameras=False, realism=realistic)
    assert sim.truth is not None and sim.seed == 5
    assert sim.truth.plate.mass == draw_truth(desc, 9, realistic.tolerances).plate.mass
    assert sim.truth.plate.mass != draw_truth(desc, 5, realistic.tolerances).plate.mass

    exc = tmp_path / "excitation.csv"
    exc.write_text("0,0,0,-0.55,0,0,0\n1,0,0,-0.55,0,0,0\n", encoding="utf-8")
    cfg = CampaignConfig(cases=3, free_seconds=150.0, realisms=("realistic",), seed=2, robots=2,
                         calibrate=str(exc), workers=1, isolation="oracle", identify=False)
    jobs = jobs_of(cfg)
    kinds = [k for k, _ in jobs]
    assert kinds[:2] == ["calibrate", "calibrate"] and "calibrate" not in kinds[2:]
    pool = sorted(j["robot_seed"] for k, j in jobs if k == "calibrate")
    assert len(set(pool)) == 2
    for kind in ("free", "contact"):
        seeds = [j["robot_seed"] for k, j in jobs if k == kind]
        assert set(seeds) == set(pool) and all(a != b for a, b in zip(seeds, seeds[1:]))   # the robots in turn
    own = jobs_of(dataclasses.replace(cfg, robots=0))       # a robot per job, calibrated in its job
    assert all(k != "calibrate" and j["robot_seed"] == j["sim_seed"] for k, j in own)
    with pytest.raises(ValueError, match="robots must be >= 0"):
        CampaignConfig(robots=-1)

    identified: list[int] = []

    def identify(excitation, seed, realism, base, out):
        identified.append(seed)
        mass = 0.2 + 0.01 * (seed - pool[0])        # a model per robot, told apart by its plate mass
        out.write_text(f"calibration_of: ''\ninertia:\n  plate:\n    mass: {mass}\n", encoding="utf-8")
        return load_hexa(out), None

    ran: list[tuple[int, int, float]] = []

    def simulate(*args, **kw):
        ran.append((kw["seed"], kw["robot_seed"], kw["nodes_desc"].plate.mass))
        raise _Stop

    class _Stop(Exception):
        pass

    monkeypatch.setattr(simulated, "calibrate_simulated_robot", identify)
    monkeypatch.setattr(campaign, "simulate", simulate)
    with pytest.raises(_Stop):
        run_campaign(dataclasses.replace(cfg, cases=0))
    assert sorted(identified) == pool                 # once per robot, before any job
    (sim_seed, robot, mass), = ran
    assert robot in pool and sim_seed != robot and mass == pytest.approx(0.2 + 0.01 * (robot - pool[0]))


def test_the_report_counts_false_alarms_and_detections_per_robot():
    """summarize_robots groups free motion and contacts by their robot: false alarms of each detector at × 1 and the
    live detector's STARTs, hours, and strong contacts detected, each on its own robot only."""
    from hexa.eval.report import STRONG_N, summarize_robots

    one = THRESHOLD_SCALES.index(1.0)

    def free(seed, live, fa):
        starts = {n: [0] * len(THRESHOLD_SCALES) for n in DETECTOR_NAMES}
        starts["threshold"][one] = fa
        return {"robot_seed": seed, "seconds": 1800.0, "live_starts": live, "starts": starts}

    def contact(seed, detect_time):
        return {"robot_seed": seed, "peak_force": STRONG_N + 1.0, "onset": 1.0, "rise_time": 0.1, "hold_time": 0.2,
                "release_time": 0.1, "metrics": {"detect_time": detect_time}}

    r = summarize_robots([contact(1, 1.05), contact(2, float("nan")), contact(2, 1.02)],
                         [free(1, 0, 0), free(1, 2, 3), free(2, 1, 1)])
    assert r[1]["free_hours"] == 1.0 and r[2]["free_hours"] == 0.5
    assert (r[1]["live_false_starts_free"], r[2]["live_false_starts_free"]) == (2, 1)
    assert (r[1]["false_alarms"]["threshold"], r[2]["false_alarms"]["threshold"]) == (3, 1)
    assert r[1]["false_alarms"]["paper"] == 0
    assert (r[1]["strong_detected"], r[1]["strong_cases"], r[2]["strong_detected"], r[2]["strong_cases"]) == (1, 1,
                                                                                                              1, 2)


def test_lost_sample_bursts_leave_gaps_in_board_time_and_commands_keep_their_order():
    """JitterConfig.loss_rate / loss_max: a stalled host loses bursts of samples, which the nodes see as gaps in board
    time (none without). Commands share one serial link: whatever their delays, the servos receive them in the
    order they were sent, so the set-points the samples carry follow the trajectory without stepping back."""
    from hexa.eval.campaign import simulate
    from hexa.sim.realism import JitterConfig, RealismConfig

    ideal = RealismConfig.ideal()
    lossy = dataclasses.replace(ideal, jitter=JitterConfig(loss_rate=0.02, loss_max=0.05))
    spans = {}
    for name, real in (("clean", ideal), ("lossy", lossy)):
        rec = simulate(None, "circle", 2.0, real, 3, identify=False)
        spans[name] = np.diff(rec.t[rec.t > 0.2])
    assert spans["clean"].max() < 0.0075 and spans["lossy"].max() > 0.015
    assert len(spans["lossy"]) < len(spans["clean"])

    from hexa.eval.campaign import CommandLink

    link, rng, got = CommandLink(), np.random.default_rng(4), []
    jitter = JitterConfig(command_mean=0.02, command_max=0.07)
    for k in range(400):                      # commands every 10 ms with delays far above that
        now = 0.01 * k
        link.send(now + jitter.command_delay(rng), None, k)
        for step in range(10):
            arrived = link.arrived(now + 0.001 * step)
            if arrived is not None:
                got.append(arrived[1])
    assert got == sorted(got) and len(set(got)) == len(got) and 50 < len(got) < 400   # in order, some skipped


def test_an_excitation_file_that_is_no_pose_file_is_refused_by_name(tmp_path):
    """`--calibrate FILE` with a file that is not `hexa calibrate excite`'s pose file: one clear error, first."""
    bad = tmp_path / "notes.csv"
    bad.write_text("garbage\n", encoding="utf-8")
    with pytest.raises(ValueError, match="notes.csv is not a pose file of `hexa calibrate excite`"):
        CampaignConfig(calibrate=str(bad), robots=2)


def test_the_report_tells_contacts_the_detector_could_see_and_its_own_delay():
    """within_reach: of the strong contacts, those whose true load crossed the thresholds (plate_exceed_time
    finite) and how many were detected; the detector's own delay over the detected ones only."""
    from hexa.eval.report import STRONG_N, within_reach

    def case(peak, exceed, own, load):
        return {"peak_force": peak, "metrics": {"plate_exceed_time": exceed, "observer_delay_ms": own,
                                                "load_peak": load}}

    nan = float("nan")
    cases = [case(STRONG_N + 1, 1.0, 30.0, 2.0), case(STRONG_N + 1, 1.0, nan, 1.1), case(STRONG_N + 1, nan, nan, 0.6),
             case(STRONG_N - 1, 1.0, 50.0, 3.0), case(STRONG_N + 2, 1.2, 40.0, 1.5), case(STRONG_N + 1, nan, nan, nan)]
    r = within_reach(cases, [True, False, False, True, True, False])
    assert (r["strong_reach_detected"], r["strong_reach_cases"]) == (2, 3)
    assert r["own_delay_median_ms"] == 40.0 and r["own_delay_p95_ms"] == pytest.approx(49.0)
    # the strong ones with a measured load: 2.0, 1.1, 0.6, 1.5 (the weak one and the one without a pose left out)
    assert r["strong_load_cases"] == 4 and r["strong_load_at"] == {"0.5": 4, "0.75": 3, "1": 3}
    assert within_reach([], [])["strong_reach_cases"] == 0
