"""`hexa bringup replay BAG` plays only the bag's sensor inputs and /clock, never its recorded outputs: a bag recorded
from the simulated graph (outputs included) replayed through the processing nodes yields each output once, from the
live nodes; `--topics` and `--exclude` change the choice."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from hexa_bringup.graphs import SENSOR_INPUTS, replay_topics
from hexa_bringup.supervisor import SupervisorError

PY = sys.executable
#: outputs of the replay graph recorded in a demo bag, and what makes one message unique on each
OUTPUTS = ["/hexa/residual", "/hexa/zeta_estimate", "/hexa/external_wrench", "/hexa/collision",
           "/hexa/plate_pose_estimate"]


def test_replay_topics_are_the_sensor_inputs_the_bag_holds_by_default():
    bag = ["/hexa/joint_states", "/hexa/motor_currents", "/hexa/residual", "/hexa/collision", "/hexa/contact",
           "/hexa/plate_pose", "/hexa/cam_top/color/image_raw", "/tf", "/tf_static", "/clock", "/diagnostics"]
    assert replay_topics(bag) == ["/hexa/cam_top/color/image_raw", "/hexa/motor_currents", "/hexa/joint_states"]
    assert replay_topics(bag, exclude=["cam_top/color/image_raw"]) == ["/hexa/motor_currents", "/hexa/joint_states"]
    assert replay_topics(bag, topics=["joint_states", "/hexa/plate_pose"]) == ["/hexa/joint_states",
                                                                                "/hexa/plate_pose"]
    assert replay_topics(["/robot/joint_states"], "/robot") == ["/robot/joint_states"]
    assert len(SENSOR_INPUTS) == 8      # both cameras' colour, aligned depth and camera_info + the driver's streams


def test_replay_topics_name_what_is_missing():
    with pytest.raises(SupervisorError, match="no topic /hexa/nope"):
        replay_topics(["/hexa/joint_states"], topics=["nope"])
    with pytest.raises(SupervisorError, match="holds /hexa/residual"):
        replay_topics(["/hexa/residual"])
    with pytest.raises(SupervisorError, match="nothing to replay"):
        replay_topics(["/hexa/joint_states"], exclude=["/hexa/joint_states"])


@pytest.fixture
def demo_bag(plate_demo_bag):
    """The plate case of the demo with its images (conftest.plate_demo_bag)."""
    return plate_demo_bag


def _messages(bag, topics) -> dict[str, list]:
    from hexa_bringup.bag import read_bag, typestore

    store = typestore()
    out: dict[str, list] = {t: [] for t in topics}
    for topic, msgtype, _t, data in read_bag(bag, topics):
        out[topic].append(store.deserialize_cdr(data, msgtype))
    return out


def _key(topic: str, m) -> tuple:
    stamp = (m.header.stamp.sec, m.header.stamp.nanosec)
    return (stamp, int(m.event), int(m.id)) if topic.endswith("/collision") else stamp


def _stop(proc, grace: float = 20.0) -> tuple[str, str]:
    for sig, wait in ((signal.SIGINT, grace), (signal.SIGKILL, 10.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            return proc.communicate(timeout=wait)
        except subprocess.TimeoutExpired:
            continue
    return "", ""


def test_replay_of_a_demo_bag_yields_each_output_once(demo_bag, procs, ros_env, tmp_path):
    from hexa_bringup.bag import bag_topics

    held = bag_topics(demo_bag)
    recorded = [t for t in OUTPUTS if t in held and held[t][1] > 0]
    assert {"/hexa/residual", "/hexa/collision"} <= set(recorded), f"the demo bag lacks outputs: {sorted(held)}"
    out_bag = tmp_path / "outputs"
    rec = procs.start([PY, "-m", "hexa_bringup.cli", "record", *recorded, "-o", str(out_bag), "--use-sim-time"],
                      ros_env)
    graph = procs.start([PY, "-m", "hexa_bringup.cli", "bringup", "replay", str(demo_bag), "--log-dir",
                         str(tmp_path / "logs"), "--status-every", "1e9"], ros_env)
    try:
        gout, gerr = graph.communicate(timeout=300)     # the graph ends with the player, at the bag's end
    except subprocess.TimeoutExpired:
        gout, gerr = _stop(graph)
        pytest.fail(f"the replay did not end with its bag: {gerr[-2000:]}")
    time.sleep(2.0)                                      # the last outputs reach the recorder
    _stop(rec)
    assert graph.returncode == 0, (gout[-2000:], gerr[-2000:])
    played = next(line for line in gout.splitlines() if "replaying" in line)
    inputs = [f"/hexa/{t}" for t in SENSOR_INPUTS]
    assert played.split("/clock: ", 1)[1].split(", ") == inputs, played        # no recorded output in it
    live = _messages(demo_bag, recorded)
    again = _messages(out_bag, recorded)
    report = {t: (len(live[t]), len(again[t])) for t in recorded}
    print(json.dumps({"recorded (live, replay)": report}))
    for topic in recorded:
        keys = [_key(topic, m) for m in again[topic]]
        assert len(keys) == len(set(keys)), f"{topic}: {len(keys) - len(set(keys))} outputs came twice"
    # the replay's outputs come from the live nodes: some (its ζ estimator waits for the first camera pose), at most
    # one per current sample the bag holds (the recorded residuals played beside them would exceed that). The live
    # run's count is no upper bound: its recorder and observer start beside the simulator and may miss the first ones.
    n_live, n_again = report["/hexa/residual"]
    n_samples = held["/hexa/motor_currents"][1]
    assert 0.25 * n_live <= n_again <= n_samples, (report, n_samples)
    starts = [m for m in again["/hexa/collision"] if m.event == 0]
    assert len(starts) == len({m.id for m in starts}), report
