"""Card protocol codec (version 3 = 2 + SET_POSITION): CRC vectors, frames, round trips, resync.

The CRC oracles are independent of the codec: bit-by-bit implementations written here from the
algorithms' definitions, the CRC catalogue's check values, and ``zlib.crc32`` (the codec uses
``binascii.crc32`` and a table for CRC-8). The error-detection claims of docs/protocol.md are
proved here from the CRCs' linearity, not quoted.
"""

from __future__ import annotations

import itertools
import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.output.stream import protocol as p


def crc8_bitwise(data: bytes) -> int:
    """CRC-8/SMBUS, one bit at a time: poly 0x07, init 0, MSB first, no final xor."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def crc32_bitwise(data: bytes) -> int:
    """CRC-32/ISO-HDLC, one bit at a time: reflected poly 0xEDB88320, init/xorout 0xFFFFFFFF."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xEDB88320 if crc & 1 else crc >> 1
    return crc ^ 0xFFFFFFFF


def test_crc_published_vectors():
    # The CRC catalogue's check values (reveng.sourceforge.io/crc-catalogue).
    assert p.crc8_smbus(b"123456789") == crc8_bitwise(b"123456789") == 0xF4
    assert p.crc32_iso_hdlc(b"123456789") == crc32_bitwise(b"123456789") == 0xCBF43926
    assert zlib.crc32(b"123456789") == 0xCBF43926
    assert p.crc8_smbus(b"") == 0 and p.crc32_iso_hdlc(b"") == 0


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_crcs_match_independent_references_and_residues(data):
    assert p.crc8_smbus(data) == crc8_bitwise(data)
    crc = p.crc32_iso_hdlc(data)
    assert crc == zlib.crc32(data) == crc32_bitwise(data)
    # Appending the CRC (CRC-8 MSB first; CRC-32 little-endian, as sent) leaves the
    # catalogue's residue: 0 for CRC-8/SMBUS, 0x2144DF1C for CRC-32/ISO-HDLC.
    assert p.crc8_smbus(data + bytes((p.crc8_smbus(data),))) == 0
    assert zlib.crc32(data + struct.pack("<I", crc)) == 0x2144DF1C


def test_frame_layout_byte_by_byte():
    frame = p.encode_frame(0x82, b"\x05\x00\x10\x00", seq=0x1234)
    head = bytes([4, 0x34, 0x12, 0x82])
    assert frame[:1] == b"\xa5"
    assert frame[1:5] == head and frame[5] == crc8_bitwise(head)
    assert frame[6:-4] == b"\x05\x00\x10\x00"
    assert frame[-4:] == struct.pack("<I", crc32_bitwise(frame[1:-4]))
    assert len(frame) == 4 + p.OVERHEAD_BYTES == 14
    assert p.FrameDecoder().feed(frame) == [p.Frame(0x82, 0x1234, b"\x05\x00\x10\x00")]


def test_batch_layout_and_sizes():
    pulses = np.array([[1, -2, 3], [127, -127, 0]])
    frame = p.encode_message(p.Batch(pulses, (-1, 70000, 5)), seq=7)
    # format byte: 3 axes, int8 (width code 0); the start position as 3 int32; then the
    # counts period by period as signed bytes.
    assert frame[6:-4] == (
        bytes([0x03]) + struct.pack("<3i", -1, 70000, 5) + bytes([1, 0xFE, 3, 127, 0x81, 0])
    )
    assert len(frame) == p.batch_frame_bytes(2, 3) == 10 + 1 + 12 + 6
    wide = p.encode_message(p.Batch(np.array([[128, 0, -300]]), (0, 0, 0)))
    assert wide[6] == 0x13  # 3 axes, 2 bytes per count
    assert wide[19:-4] == struct.pack("<3h", 128, 0, -300)
    assert p.max_batch_periods(3, 1) == 80 and p.max_batch_periods(3, 2) == 40
    p.encode_message(p.Batch(np.zeros((80, 3), dtype=int), (0, 0, 0)))
    with pytest.raises(ValueError):
        p.encode_message(p.Batch(np.zeros((81, 3), dtype=int), (0, 0, 0)))
    with pytest.raises(ValueError):
        p.encode_message(p.Batch(np.array([[40000, 0, 0]]), (0, 0, 0)))
    with pytest.raises(ValueError):
        p.encode_message(p.Batch(np.zeros((1, 3), dtype=int), (0, 0)))


