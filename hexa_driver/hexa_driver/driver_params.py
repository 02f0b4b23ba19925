"""What each driver parameter means (the descriptors of the driver node's parameters; defaults and long comments in
hexa_driver/config/driver.yaml). All are read at start-up: read-only on the running node."""
from __future__ import annotations

from hexa_ros.node import Param, descriptor

#: scalar key of driver.yaml → its description (unit first)
TEXT = {
    "config": "driver YAML path (default hexa_driver/config/driver.yaml); ROS parameters override its scalars",
    "uno_port": "serial port of the servo board (Arduino Uno); prefer /dev/serial/by-id paths",
    "mega_port": "serial port of the current board (Arduino Mega 2560)",
    "baud": "baud rate of both boards (firmware HX_BAUD); ptys ignore it",
    "stream_rate_hz": "Hz, Mega sample rate, 1..1000",
    "stale_timeout": "s without telemetry before the data is STALE (diagnostics ERROR)",
    "stream_rerequest_period": "s between stream re-requests to a board that is quiet on an open port",
    "stream_reconnect_after": "s of a quiet stream (> stale_timeout) before the port is closed and reconnected",
    "drop_after": "s stale before the port is closed and reopened",
    "reconnect_period": "s between attempts to reopen a vanished port",
    "hello_timeout": "s of HELLO retries after opening a port",
    "boot_delay": "s to wait after opening a real tty (bootloader after the DTR reset); 0 on ptys",
    "command_rate_hz": "Hz, most SET_TARGETS per second; faster commands are coalesced (latest wins)",
    "max_speed": "rad/s slew limit between commands in robot time; 0 = off",
    "board_clock_max_extrapolation": "s the host-to-board clock map extrapolates past the newest sample",
    "watchdog_ms": "ms without a command before the Uno holds its targets (WATCHDOG_HOLD)",
    "diagnostics_period": "s between /diagnostics messages",
    "calibration_duration": "s averaged by calibrate_currents when the request says 0",
    "rest_quiet_time": "s without a new joint command required before a zero-current calibration",
    "frame_id": "frame of joint_states and motor_currents",
    "latch_report": "the Uno reports each pulse frame; samples carry the set-point each servo acted on"}


def driver_descriptor(name: str, default: object) -> object:
    """The read-only ParameterDescriptor of driver parameter `name`."""
    return descriptor(Param(default, TEXT.get(name, name)))
