"""The observer node's `monitoring` topic: hexa.dynamics.monitoring.MonitoringWatch evaluated on two timers and
published as hexa_msgs/MonitoringState (reliable, transient local), logged at each change (docs/monitoring.md)."""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from hexa_msgs.msg import MonitoringState
from hexa_ros import qos
from hexa_ros.stamps import to_stamp
from rclpy.clock import Clock, ClockType

from hexa.dynamics.monitor import CollisionMonitor
from hexa.dynamics.monitoring import LOST, MonitoringStatus, MonitoringWatch, WatchConfig


#: s (node clock) between re-publications of the current state: the trajectory node takes silence on `monitoring`
#: (the observer killed or hung) as LOST
HEARTBEAT = 0.05


class MonitoringPublisher:
    """A MonitoringWatch of `monitor` (the node sends its inputs through `watch`), evaluated every timeout/5 of the
    node's clock and every 0.1 s of a steady clock (which runs when a simulator's /clock stalls); publishes each new
    state (logged) and calls `on_change` (the node's diagnostics), and re-publishes the current one every HEARTBEAT."""

    def __init__(self, node: Any, monitor: CollisionMonitor, config: WatchConfig, frame_id: str,
                 on_change: Callable[[], Any]) -> None:
        self.node, self.frame_id, self.on_change = node, frame_id, on_change
        self.watch = watch = MonitoringWatch(monitor, config, self.now())
        self.pub = node.create_publisher(MonitoringState, "monitoring", qos.LATCHED)
        self._publish(watch.status)
        node.create_timer(watch.config.timeout / 5, self.evaluate)
        node.create_timer(0.1, self.evaluate, clock=Clock(clock_type=ClockType.STEADY_TIME))
        node.create_timer(HEARTBEAT, lambda: self._publish(watch.status, log=False))

    def now(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def evaluate(self) -> None:
        st = self.watch.evaluate(self.now(), time.monotonic())
        if st is not None:
            self._publish(st)
            self.on_change()

    def _publish(self, st: MonitoringStatus, log: bool = True) -> None:
        m = MonitoringState(level=getattr(MonitoringState, st.level), level_name=st.level, reason=st.reason,
                            residual_age=st.residual_age, timeout=self.watch.config.timeout,
                            lost_count=self.watch.lost_count)
        now = self.now()
        m.header.stamp, m.header.frame_id = to_stamp(now), self.frame_id
        self.pub.publish(m)
        if not log:
            return
        text = f"monitoring {st.level} at {now:.3f} s" + (f": {st.reason}" if st.reason else "")
        if st.level == LOST:   # (rclpy fixes one severity per call site)
            self.node.get_logger().error(text)
        else:
            self.node.get_logger().info(text)