positions = st.tuples(*[st.integers(-(2**31), 2**31 - 1)] * 3)
u16 = st.integers(0, 0xFFFF)
u8 = st.integers(0, 255)
messages = st.one_of(
    st.builds(p.Hello, u8),
    st.builds(
        p.Caps,
        u8,
        st.integers(1, 15),
        u16,
        u16,
        st.integers(0, 2**32 - 1),
        st.integers(0, 2**32 - 1),
        u8,
        positions,
    ),
    st.builds(p.End, st.integers(0, 2**32 - 1), positions),
    st.builds(p.SetPosition, positions),
    st.sampled_from([p.StatusRequest(), p.Hold(), p.Resume(), p.Abort()]),
    st.builds(p.Ack, u16, u16),
    st.builds(p.Nak, u16, u16, u8),
    st.builds(p.Status, u8, u8, u16, u16, u16, st.integers(0, 2**32 - 1), positions),
    st.builds(p.Alarm, u8, st.text(max_size=60)),
    st.builds(
        lambda a, s: p.Batch(np.array(a, dtype=np.int64), s),
        st.lists(
            st.lists(st.integers(-32767, 32767), min_size=3, max_size=3), min_size=1, max_size=40
        ),
        positions,
    ),
)


@settings(max_examples=300, deadline=None)
@given(messages, u16)
def test_every_message_round_trips(msg, seq):
    frame = p.encode_message(msg, seq=seq)
    (decoded,) = p.FrameDecoder().feed(frame)
    assert isinstance(decoded, p.Frame)
    assert p.decode_message(decoded) == msg
    sequenced = isinstance(msg, (p.Batch, p.End))
    assert decoded.seq == (seq if sequenced else 0)


def test_decoder_splits_byte_by_byte_and_skips_noise():
    frames = [p.encode_message(p.Ack(i, 100 + i)) for i in range(5)]
    noise = b"\x00\x01\xff"
    stream = noise + frames[0] + frames[1] + noise + frames[2] + frames[3] + frames[4]
    dec = p.FrameDecoder()
    out = []
    for byte in stream:
        out += dec.feed(bytes([byte]))
    assert [p.decode_message(f) for f in out] == [p.Ack(i, 100 + i) for i in range(5)]
    assert dec.noise_bytes == 2 * len(noise)
    assert dec.pending_bytes == 0


