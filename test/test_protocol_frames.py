"""Frame encoding, CRC-16 and the streaming parser (hexa.protocol.frames)."""
from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

from hexa.protocol import frames as fr


def test_crc16_is_ccitt_false_check_value():
    assert fr.crc16(b"123456789") == 0x29B1


def test_encode_frame_layout_and_crc_little_endian():
    data = fr.encode_frame(fr.PING, 7, fr.pack_ping(0x01020304))
    assert data[:2] == b"\xa5\x5a"
    assert data[2] == 4 and data[3] == fr.PING and data[4] == 7
    assert data[5:9] == bytes((4, 3, 2, 1))
    c = fr.crc16(data[2:-2])
    assert data[-2] == c & 0xFF and data[-1] == c >> 8


def test_encode_rejects_oversize_payload_naming_size():
    with pytest.raises(fr.ProtocolError, match="65 bytes"):
        fr.encode_frame(fr.PING, 0, bytes(65))


frame_st = st.tuples(st.integers(0, 255), st.integers(0, 255), st.binary(max_size=fr.MAX_PAYLOAD))


@given(st.lists(frame_st, max_size=20), st.lists(st.integers(1, 40), min_size=1, max_size=10))
@settings(max_examples=200, deadline=None)
def test_parser_round_trip_any_chunking(frames, chunks):
    wire = b"".join(fr.encode_frame(t, s, p) for t, s, p in frames)
    parser = fr.FrameParser()
    out = []
    i = k = 0
    while i < len(wire):
        n = chunks[k % len(chunks)]
        out += parser.feed(wire[i:i + n])
        i += n
        k += 1
    assert [(f.type, f.seq, f.payload) for f in out] == frames
    assert parser.stats.crc_errors == 0 and parser.stats.discarded == 0


def test_parser_rejects_single_bit_flip_and_recovers_next_frame():
    good = fr.encode_frame(fr.SAMPLE, 1, fr.pack_sample(5, 6, [1, 2, 3, 4, 5, 6]))
    for bit in range(8 * 2, 8 * len(good)):  # every bit after the sync pair
        bad = bytearray(good)
        bad[bit // 8] ^= 1 << (bit % 8)
        parser = fr.FrameParser()
        # a corrupted LEN may claim up to MAX_FRAME bytes: the parser resolves it once that many have arrived
        out = parser.feed(bytes(bad) + good + good)
        assert out == [fr.Frame(fr.SAMPLE, 1, good[5:-2])] * 2, bit
        assert parser.stats.crc_errors + parser.stats.bad_length >= 1


def test_parser_counts_impossible_length_and_resyncs():
    good = fr.encode_frame(fr.PING, 3, fr.pack_ping(9))
    parser = fr.FrameParser()
    out = parser.feed(b"\xa5\x5a\xff\x01\x02" + b"noise" + good)
    assert out == [fr.Frame(fr.PING, 3, fr.pack_ping(9))]
    assert parser.stats.bad_length == 1 and parser.stats.resyncs >= 1


def test_parser_truncated_frame_then_good_frame():
    good = fr.encode_frame(fr.HELLO, 1, fr.pack_hello())
    parser = fr.FrameParser()
    out = parser.feed(good[:-3]) + parser.feed(good)
    assert out == [fr.Frame(fr.HELLO, 1, b"\x01")]


def test_parser_keeps_trailing_sync_byte_across_chunks():
    good = fr.encode_frame(fr.GET_STATUS, 2)
    parser = fr.FrameParser()
    assert parser.feed(b"xx" + good[:1]) == []
    assert parser.feed(good[1:]) == [fr.Frame(fr.GET_STATUS, 2, b"")]


@given(st.lists(st.integers(0, 0xFFFF), min_size=6, max_size=6), st.integers(0, 2**32 - 1),
       st.integers(0, 2**32 - 1))
def test_sample_payload_round_trip(counts, seq, t):
    s = fr.unpack_sample(fr.pack_sample(seq, t, counts))
    assert s == fr.Sample(seq, t, tuple(counts))


def test_status_round_trips():
    s = fr.ServoStatus(5, 1, 2, 3, 4, (500, 600, 700, 800, 900, 1000), 17)
    assert fr.unpack_servo_status(fr.pack_servo_status(s)) == s
    c = fr.CurrentStatus(1, 2, 3, 4, 5, 1000, 6, 7)
    assert fr.unpack_current_status(fr.pack_current_status(c)) == c


def test_unpack_wrong_length_names_type():
    with pytest.raises(fr.ProtocolError, match="SAMPLE payload has 3 bytes"):
        fr.unpack_sample(b"abc")
    with pytest.raises(fr.ProtocolError, match="needs 6 values"):
        fr.pack_targets([1500] * 5)


latch_st = st.builds(fr.Latch, st.integers(0, 2**32 - 1),
                     st.lists(st.integers(0, 0xFFFF), min_size=6, max_size=6).map(tuple),
                     st.lists(st.integers(0, 255), min_size=6, max_size=6).map(tuple), st.integers(0, 0x3F))


@given(latch_st)
def test_latch_payload_round_trip(latch):
    payload = fr.pack_latch(latch)
    assert len(payload) == fr.LATCH_SIZE == 23
    assert fr.unpack_latch(payload) == latch
    (frame,) = fr.FrameParser().feed(fr.encode_frame(fr.LATCH, 3, payload))
    assert frame.type == fr.LATCH and fr.unpack_latch(frame.payload) == latch


def test_latch_layout_little_endian_fields_in_order():
    latch = fr.Latch(0x01020304, (0, 1500, 3000, 4500, 6000, 7500), (9, 9, 9, 10, 10, 10), 0b111111)
    p = fr.pack_latch(latch)
    assert p[:4] == bytes((4, 3, 2, 1)) and p[4:8] == bytes((0, 0, 0xDC, 0x05))
    assert p[16:22] == bytes((9, 9, 9, 10, 10, 10)) and p[22] == 0x3F
    assert latch.pulse_start_us(2) == 0x01020304 + 3000
    assert fr.Latch(0xFFFFFF00, (0, 0x200) + (0,) * 4, (0,) * 6, 1).pulse_start_us(1) == 0x100   # wraps like micros()


def test_latch_and_latch_report_reject_wrong_lengths_and_values():
    with pytest.raises(fr.ProtocolError, match="LATCH payload has 22 bytes, expected 23"):
        fr.unpack_latch(bytes(22))
    with pytest.raises(fr.ProtocolError, match="LATCH payload has 24 bytes"):
        fr.unpack_latch(bytes(24))
    with pytest.raises(fr.ProtocolError, match="SET_LATCH_REPORT payload has 2 bytes"):
        fr.unpack_latch_report(b"\x01\x00")
    assert fr.unpack_latch_report(fr.pack_latch_report(True)) == 1
    assert fr.REQUEST_SIZES[fr.SET_LATCH_REPORT] == 1
    with pytest.raises(fr.ProtocolError, match="needs 6 seqs"):
        fr.pack_latch(fr.Latch(0, (0,) * 6, (0,) * 5, 1))
    with pytest.raises(fr.ProtocolError, match="needs 6 values"):
        fr.pack_latch(fr.Latch(0, (0,) * 7, (0,) * 6, 1))
    with pytest.raises(fr.ProtocolError, match="mask"):
        fr.pack_latch(fr.Latch(0, (0,) * 6, (0,) * 6, 0x40))
