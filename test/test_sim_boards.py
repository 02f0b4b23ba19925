"""Virtual Arduino boards of the simulator: the Mega's stream parses with the protocol and carries τ/K_t; the Uno
drives the simulated servos."""
from __future__ import annotations

import os
import select
import time

import numpy as np
import pytest

pytest.importorskip("mujoco")

from hexa.protocol import frames as fr  # noqa: E402
from hexa.robots.hexa_description import load_hexa  # noqa: E402
from hexa.sim import Simulator  # noqa: E402
from hexa.sim.boards import VirtualBoards  # noqa: E402


def _open(port: str) -> int:
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    import tty

    tty.setraw(fd)
    return fd


def _read_frames(fd: int, parser: fr.FrameParser, timeout: float) -> list[fr.Frame]:
    out: list[fr.Frame] = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        r, _, _ = select.select([fd], [], [], 0.01)
        if r:
            try:
                out += parser.feed(os.read(fd, 4096))
            except BlockingIOError:
                pass
    return out


@pytest.fixture
def rig(tmp_path):
    desc = load_hexa()
    sim = Simulator(desc, cameras=False, seed=3)
    boards = VirtualBoards(sim, link_dir=tmp_path).start()
    try:
        yield sim, boards
    finally:
        boards.stop()


def test_mega_stream_parses_and_its_currents_match_tau_over_kt_within_the_noise_model(rig):
    sim, boards = rig
    assert os.path.realpath(boards.mega.port).startswith("/dev/pts/")
    fd = _open(boards.mega.port)
    parser = fr.FrameParser()
    try:
        os.write(fd, fr.encode_frame(fr.START_STREAM, 1, fr.pack_start_stream(1000)))
        frames = _read_frames(fd, parser, 0.2)
        assert any(f.type == fr.ACK for f in frames)
        samples = []
        sim.apply_external_force("plate", 0, sim.state().pose[:3], [0.0, 0.0, -3.0])  # make τ change
        for _ in range(30):                       # 0.3 s of sim time, 10 ms per round
            sim.step(10)
            samples += [fr.unpack_sample(f.payload) for f in _read_frames(fd, parser, 0.01) if f.type == fr.SAMPLE]
        samples += [fr.unpack_sample(f.payload) for f in _read_frames(fd, parser, 0.1) if f.type == fr.SAMPLE]
    finally:
        os.close(fd)
    assert parser.stats.crc_errors == 0
    assert len(samples) >= 200                    # ~1 kHz of sim time
    seqs = [s.sequence for s in samples]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    t = np.array([s.board_time_us for s in samples]) * 1e-6
    assert np.allclose(np.diff(t), 1e-3, atol=2e-6)   # board time follows sim time
    counts = np.array([s.counts for s in samples])
    amps = boards.sensor.current_from_counts(counts)
    expected = np.array([boards.currents_at(boards.sim_time_of(ti)) for ti in t])
    err = amps - expected
    lsb = boards.sensor.amps_per_count
    sigma = sim.config.current_noise_counts * lsb
    assert np.abs(err).max() < 0.5 * lsb + 5 * sigma
    assert abs(err.mean()) < 0.6 * lsb
    assert np.std(err) == pytest.approx(np.sqrt(sigma ** 2 + lsb ** 2 / 12), rel=0.35)
    assert np.ptp(expected[:, 0]) > 0.05          # the torques really changed during the stream


def test_uno_targets_drive_the_simulated_servos_through_the_driver_calibration(rig):
    sim, boards = rig
    zeta0 = sim.state().zeta
    goal = zeta0 + np.array([0.05, -0.05, 0.03, -0.03, 0.02, -0.02])
    pulses = [s.pulse_from_angle(z) for s, z in zip(boards.servos, goal)]
    fd = _open(boards.uno.port)
    try:
        os.write(fd, fr.encode_frame(fr.SET_TARGETS, 1, fr.pack_targets(pulses)))
        deadline = time.monotonic() + 2.0
        while boards.uno.commands == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        os.close(fd)
    assert boards.uno.commands == 1
    commanded = boards.angles_from_pulses(tuple(pulses))
    np.testing.assert_allclose(commanded, goal, atol=1.0 / 636.0)   # one microsecond of pulse resolution
    sim.step(500)
    np.testing.assert_allclose(sim.state().zeta, commanded, atol=0.02)


def test_uno_reports_the_simulators_pulse_frames_and_none_without_them(tmp_path):
    """With the pulse frame simulated, the virtual Uno's LATCH reports are the simulator's frames: 20 ms apart on the
    board clock, each servo's SEQ the SET_TARGETS whose target the simulated servo took. Without the frame the Uno is
    firmware without the report: SET_LATCH_REPORT is answered UNKNOWN_TYPE."""
    desc = load_hexa()
    for frame in (0.02, 0.0):
        sim = Simulator(desc, cameras=False, seed=3, servo_frame_period=frame)
        zeta0 = sim.state().zeta
        with VirtualBoards(sim, link_dir=tmp_path / str(frame)) as boards:
            fd = _open(boards.uno.port)
            parser = fr.FrameParser()
            try:
                os.write(fd, fr.encode_frame(fr.SET_LATCH_REPORT, 1, fr.pack_latch_report(True)))
                reply = [f for f in _read_frames(fd, parser, 0.3) if f.type in (fr.ACK, fr.ERROR)]
                if frame == 0.0:
                    assert reply and reply[0].type == fr.ERROR
                    assert fr.unpack_error(reply[0].payload).code == fr.ERR_UNKNOWN_TYPE
                    continue
                assert reply and reply[0].type == fr.ACK
                latches, taken = [], []
                for k in range(40):                      # a command every 5 ms of sim time, SEQ 10..49
                    z = zeta0 + 0.001 * k
                    pulses = [s.pulse_from_angle(v) for s, v in zip(boards.servos, z)]
                    os.write(fd, fr.encode_frame(fr.SET_TARGETS, 10 + k, fr.pack_targets(pulses)))
                    deadline = time.monotonic() + 1.0
                    while boards.uno.commands < k + 1 and time.monotonic() < deadline:
                        time.sleep(0.001)
                    for _ in range(5):
                        sim.step(1)
                        taken.append((sim.time, sim._setpoint_tags.copy()))
                    latches += [fr.unpack_latch(f.payload) for f in _read_frames(fd, parser, 0.005)
                                if f.type == fr.LATCH]
                latches += [fr.unpack_latch(f.payload) for f in _read_frames(fd, parser, 0.2) if f.type == fr.LATCH]
            finally:
                os.close(fd)
        assert len(latches) >= 8
        starts = np.array([la.frame_start_us for la in latches], dtype=float)
        np.testing.assert_allclose(np.diff(starts), 20_000, atol=2)
        t_tag = np.array([t for t, _ in taken])
        for la in latches:
            assert la.mask == 0x3F and la.offsets_us == (0, 1500, 3000, 4500, 6000, 7500)
            # the tags the simulated servos held right after the frame's last pulse
            t_end = boards.uno.clock_zero + (la.frame_start_us + 7500 + 1500) * 1e-6
            held = taken[int(np.searchsorted(t_tag, t_end + 0.0011))][1]   # a step (1 ms) after it
            assert tuple(int(v) & 0xFF for v in held) == la.seqs, (la, held)