def test_every_single_bit_error_is_caught_and_the_next_frame_is_found_at_once():
    """A damaged frame costs only itself: one intact frame right after it is always decoded.

    With version 1's unchecked LEN, a flipped length bit made the receiver wait for up to 255
    more bytes, swallowing the frames behind it (the link issue); the header CRC refuses it
    after 6 bytes."""
    bad = p.encode_message(p.Batch(np.arange(-24, 24).reshape(16, 3), (1, 2, 3)), seq=3)
    good = p.encode_message(p.Ack(9, 99))
    for bit in range(8 * len(bad)):
        damaged = bytearray(bad)
        damaged[bit // 8] ^= 1 << (bit % 8)
        dec = p.FrameDecoder()
        out = dec.feed(bytes(damaged) + good)
        frames = [f for f in out if isinstance(f, p.Frame)]
        assert frames == [p.Frame(p.MsgType.ACK, 0, good[6:-4])], bit
        assert dec.pending_bytes == 0, bit
        if bit >= 8:  # a damaged sync byte is noise; anything else is reported as bad
            assert any(isinstance(f, p.BadFrame) for f in out), bit
        if 8 <= bit < 48:  # LEN, SEQ, TYPE or HCRC: refused by the header check
            assert out[0] == p.BadFrame(bytes(damaged[:6]), "header"), bit


def test_a_stalled_partial_frame_is_abandoned_after_the_gap():
    """Bytes lost on the line, or a false sync whose header happens to check, hold the
    receiver for ``gap_s`` at most; the intact frames behind are then found."""
    good = p.encode_message(p.Ack(1, 2))
    cut = p.encode_message(p.Ack(3, 4))[:9]  # the rest was lost
    dec = p.FrameDecoder(gap_s=0.01)
    assert dec.feed(cut, now=0.0) == [] and dec.expires_s == 0.01
    assert dec.expire(0.009) == []
    assert dec.expire(0.010) == [p.BadFrame(cut, "gap")]
    assert dec.feed(good, now=0.02) == [p.Frame(p.MsgType.ACK, 0, good[6:-4])]
    # A false sync with a valid header announcing 255 bytes swallows a good frame …
    head = bytes([255, 0, 0, 0x84])
    false_sync = bytes([p.SYNC]) + head + bytes([crc8_bitwise(head)])
    dec = p.FrameDecoder(gap_s=0.01)
    assert dec.feed(false_sync + good, now=1.0) == []
    # … until the line has been quiet for the gap: then the frame behind it is found.
    out = dec.expire(1.0101)
    assert out[0].reason == "gap" and out[1:] == [p.Frame(p.MsgType.ACK, 0, good[6:-4])]
    assert dec.pending_bytes == 0


def _syndromes_crc32(data_bytes: int) -> np.ndarray:
    """The CRC-32 syndrome of every single-bit error in a frame of ``data_bytes`` covered bytes
    plus its 4 CRC bytes: an error pattern is undetected iff its bits' syndromes xor to 0."""
    zero = zlib.crc32(bytes(data_bytes))
    rows = []
    for i in range(8 * data_bytes):
        unit = bytearray(data_bytes)
        unit[i // 8] = 1 << (i % 8)
        rows.append(zlib.crc32(bytes(unit)) ^ zero)  # the CRC is affine: its linear part
    rows += [1 << j for j in range(32)]  # a flipped CRC bit (sent little-endian)
    return np.array(rows, dtype=np.uint32)


def test_crc32_detects_every_error_of_up_to_4_bits_in_the_longest_frame():
    """Hamming distance ≥ 5 for 260 covered bytes (LEN … a 255-byte payload): no syndrome is
    0 (1 bit), all differ (2), no pair's xor is a single syndrome (3), no two pairs xor alike
    (4 bits)."""
    s = np.sort(_syndromes_crc32(5 + p.MAX_PAYLOAD_BYTES))
    assert np.all(s != 0) and np.all(np.diff(s) != 0)
    pairs = np.sort(np.concatenate([s[k] ^ s[k + 1 :] for k in range(len(s) - 1)]))
    assert len(pairs) == len(s) * (len(s) - 1) // 2
    at = np.minimum(np.searchsorted(s, pairs), len(s) - 1)
    assert not np.any(s[at] == pairs)
    assert np.all(pairs[1:] != pairs[:-1])


def test_header_crc8_detects_every_error_of_up_to_3_bits():
    head = bytes([16, 0x34, 0x12, 0x02])
    word = int.from_bytes(head + bytes((p.crc8_smbus(head),)), "big")
    for k in (1, 2, 3):
        for bits in itertools.combinations(range(40), k):
            damaged = (word ^ sum(1 << b for b in bits)).to_bytes(5, "big")
            assert p.crc8_smbus(damaged[:4]) != damaged[4], bits


def test_malformed_payloads_are_protocol_errors():
    pos = struct.pack("<3i", 0, 0, 0)
    for frame in (
        p.Frame(0x42, 0, b""),  # unknown type
        p.Frame(p.MsgType.ACK, 0, b"\x00"),  # short
        p.Frame(p.MsgType.ABORT, 0, b"\x00"),  # empty type with payload
        p.Frame(p.MsgType.BATCH, 0, b"\x03" + pos + b"\x01\x02"),  # not whole periods
        p.Frame(p.MsgType.BATCH, 0, b"\x33" + pos + b"\x00\x00\x00"),  # width code 3
        p.Frame(p.MsgType.BATCH, 0, b"\x03" + pos),  # no counts
        p.Frame(p.MsgType.BATCH, 0, b"\x03\x00\x00\x00"),  # no whole start position
        p.Frame(p.MsgType.STATUS, 0, bytes(12) + b"\x01"),  # position not whole int32s
        p.Frame(p.MsgType.HELLO, 0, b""),
    ):
        with pytest.raises(p.ProtocolError):
            p.decode_message(frame)


def test_sequence_arithmetic_wraps():
    assert p.seq_ahead(65535, 1) == 2
    assert p.seq_ahead(5, 5) == 0
    assert p.seq_ahead(5, 4) == 65535
    frame = p.encode_message(p.End(0, (0, 0, 0)), seq=65536 + 3)
    assert p.FrameDecoder().feed(frame)[0].seq == 3
