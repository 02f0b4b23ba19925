"""hexa_driver node: Uno servo board + Mega current board over serial -> joint_states, motor_currents, diagnostics.

An adapter: links hexa.protocol.link, conversions hexa.protocol.driver_core, command scheduling and sample/set-point
pairing hexa.protocol.driver_scheduler. Topics (relative, run it in /hexa): sub `joint_commands`; pub `joint_states`
(position = the set-points when the sample was measured, effort = K_t (I - I_0)), `motor_currents` (with the same
set-points, arm_1..arm_6, in `setpoint`: a consumer needs one topic), `/diagnostics`
(the link threads publish the samples). Service `calibrate_currents`. Parameters: config/driver.yaml (docs/driver.md).
"""
from __future__ import annotations

import functools
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from hexa_msgs.msg import MotorCurrents
from hexa_msgs.srv import CalibrateCurrents
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from sensor_msgs.msg import JointState

import hexa_ros.node
from hexa.protocol import frames as fr
from hexa.protocol.driver_core import (SCALAR_KEYS, CommandRejected, default_driver_config_path,
                                       driver_core_from_config, driver_links_from_config, load_driver_config,
                                       servo_calibrations_from_config)
from hexa.protocol.driver_scheduler import CalibrationRefused, DriverScheduler, calibration_duration, driver_reports
from hexa.protocol.link import CONNECTED
from hexa.robots.hexa_description import calibration_summary, load_hexa
from hexa_ros import cdr, diagnostics, qos
from hexa_ros.conversions import JOINT_NAMES
from hexa_ros.deferred import DeferredService, Later
from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, descriptor
from hexa_ros.realtime import (REALTIME_PRIORITY, REALTIME_PRIORITY_PARAM, realtime_priority_of,
                               request_realtime_priority)
from hexa_driver.driver_params import driver_descriptor


