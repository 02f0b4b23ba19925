"""Robustness of the frame parser and the link: noise, truncation, bad CRC, wrong lengths, bursts (>= 1e5 frames)."""
from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from hexa.protocol import frames as fr
from hexa.protocol.emulator import MegaEmulator
from hexa.protocol.link import CurrentLink

good_frame = st.builds(lambda t, s, p: fr.encode_frame(t, s, p), st.integers(0, 255), st.integers(0, 255),
                       st.binary(max_size=fr.MAX_PAYLOAD))


@st.composite
def damaged(draw):
    """A damaged piece of stream: noise, a truncated frame, a frame with flipped bits, or an impossible LEN."""
    kind = draw(st.sampled_from(["noise", "truncated", "flipped", "bad_len", "sync_burst"]))
    f = draw(good_frame)
    if kind == "noise":
        return draw(st.binary(min_size=1, max_size=100))
    if kind == "truncated":
        return f[:draw(st.integers(1, len(f) - 1))]
    if kind == "flipped":
        b = bytearray(f)
        for _ in range(draw(st.integers(1, 3))):
            i = draw(st.integers(2, len(b) - 1))
            b[i] ^= 1 << draw(st.integers(0, 7))
        return bytes(b)
    if kind == "bad_len":
        return bytes((fr.SYNC1, fr.SYNC2, draw(st.integers(fr.MAX_PAYLOAD + 1, 255)))) + f[3:]
    return fr.SYNC * draw(st.integers(1, 40))


stream = st.lists(st.one_of(good_frame.map(lambda b: ("good", b)), damaged().map(lambda b: ("bad", b))),
                  max_size=40)


@given(stream, st.lists(st.integers(1, 64), min_size=1, max_size=8))
@settings(max_examples=400, deadline=None)
def test_parser_never_crashes_never_invents_frames_and_recovers_good_ones(pieces, chunks):
    wire = b"".join(b for _, b in pieces) + fr.encode_frame(0x7F, 0, bytes(fr.MAX_PAYLOAD))  # flush a long LEN
    parser = fr.FrameParser()
    out: list[fr.Frame] = []
    i = k = 0
    while i < len(wire):
        n = chunks[k % len(chunks)]
        out += parser.feed(wire[i:i + n])
        i += n
        k += 1
    encoded = [fr.encode_frame(f.type, f.seq, f.payload) for f in out]
    for e in encoded:
        assert e in wire  # every accepted frame was on the wire with its valid CRC: none fabricated
    goods = [b for kind, b in pieces if kind == "good"]
    # each good frame is recovered unless a (2^-16-rare) chance-valid frame inside damage swallowed its bytes
    false_accepts = len([e for e in encoded[:-1] if e not in goods])
    if false_accepts == 0:
        recovered = encoded[:-1]
        it = iter(recovered)
        assert all(any(g == r for r in it) for g in goods), "a good frame was lost"
    assert encoded[-1] == fr.encode_frame(0x7F, 0, bytes(fr.MAX_PAYLOAD))


def _damaged_stream(seed: int, n_frames: int, p_damage: float) -> tuple[bytes, list[bytes]]:
    """`n_frames` SAMPLE frames, a fraction `p_damage` of them truncated, bit-flipped, wrapped in noise bursts or
    replaced by an impossible LEN; returns the wire bytes and the intact frames on it."""
    rng = np.random.default_rng(seed)
    pieces, good = [], []
    counts = rng.integers(0, 1024, (n_frames, 6))
    kinds = rng.random(n_frames)
    for k in range(n_frames):
        f = fr.encode_frame(fr.SAMPLE, k & 0xFF, fr.pack_sample(k, 1000 * k, counts[k]))
        r = kinds[k] / max(p_damage, 1e-12)
        if r >= 1.0:                                   # intact
            pieces.append(f)
            good.append(f)
        elif r < 0.25:
            pieces.append(f[:rng.integers(1, len(f))])                          # truncated
        elif r < 0.5:
            b = bytearray(f)
            b[rng.integers(5, len(b))] ^= 1 << int(rng.integers(0, 8))         # one bit flipped after LEN
            pieces.append(bytes(b))
        elif r < 0.75:
            noise = rng.integers(0, 256, rng.integers(1, 80)).astype(np.uint8).tobytes()
            pieces.append(noise + f)                                           # noise burst, then the frame
            good.append(f)
        else:
            pieces.append(bytes((fr.SYNC1, fr.SYNC2, int(rng.integers(65, 256)))))  # impossible LEN
    return b"".join(pieces), good


