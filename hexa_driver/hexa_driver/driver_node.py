"""hexa_driver node: Uno servo board + Mega current board over serial -> joint_states, motor_currents, diagnostics.

Thin ROS wrapper: the protocol, links and conversions live in hexa.protocol (link.py, driver_core.py).
Topics (relative, run it in /hexa): sub `joint_commands` (sensor_msgs/JointState, rad); pub `joint_states`
(position = the command in effect when the current sample was measured, effort = K_t (I - I_0)), `motor_currents`
(hexa_msgs/MotorCurrents), `/diagnostics`.
Service `calibrate_currents` (hexa_msgs/CalibrateCurrents). Parameters: config/driver.yaml (docs/driver.md).
"""
from __future__ import annotations

import signal
import sys
import threading
import time
from collections import deque

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from hexa_msgs.msg import MotorCurrents
from hexa_msgs.srv import CalibrateCurrents
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from sensor_msgs.msg import JointState

from hexa.protocol import frames as fr
from hexa.protocol.board_clock import BoardClockMap, CommandTimeline, ServoFrameTimeline
from hexa.protocol.driver_core import (SCALAR_KEYS, CommandRejected, default_driver_config_path,
                                       driver_core_from_config, load_driver_config,
                                       servo_calibrations_from_config)
from hexa.protocol.link import CONNECTED, STALE, CurrentLink, ServoLink

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


def _load_description(cfg: dict):
    """The robot description (hexa.robots.hexa_description.load_hexa): joint limits, K_t, servo pulse map."""
    from hexa.robots.hexa_description import load_hexa

    return load_hexa(cfg.get("robot_description") or None)