class DriverNode(Node):
    """The serial driver: one ServoLink, one CurrentLink, their timing in a DriverScheduler."""

    def __init__(self, **kwargs) -> None:
        super().__init__("driver", **kwargs)
        d = driver_descriptor          # read at start-up only (read-only); a -p value of the wrong type is a
        try:                           # configuration error
            path = str(default_driver_config_path())
            self.cfg = cfg = load_driver_config(self.declare_parameter("config", path, d("config", path)).value)
            cfg.update({k: self.declare_parameter(k, cfg[k], d(k, cfg[k])).value for k in SCALAR_KEYS})
            desc = load_hexa(self.declare_parameter(DESCRIPTION, "", descriptor(DESCRIPTION_PARAM)).value or None)
            priority = int(self.declare_parameter(REALTIME_PRIORITY, REALTIME_PRIORITY_PARAM.default,
                                                  descriptor(REALTIME_PRIORITY_PARAM)).value)
        except ParameterException as exc:
            raise ValueError(str(exc)) from exc
        self.get_logger().info(calibration_summary(desc))   # the overlay's horn offsets shift the pulse map
        if sorted(cfg["joint_names"]) != sorted(JOINT_NAMES):
            raise ValueError(f"joint_names {cfg['joint_names']} must name the graph's joints {list(JOINT_NAMES)}")
        self.core = driver_core_from_config(cfg, desc.zeta_min, desc.zeta_max, desc.K_t,
                                            servo_calibrations_from_config(cfg["servos"], desc))
        self.sched = DriverScheduler.from_config(self.core, cfg)
        self._graph_order = [list(self.core.joint_names).index(n) for n in JOINT_NAMES]   # MotorCurrents.setpoint
        self._closed = False

        self.pub_states = self.create_publisher(JointState, "joint_states", qos.STREAM)
        self.pub_currents = self.create_publisher(MotorCurrents, "motor_currents", qos.STREAM)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.create_subscription(JointState, "joint_commands", self._on_command, qos.RELIABLE)
        # answered when the averaging ends: the executor does not wait for it
        self._calib_srv = DeferredService(self, CalibrateCurrents, "calibrate_currents", self._on_calibrate)
        self.uno, self.mega = driver_links_from_config(cfg, self.core, self._on_samples, self.sched.on_latch,
                                                       self._on_link_state)
        self.create_timer(float(cfg["diagnostics_period"]), self._publish_diagnostics)
        # the serial link's rate limit is a wall-time matter, also under use_sim_time (docs/driver.md)
        self.create_timer(self.sched.min_interval, self._flush, clock=Clock(clock_type=ClockType.STEADY_TIME))
        request_realtime_priority(self, priority)   # the entry point raises the process, link threads included
        self.uno.start()
        self.mega.start()
        self._said: dict[str, str] = {}
        self.get_logger().info(f"uno={cfg['uno_port']} mega={cfg['mega_port']} rate={cfg['stream_rate_hz']} Hz")

    def close(self) -> None:
        """Stop the timers and the serial links first: the link threads publish."""
        self._closed = True
        self._calib_srv.close()
        self.uno.stop()
        self.mega.stop()

    def _on_link_state(self, board: str, state: str) -> None:
        if self._closed or not self.context.ok():
            return
        if state == CONNECTED:
            self.sched.on_connected(board)
            self.get_logger().info(f"{board} link CONNECTED")
        else:
            self.get_logger().warning(f"{board} link {state}")

    def _on_command(self, msg: JointState) -> None:
        try:
            zeta = self.core.order_command(list(msg.name), list(msg.position))
        except CommandRejected as exc:
            self.get_logger().warning(f"joint command rejected: {exc}", throttle_duration_sec=1.0)
            return
        if self.sched.submit(zeta, time.monotonic()):
            self._flush()

    def _flush(self) -> None:
        if not self._closed:
            self.sched.flush(time.monotonic(), self._send_targets)

    def _send_targets(self, pulses: list[int]) -> int | None:
        return self.uno.last_targets_seq if self.uno.set_targets(pulses) else None

    def _on_samples(self, batch: list[tuple[fr.Sample, int]], t_read: float, t_rx: float) -> None:
        frame_id, names = self.cfg["frame_id"], self.core.joint_names
        for r in self.sched.on_samples([s for s, _ in batch], t_read, t_rx, servos_driven=self.uno.connected):
            if self._closed or not self.context.ok():   # shutting down: the link thread outlives the node briefly
                return
            sec, nsec = divmod(self.get_clock().now().nanoseconds, 1_000_000_000)
            setpoints = r.setpoints.tolist()
            # serialized here (hexa_ros.cdr): at 1 kHz the message objects cost more than the rest of the sample
            self.pub_currents.publish(cdr.motor_currents_to_cdr(
                sec, nsec, frame_id, r.currents.tolist(), r.sample.counts, r.sample.sequence,
                r.sample.board_time_us, self.mega.sample_gaps & 0xFFFFFFFF, [setpoints[i] for i in self._graph_order]))
            self.pub_states.publish(cdr.joint_state_to_cdr(sec, nsec, frame_id, names, setpoints, [],
                                                           r.efforts.tolist()))

    def _on_calibrate(self, req: CalibrateCurrents.Request, resp: CalibrateCurrents.Response):
        resp.offsets = self.core.offsets.tolist()
        try:
            duration = calibration_duration(req.duration, float(self.cfg["calibration_duration"]))
            self.sched.start_calibration(time.monotonic(), float(self.cfg["rest_quiet_time"]), self.mega.stats.state)
        except CalibrationRefused as exc:
            resp.success, resp.message = False, str(exc)
            return resp
        return Later(duration, functools.partial(self._finish_calibration, duration))

    def _finish_calibration(self, duration: float, resp: CalibrateCurrents.Response) -> None:
        try:
            offsets, n = self.sched.finish_calibration(duration)
            resp.success, resp.offsets = True, offsets.tolist()
            resp.message = f"I_0 from {n} samples over {duration:.2f} s"
            self.get_logger().info(f"zero-current calibration: I_0 = {np.round(offsets, 4).tolist()} A")
        except CalibrationRefused as exc:
            resp.success, resp.message = False, str(exc)

    def _publish_diagnostics(self) -> None:
        reports = driver_reports(self.sched, self.uno, self.mega, time.monotonic(), float(self.cfg["stale_timeout"]))
        self.pub_diag.publish(diagnostics.array(self, [
            diagnostics.status(r.name, getattr(diagnostics, r.level), r.message,
                               {**r.values, REALTIME_PRIORITY: realtime_priority_of()}, r.hardware_id)
            for r in reports]))
        for board, link in (("uno", self.uno), ("mega", self.mega)):   # an absent port: named once per new error
            err = link.stats.last_error if link.stats.state != CONNECTED else ""
            if err and err != self._said.get(board):
                self.get_logger().warning(f"{board} board at {link.port}: {err}; retrying")
            self._said[board] = err


def main(args: list[str] | None = None) -> int:
    """Entry point `hexa-driver` (run with `--ros-args -r __ns:=/hexa -p uno_port:=... -p mega_port:=...`)."""
    return hexa_ros.node.main(DriverNode, "driver", args)


if __name__ == "__main__":
    raise SystemExit(main())