@pytest.mark.slow
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.6), st.integers(1, 600))
@settings(max_examples=50, deadline=None, derandomize=True)
def test_parser_fuzz_over_1e5_frames_resyncs_with_zero_crashes(seed, p_damage, max_chunk):
    """50 examples x 2500 frames = 1.25e5 frames of damaged streams in random chunk sizes."""
    wire, good = _damaged_stream(seed, 2500, p_damage)
    wire += fr.encode_frame(0x7F, 0, bytes(fr.MAX_PAYLOAD))   # resolves a pending long LEN at the end
    rng = np.random.default_rng(seed ^ 0x5A5A)
    parser = fr.FrameParser()
    out: list[fr.Frame] = []
    pos = 0
    while pos < len(wire):
        n = int(rng.integers(1, max_chunk + 1))
        out += parser.feed(wire[pos:pos + n])
        pos += n
    got = [fr.encode_frame(f.type, f.seq, f.payload) for f in out[:-1]]
    good_set = set(good)
    strangers = [g for g in got if g not in good_set]
    for g in strangers:
        assert g in wire      # a chance-valid frame inside damage (p ~ 2^-16), never a fabricated one
    recovered = len(set(got) & good_set)
    assert recovered >= len(good_set) - 3 * len(strangers)   # each can swallow at most 71 bytes = 3 frames
    assert len(strangers) <= 3
    if p_damage > 0.2:
        assert parser.stats.crc_errors + parser.stats.bad_length > 0 and parser.stats.resyncs > 0


def test_single_to_triple_bit_errors_after_len_are_never_accepted():
    rng = np.random.default_rng(99)
    parser = fr.FrameParser()
    accepted = 0
    for k in range(20_000):
        f = bytearray(fr.encode_frame(fr.SET_TARGETS, k & 0xFF, fr.pack_targets(rng.integers(500, 2500, 6))))
        positions = rng.choice(np.arange(3 * 8, len(f) * 8), size=int(rng.integers(1, 4)), replace=False)
        for bit in positions:
            f[bit // 8] ^= 1 << (bit % 8)
        accepted += len(parser.feed(bytes(f)))
        parser.reset()
    assert accepted == 0   # CRC-16/CCITT detects every 1-3 bit error in frames this short (HD 4)


def test_link_keeps_streaming_correct_samples_through_noise_bursts(tmp_path):
    rng = np.random.default_rng(5)
    amps = [0.1, 0.2, 0.3, -0.1, -0.2, -0.3]
    expected = tuple(int(c) for c in MegaEmulator(units="amps").sensor.counts_from_current(amps))
    n_bursts = [0]

    def noisy(data: bytes) -> bytes:
        if rng.random() < 0.1:   # a burst of line noise before 10 % of the frames
            n_bursts[0] += 1
            return rng.integers(0, 256, int(rng.integers(1, 60))).astype(np.uint8).tobytes() + data
        return data

    samples = []
    with MegaEmulator(current_source=lambda t: amps, link=tmp_path / "mega", tx_filter=noisy) as mega:
        with CurrentLink(mega.port, rate_hz=1000, on_sample=lambda s, t, g: samples.append(s)) as link:
            assert link.wait_connected(3.0)
            t_end = time.monotonic() + 5.0
            while len(samples) < 1000 and time.monotonic() < t_end:
                time.sleep(0.01)
            assert len(samples) >= 1000
            assert all(s.counts == expected for s in samples)   # nothing wrong got through
            assert n_bursts[0] > 50 and link.stats.resyncs > 0
            assert link.sample_gaps <= link.stats.crc_errors + link.stats.bad_length  # a gap only where damaged


def test_servo_link_parses_latch_reports_through_noise_bursts(tmp_path):
    from hexa.protocol.emulator import UnoEmulator
    from hexa.protocol.link import ServoLink

    rng = np.random.default_rng(7)
    n_bursts = [0]

    def noisy(data: bytes) -> bytes:
        if rng.random() < 0.3:   # garbage between 30 % of the board's frames
            n_bursts[0] += 1
            return rng.integers(0, 256, int(rng.integers(1, 60))).astype(np.uint8).tobytes() + data
        return data

    latches: list[fr.Latch] = []
    with UnoEmulator(link=tmp_path / "uno", tx_filter=noisy) as uno:
        with ServoLink(uno.port, on_latch=lambda x, t: latches.append(x)) as link:
            assert link.wait_connected(3.0), link.stats.last_error
            assert link.set_targets([1234] * 6)
            seq = link.last_targets_seq
            t_end = time.monotonic() + 5.0
            while len(latches) < 40 and time.monotonic() < t_end:
                time.sleep(0.01)
            assert len(latches) >= 40 and n_bursts[0] > 10
            if latches[0].mask != 0x3F:   # the command arrived mid-frame: channels before it were still off
                del latches[0]
            # nothing wrong got through: every LATCH is a whole frame of the one command, on the 20 ms grid
            assert all(x.seqs == (seq,) * 6 and x.mask == 0x3F and x.frame_start_us % 20000 == 0 for x in latches)
            assert all(x.offsets_us == tuple(1234 * i for i in range(6)) for x in latches)
            missing = sum((b.frame_start_us - a.frame_start_us) // 20000 - 1 for a, b in zip(latches, latches[1:]))
            assert missing <= link.stats.crc_errors + link.stats.bad_length   # a LATCH lost only where damaged
            assert link.stats.decode_errors == 0
