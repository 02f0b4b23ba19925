"""`hexa calibrate` on bags (no ROS graph): a short model run written as a real MCAP bag is read back, identified
and validated through the CLI; a user's mistake ends in one line and exit 2."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hexa.calibration.excitation import ExcitationSettings, design_excitation
from hexa.calibration.recording import Recording
from hexa.rotations import quaternion_from_zyx
from hexa_bringup.bag import BagRecorder, typestore
from hexa_bringup.cli import main


def _write_bag(path, rec: Recording) -> None:
    """`rec` as the live graph records it: /hexa/motor_currents, /hexa/joint_states, /hexa/plate_pose."""
    store = typestore()
    T = store.types
    hdr = lambda t: T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](  # noqa: E731
        sec=int(t), nanosec=int(round((t - int(t)) * 1e9)) % 1_000_000_000), frame_id="base")
    names = [f"arm_{i}" for i in range(1, 7)]
    rows = [(t, "c", k) for k, t in enumerate(rec.t_current)] + [(t, "s", k) for k, t in enumerate(rec.t_state)] + \
        [(t, "p", k) for k, t in enumerate(rec.t_pose)]
    with BagRecorder(path) as bag:
        bag.add_topic("/hexa/motor_currents", "hexa_msgs/msg/MotorCurrents")
        bag.add_topic("/hexa/joint_states", "sensor_msgs/msg/JointState")
        bag.add_topic("/hexa/plate_pose", "geometry_msgs/msg/PoseStamped")
        for t, kind, k in sorted(rows):
            ns = int(round(t * 1e9)) + 1
            if kind == "c":
                m = T["hexa_msgs/msg/MotorCurrents"](header=hdr(t), current=rec.currents[k].astype(float),
                                                     raw=np.zeros(6, dtype=np.uint16), sequence=k,
                                                     board_time_us=int(t * 1e6), gaps=0, setpoint=np.zeros(0))
                bag.write("/hexa/motor_currents", ns, bytes(store.serialize_cdr(m, "hexa_msgs/msg/MotorCurrents")))
            elif kind == "s":
                m = T["sensor_msgs/msg/JointState"](header=hdr(t), name=names, position=rec.setpoints[k].astype(float),
                                                    velocity=np.zeros(0), effort=np.zeros(0))
                bag.write("/hexa/joint_states", ns, bytes(store.serialize_cdr(m, "sensor_msgs/msg/JointState")))
            else:
                p = rec.poses[k]
                q = quaternion_from_zyx(*p[3:])
                pose = T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                    orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))
                m = T["geometry_msgs/msg/PoseStamped"](header=hdr(t), pose=pose)
                bag.write("/hexa/plate_pose", ns, bytes(store.serialize_cdr(m, "geometry_msgs/msg/PoseStamped")))


def test_identify_and_validate_read_the_graphs_bags(tmp_path, capsys):
    from test_calibration import _record, _truth

    e = design_excitation(settings=ExcitationSettings(period=4.0, harmonics=5, cycles=2, iterations=0, seed=1))
    exc_file = e.write(tmp_path / "excitation.csv")
    rng = np.random.default_rng(2)
    truth = _truth(rng)
    for name, mass in (("run", 0.0), ("run_mass", 0.25)):
        _write_bag(tmp_path / name, _record(e, truth, mass, rng))
    out = tmp_path / "calibration.yaml"
    assert main(["calibrate", "identify", str(tmp_path / "run"), "--payload-bag", str(tmp_path / "run_mass"),
                 "--payload", "0.25", "--trajectory", str(exc_file), "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    cal = res["calibration"]
    assert cal["scale"] == "payload" and cal["sources"] == [str(tmp_path / "run"), str(tmp_path / "run_mass")]
    assert np.all(np.abs(np.array(cal["k_t"]) / truth["K"] - 1.0) < 0.06)          # 8 s of excitation per run
    assert np.all(np.abs(np.array(cal["horn_offset"]) - truth["horn"]) < 0.005)
    assert main(["calibrate", "validate", str(tmp_path / "run"), "--calibration", str(out), "--out",
                 str(tmp_path / "v"), "--json"]) == 0
    val = json.loads(capsys.readouterr().out)
    assert all(r["after"] < r["before"] for r in val["axes"].values())
    assert (tmp_path / "v" / "residual_before_after.png").stat().st_size > 0


@pytest.mark.parametrize("argv, message", [
    (["calibrate", "identify", "nowhere_bag", "--trajectory", "nowhere.csv"], "no excitation file nowhere.csv"),
    (["calibrate", "validate", "--calibration", "nowhere.yaml"], "no calibration overlay nowhere.yaml"),
    (["calibrate", "excite", "--period", "0.1"], "period must be 1..60 s"),
])
def test_user_mistakes_end_in_one_line(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and err.count("\n") == 1


def test_bringup_plays_a_pose_file_and_gives_every_node_but_the_simulator_the_overlay(tmp_path):
    import argparse

    from hexa_bringup.commands.bringup import description_args, mode_node_args
    from hexa_bringup.graphs import DEFAULT_PARAMS, build_graph
    from hexa_bringup.supervisor import SupervisorError

    e = design_excitation(settings=ExcitationSettings(period=4.0, harmonics=2, cycles=1, iterations=0, seed=1))
    f = e.write(tmp_path / "excitation.csv")
    args = argparse.Namespace(mode="sim", approach_speed=None, realism=None, trajectory=str(f),
                              collision_policy="ignore", uno=None, mega=None, cameras=[])
    na = mode_node_args(args)
    assert na["trajectory"] == ["-p", "trajectory:=file", "-p", f"file:={f.resolve()}", "-p",
                                "collision_policy:=ignore"]
    with pytest.raises(SupervisorError, match="does not exist"):
        mode_node_args(argparse.Namespace(**{**vars(args), "trajectory": str(tmp_path / "none.csv")}))
    with pytest.raises(SupervisorError, match="sim and robot"):
        mode_node_args(argparse.Namespace(**{**vars(args), "mode": "replay"}))
    overlay = tmp_path / "calibration.yaml"
    overlay.write_text("calibration_of: ''\nactuators: {K_t: 0.5}\ncalibration: {horn_offset: [0, 0, 0, 0, 0, 0]}\n",
                       encoding="utf-8")
    out = description_args(str(overlay), build_graph("sim", "/hexa", DEFAULT_PARAMS, na), na)
    assert "sim" not in out or f"description:={overlay}" not in out["sim"]
    for name in ("driver", "observer", "trajectory"):
        assert out[name][-2:] == ["-p", f"description:={overlay.resolve()}"]
    with pytest.raises(SupervisorError, match="nowhere"):
        description_args(str(tmp_path / "nowhere.yaml"), [], {})
