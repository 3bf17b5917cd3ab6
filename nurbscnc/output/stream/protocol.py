"""The card protocol (versions 2 to 4): framing, header CRC-8, CRC-32, message types; one codec.

A frame on the wire (multi-byte integers little-endian)::

    SYNC 0xA5 | LEN u8 | SEQ u16 | TYPE u8 | HCRC u8 | PAYLOAD (LEN bytes) | CRC u32

``LEN`` counts only the payload, so a frame is ``LEN + 10`` bytes.

- ``HCRC`` is CRC-8/SMBUS (polynomial 0x07, initial value 0, no reflection, no final xor;
  check value ``crc8("123456789") = 0xF4``) over ``LEN SEQ TYPE``. A receiver trusts ``LEN``
  only when the header checks, so a corrupted length byte is found after 6 bytes instead of
  stalling the receiver until up to 265 bytes have arrived. CRC-8 with this polynomial detects
  every error of up to 3 bits in the 40 header bits (Hamming distance 4).
- ``CRC`` is CRC-32/ISO-HDLC (the CRC of zlib, Ethernet and PNG: polynomial 0x04C11DB7,
  reflected, initial value and final xor 0xFFFFFFFF; check value
  ``crc32("123456789") = 0xCBF43926``) over ``LEN … PAYLOAD`` (everything after SYNC). At the
  lengths used here (≤ 2 112 bits) its Hamming distance is at least 5: every error of up to 4
  bits in a frame is detected; ``tests/test_stream_protocol.py`` proves it for the longest frame
  from the polynomial's linearity.
- ``SEQ`` numbers the *sequenced* frames (BATCH, END) modulo 2¹⁶; every other frame carries 0.

A receiver with a time source also abandons a frame whose bytes stop arriving for ``gap_s``
(a byte lost on the line, or a sync byte inside noise whose header happened to check), so
framing resynchronises in bounded time whatever was lost. ``docs/protocol.md`` has the full
description with the reliability rules.

Everything here is pure (bytes in, values out) except :class:`FrameDecoder`, which keeps the
bytes of an incomplete frame between calls.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from nurbscnc.errors import StreamError

SYNC = 0xA5
PROTOCOL_VERSION = 4
#: Versions whose frames this codec reads: 3 adds SET_POSITION to version 2 (same frames);
#: 4 adds the axis mask to CAPS (up to six axes X Y Z A B C; every other frame alike).
COMPATIBLE_VERSIONS = (2, 3, 4)
#: The first version whose CAPS carries an axis mask (the axes the card drives).
MASK_VERSION = 4
#: The axes of a card whose CAPS carries no mask (versions 2 and 3): X Y Z.
XYZ_MASK = 0b000111
#: SYNC (1) + LEN (1) + SEQ (2) + TYPE (1) + HCRC (1), before the payload.
HEADER_BYTES = 6
#: Header + CRC-32 (4).
OVERHEAD_BYTES = 10
MAX_PAYLOAD_BYTES = 255
SEQ_MODULO = 1 << 16
#: Bits per byte on an asynchronous serial line with 8N1 framing (start + 8 data + stop).
BITS_PER_BYTE_8N1 = 10


class MsgType(IntEnum):
    """Frame types. Host → card below 0x80, card → host from 0x80."""

    HELLO = 0x01  #: open a stream; payload: protocol version u8
    BATCH = 0x02  #: sequenced: pulse counts of n periods
    END = 0x03  #: sequenced: end of program (period count, final position)
    STATUS_REQUEST = 0x04  #: ask for a STATUS
    HOLD = 0x05  #: feed hold: stop executing periods at the next period boundary
    RESUME = 0x06  #: leave a feed hold
    ABORT = 0x07  #: stop now, drop the buffer (handled out of sequence)
    SET_POSITION = 0x08  #: version 3: declare where the card stands (not while streaming)
    CAPS = 0x81  #: hello reply / unsolicited after a card reset: capabilities and session
    ACK = 0x82  #: next expected sequence number, free buffer
    NAK = 0x83  #: next expected sequence number, free buffer, reason
    STATUS = 0x84  #: state, buffer, executed periods, position
    ALARM = 0x85  #: alarm code and text


class CardState(IntEnum):
    """What the card is doing."""

    IDLE = 0  #: no stream open (after power-up or reset)
    FILLING = 1  #: stream open, filling the buffer before the first period runs
    RUNNING = 2  #: executing one period per period time
    HOLD = 3  #: feed hold
    DONE = 4  #: END executed: every period of the program ran
    ABORTED = 5  #: ABORT received
    ALARM = 6  #: stopped by an alarm


class AlarmCode(IntEnum):
    """Alarm codes (STATUS.alarm and ALARM.code)."""

    NONE = 0
    UNDERRUN = 1  #: a period was due and the buffer was empty before END
    PULSE_LIMIT = 2  #: a period asks for more pulses than the card's maximum
    END_MISMATCH = 3  #: END's period count or final position differs from what ran
    PROTOCOL = 4  #: a malformed message (wrong axes, bad payload length)


class NakReason(IntEnum):
    """Why a NAK was sent."""

    CRC = 1  #: a frame failed its header CRC or CRC-32, or stopped arriving
    SEQUENCE = 2  #: a sequenced frame arrived after a gap (a frame was lost)
    FULL = 3  #: a batch did not fit in the free buffer (the sender broke flow control)
    STATE = 4  #: the card does not accept batches in its state
    POSITION = 5  #: a BATCH or END does not continue from where the accepted frames end


# -- CRCs --------------------------------------------------------------------------------------
def _crc8_table(poly: int) -> bytes:
    """The 256 CRC-8 remainders of single bytes, MSB first (the CRC's definition, bytewise)."""
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ poly) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return bytes(table)


