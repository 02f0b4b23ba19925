"""The simulator's camera worker (hexa.sim.camera_worker): kept frames rendered on its own thread while the physics
steps on are the images `render` gives at those instants, noise included; the physics is untouched; close() renders
what was handed over; a failure on the worker's thread is raised in the caller's."""
from __future__ import annotations

import os
import threading

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("mujoco")

from hexa.robots.hexa_description import load_hexa  # noqa: E402
from hexa.sim import Simulator  # noqa: E402
from hexa.sim.camera import RenderError  # noqa: E402
from hexa.sim.camera_worker import CameraFrame, CameraWorker, CameraWorkerError  # noqa: E402
from hexa.sim.simulator import FrameState  # noqa: E402

CAMS = ("cam_top", "cam_side")


@pytest.fixture(scope="module")
def desc():
    return load_hexa()


@pytest.fixture(scope="module")
def contact():
    from hexa.eval.campaign import draw_contact

    return draw_contact(2, 8, "paper")                    # a plate push: the object is in view at its peak


def _sim(desc, contact, cameras=True):
    try:
        return Simulator(desc, seed=3, scenario=contact, cameras=cameras)
    except RenderError as exc:
        pytest.skip(f"no headless GL: {exc}")


def test_the_workers_frames_are_those_render_gives_at_each_instant_with_the_same_noise(desc, contact):
    """Frames handed over one camera period apart (the worker falls behind: the caller waits, none is skipped) are
    delivered in order and equal, noise included, what `render` gives at each instant in a run of the same seed; a
    camera nobody wants is not rendered and its noise advances as `skip_render`'s does."""
    instants = [contact.peak_time + k / 30.0 for k in range(-2, 3)]
    wanted = [set(CAMS), {"cam_top"}, set(CAMS), {"cam_side"}, set(CAMS)]
    got: list[CameraFrame] = []
    with _sim(desc, contact) as sim, _sim(desc, contact) as inline:
        with CameraWorker(sim, got.append) as worker:
            for t, want in zip(instants, wanted):
                sim.run_until(t)
                worker.submit(sim.frame_state(), want)
            sim.run_until(instants[-1] + 0.2)             # the physics moves on while the frames render
        assert worker.frames == len(instants)
        assert [f.camera for f in got] == list(CAMS) * len(instants)
        for k, (t, want) in enumerate(zip(instants, wanted)):
            inline.run_until(t)
            for j, cam in enumerate(CAMS):
                frame = got[2 * k + j]
                assert frame.time == inline.time
                if cam not in want:
                    inline.skip_render(cam)
                    assert frame.rgb is None and frame.depth is None
                    continue
                rgb, depth = inline.render(cam)
                np.testing.assert_array_equal(frame.rgb, rgb)
                np.testing.assert_array_equal(frame.depth, depth)
        # the images do change between the instants (the robot and the object move), and the noise with each frame
        assert np.abs(got[0].depth.astype(int) - got[8].depth.astype(int)).max() > 20
        assert not np.array_equal(got[0].rgb, got[4].rgb)


def test_the_physics_stepping_beside_the_worker_is_that_of_a_run_without_cameras(desc, contact):
    with _sim(desc, contact) as sim, _sim(desc, contact, cameras=False) as plain:
        with CameraWorker(sim, lambda frame: None) as worker:
            end = contact.peak_time + 0.3
            while sim.time < end:
                sim.step(33)
                worker.submit(sim.frame_state(), CAMS)
        plain.run_until(sim.time)
        assert worker.frames > 10
        assert sim.time == plain.time
        a, b = sim.truth_log(), plain.truth_log()
        for key in ("time", "force", "point", "link", "zeta", "tau", "plate_pose"):
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        assert np.abs(a["force"]).max() > 1.0             # the push did happen in the compared span


def test_close_renders_the_frames_handed_over_before_the_thread_ends(desc, contact):
    """close() while one frame is delivered and another waits: both are delivered, in order, then the worker ends
    (a later submit is refused)."""
    entered, gate = threading.Event(), threading.Event()
    got: list[CameraFrame] = []

    def deliver(frame: CameraFrame) -> None:
        entered.set()
        gate.wait()
        got.append(frame)

    with _sim(desc, contact) as sim:
        worker = CameraWorker(sim, deliver)
        sim.step(10)
        first = sim.frame_state()
        worker.submit(first, CAMS)
        entered.wait()                                    # the first frame is taken; the second one waits
        sim.step(33)
        second = sim.frame_state()
        worker.submit(second, {"cam_side"})
        closer = threading.Thread(target=worker.close)
        closer.start()
        closer.join(0.2)
        assert closer.is_alive()                          # close waits for the frames handed over
        gate.set()
        closer.join()
        assert [(f.camera, f.time, f.rgb is not None) for f in got] == [
            ("cam_top", first.time, True), ("cam_side", first.time, True),
            ("cam_top", second.time, False), ("cam_side", second.time, True)]
        with pytest.raises(CameraWorkerError, match="closed"):
            worker.submit(sim.frame_state(), CAMS)
        worker.close()                                    # closing again does nothing


def test_a_failure_on_the_workers_thread_is_raised_in_the_callers(desc, contact):
    with _sim(desc, contact) as sim:
        # a delivery that fails: the next flush raises it, chained; close then does not raise it again
        def deliver(frame: CameraFrame) -> None:
            raise OSError("publisher gone")

        worker = CameraWorker(sim, deliver)
        worker.submit(sim.frame_state(), CAMS)
        with pytest.raises(CameraWorkerError) as err:
            worker.flush()
        assert isinstance(err.value.__cause__, OSError)
        with pytest.raises(CameraWorkerError, match="failed"):  # and every later use
            worker.submit(sim.frame_state(), CAMS)
        worker.close()

        # a render that fails (a kept instant of another model): raised by close when nothing raised it before
        worker = CameraWorker(sim, lambda frame: None)
        bad = FrameState(sim.time, np.zeros(3), np.zeros((1, 3)), np.zeros((1, 4)))
        worker.submit(bad, CAMS)
        with pytest.raises(CameraWorkerError) as err:
            worker.close()
        assert isinstance(err.value.__cause__, ValueError)

        with CameraWorker(sim, lambda frame: None) as worker, pytest.raises(ValueError, match="cam_front"):
            worker.submit(sim.frame_state(), {"cam_front"})
