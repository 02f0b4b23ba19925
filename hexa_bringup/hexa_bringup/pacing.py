"""Real-time pacing of the simulator's stepping loop (ROS-free; used by sim_node).

The simulator steps as fast as it can and sleeps to keep sim time at `real_time_factor` × wall time. A camera render
(≈ 22 ms per camera) or a host stall makes it fall behind that pace. Catching up means stepping without sleeping
until the pace is restored: sim time then runs several times faster than the rest of the graph, whose commands
(trajectory → driver → virtual Uno) then reach the simulated servos sparser in sim time than they were played —
gaps of 20–50 ms followed by a burst of set-point steps, which the arms really follow with jerks that the observer
sees as unmodelled torque (docs/observer_node.md, "Command timing"). So when the loop is more than `max_lag` wall
seconds behind, the lost wall time is dropped instead: the run gets longer, and sim time never runs ahead of the
requested factor.
"""
from __future__ import annotations

import math
import time
from typing import Callable


#: shortest sleep (s): the loop is paced every step, so the virtual boards' threads (which run while it sleeps) apply a
#: command within about a step of sim time
MIN_SLEEP = 0.0005
#: default wall seconds behind the pace before the lost time is dropped (sim_node's `max_lag`)
MAX_LAG = 0.005


class Pacer:
    """Keeps sim time at `real_time_factor` × wall time; drops the wall time lost in stalls longer than `max_lag`.

    Args:
        real_time_factor: sim seconds per wall second (> 0; 0 or less = as fast as possible, `pace` never sleeps).
        max_lag: wall seconds the loop may fall behind before the lost time is dropped (math.inf = always catch up).
        clock, sleep: wall clock and sleep (replaceable in tests).
    """

    def __init__(self, real_time_factor: float, max_lag: float = MAX_LAG,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
        if not math.isfinite(real_time_factor):
            raise ValueError(f"real_time_factor must be finite, got {real_time_factor!r}")
        if math.isnan(max_lag) or max_lag < 0.0:
            raise ValueError(f"max_lag must be >= 0 s, got {max_lag!r}")
        self.rtf = float(real_time_factor)
        self.max_lag = float(max_lag)
        self._clock, self._sleep = clock, sleep
        self._wall0 = 0.0
        self._sim0 = 0.0
        self.stalls = 0          # times the loop fell more than max_lag behind
        self.dropped = 0.0       # wall seconds dropped in them

    def start(self, sim_time: float) -> None:
        """Anchor the pace: `sim_time` now."""
        self._wall0 = self._clock()
        self._sim0 = float(sim_time)

    def pace(self, sim_time: float) -> None:
        """Called every step: sleep while ahead of the pace; re-anchor when more than max_lag behind."""
        if self.rtf <= 0.0:
            return
        ahead = (sim_time - self._sim0) / self.rtf - (self._clock() - self._wall0)
        if ahead > MIN_SLEEP:
            self._sleep(ahead)
        elif ahead < -self.max_lag:
            self._wall0 -= ahead
            self.stalls += 1
            self.dropped -= ahead