_CRC8_TABLE = _crc8_table(0x07)


def crc8_smbus(data: bytes) -> int:
    """CRC-8/SMBUS of ``data``: poly 0x07, init 0, MSB first, no final xor.

    Check value (the CRC catalogue): ``crc8_smbus(b"123456789") == 0xF4``.
    """
    crc = 0
    for byte in data:
        crc = _CRC8_TABLE[crc ^ byte]
    return crc


def crc32_iso_hdlc(data: bytes) -> int:
    """CRC-32/ISO-HDLC of ``data`` (``binascii.crc32``): poly 0x04C11DB7, reflected, init and
    final xor 0xFFFFFFFF. Check value: ``crc32_iso_hdlc(b"123456789") == 0xCBF43926``."""
    return binascii.crc32(data) & 0xFFFFFFFF


# -- frames ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Frame:
    """A CRC-valid frame: its type byte, sequence number and payload."""

    type: int
    seq: int
    payload: bytes


@dataclass(frozen=True)
class BadFrame:
    """A candidate frame that failed: ``reason`` "header" (HCRC), "crc" (CRC-32) or "gap"
    (its bytes stopped arriving); ``raw`` the bytes from its sync byte on."""

    raw: bytes
    reason: str = "crc"


_HEADER = struct.Struct("<BHB")


