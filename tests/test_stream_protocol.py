"""Card protocol codec: CRC-16/CCITT-FALSE vectors, frame layout, round trips, resync.

The CRC oracle is a bit-by-bit implementation written here from the algorithm's definition
(poly 0x1021, init 0xFFFF, MSB first, no reflection, no final xor), checked against the
catalogue's check value; the codec itself uses binascii.crc_hqx.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.output.stream import protocol as p


def crc_bitwise(data: bytes) -> int:
    """CRC-16/CCITT-FALSE, one bit at a time."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def test_crc_published_vectors():
    # The CRC catalogue's check value for CRC-16/CCITT-FALSE (a.k.a. CRC-16/IBM-3740).
    assert p.crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc_bitwise(b"123456789") == 0x29B1
    assert p.crc16_ccitt_false(b"A") == 0xB915
    assert p.crc16_ccitt_false(b"") == 0xFFFF


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_crc_matches_bitwise_reference_and_has_zero_residue(data):
    crc = p.crc16_ccitt_false(data)
    assert crc == crc_bitwise(data)
    # Non-reflected, no final xor: appending the CRC big-endian leaves a remainder of 0.
    assert p.crc16_ccitt_false(data + struct.pack(">H", crc)) == 0


def test_frame_layout_byte_by_byte():
    frame = p.encode_frame(0x82, b"\x05\x00\x10\x00", seq=0x1234)
    body = bytes([4, 0x34, 0x12, 0x82, 5, 0, 0x10, 0])
    assert frame[:1] == b"\xa5"
    assert frame[1:-2] == body
    assert frame[-2:] == struct.pack(">H", crc_bitwise(body))
    assert len(frame) == 4 + p.OVERHEAD_BYTES
    assert p.FrameDecoder().feed(frame) == [p.Frame(0x82, 0x1234, b"\x05\x00\x10\x00")]


def test_batch_layout_and_sizes():
    pulses = np.array([[1, -2, 3], [127, -127, 0]])
    frame = p.encode_message(p.Batch(pulses), seq=7)
    # format byte: 3 axes, int8 (width code 0); counts period by period, as signed bytes.
    assert frame[5:-2] == bytes([0x03, 1, 0xFE, 3, 127, 0x81, 0])
    assert len(frame) == p.batch_frame_bytes(2, 3) == 7 + 1 + 6
    wide = p.encode_message(p.Batch(np.array([[128, 0, -300]])))
    assert wide[5] == 0x13  # 3 axes, 2 bytes per count
    assert wide[6:-2] == struct.pack("<3h", 128, 0, -300)
    assert p.max_batch_periods(3, 1) == 84 and p.max_batch_periods(3, 2) == 42
    p.encode_message(p.Batch(np.zeros((84, 3), dtype=int)))
    with pytest.raises(ValueError):
        p.encode_message(p.Batch(np.zeros((85, 3), dtype=int)))
    with pytest.raises(ValueError):
        p.encode_message(p.Batch(np.array([[40000, 0, 0]])))


positions = st.tuples(*[st.integers(-(2**31), 2**31 - 1)] * 3)
u16 = st.integers(0, 0xFFFF)
u8 = st.integers(0, 255)
messages = st.one_of(
    st.builds(p.Hello, u8),
    st.builds(p.Caps, u8, st.integers(1, 15), u16, u16, st.integers(0, 2**32 - 1),
              st.integers(0, 2**32 - 1), u8, positions),
    st.builds(p.End, st.integers(0, 2**32 - 1), positions),
    st.sampled_from([p.StatusRequest(), p.Hold(), p.Resume(), p.Abort()]),
    st.builds(p.Ack, u16, u16),
    st.builds(p.Nak, u16, u16, u8),
    st.builds(p.Status, u8, u8, u16, u16, u16, st.integers(0, 2**32 - 1), positions),
    st.builds(p.Alarm, u8, st.text(max_size=60)),
    st.builds(lambda a: p.Batch(np.array(a, dtype=np.int64)),
              st.lists(st.lists(st.integers(-32767, 32767), min_size=3, max_size=3),
                       min_size=1, max_size=40)),
)  # fmt: skip


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


def test_every_single_bit_error_is_caught_and_the_stream_resyncs():
    """CRC-16 detects every single-bit error; the decoder then finds the following frames."""
    bad = p.encode_message(p.Batch(np.arange(-24, 24).reshape(16, 3)), seq=3)
    good = p.encode_message(p.Ack(9, 99))
    k = 300 // len(good) + 2  # enough bytes after the damage to resolve any corrupt LEN
    for bit in range(8 * len(bad)):
        damaged = bytearray(bad)
        damaged[bit // 8] ^= 1 << (bit % 8)
        out = p.FrameDecoder().feed(bytes(damaged) + good * k)
        frames = [f for f in out if isinstance(f, p.Frame)]
        assert frames == [p.Frame(p.MsgType.ACK, 0, good[5:-2])] * k, bit
        if bit >= 8:  # a damaged sync byte is noise; anything else is reported as bad
            assert any(isinstance(f, p.BadFrame) for f in out), bit


def test_malformed_payloads_are_protocol_errors():
    for frame in (
        p.Frame(0x42, 0, b""),  # unknown type
        p.Frame(p.MsgType.ACK, 0, b"\x00"),  # short
        p.Frame(p.MsgType.ABORT, 0, b"\x00"),  # empty type with payload
        p.Frame(p.MsgType.BATCH, 0, b"\x03\x01\x02"),  # not whole periods
        p.Frame(p.MsgType.BATCH, 0, b"\x33\x00\x00\x00"),  # width code 3
        p.Frame(p.MsgType.BATCH, 0, b"\x03"),  # no counts
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
