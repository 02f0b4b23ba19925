"""The simulator's cameras rendered on a thread of their own, beside the stepping (CameraWorker).

Rendering both cameras costs ~15 ms of CPU per camera and frame (GL render, then the noise and the depth
conversion), while a 1 ms physics step costs ~20 µs: rendered inline at every camera instant, the frames take most of
the stepping loop's wall time and a paced run falls below half of real time. MuJoCo's GL calls and numpy's large array
operations release the GIL, so a render on another thread leaves the stepping thread running.

    worker = CameraWorker(sim, deliver)               # deliver(CameraFrame) is called on the worker's thread
    ...
    worker.submit(sim.frame_state(), wanted={"cam_top"})   # at each camera instant, from the stepping thread
    ...
    worker.close()                                    # renders what was handed over, frees its GL context

The stepping thread keeps the instant (`Simulator.frame_state`: joints and mocap placements, the physics' data
untouched) and hands it over; the worker renders it with its own RGBDRenderer (its GL context made and freed on its
thread) and its own MjData, never holding the simulator's lock, so `Simulator.step` runs meanwhile. The frames are
those of `Simulator.render` at that instant, noise included: the worker draws each camera's noise from the
simulator's NoiseBank in the order `render` does (per frame the cameras in CAMERA_NAMES order, per camera colour then
depth), and advances a camera nobody wants as `skip_render` does. While a worker is open it owns the simulator's
image noise: the simulator's own `render`, `render_frame` and `skip_render` would draw from the same banks.

Frames are rendered and delivered strictly in order, and none is skipped: at most one frame waits while one is
rendered; a `submit` that finds one waiting blocks until the worker takes it. The stepping loop then loses that wall
time (hexa.sim.pacing.Pacer drops it), exactly as it lost the inline render before, so for a given seed the frames
and their times are the same at any speed of the machine. An error on the worker's thread (a render, a delivery) is
raised as CameraWorkerError in the caller's thread by every later `submit` and `flush`, and by `close` unless one of
them raised it already.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from hexa.sim.camera import RGBDRenderer
from hexa.sim.config import CAMERA_NAMES

import mujoco  # noqa: E402  (after hexa.sim.camera set MUJOCO_GL)

if TYPE_CHECKING:
    from hexa.sim.simulator import FrameState, Simulator


class CameraWorkerError(RuntimeError):
    """The camera worker's thread failed (its error is the `__cause__`), or the worker was used after `close`."""


@dataclass(frozen=True)
class CameraFrame:
    """One camera's images of one kept instant: camera name, sim time (s), colour (H,W,3 uint8) and aligned depth
    (H,W uint16 mm, 0 = invalid) as `Simulator.render` gives them; rgb and depth are None when nobody wanted this
    camera at that instant (not rendered; its noise advanced)."""

    camera: str
    time: float
    rgb: np.ndarray | None
    depth: np.ndarray | None


