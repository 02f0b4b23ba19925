"""A service answered when timed work ends, without holding the executor while it runs.

rclpy sends a service's response as soon as its callback returns. A request that starts work lasting some time
(averaging samples at rest, say) would otherwise block the node's executor for that time. Here the callback starts
the work and returns `Later(delay, finish)`: the response goes out `delay` s afterwards from a daemon timer thread,
once `finish(response)` has filled it in. A callback that returns the response answers at once, as usual.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any, Callable

from rclpy.node import Node


@dataclass(frozen=True)
class Later:
    """Answer `delay` s from now, after `finish(response)` has filled the response in."""
    delay: float
    finish: Callable[[Any], None]

    def __post_init__(self) -> None:
        if not 0.0 <= self.delay < 1e6:   # NaN fails too; a timer thread cannot wait longer than its platform's time_t
            raise ValueError(f"Later: delay must be in [0, 1e6) s, got {self.delay!r}")


class DeferredService:
    """A service of `node` whose callback `start(request, response)` returns the response (sent at once) or `Later`.

    `close()` cancels the answers still to come (the node is going away: nothing is sent after it).
    """

    def __init__(self, node: Node, srv_type: Any, name: str,
                 start: Callable[[Any, Any], Any]) -> None:
        self._node, self._start = node, start
        self._later: dict[int, tuple[Any, Later]] = {}   # id(response) -> the response and when to answer it
        self._timers: list[threading.Timer] = []
        self._closed = False
        self.service = node.create_service(srv_type, name, self._on_request)
        # rclpy's executor calls service.send_response(response, header) with what the callback returned
        self._send = self.service.send_response
        self.service.send_response = self._respond

    def _on_request(self, request: Any, response: Any) -> Any:
        out = self._start(request, response)
        if isinstance(out, Later):
            self._later[id(response)] = (response, out)
            return response
        return out

    def _respond(self, response: Any, header: Any) -> None:
        job = self._later.pop(id(response), None)
        if job is None:
            self._send(response, header)
            return
        timer = threading.Timer(job[1].delay, self._finish, (response, job[1].finish, header))
        timer.daemon = True
        self._timers = [t for t in self._timers if t.is_alive()] + [timer]
        timer.start()

    def _finish(self, response: Any, finish: Callable[[Any], None], header: Any) -> None:
        finish(response)
        if not self._closed and self._node.context.ok():
            self._send(response, header)

    def close(self) -> None:
        self._closed = True
        for timer in self._timers:
            timer.cancel()
