"""ROS-free driver conversions (hexa.protocol.driver_core): calibration, command checks, currents, torques."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, strategies as st

from hexa.protocol.driver_core import (CommandRejected, DriverConfigError, DriverCore, ServoCalibration,
                                       driver_core_from_config, load_driver_config, servo_calibrations_from_config)
from hexa.protocol.sensor_model import CurrentSensorModel, SensorModelError
from hexa.robots.hexa_description import load_hexa


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


@pytest.fixture
def core(desc):
    cfg = load_driver_config()
    c = driver_core_from_config(cfg, desc.zeta_min, desc.zeta_max, desc.K_t)
    c.max_speed, c.slew_period = 0.0, 0.0
    return c


def test_default_servo_map_comes_from_the_description(desc):
    servos = servo_calibrations_from_config(None, desc)
    assert [s.pulse_from_angle(desc.zeta_center) for s in servos] == [round(desc.pulse_center_us)] * 6
    step = 0.1
    for s, d in zip(servos, desc.servo_direction):
        assert s.pulse_from_angle(desc.zeta_center + step) - desc.pulse_center_us == round(d * desc.us_per_rad * step)


@given(st.floats(-4.0, -1.2))
def test_pulse_angle_round_trip_within_half_a_microsecond(zeta):
    s = ServoCalibration(zero_us=1500, us_per_rad=-636.62, zeta_ref=-2.618, min_us=500, max_us=2500)
    p = s.pulse_from_angle(zeta)
    if 500 < p < 2500:
        assert abs(s.angle_from_pulse(p) - zeta) <= 0.5 / 636.62 + 1e-12
    else:
        assert p in (500, 2500)


def test_servo_calibration_rejects_zero_slope_and_bad_limits():
    with pytest.raises(DriverConfigError, match="us_per_rad 0"):
        ServoCalibration(zero_us=1500, us_per_rad=0.0)
    with pytest.raises(DriverConfigError, match="min_us=2000 max_us=1000"):
        ServoCalibration(zero_us=1500, us_per_rad=600, min_us=2000, max_us=1000)
    with pytest.raises(DriverConfigError, match="expected 6 entries"):
        servo_calibrations_from_config([{"zero_us": 1500, "us_per_rad": 600}])


def test_order_command_by_name_and_rejections(core, desc):
    names = ["arm_3", "arm_1", "arm_2", "arm_6", "arm_5", "arm_4"]
    c = desc.zeta_center
    z = core.order_command(names, [c + 0.3, c + 0.1, c + 0.2, c + 0.6, c + 0.5, c + 0.4])
    assert np.allclose(z - c, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    with pytest.raises(CommandRejected, match="non-finite"):
        core.order_command([], [c, c, float("nan"), c, c, c])
    with pytest.raises(CommandRejected, match="non-finite"):
        core.order_command([], [c, c, c, float("-inf"), c, c])
    with pytest.raises(CommandRejected, match="lacks \\['arm_4'\\]"):
        core.order_command(names[:5] + ["wrist"], [c] * 6)
    with pytest.raises(CommandRejected, match="5 positions without names"):
        core.order_command([], [c] * 5)
    with pytest.raises(CommandRejected, match="6 names but 7 positions"):
        core.order_command(names, [c] * 7)
    assert (core.counters.rejected_nan, core.counters.rejected_names, core.counters.rejected_size) == (2, 1, 2)
    assert core.counters.accepted == 0


@pytest.mark.parametrize("value", [1e9, -1e9, "max", "min"])
def test_a_command_outside_the_joint_range_is_rejected_not_clamped(core, desc, value):
    step = 1e-3
    zeta = {"max": desc.zeta_max + step, "min": desc.zeta_min - step}.get(value, value)
    with pytest.raises(CommandRejected, match=r"arm_2 = .* rad outside its range \[-4\.1888, -1\.0472\] rad"):
        core.order_command([], [desc.zeta_center, zeta] + [desc.zeta_center] * 4)
    assert core.counters.rejected_range == 1 and core.counters.clamped == 0
    at_limit = core.order_command([], [desc.zeta_max + 1e-9] + [desc.zeta_center] * 5)   # float noise at a limit
    assert np.allclose(core.limit_command(at_limit, now=0.0)[0], desc.zeta_max)


def test_limit_command_clamps_to_joint_limits_and_slew(core, desc):
    z = core.limit_command(np.full(6, desc.zeta_max + 1.0), now=0.0)
    assert np.allclose(z, desc.zeta_max) and core.counters.clamped == 1
    core.accept(np.full(6, desc.zeta_center), now=10.0)
    core.max_speed = 2.0
    z = core.limit_command(np.full(6, desc.zeta_center + 1.0), now=10.1)
    assert np.allclose(z, desc.zeta_center + 0.2) and core.counters.slew_limited == 1


def test_the_slew_allowance_builds_up_over_one_command_period_at_most(core, desc):
    """After a stall the newest command can lie far ahead; the time since the last command would allow the whole
    jump, but the allowance stops at slew_period: the servos catch up at max_speed, on the clock given as slew_now
    (robot time), whatever the host's monotonic clock says."""
    assert driver_core_from_config(load_driver_config(), desc.zeta_min, desc.zeta_max, desc.K_t).slew_period == \
        pytest.approx(0.01)                                # 1 / command_rate_hz
    core.max_speed, core.slew_period = 1.5, 0.01
    core.accept(np.full(6, desc.zeta_center), now=500.0, slew_now=10.0)
    far = np.full(6, desc.zeta_center) + np.array([0.05, -0.05, 0.01, 0.0, 0.02, -0.1])
    z = core.limit_command(far, now=11.0)                  # a second later: 1.5 rad/s · 0.01 s, not · 1 s
    assert np.allclose(z - desc.zeta_center, [0.015, -0.015, 0.01, 0.0, 0.015, -0.015])
    assert core.counters.slew_limited == 1
    core.accept(z, now=500.5, slew_now=11.0)
    z = core.limit_command(far, now=11.004)                # 4 ms later: 6 mrad more
    assert np.allclose(z - desc.zeta_center, [0.021, -0.021, 0.01, 0.0, 0.02, -0.021])
    assert core.last_command_time == 500.5                 # rest detection stays on the host clock
    with pytest.raises(DriverConfigError, match="slew_period"):
        DriverCore(servos=core.servos, zeta_min=desc.zeta_min, zeta_max=desc.zeta_max, k_t=desc.K_t,
                   slew_period=-0.01)