class DriverNode(Node):
    """The serial driver: one ServoLink, one CurrentLink, conversions in DriverCore."""

    def __init__(self) -> None:
        super().__init__("hexa_driver")
        cfg_path = self.declare_parameter("config", str(default_driver_config_path())).value
        cfg = load_driver_config(cfg_path)
        for key in SCALAR_KEYS:
            cfg[key] = self.declare_parameter(key, cfg[key]).value
        self.cfg = cfg
        cfg["robot_description"] = self.declare_parameter("robot_description", "").value
        desc = _load_description(cfg)
        servos = servo_calibrations_from_config(cfg["servos"], desc)
        self.core = driver_core_from_config(cfg, desc.zeta_min, desc.zeta_max, desc.K_t, servos)
        self.frame_id = str(cfg["frame_id"])

        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
        self.pub_states = self.create_publisher(JointState, "joint_states", reliable)
        self.pub_currents = self.create_publisher(MotorCurrents, "motor_currents", reliable)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(JointState, "joint_commands", self._on_command, 10)
        self.create_service(CalibrateCurrents, "calibrate_currents", self._on_calibrate,
                            callback_group=ReentrantCallbackGroup())

        self._lock = threading.Lock()
        self._pending: np.ndarray | None = None
        self._last_sent = 0.0
        self._min_interval = 1.0 / float(cfg["command_rate_hz"])
        self._calib: list | None = None
        # each sample is paired with the command in effect when the Mega measured it (by its board clock), not the
        # one current when this node handled it: samples arrive in bursts (hexa.protocol.board_clock)
        max_extrapolation = float(cfg["board_clock_max_extrapolation"])
        if not (max_extrapolation >= 0.0 and np.isfinite(max_extrapolation)):
            raise ValueError(f"parameter board_clock_max_extrapolation must be >= 0 s, got {max_extrapolation}")
        self.board_clock = BoardClockMap(max_extrapolation=max_extrapolation)
        self.timeline = CommandTimeline()
        # with the Uno's latch report, each servo's set-point is the command its last pulse carried (the 20 ms pulse
        # frame), its frames moved from the Uno's clock onto the Mega's (_on_latch)
        self.latch_report = bool(cfg["latch_report"])
        self.uno_clock = BoardClockMap(max_extrapolation=max_extrapolation)   # its clock stops as the Mega's does
        self.frames = ServoFrameTimeline()
        self._pulses_by_seq: dict[int, list[int]] = {}
        self._uno_offsets: deque[float] = deque(maxlen=50)   # Uno board time − Mega board time, per LATCH (s)
        self.latches_unmapped = 0
        # commands timed into the frame's quiet gap (ServoFrameTimeline.aim), once frames are reported
        self.command_sync = bool(cfg["command_sync"]) and self.latch_report
        self.sync_guard = float(cfg["command_sync_guard"])
        if not (np.isfinite(self.sync_guard) and 0.0 <= self.sync_guard < 0.005):
            raise ValueError(f"parameter command_sync_guard must be in [0, 0.005) s, got {cfg['command_sync_guard']}")
        if self.command_sync:   # one command per frame: the slew allowance builds up over a frame
            self.core.slew_period = max(self.core.slew_period, self.frames.period)
        self._sync_timer: threading.Timer | None = None
        self._aim_frame: float | None = None      # the frame (its start, Mega clock) the command being sent is for
        self._sync_deferrals = 0          # of the pending command (a few at most, then it goes anyway)
        self.sync_held = 0                # commands held for the quiet gap
        self.sync_sent_in_gap = 0         # commands sent when aimed at the gap (held or not)
        self.sync_unsynced = 0            # commands sent without a gap to aim at (no frame yet) or given up on
        self._board_restarts = 0
        self._last_sample_time = 0.0
        self._rate_mark = (time.monotonic(), 0)
        self._rate_hz = 0.0
        self.tx_failures = 0

        common = dict(baud=int(cfg["baud"]), stale_timeout=float(cfg["stale_timeout"]),
                      drop_after=float(cfg["drop_after"]), reconnect_period=float(cfg["reconnect_period"]),
                      hello_timeout=float(cfg["hello_timeout"]), boot_delay=float(cfg["boot_delay"]))
        servos = self.core.servos
        self.uno = ServoLink(str(cfg["uno_port"]), min_us=[s.min_us for s in servos],
                             max_us=[s.max_us for s in servos], watchdog_ms=int(cfg["watchdog_ms"]),
                             on_latch=self._on_latch if self.latch_report else None,
                             on_state=lambda s: self._on_link_state("uno", s), **common)
        self.mega = CurrentLink(str(cfg["mega_port"]), rate_hz=int(cfg["stream_rate_hz"]),
                                on_samples=self._on_samples, on_state=lambda s: self._on_link_state("mega", s),
                                **common)
        self.uno.start()
        self.mega.start()
        timers = MutuallyExclusiveCallbackGroup()
        self.create_timer(float(cfg["diagnostics_period"]), self._publish_diagnostics, callback_group=timers)
        # the serial link's rate limit is a wall-time matter: under use_sim_time a sim-time timer would hold a pending
        # command for a whole /clock period (at real-time factor 0.3, 3x longer), and the next command would replace
        # it (coalesced): the servos then got double steps (docs/driver.md)
        self.create_timer(self._min_interval, self._flush_command, callback_group=timers,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"hexa_driver: uno={cfg['uno_port']} mega={cfg['mega_port']} "
                               f"rate={cfg['stream_rate_hz']} Hz")

    def close(self) -> None:
        with self._lock:
            if self._sync_timer is not None:
                self._sync_timer.cancel()
                self._sync_timer = None
        self.uno.stop()
        self.mega.stop()

    # ------------------------------------------------------------------------------------------ links
    def _on_link_state(self, board: str, state: str) -> None:
        if not self.context.ok():
            return
        if state == CONNECTED:  # the board may have restarted: its clock with it
            with self._lock:
                if board == "mega":
                    self.board_clock.reset()
                    self.timeline.rebase()
                else:
                    self.uno_clock.reset()
                self._uno_offsets.clear()
                self.frames.reset()
        # separate call sites: rclpy refuses one call site logging at two severities
        if state == CONNECTED:
            self.get_logger().info(f"{board} link CONNECTED")
        else:
            self.get_logger().warning(f"{board} link {state}")

    # ------------------------------------------------------------------------------------------ commands
    def _on_command(self, msg: JointState) -> None:
        try:
            zeta = self.core.order_command(list(msg.name), list(msg.position))
        except CommandRejected as exc:
            self.get_logger().warning(f"joint command rejected: {exc}", throttle_duration_sec=1.0)
            return
        with self._lock:
            if self._pending is not None:
                self.core.counters.coalesced += 1
            self._pending = zeta
        if time.monotonic() - self._last_sent >= self._min_interval:
            self._flush_command()

    def _flush_synced(self) -> None:
        """The quiet-gap timer (a threading.Timer): send the held command."""
        with self._lock:
            self._sync_timer = None
        if self.context.ok():
            self._flush_command()

    def _hold_for_gap(self, now: float) -> bool:
        """With command_sync: True (and a timer armed) when the pending command would reach the Uno outside the
        frame's quiet gap; the timer sends it when it would land in the gap's middle. Called with the lock held."""
        if not self.command_sync:
            return False
        if self._sync_timer is not None:          # already waiting for the gap
            return True
        board_now = self.board_clock.board_time_at(now)
        aim = None if board_now is None else self.frames.aim(board_now, self.sync_guard)
        wait = None if aim is None else aim[0]
        if wait is None:                          # no frame reported yet: nothing to aim at
            self.sync_unsynced += 1
            return False
        if wait <= 0:
            self.sync_sent_in_gap += 1
            self._aim_frame = aim[1]
            return False
        if self._sync_deferrals >= 3:             # the timer keeps missing the gap (the clocks disagree): send now
            self.sync_unsynced += 1
            return False
        self._sync_deferrals += 1
        if self._sync_deferrals == 1:
            self.sync_held += 1
        # board seconds to host seconds (sim time runs slower than the host's in simulation)
        host_wait = wait / max(self.board_clock.rate, 1e-3)
        self._sync_timer = threading.Timer(min(host_wait, 1.0), self._flush_synced)
        self._sync_timer.daemon = True
        self._sync_timer.start()
        return True

    def _flush_command(self) -> None:
        with self._lock:
            if self._pending is None:
                return
            now = time.monotonic()
            self._aim_frame = None
            if self._hold_for_gap(now):
                return
            self._sync_deferrals = 0
            zeta, self._pending = self._pending, None
            # the slew limit runs on the robot's time — the Mega's clock, sim time in simulation, where the ROS clock
            # moves in 4 ms /clock steps — its allowance never more than one command period: after a stall the
            # servos catch up at max_speed instead of jumping (docs/driver.md, "Catching up after a stall")
            board_now = self.board_clock.board_time_at(now)
            robot_now = now if board_now is None else board_now   # no sample yet: the host's clock (one command)
            zeta = self.core.limit_command(zeta, robot_now)
            pulses = self.core.accept(zeta, now, slew_now=robot_now)
            sent = self.uno.set_targets(pulses)
            # dated from after the write: the Uno cannot have the command earlier. Timed before it, a process stop
            # between the clock read and the write dated a command written after the stop back to its start, and the
            # stop's samples carried it (a rare failure of test_driver_node's stall test). Provisional: samples still
            # waiting in the Mega's port are not in the clock map yet (_on_samples)
            t_sent = time.monotonic()
            b_sent = self.timeline.add(self.board_clock.board_time_at(t_sent), self.core.commanded, sent_at=t_sent)
            seq = self.uno.last_targets_seq
            if sent and seq is not None:
                self.frames.add_command(seq, self.core.commanded, b_sent, aimed_at=self._aim_frame)
                self._pulses_by_seq[seq] = pulses
            self._last_sent = now
        if not sent:
            self.tx_failures += 1

    # ------------------------------------------------------------------------------------------ telemetry
    def _on_samples(self, batch: list[tuple[fr.Sample, int]], t_read: float, t_rx: float) -> None:
        """One read of the Mega's port: its samples in order; the read started at host time t_read (s)."""
        with self._lock:
            board_times = []
            for sample, _gap in batch:
                board_times.append(self.board_clock.update(sample.board_time_us, t_rx))
                if self.board_clock.restarts != self._board_restarts:
                    self._board_restarts = self.board_clock.restarts
                    self.timeline.rebase()
            # a command sent before this read is dated no earlier than its samples prove (board_clock.CommandTimeline)
            self.timeline.confirm(t_read, max(board_times), self.board_clock.rate)
            commands = [self._setpoints_at(b) for b in board_times]
        for (sample, _gap), command in zip(batch, commands):
            self._publish_sample(sample, command, t_rx)

    def _setpoints_at(self, board_time: float) -> np.ndarray | None:
        """The set-points the servos acted on at Mega board time `board_time`: from the Uno's pulse frames when it
        reports them, else the command in effect (sent) then."""
        z = self.frames.setpoints_at(board_time, self.timeline)
        return self.timeline.at(board_time) if z is None else z

    def _on_latch(self, latch: fr.Latch, t_rx: float) -> None:
        """A LATCH from the Uno (its link thread): the frame's pulses onto the Mega's clock, into the frame timeline.

        The Uno sends it right after the frame's last pulse, so that pulse's end is what the Uno's clock read, at the
        latest, when the report arrived at host time t_rx, as the Mega's clock map says what the Mega's read then.
        Their difference is the offset between the two board clocks plus the difference of the two delays; its
        median over the last 50 frames (1 s) is the offset (crystals drift by ppm: constant over a second; in
        simulation both clocks are sim time and stop together while a camera frame renders, which a single
        mapping through the host's clock would read as a jump)."""
        with self._lock:
            widths = np.array([(self._pulses_by_seq.get(s) or [1500] * 6)[i] for i, s in enumerate(latch.seqs)],
                              dtype=float) * 1e-6
            starts = np.asarray(latch.offsets_us, dtype=float) * 1e-6
            end_us = (latch.frame_start_us + int(latch.offsets_us[5]) + int(round(widths[5] * 1e6))) & 0xFFFFFFFF
            restarts = self.uno_clock.restarts
            b_end = self.uno_clock.update(end_us, t_rx)     # unwrapped (µs counter wraps, board restarts)
            if self.uno_clock.restarts != restarts:
                self._uno_offsets.clear()
                self.frames.reset()
            mega_now = self.board_clock.board_time_at(t_rx)
            if mega_now is None:
                self.latches_unmapped += 1
                return
            self._uno_offsets.append(b_end - mega_now)
            offset = float(np.median(self._uno_offsets))
            frame_start = b_end - starts[5] - widths[5] - offset     # on the Mega's clock
            self.frames.add_frame(frame_start, starts, starts + widths, np.asarray(latch.seqs), int(latch.mask),
                                  commands=self.timeline)

    def _publish_sample(self, sample: fr.Sample, command: np.ndarray | None, t_rx: float) -> None:
        currents = self.core.currents_from_counts(sample.counts)
        effort = self.core.torques_from_currents(currents)
        stamp = self.get_clock().now().to_msg()
        m = MotorCurrents()
        m.header.stamp = stamp
        m.header.frame_id = self.frame_id
        m.current = [float(c) for c in currents]
        m.raw = [int(c) for c in sample.counts]
        m.sequence = int(sample.sequence)
        m.board_time_us = int(sample.board_time_us)
        m.gaps = int(self.mega.sample_gaps) & 0xFFFFFFFF
        js = JointState()
        js.header.stamp = stamp
        js.header.frame_id = self.frame_id
        js.name = list(self.core.joint_names)
        if self.uno.connected and command is not None:
            js.position = [float(z) for z in command]
        else:  # no servo board, or nothing commanded yet (the servos are limp): the arms' angle is unknown
            js.position = [float("nan")] * len(self.core.joint_names)
        js.effort = [float(t) for t in effort]
        if not self.context.ok():  # shutting down: the link thread outlives the context briefly
            return
        self.pub_currents.publish(m)
        self.pub_states.publish(js)
        self._last_sample_time = t_rx
        calib = self._calib
        if calib is not None:
            calib.append(sample.counts)

    def _on_calibrate(self, req: CalibrateCurrents.Request, resp: CalibrateCurrents.Response):
        duration = req.duration if req.duration > 0 else float(self.cfg["calibration_duration"])
        quiet = float(self.cfg["rest_quiet_time"])
        t_cmd = self.core.last_command_time
        resp.offsets = [float(v) for v in self.core.offsets]
        if self.mega.stats.state != CONNECTED:
            resp.success, resp.message = False, f"current board link is {self.mega.stats.state}"
            return resp
        if t_cmd is not None and time.monotonic() - t_cmd < quiet:
            resp.success, resp.message = False, f"not at rest: a joint command arrived less than {quiet} s ago"
            return resp
        n_cmd = self.core.counters.accepted
        self._calib = samples = []
        time.sleep(duration)
        self._calib = None
        if self.core.counters.accepted != n_cmd:
            resp.success, resp.message = False, "not at rest: joint commands arrived during the calibration"
            return resp
        if len(samples) < 5:
            resp.success, resp.message = False, f"only {len(samples)} samples in {duration} s"
            return resp
        offsets = self.core.calibrate_offsets(np.asarray(samples))
        resp.success = True
        resp.message = f"I_0 from {len(samples)} samples over {duration:.2f} s"
        resp.offsets = [float(v) for v in offsets]
        self.get_logger().info(f"zero-current calibration: I_0 = {np.round(offsets, 4).tolist()} A")
        return resp

    # ------------------------------------------------------------------------------------------ diagnostics
    def _link_status(self, name: str, link, extra: list[tuple[str, object]]) -> DiagnosticStatus:
        st = link.stats
        d = DiagnosticStatus()
        d.name = f"hexa_driver: {name}"
        d.hardware_id = str(link.port)
        if st.state == CONNECTED:
            d.level, d.message = OK, "connected"
        elif st.state == STALE:
            d.level, d.message = ERROR, f"telemetry stale (no data for {time.monotonic() - st.last_rx:.2f} s)"
        else:
            d.level = ERROR
            d.message = f"{st.state.lower()}: {st.last_error}" if st.last_error else st.state.lower()
        rtt = st.rtt_s * 1e3 if st.rtt_s == st.rtt_s else float("nan")
        values = [("state", st.state), ("port", link.port), ("connects", st.connects),
                  ("disconnects", st.disconnects), ("last_reconnect_s", f"{st.last_reconnect_s:.3f}"),
                  ("frames_rx", st.frames_rx), ("frames_tx", st.frames_tx), ("crc_errors", st.crc_errors),
                  ("bad_length", st.bad_length), ("resyncs", st.resyncs), ("discarded_bytes", st.discarded_bytes),
                  ("dropped_frames", st.dropped_frames), ("board_errors", st.board_errors),
                  ("decode_errors", st.decode_errors), ("latency_rtt_ms", f"{rtt:.3f}"),
                  ("firmware_version", hex(st.firmware_version)), ("last_error", st.last_error)] + extra
        d.values = [KeyValue(key=k, value=str(v)) for k, v in values]
        return d

    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        t0, n0 = self._rate_mark
        n = self.mega.samples
        if now > t0:
            self._rate_hz = (n - n0) / (now - t0)
        self._rate_mark = (now, n)
        age = now - self._last_sample_time if self._last_sample_time else float("inf")
        c = self.core.counters
        uno_status = self.uno.status
        mega_extra = [("sample_rate_hz", f"{self._rate_hz:.1f}"), ("sample_rate_commanded_hz", self.mega.rate_hz),
                      ("samples", self.mega.samples), ("sample_gaps", self.mega.sample_gaps),
                      ("data_age_s", f"{age:.3f}"), ("board_clock_rate", f"{self.board_clock.rate:.4f}"),
                      ("board_clock_restarts", self.board_clock.restarts),
                      ("commands_redated", self.timeline.redated),
                      ("board_overruns", self.mega.status.overruns if self.mega.status else "?")]
        uno_extra = [("commands_accepted", c.accepted), ("commands_rejected_nan", c.rejected_nan),
                     ("commands_rejected_names", c.rejected_names), ("commands_clamped", c.clamped),
                     ("commands_slew_limited", c.slew_limited), ("commands_coalesced", c.coalesced),
                     ("commands_unsent", self.tx_failures), ("targets_restored_after_reconnect", self.uno.restored),
                     ("board_pulses_us", list(uno_status.pulses_us) if uno_status else "?"),
                     ("latch_report", self.latch_report), ("latch_frames", self.frames.frames),
                     ("latch_unknown_seq", self.frames.unknown_seq),
                     ("latch_predicted_wrong", self.frames.mismatches),
                     ("latch_delivery_delay_ms", f"{1e3 * self.frames.delivery_delay:.2f}"),
                     ("latch_unmapped", self.latches_unmapped),
                     ("uno_clock_rate", f"{self.uno_clock.rate:.4f}"),
                     ("command_sync", self.command_sync), ("commands_held_for_gap", self.sync_held),
                     ("commands_sent_in_gap", self.sync_sent_in_gap),
                     ("commands_sent_unsynced", self.sync_unsynced),
                     ("board_watchdog_hold", bool(uno_status.flags & fr.FLAG_WATCHDOG_HOLD) if uno_status else "?")]
        mega = self._link_status("current board (Mega)", self.mega, mega_extra)
        if mega.level == OK and age > float(self.cfg["stale_timeout"]):
            mega.level, mega.message = ERROR, f"telemetry stale (no sample for {age:.2f} s)"
        uno = self._link_status("servo board (Uno)", self.uno, uno_extra)
        if uno.level == OK and uno_status is not None and uno_status.flags & fr.FLAG_WATCHDOG_HOLD and \
                self.core.last_command_time is not None:
            uno.level, uno.message = WARN, "holding last command (no joint_commands within the watchdog)"
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [uno, mega]
        self.pub_diag.publish(arr)


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def main(args: list[str] | None = None) -> int:
    """Entry point `hexa-driver` (run with `--ros-args -r __ns:=/hexa -p uno_port:=... -p mega_port:=...`)."""
    from hexa_bringup.rosenv import apply_defaults

    apply_defaults()
    # Our own SIGINT/SIGTERM handling: stop the serial links first, then shut ROS down (no logging into a dead
    # context from the link threads).
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        node = DriverNode()
    except Exception as exc:
        print(f"hexa-driver: {type(exc).__name__}: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 1
    executor = MultiThreadedExecutor(num_threads=3)
    executor.add_node(node)
    try:
        # spin_once with a timeout, not spin(): with our own signal handling the C wait is not woken by SIGINT,
        # and with use_sim_time no timer fires once /clock stops (e.g. the simulator exited first).
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.close()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
