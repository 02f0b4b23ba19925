"""The simulator's camera frames rendered on a thread of their own, while the physics steps.

Rendering both cameras costs 15-25 ms of wall time per frame pair on 2 cores, 30 pairs per sim second. Rendered in
the stepping loop, that time stops sim time, and the pacing drops it rather than catch it up in a burst
(hexa.sim.pacing): a graph asked for 0.5x real time then reaches about 0.38x. Here the loop only takes the frame's
state (`Simulator.frame_state`, tens of µs) and hands it over; this thread renders it with its own GL context and
MjData (MuJoCo releases the GIL while it renders) and hands the images on, stamped with the frame's sim time. A frame
reaches its subscribers one render later in wall time, as a real camera's frames do after exposure and transfer.

Every frame is rendered, in order, so the images and their noise are those of a run that rendered in the loop: a
frame handed over while the previous one still waits blocks the loop until the thread takes it (the pacing then sees
a stall, as it did with the render in the loop), never drops it.
"""
from __future__ import annotations

import queue
import threading
import time
from typing import TYPE_CHECKING, Callable

import numpy as np

if TYPE_CHECKING:
    from hexa.sim.simulator import FrameState, Simulator

#: the images of one camera at one frame: (sim time s, camera, colour H×W×3 uint8, depth H×W uint16 mm), or with
#: None images for a camera nobody wanted (its noise advanced, nothing rendered)
Deliver = Callable[[float, str, "np.ndarray | None", "np.ndarray | None"], None]


class RenderThread:
    """Renders `Simulator` frame states on a daemon thread and passes each camera's images to `deliver`.

    Args:
        sim: the simulator (built with cameras: its camera set-up and image noise are used).
        deliver: called on this thread for every camera of every frame, in frame order.
        max_pending: frames handed over and not yet taken; `submit` waits for room beyond it.
    """

    def __init__(self, sim: Simulator, deliver: Deliver, max_pending: int = 1) -> None:
        self.sim = sim
        self._deliver = deliver
        self._queue: queue.Queue[tuple[FrameState, dict[str, bool]] | None] = queue.Queue(maxsize=max(1, max_pending))
        self.frames = 0            # frames rendered (or skipped) and delivered
        self.waited = 0.0          # wall seconds `submit` waited for room
        self.error: BaseException | None = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hexa-sim-render", daemon=True)
        self._thread.start()
        self._ready.wait(30.0)
        if self.error is not None:
            raise self.error

    def submit(self, frame: FrameState, wanted: dict[str, bool]) -> None:
        """Hand over one frame: `wanted[camera]` says whether to render it (False: only its noise advances).

        Raises:
            the render thread's error (a failed render stops the thread; the images would stop silently).
        """
        t = time.monotonic()
        while True:
            if self.error is not None:
                raise self.error
            try:
                self._queue.put((frame, dict(wanted)), timeout=0.5)
                break
            except queue.Full:
                if not self._thread.is_alive():
                    raise RuntimeError("the render thread stopped") from self.error
        self.waited += time.monotonic() - t

    def _run(self) -> None:
        import mujoco

        try:
            renderer = self.sim.new_renderer()
            data = mujoco.MjData(self.sim.model)
        except BaseException as exc:  # noqa: BLE001 - reported to the constructor's caller
            self.error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            while True:
                item = self._queue.get()
                if item is None:
                    return
                frame, wanted = item
                for camera, want in wanted.items():
                    if want:
                        rgb, depth = self.sim.render_frame_on(renderer, data, camera, frame)
                        self._deliver(frame.time, camera, rgb, depth)
                    else:
                        self.sim.skip_render(camera)
                        self._deliver(frame.time, camera, None, None)
                self.frames += 1
        except BaseException as exc:  # noqa: BLE001 - kept for submit() to raise in the stepping loop
            self.error = exc
        finally:
            renderer.close()

    def close(self, timeout: float = 5.0) -> None:
        """Render what was handed over, then stop the thread."""
        if self._thread.is_alive():
            try:
                self._queue.put(None, timeout=timeout)
            except queue.Full:
                return
            self._thread.join(timeout)