@pytest.mark.parametrize("key, value", [("max_speed", -1.0), ("max_speed", float("nan")), ("command_rate_hz", 0.0),
                                        ("stream_rate_hz", 0), ("stream_rate_hz", 5000)])
def test_a_bad_speed_limit_or_command_rate_is_refused_naming_it(desc, key, value):
    cfg = dict(load_driver_config(), **{key: value})
    with pytest.raises(DriverConfigError, match=key):
        driver_core_from_config(cfg, desc.zeta_min, desc.zeta_max, desc.K_t)


def test_the_links_of_a_config_carry_its_ports_limits_and_latch_report(core):
    from hexa.protocol.driver_core import driver_links_from_config

    states = []
    cfg = dict(load_driver_config(), uno_port="/dev/null/uno", mega_port="/dev/null/mega", stream_rate_hz=500)
    uno, mega = driver_links_from_config(cfg, core, print, on_latch=print, on_state=lambda *a: states.append(a))
    assert (uno.port, mega.port, mega.rate_hz) == ("/dev/null/uno", "/dev/null/mega", 500)
    assert uno.min_us == tuple(s.min_us for s in core.servos) and uno.on_latch is print
    uno.on_state("CONNECTED")
    mega.on_state("STALE")
    assert states == [("uno", "CONNECTED"), ("mega", "STALE")]
    uno, _ = driver_links_from_config(dict(cfg, latch_report=False), core, print, on_latch=print)
    assert uno.on_latch is None


def test_currents_torques_and_zero_current_calibration(core, desc):
    sensor = core.sensor
    amps = np.array([0.3, -0.3, 1.0, -1.0, 2.0, 0.0])
    counts = sensor.counts_from_current(amps)
    i = core.currents_from_counts(counts)
    assert np.all(np.abs(i - amps) <= sensor.amps_per_count)
    assert np.allclose(core.torques_from_currents(i), desc.K_t * i)
    rest = np.tile(sensor.counts_from_current([0.05] * 6), (50, 1))
    offsets = core.calibrate_offsets(rest)
    assert np.allclose(offsets, sensor.current_from_counts(rest[0]))
    assert np.allclose(core.currents_from_counts(rest[0]), 0.0)


@given(st.floats(-5.0, 5.0))
def test_sensor_model_inverse_within_one_step(amps):
    s = CurrentSensorModel()
    c = s.counts_from_current(amps)
    assert abs(float(s.current_from_counts(c)) - amps) <= s.amps_per_count / 2 + 1e-9


def test_sensor_model_clips_and_validates():
    s = CurrentSensorModel()
    assert s.counts_from_current(100.0) == 1023 and s.counts_from_current(-100.0) == 0
    with pytest.raises(SensorModelError, match="sensitivity -1"):
        CurrentSensorModel(sensitivity=-1)
    with pytest.raises(SensorModelError, match="unknown sensor-model key"):
        CurrentSensorModel.from_dict({"gain": 1})