def encode_frame(msg_type: int, payload: bytes = b"", seq: int = 0) -> bytes:
    """The bytes of one frame (see the module docstring for the layout)."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD_BYTES}")
    head = _HEADER.pack(len(payload), seq % SEQ_MODULO, int(msg_type))
    body = head + bytes((crc8_smbus(head),)) + bytes(payload)
    return bytes((SYNC,)) + body + struct.pack("<I", crc32_iso_hdlc(body))


class FrameDecoder:
    """Splits a byte stream into frames, resynchronising after corruption in bounded time.

    :meth:`feed` returns, in order, every :class:`Frame` whose CRCs match and a
    :class:`BadFrame` for every candidate that fails: a sync byte whose header CRC does not
    match (found after 6 bytes, so a corrupted ``LEN`` is never trusted), or a frame whose
    CRC-32 does not. After a failure the search restarts one byte after the candidate's sync
    byte, so a damaged frame costs only itself. Bytes before a sync byte are counted in
    ``noise_bytes`` and dropped.

    With ``gap_s`` (and times passed to :meth:`feed` / :meth:`expire`), an incomplete frame
    whose bytes stopped arriving for longer than ``gap_s`` is abandoned (a "gap" BadFrame) and
    the bytes after its sync byte are searched again: a lost byte, or a false sync whose header
    happened to check, stalls the receiver for ``gap_s`` at most.
    """

    def __init__(self, gap_s: float | None = None) -> None:
        self._buf = bytearray()
        self.noise_bytes = 0
        self.gap_s = gap_s
        self._last_s: float | None = None  # when the held bytes last grew

    def feed(self, data: bytes, now: float | None = None) -> list[Frame | BadFrame]:
        """Frames completed by ``data`` (arrived at ``now`` [s], optional).

        New bytes never expire the bytes held before them (a receiver that was busy must not
        take its own delay for a gap on the line): the gap is enforced by :meth:`expire`,
        which the receiver calls when no bytes come.
        """
        out: list[Frame | BadFrame] = []
        if data:
            self._buf += data
            self._last_s = now
        self._scan(out, final=False)
        return out

    def expire(self, now: float) -> list[Frame | BadFrame]:
        """Abandon an incomplete frame whose bytes stopped arriving ``gap_s`` before ``now``."""
        out: list[Frame | BadFrame] = []
        if (
            self.gap_s is not None
            and self._buf
            and self._last_s is not None
            and now - self._last_s >= self.gap_s
        ):
            self._scan(out, final=True)
        return out

    def _scan(self, out: list, final: bool) -> None:
        """Take every complete candidate from the buffer; with ``final`` nothing is kept."""
        buf = self._buf
        i = 0
        abandoned = False
        while True:
            j = buf.find(SYNC, i)
            if j < 0:
                self.noise_bytes += len(buf) - i
                i = len(buf)
                break
            self.noise_bytes += j - i
            i = j
            have = len(buf) - j
            if have >= HEADER_BYTES and crc8_smbus(buf[j + 1 : j + 5]) != buf[j + 5]:
                out.append(BadFrame(bytes(buf[j : j + HEADER_BYTES]), "header"))
                i = j + 1
                continue
            total = buf[j + 1] + OVERHEAD_BYTES if have >= 2 else OVERHEAD_BYTES
            if have < max(total, HEADER_BYTES):
                if not final:
                    break
                if not abandoned:  # report the stale frame once; what follows is searched
                    out.append(BadFrame(bytes(buf[j:]), "gap"))
                    abandoned = True
                i = j + 1
                continue
            body = bytes(buf[j + 1 : j + total - 4])
            (crc,) = struct.unpack_from("<I", buf, j + total - 4)
            if crc32_iso_hdlc(body) == crc:
                seq = body[1] | (body[2] << 8)
                out.append(Frame(body[3], seq, body[5:]))
                i = j + total
            else:
                out.append(BadFrame(bytes(buf[j : j + total]), "crc"))
                i = j + 1
        del buf[:i]

    @property
    def pending_bytes(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    @property
    def expires_s(self) -> float | None:
        """When the bytes held back will be abandoned (None: nothing held, or no gap limit)."""
        if not self._buf or self.gap_s is None or self._last_s is None:
            return None
        return self._last_s + self.gap_s


def seq_ahead(base: int, seq: int) -> int:
    """How far ``seq`` is ahead of ``base`` modulo 2¹⁶ (0 … 65535)."""
    return (seq - base) % SEQ_MODULO


# -- messages ----------------------------------------------------------------------------------
class ProtocolError(StreamError):
    """A CRC-valid frame whose content is not a valid message."""


@dataclass(frozen=True)
class Hello:
    """Host → card: open a stream (resets the card's sequence numbers and buffer)."""

    version: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class Caps:
    """Card → host: capabilities, session and where the card is.

    ``session_id`` changes every time the card powers up or resets: a CAPS with a new session
    id in the middle of a stream means the card lost its buffer and position.
    ``axis_mask`` (version 4): the axes the card drives, bit i of X Y Z A B C; positions and
    counts carry one value per driven axis in that order. Versions 2 and 3 send no mask: X Y Z.
    """

    version: int
    axes: int
    max_pulses_per_period: int
    buffer_periods: int
    period_us: int
    session_id: int
    state: int
    position_steps: tuple[int, ...]
    axis_mask: int = XYZ_MASK


@dataclass(frozen=True, eq=False)
class Batch:
    """Host → card (sequenced): pulse counts ``pulses`` (n_periods, axes) int, and the
    position [steps] the card stands at before the first of them, ``start_steps`` (the
    program's start plus every pulse of the batches before): a card refuses a batch that does
    not continue from where its accepted batches end."""

    pulses: np.ndarray
    start_steps: tuple[int, ...]

    def __eq__(self, other) -> bool:
        return (
            isinstance(other, Batch)
            and np.array_equal(self.pulses, other.pulses)
            and tuple(self.start_steps) == tuple(other.start_steps)
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class End:
    """Host → card (sequenced): the program has ``periods`` periods and ends at this position."""

    periods: int
    position_steps: tuple[int, ...]


@dataclass(frozen=True)
class StatusRequest:
    """Host → card: reply with a STATUS."""


@dataclass(frozen=True)
class Hold:
    """Host → card: feed hold."""


@dataclass(frozen=True)
class Resume:
    """Host → card: leave the feed hold."""


@dataclass(frozen=True)
class Abort:
    """Host → card: stop now and drop the buffer."""


@dataclass(frozen=True)
class SetPosition:
    """Host → card (version 3): the card stands at ``position_steps`` from now on (a zero or
    a re-home); refused (NAK reason STATE) while a stream is FILLING, RUNNING or HOLD."""

    position_steps: tuple[int, ...]


@dataclass(frozen=True)
class Ack:
    """Card → host: every sequenced frame before ``next_seq`` was accepted."""

    next_seq: int
    free_periods: int


@dataclass(frozen=True)
class Nak:
    """Card → host: resend from ``next_seq`` (``reason``: :class:`NakReason`)."""

    next_seq: int
    free_periods: int
    reason: int


@dataclass(frozen=True)
class Status:
    """Card → host: state, alarm code, buffer, executed period count and position [steps]."""

    state: int
    alarm: int
    next_seq: int
    free_periods: int
    fill_periods: int
    executed_periods: int
    position_steps: tuple[int, ...]


@dataclass(frozen=True)
class Alarm:
    """Card → host: an alarm stopped the card."""

    code: int
    text: str


Message = (
    Hello
    | Caps
    | Batch
    | End
    | StatusRequest
    | Hold
    | Resume
    | Abort
    | SetPosition
    | Ack
    | Nak
    | Status
    | Alarm
)

_EMPTY = {
    MsgType.STATUS_REQUEST: StatusRequest,
    MsgType.HOLD: Hold,
    MsgType.RESUME: Resume,
    MsgType.ABORT: Abort,
}
_EMPTY_TYPES = {cls: t for t, cls in _EMPTY.items()}
_CAPS = struct.Struct("<BBHHIIB")
_ACK = struct.Struct("<HH")
_NAK = struct.Struct("<HHB")
_STATUS = struct.Struct("<BBHHHI")
_END = struct.Struct("<I")
_POSITION_LIMIT = 1 << 31
_WIDTH_DTYPES = {1: "<i1", 2: "<i2"}


def pulse_width_bytes(max_abs_pulses: int) -> int:
    """Bytes per pulse count: 1 (int8) up to 127 pulses, 2 (int16) up to 32767."""
    if max_abs_pulses <= 127:
        return 1
    if max_abs_pulses <= 32767:
        return 2
    raise ValueError(f"{max_abs_pulses} pulses per period cannot be encoded (limit 32767)")


def max_batch_periods(axes: int, width_bytes: int = 1) -> int:
    """The most periods one BATCH frame carries (payload ≤ 255 bytes: format byte, start
    position 4·axes bytes, counts)."""
    return (MAX_PAYLOAD_BYTES - 1 - 4 * axes) // (axes * width_bytes)


def batch_frame_bytes(periods: int, axes: int, width_bytes: int = 1) -> int:
    """Size on the wire of a BATCH frame: 10 + 1 + 4·axes + periods·axes·width."""
    return OVERHEAD_BYTES + 1 + 4 * axes + periods * axes * width_bytes


def _pack_position(position) -> bytes:
    pos = [int(p) for p in position]
    if any(not -_POSITION_LIMIT <= p < _POSITION_LIMIT for p in pos):
        raise ValueError(f"position {pos} does not fit 32-bit steps")
    return struct.pack(f"<{len(pos)}i", *pos)


def _unpack_position(data: bytes, what: str) -> tuple[int, ...]:
    if len(data) % 4:
        raise ProtocolError(f"{what}: position of {len(data)} bytes is not whole int32s")
    return tuple(int(v) for v in struct.unpack(f"<{len(data) // 4}i", data))


def encode_message(msg: Message, seq: int = 0) -> bytes:
    """One message as a frame; ``seq`` matters for BATCH and END only."""
    if isinstance(msg, Batch):
        return encode_frame(MsgType.BATCH, _batch_payload(msg.pulses, msg.start_steps), seq)
    if isinstance(msg, End):
        return encode_frame(
            MsgType.END, _END.pack(msg.periods) + _pack_position(msg.position_steps), seq
        )
    if isinstance(msg, Hello):
        return encode_frame(MsgType.HELLO, bytes((msg.version,)))
    if isinstance(msg, SetPosition):
        return encode_frame(MsgType.SET_POSITION, _pack_position(msg.position_steps))
    if type(msg) in _EMPTY_TYPES:
        return encode_frame(_EMPTY_TYPES[type(msg)])
    if isinstance(msg, Caps):
        head = _CAPS.pack(
            msg.version,
            msg.axes,
            msg.max_pulses_per_period,
            msg.buffer_periods,
            msg.period_us,
            msg.session_id,
            msg.state,
        )
        if msg.version >= MASK_VERSION:
            head += bytes((msg.axis_mask,))
        return encode_frame(MsgType.CAPS, head + _pack_position(msg.position_steps))
    if isinstance(msg, Ack):
        return encode_frame(MsgType.ACK, _ACK.pack(msg.next_seq % SEQ_MODULO, msg.free_periods))
    if isinstance(msg, Nak):
        return encode_frame(
            MsgType.NAK, _NAK.pack(msg.next_seq % SEQ_MODULO, msg.free_periods, msg.reason)
        )
    if isinstance(msg, Status):
        head = _STATUS.pack(
            msg.state,
            msg.alarm,
            msg.next_seq % SEQ_MODULO,
            msg.free_periods,
            msg.fill_periods,
            msg.executed_periods,
        )
        return encode_frame(MsgType.STATUS, head + _pack_position(msg.position_steps))
    if isinstance(msg, Alarm):
        text = msg.text.encode("utf-8")[: MAX_PAYLOAD_BYTES - 1]
        return encode_frame(MsgType.ALARM, bytes((msg.code,)) + text)
    raise TypeError(f"not a message: {msg!r}")


def _batch_payload(pulses, start_steps) -> bytes:
    """Format byte (bits 0-3 axes, bits 4-5 width−1), the start position (axes × i32), then
    the counts period by period."""
    p = np.asarray(pulses)
    if p.ndim != 2 or p.shape[0] < 1 or not 1 <= p.shape[1] <= 15:
        raise ValueError(f"a batch needs (n >= 1, 1..15 axes) pulses, got shape {p.shape}")
    if len(start_steps) != p.shape[1]:
        raise ValueError(f"a batch of {p.shape[1]} axes needs {p.shape[1]} start positions")
    width = pulse_width_bytes(int(np.abs(p).max()))
    return (
        bytes((p.shape[1] | ((width - 1) << 4),))
        + _pack_position(start_steps)
        + p.astype(_WIDTH_DTYPES[width]).tobytes()
    )


def decode_message(frame: Frame) -> Message:
    """The message in a CRC-valid frame; ProtocolError if its payload is malformed."""
    t, data = frame.type, frame.payload
    try:
        kind = MsgType(t)
    except ValueError:
        raise ProtocolError(f"unknown frame type 0x{t:02x}") from None
    if kind in _EMPTY:
        if data:
            raise ProtocolError(f"{kind.name} carries no payload, got {len(data)} bytes")
        return _EMPTY[kind]()
    try:
        if kind is MsgType.BATCH:
            return _batch(data)
        if kind is MsgType.END:
            (periods,) = _END.unpack_from(data)
            return End(periods, _unpack_position(data[_END.size :], "END"))
        if kind is MsgType.SET_POSITION:
            if not data:
                raise ProtocolError("SET_POSITION without a position")
            return SetPosition(_unpack_position(data, "SET_POSITION"))
        if kind is MsgType.HELLO:
            if len(data) != 1:
                raise ProtocolError(f"HELLO carries 1 byte, got {len(data)}")
            return Hello(data[0])
        if kind is MsgType.CAPS:
            return _caps(data)
        if kind is MsgType.ACK:
            return Ack(*_ACK.unpack(data))
        if kind is MsgType.NAK:
            return Nak(*_NAK.unpack(data))
        if kind is MsgType.STATUS:
            head = _STATUS.unpack_from(data)
            return Status(*head, position_steps=_unpack_position(data[_STATUS.size :], "STATUS"))
        if len(data) < 1:  # ALARM
            raise ProtocolError("ALARM without a code")
        return Alarm(data[0], data[1:].decode("utf-8", errors="replace"))
    except struct.error as exc:
        raise ProtocolError(f"{kind.name}: payload of {len(data)} bytes: {exc}") from None


def _caps(data: bytes) -> Caps:
    """CAPS: the fixed head, from version 4 the axis mask, then the position."""
    head = _CAPS.unpack_from(data)
    at, mask = _CAPS.size, XYZ_MASK
    if head[0] >= MASK_VERSION:
        if len(data) <= at:
            raise ProtocolError("CAPS of version 4 without its axis mask")
        at, mask = at + 1, data[at]
    position = _unpack_position(data[at:], "CAPS")
    if head[0] >= MASK_VERSION and (mask >> 6 or bin(mask).count("1") != len(position)):
        raise ProtocolError(f"CAPS axis mask 0x{mask:02x} does not fit {len(position)} positions")
    return Caps(*head, position_steps=position, axis_mask=mask)


def _batch(data: bytes) -> Batch:
    if len(data) < 2:
        raise ProtocolError("BATCH without pulse counts")
    axes, width = data[0] & 0x0F, (data[0] >> 4) + 1
    if axes == 0 or width not in _WIDTH_DTYPES:
        raise ProtocolError(f"BATCH format byte 0x{data[0]:02x} is invalid")
    start = _unpack_position(data[1 : 1 + 4 * axes], "BATCH")
    body = data[1 + 4 * axes :]
    if len(start) != axes or not body or len(body) % (axes * width):
        raise ProtocolError(
            f"BATCH of {len(data)} bytes is not a start position and whole periods of {axes} axes"
        )
    pulses = np.frombuffer(body, dtype=_WIDTH_DTYPES[width]).astype(np.int64).reshape(-1, axes)
    return Batch(pulses, start)
