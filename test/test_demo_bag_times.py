"""A demo case read from its bag is on the scenario's clock: when the live trajectory started late and the simulator
moved the scripted collision with it (`sim/scenario_start`), every time (truth, residual, events, contacts,
wrenches) is moved back by as much, so the case compares with an offline run that starts at LEAD_IN. Real MCAP bags
written with the recorder's own writer."""
from __future__ import annotations

import pytest

pytest.importorskip("rosbags")

from hexa_bringup.bag import BagRecorder, typestore  # noqa: E402
from hexa_bringup.demo_run import LEAD_IN, case_data_from_bag  # noqa: E402

NS = "/hexa"


def _time(store, t: float):
    sec = int(t)
    return store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((t - sec) * 1e9)))


def _header(store, t: float):
    return store.types["std_msgs/msg/Header"](stamp=_time(store, t), frame_id="base")


def _write_case(path, scenario_starts: list[float], onset: float) -> None:
    """A plate contact from `onset` (truth at 100 Hz, force ramping), a START 40 ms after it, a contact and a wrench
    after that; `scenario_starts` published on sim/scenario_start in that order."""
    store = typestore()
    T = store.types
    vec = T["geometry_msgs/msg/Vector3"]
    point = T["geometry_msgs/msg/Point"]
    msgs: list[tuple[str, str, float, object]] = []
    for k, t0 in enumerate(scenario_starts):
        msgs.append(("sim/scenario_start", "std_msgs/msg/Header", 0.5 * k, _header(store, t0)))
    for i in range(300):
        t = 0.01 * i
        f = max(0.0, (t - onset) * 20.0)
        msgs.append(("sim/contact_truth", "hexa_msgs/msg/Contact", t, T["hexa_msgs/msg/Contact"](
            header=_header(store, t), collision_id=0, link=0, chain=0, point=point(x=0.1, y=0.0, z=0.2),
            pixel_u=-1.0, pixel_v=-1.0, camera="", confidence=1.0 if f > 0 else 0.0,
            push_direction=vec(x=0.0, y=0.0, z=0.0))))
        msgs.append(("sim/wrench_truth", "geometry_msgs/msg/WrenchStamped", t, T["geometry_msgs/msg/WrenchStamped"](
            header=_header(store, t), wrench=T["geometry_msgs/msg/Wrench"](force=vec(x=f, y=0.0, z=0.0),
                                                                          torque=vec(x=0.0, y=0.0, z=0.0)))))
    start = onset + 0.04
    msgs.append(("collision", "hexa_msgs/msg/CollisionEvent", start, T["hexa_msgs/msg/CollisionEvent"](
        header=_header(store, start), event=0, id=1, onset=_time(store, start - 0.005), axis=0, axis_name="fx",
        value=2.5, peak=2.5, duration=0.0)))
    msgs.append(("contact", "hexa_msgs/msg/Contact", start + 0.05, T["hexa_msgs/msg/Contact"](
        header=_header(store, start + 0.05), collision_id=1, link=0, chain=0, point=point(x=0.1, y=0.0, z=0.2),
        pixel_u=10.0, pixel_v=20.0, camera="cam_top", confidence=0.9, push_direction=vec(x=0.0, y=0.0, z=0.0))))
    msgs.append(("contact_wrench", "hexa_msgs/msg/ContactWrench", start + 0.06, T["hexa_msgs/msg/ContactWrench"](
        header=_header(store, start + 0.06), collision_id=1, link=0, chain=0, point=point(x=0.1, y=0.0, z=0.2),
        force=vec(x=3.0, y=0.0, z=0.0), rank=3, condition=1.0, observable=True, residual_norm=0.0,
        servo_stalled=False, force_model="measured")))
    with BagRecorder(path) as rec:
        for topic, msgtype, _t, _m in msgs:
            rec.add_topic(f"{NS}/{topic}", msgtype, transient_local=topic == "sim/scenario_start")
        for topic, msgtype, t, m in sorted(msgs, key=lambda x: x[2]):
            rec.write(f"{NS}/{topic}", int(t * 1e9), bytes(store.serialize_cdr(m, msgtype)))


@pytest.mark.parametrize("starts, moved", [([LEAD_IN], 0.0), ([LEAD_IN, LEAD_IN + 0.81], 0.81), ([], 0.0)])
def test_a_case_is_read_on_the_scenario_clock(tmp_path, starts, moved):
    onset = 1.5 + moved
    _write_case(tmp_path / "bag", starts, onset)
    d = case_data_from_bag("plate", tmp_path / "bag", NS)
    first_force = d.truth_t[(d.truth_force[:, 0] > 0).argmax()]
    assert first_force == pytest.approx(1.51, abs=1e-6)          # the onset where the scenario put it
    assert d.events[0][0] == pytest.approx(1.54, abs=1e-6) and d.events[0][1] == "START"
    assert d.contact_t[0] == pytest.approx(1.59, abs=1e-6) and d.wrench_t[0] == pytest.approx(1.60, abs=1e-6)
    assert d.truth_t[0] == pytest.approx(-moved, abs=1e-6)       # every time moved by as much
