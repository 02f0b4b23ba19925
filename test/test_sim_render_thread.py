"""Frames rendered on the render thread are those the stepping loop would render itself: the same colour and depth
(noise included) for the same frame states, in order, a skipped camera advancing its noise as in the loop; the loop
is blocked, never a frame dropped, when the thread falls behind; a render error reaches the loop."""
from __future__ import annotations

import threading

import numpy as np
import pytest

pytest.importorskip("mujoco")

from hexa.sim import Simulator  # noqa: E402
from hexa.sim.render_thread import RenderThread  # noqa: E402


def _frames(sim: Simulator, n: int) -> list:
    out = []
    for _ in range(n):
        sim.run_until(sim.time + 1 / 30)
        out.append(sim.frame_state())
    return out


def test_the_thread_renders_every_frame_as_the_loop_would_with_the_same_noise():
    wanted = [{"cam_top": True, "cam_side": True}, {"cam_top": True, "cam_side": False},
              {"cam_top": True, "cam_side": True}]
    loop = Simulator(scenario="plate", cameras=True, seed=3)
    expected = []
    for frame, want in zip(_frames(loop, 3), wanted):
        for cam, w in want.items():
            if w:
                expected.append((frame.time, cam, *loop.render_frame(cam, frame)))
            else:
                loop.skip_render(cam)
                expected.append((frame.time, cam, None, None))
    loop.close()

    sim = Simulator(scenario="plate", cameras=True, seed=3)
    got = []
    worker = RenderThread(sim, lambda t, cam, rgb, depth: got.append((t, cam, rgb, depth)))
    for frame, want in zip(_frames(sim, 3), wanted):
        worker.submit(frame, want)
    worker.close()
    sim.close()
    assert worker.frames == 3 and len(got) == len(expected) == 6
    for (t, cam, rgb, depth), (te, came, rgbe, depthe) in zip(got, expected):
        assert (t, cam) == (te, came)
        if rgbe is None:
            assert rgb is None and depth is None
        else:
            assert rgb.dtype == np.uint8 and depth.dtype == np.uint16
            assert np.array_equal(rgb, rgbe) and np.array_equal(depth, depthe)


def test_a_busy_thread_blocks_the_loop_and_drops_nothing_and_its_error_reaches_the_loop():
    sim = Simulator(scenario="plate", cameras=True)
    gate, got = threading.Event(), []

    def slow(t, cam, rgb, depth):
        gate.wait(10.0)
        got.append((t, cam))

    worker = RenderThread(sim, slow, max_pending=1)
    frames = _frames(sim, 3)
    worker.submit(frames[0], {"cam_top": False})      # taken by the thread, which then waits on the gate
    worker.submit(frames[1], {"cam_top": False})      # pending
    third = threading.Thread(target=worker.submit, args=(frames[2], {"cam_top": False}))
    third.start()
    third.join(0.3)
    assert third.is_alive()                           # no room: the loop waits
    gate.set()
    third.join(5.0)
    worker.close()
    assert [t for t, _ in got] == [f.time for f in frames] and worker.waited > 0.2

    def broken(*_a):
        raise RuntimeError("publisher gone")

    failing = RenderThread(sim, broken)
    failing.submit(frames[0], {"cam_top": False})
    with pytest.raises(RuntimeError, match="publisher gone"):
        for f in frames * 20:                         # the error surfaces on a later hand-over
            failing.submit(f, {"cam_top": False})
    failing.close()
    sim.close()
