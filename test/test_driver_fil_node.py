"""Firmware-in-the-loop with the driver node unchanged: the real Uno/Mega firmware in simavr on ptys.

A commanded angle must produce the right pulse width on the right pin; an injected ADC voltage must arrive as the
right current on motor_currents and the right effort on joint_states. Fails (never skips) without the build.
"""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

from hexa.protocol import frames as fr
from hexa.protocol.driver_core import servo_calibrations_from_config
from hexa.protocol.emulator import UnoEmulator
from hexa.protocol.sensor_model import DEFAULT_SENSOR
from hexa.protocol.simavr import SERVO_PINS, SimavrBoard, simavr_counts
from hexa.robots.hexa_description import load_hexa
from test_driver_helpers import RosProbe, driver_args, kv, wait_for

pytestmark = pytest.mark.slow   # the firmware in simavr: left out of `make check`


@pytest.fixture
def probe(ros_env, monkeypatch):
    p = RosProbe(ros_env, monkeypatch)
    try:
        yield p
    finally:
        p.close()


def test_driver_node_through_real_firmware_in_simavr(tmp_path, procs, ros_env, probe):
    desc = load_hexa()
    servos = servo_calibrations_from_config(None, desc)
    volts = [2.5, 2.7, 2.3, 3.0, 2.0, 2.6]     # ACS712 outputs: 0 A, +1.08 A, -1.08 A, +2.7 A, -2.7 A, +0.54 A
    with SimavrBoard("uno", link=tmp_path / "uno") as uno, SimavrBoard("mega", link=tmp_path / "mega") as mega:
        for ch, v in enumerate(volts):
            mega.set_adc(ch, v)
        procs.start(driver_args(uno.port, mega.port, "stream_rate_hz:=250", "max_speed:=0.0"), ros_env)
        assert wait_for(lambda: len(probe.currents) >= 50, 30.0), "no motor_currents through the firmware"

        # ADC voltage -> counts (firmware) -> amps (driver, sensor model) -> effort = K_t * I
        counts = [simavr_counts(v) for v in volts]
        _, m = probe.currents[-1]
        assert list(m.raw) == counts
        amps = DEFAULT_SENSOR.current_from_counts(counts)
        assert np.allclose(m.current, amps, atol=1e-12)
        assert np.allclose(m.current, [(v - 2.5) / 0.185 for v in volts], atol=DEFAULT_SENSOR.amps_per_count)
        _, js = probe.states[-1]
        assert np.allclose(js.effort, desc.K_t * amps, atol=1e-12)
        assert m.gaps == 0

        # commanded angles -> pulses on D2..D7 (measured in simulated CPU cycles)
        zeta = desc.zeta_center + np.array([0.0, 0.3, -0.3, 0.6, -0.6, 1.0])
        t_cmd = time.monotonic()
        probe.command(zeta)
        for pin, servo, z in zip(SERVO_PINS, servos, zeta):
            width = servo.pulse_from_angle(z)
            pulse = uno.wait_pulse(pin, width, tol_us=1.0, after=t_cmd, timeout=5.0)
            assert pulse is not None, (pin, width, uno.latest_widths())
        assert wait_for(lambda: np.allclose(probe.states[-1][1].position, zeta), 3.0)

        # a new voltage on one channel shows up on the topic
        mega.set_adc(3, 2.2)
        assert wait_for(lambda: probe.currents[-1][1].raw[3] == simavr_counts(2.2), 3.0)


def test_the_real_mega_firmware_streams_again_after_one_stop_stream_frame_on_its_port(tmp_path, procs, ros_env, probe):
    with UnoEmulator(link=tmp_path / "uno") as uno, SimavrBoard("mega", link=tmp_path / "mega") as mega:
        procs.start(driver_args(uno.port, mega.port, "stream_rate_hz:=250", "diagnostics_period:=0.1"), ros_env)
        assert wait_for(lambda: len(probe.currents) >= 50, 30.0), "no motor_currents through the firmware"
        fd = os.open(mega.port, os.O_WRONLY | os.O_NOCTTY)   # the frame reaches the firmware, not the driver
        try:
            os.write(fd, fr.encode_frame(fr.STOP_STREAM, 0))
        finally:
            os.close(fd)
        t_stop = time.monotonic()
        assert wait_for(lambda: probe.currents[-1][0] > t_stop + 0.5, 5.0), "the stream did not come back"
        gap = max(b[0] - a[0] for a, b in zip(probe.currents, probe.currents[1:]) if b[0] > t_stop)
        print(f"firmware STOP_STREAM -> streaming again: {gap * 1e3:.0f} ms")
        assert 0.2 < gap < 1.0           # it did stop, and came back within a second
        t_now = time.monotonic()
        st = wait_for(lambda: (s := probe.diag_status("current board", since=t_now)) is not None and s, 2.0)
        assert st and int(kv(st)["stream_rerequests"]) >= 1 and int(kv(st)["connects"]) == 1
