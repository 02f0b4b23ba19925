"""Helpers for the driver-node tests (no tests here): an in-process ROS probe and the driver process."""
from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

DRIVER = str(Path(sys.executable).with_name("hexa-driver"))


def driver_args(uno_port: str, mega_port: str, *params: str) -> list[str]:
    """Command line of the driver node in /hexa with the given ports and extra `name:=value` parameters."""
    args = [DRIVER, "--ros-args", "-r", "__ns:=/hexa", "-p", f"uno_port:={uno_port}", "-p", f"mega_port:={mega_port}"]
    for p in params:
        args += ["-p", p]
    return args


def wait_for(cond, timeout: float = 5.0, period: float = 0.01):
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        v = cond()
        if v:
            return v
        time.sleep(period)
    return cond()


class RosProbe:
    """A node in this test process: records joint_states, motor_currents, /diagnostics; publishes commands."""

    def __init__(self, env: dict[str, str], monkeypatch) -> None:
        for key in ("RMW_IMPLEMENTATION", "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
                    "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID"):
            if key in env:
                monkeypatch.setenv(key, env[key])
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from hexa_msgs.msg import MotorCurrents
        from hexa_msgs.srv import CalibrateCurrents
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState

        self.rclpy = rclpy
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
        self.node = rclpy.create_node("driver_probe", context=self.ctx)
        qos = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
        self.states: list[tuple[float, object]] = []
        self.currents: list[tuple[float, object]] = []
        self.diags: list[tuple[float, object]] = []
        self.node.create_subscription(JointState, "/hexa/joint_states",
                                      lambda m: self.states.append((time.monotonic(), m)), qos)
        self.node.create_subscription(MotorCurrents, "/hexa/motor_currents",
                                      lambda m: self.currents.append((time.monotonic(), m)), qos)
        self.node.create_subscription(DiagnosticArray, "/diagnostics",
                                      lambda m: self.diags.append((time.monotonic(), m)), 50)
        self.cmd_pub = self.node.create_publisher(JointState, "/hexa/joint_commands", 10)
        self.calib = self.node.create_client(CalibrateCurrents, "/hexa/calibrate_currents")
        self.JointState = JointState
        self.CalibrateCurrents = CalibrateCurrents
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            while self.ctx.ok():
                self.executor.spin_once(timeout_sec=0.05)
        except Exception:
            pass

    def command(self, positions, names=None) -> None:
        msg = self.JointState()
        msg.name = list(names) if names is not None else [f"arm_{i}" for i in range(1, 7)]
        msg.position = [float(p) for p in positions]
        self.cmd_pub.publish(msg)

    def calibrate(self, duration: float, timeout: float = 10.0):
        assert self.calib.wait_for_service(timeout_sec=5.0), "calibrate_currents service not available"
        req = self.CalibrateCurrents.Request()
        req.duration = float(duration)
        fut = self.calib.call_async(req)
        t_end = time.monotonic() + timeout
        while not fut.done() and time.monotonic() < t_end:
            time.sleep(0.01)
        assert fut.done(), "calibrate_currents did not answer"
        return fut.result()

    def diag_status(self, name_part: str, since: float = 0.0):
        """Latest DiagnosticStatus whose name contains `name_part` received after `since` (or None)."""
        for t, arr in reversed(self.diags):
            if t < since:
                break
            for s in arr.status:
                if name_part in s.name:
                    return s
        return None

    def close(self) -> None:
        try:
            self.node.destroy_node()
        finally:
            self.rclpy.try_shutdown(context=self.ctx)
            self._thread.join(timeout=2)


def kv(status) -> dict[str, str]:
    return {v.key: v.value for v in status.values}