class CameraWorker:
    """Renders kept frames (`Simulator.frame_state`) of `sim`'s cameras on its own thread and passes each camera's
    images to `deliver` (see module docstring).

    Args:
        sim: the simulator whose model, cameras and image noise are rendered.
        deliver: called on the worker's thread with each CameraFrame, every camera of a frame in CAMERA_NAMES order,
            frames in the order they were submitted; an exception it raises stops the worker (CameraWorkerError in
            the caller).
        noise: apply the cameras' image noise (False: the noise-free images, the banks untouched).
        name: the thread's name.

    Raises:
        RenderError: the worker's GL context cannot be created (raised by the constructor).
    """

    def __init__(self, sim: Simulator, deliver: Callable[[CameraFrame], None], noise: bool = True,
                 name: str = "hexa-sim-cameras") -> None:
        self._sim, self._deliver, self._noise = sim, deliver, bool(noise)
        self._cond = threading.Condition()
        self._waiting: tuple[FrameState, frozenset[str]] | None = None   # handed over, not yet taken
        self._busy = False               # a frame is being rendered or delivered
        self._closing = False
        self._error: BaseException | None = None
        self._reported = False           # the error was raised in the caller once
        self._started = threading.Event()
        self.frames = 0                  # frames rendered and delivered
        self.waited = 0.0                # wall seconds `submit` blocked for the worker
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()
        self._started.wait()
        if self._error is not None:      # no GL context: nothing to free, the thread has ended
            self._thread.join()
            self._reported = True
            raise self._error

    # ------------------------------------------------------------------ the caller's side
    def submit(self, frame: FrameState, wanted: Collection[str]) -> None:
        """Hand over the kept instant `frame`, rendering the cameras in `wanted` (the others' noise advances).
        Blocks while a frame handed over earlier still waits to be taken.

        Raises:
            ValueError: an unknown camera in `wanted`; CameraWorkerError: the worker failed or is closed.
        """
        want = frozenset(wanted)
        if not want <= set(CAMERA_NAMES):
            raise ValueError(f"unknown cameras {sorted(want - set(CAMERA_NAMES))}; cameras: {list(CAMERA_NAMES)}")
        with self._cond:
            if self._waiting is not None and self._error is None:
                t0 = time.monotonic()
                while self._waiting is not None and self._error is None:
                    self._cond.wait()
                self.waited += time.monotonic() - t0
            self._raise_error()
            if self._closing:
                raise CameraWorkerError("the camera worker is closed")
            self._waiting = (frame, want)
            self._cond.notify_all()

    def flush(self) -> None:
        """Wait until every frame handed over is delivered.

        Raises:
            CameraWorkerError: the worker failed.
        """
        with self._cond:
            while (self._waiting is not None or self._busy) and self._error is None:
                self._cond.wait()
            self._raise_error()

    def close(self) -> None:
        """Render and deliver the frames already handed over, then end the thread (its GL context freed on it).
        Closing again does nothing.

        Raises:
            CameraWorkerError: the worker failed and no earlier call has raised it.
        """
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        self._thread.join()
        with self._cond:
            self._raise_error(again=False)

    def __enter__(self) -> CameraWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _raise_error(self, again: bool = True) -> None:
        """Raise the worker's error in the caller; `again` False: only if no call has raised it yet. Call with the
        condition held."""
        if self._error is not None and (again or not self._reported):
            self._reported = True
            raise CameraWorkerError(f"the camera worker failed: {self._error!r}") from self._error

    # ------------------------------------------------------------------ the worker's thread
    def _run(self) -> None:
        try:
            data = mujoco.MjData(self._sim.model)
            renderer = RGBDRenderer(self._sim.model, *self._sim.render_size)   # its GL context belongs to this thread
        except BaseException as exc:  # noqa: BLE001 - raised by the constructor in the caller's thread
            self._error = exc
            self._started.set()
            return
        self._started.set()
        try:
            while True:
                with self._cond:
                    while self._waiting is None and not self._closing:
                        self._cond.wait()
                    if self._waiting is None:
                        return
                    frame, wanted = self._waiting
                    self._waiting, self._busy = None, True
                    self._cond.notify_all()
                self._render(frame, wanted, renderer, data)
                with self._cond:
                    self._busy = False
                    self.frames += 1
                    self._cond.notify_all()
        except BaseException as exc:  # noqa: BLE001 - every failure reaches the caller (CameraWorkerError)
            with self._cond:
                self._error, self._waiting, self._busy = exc, None, False
                self._cond.notify_all()
        finally:
            renderer.close()

    def _render(self, frame: FrameState, wanted: frozenset[str], renderer: RGBDRenderer, data: Any) -> None:
        """Each camera of `frame` in order: render it (or advance its noise) and deliver it."""
        sim = self._sim
        for camera in CAMERA_NAMES:
            if camera in wanted:
                rgb, depth = sim.render_frame(camera, frame, noise=self._noise, renderer=renderer, data=data)
                self._deliver(CameraFrame(camera, frame.time, rgb, depth))
            else:
                if self._noise:
                    sim.skip_render(camera)
                self._deliver(CameraFrame(camera, frame.time, None, None))
