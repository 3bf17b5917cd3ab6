"""The sender's state and records: its options, the link's phases and state, one record per
unacknowledged frame, the counters, and the progress and report it hands out."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

from nurbscnc.errors import EXIT_INTERRUPTED, ConfigError, StreamError
from nurbscnc.output.stream import protocol as p

#: Card states of an open stream (the card has not stopped).
STREAMING_STATES = (p.CardState.FILLING, p.CardState.RUNNING, p.CardState.HOLD)


class StreamInterrupted(StreamError):
    """The user interrupted the stream (SIGINT/SIGTERM); an abort was sent."""

    exit_code = EXIT_INTERRUPTED


@dataclass(frozen=True)
class SenderOptions:
    """Sender tuning. Times in seconds."""

    batch_periods: int = 16  #: periods per BATCH frame (capped by the 255-byte payload)
    timeout_s: float = 2.0  #: no valid frame from the card for this long: lost communication
    rto_s: float = 0.2  #: retransmission timeout before the first round-trip measurement
    rto_min_s: float = 0.02  #: floor of the measured retransmission timeout
    rto_max_s: float = 1.0  #: back-off cap
    poll_s: float = 0.1  #: ask for a STATUS when the card has been quiet this long
    abort_wait_s: float = 0.5  #: how long ABORT is repeated waiting for the card to confirm
    abort_retry_s: float = 0.1  #: ABORT is sent again this often until confirmed
    read_wait_s: float = 0.001  #: port read timeout: the driver's idle tick
    gap_s: float = 0.05  #: a reply whose bytes stop arriving this long is abandoned
    link_baud: int | None = None  #: line rate for the queue model (None: the port's baudrate)
    #: most periods queued ahead of the card's execution (buffered + in flight); None: its
    #: whole buffer. Less makes a feed hold act sooner, at the cost of margin against an
    #: underrun; at least half the card's buffer (where a card starts executing).
    lead_periods: int | None = None
    #: frames in flight and none acknowledged for this long though the card answers: give up
    #: [s]. None: the limit follows the measured frame error rate (see
    #: :func:`~.linkstreaming.attempts_needed`)
    stall_limit_s: float | None = None

    def __post_init__(self) -> None:
        if self.batch_periods < 1:
            raise ConfigError(f"--batch must be >= 1 period, got {self.batch_periods}")
        if self.lead_periods is not None and self.lead_periods < 1:
            raise ConfigError(f"--lead must be >= 1 period, got {self.lead_periods}")
        if not self.timeout_s > 0.0:
            raise ConfigError(f"--timeout must be > 0 s, got {self.timeout_s}")
        if self.stall_limit_s is not None and not self.stall_limit_s > 0.0:
            raise ConfigError(f"--stall-limit must be > 0 s, got {self.stall_limit_s}")


@dataclass(frozen=True)
class Progress:
    """A progress snapshot [periods]; ``line`` the source line of the period executing (0:
    unknown), ``note`` what the controller is doing (waiting at a pause, holding…),
    ``position_steps`` the card's last reported position (empty before its first STATUS),
    ``axes`` its axes ("xyz", "xyza", …: the axes the card drives)."""

    periods: int
    sent: int
    acked: int
    executed: int
    fill: int
    buffer: int
    line: int = 0
    note: str = ""
    position_steps: tuple = ()
    axes: str = "xyz"


@dataclass(frozen=True)
class StreamReport:
    """What a finished stream did (``stream --json``)."""

    periods: int
    frames_sent: int
    bytes_sent: int
    bytes_received: int
    retransmits: int
    timeouts: int
    naks_received: int
    crc_errors: int
    polls: int
    executed_periods: int
    final_position_steps: tuple[int, ...]
    expected_position_steps: tuple[int, ...]
    max_in_flight_periods: int
    buffer_periods: int
    session_id: int
    duration_s: float
    #: copies of the acknowledged frames that were lost or damaged (either way), over all
    #: their copies: the line's measured frame error rate
    frame_error_rate: float = 0.0
    #: periods per BATCH frame at the end (fewer than asked on a noisy line)
    batch_periods: int = 0
    #: the axes of the positions, X Y Z then the rotary axes the card drives ("xyza")
    axes: str = "xyz"

    def to_json(self) -> dict:
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        out["final_position_steps"] = list(self.final_position_steps)
        out["expected_position_steps"] = list(self.expected_position_steps)
        return out


class Phase(enum.Enum):
    HANDSHAKE = "handshake"
    STREAMING = "streaming"
    STOPPING = "stopping"  #: ABORT sent, waiting for the card to confirm
    FINISHED = "finished"


@dataclass
class InFlight:
    """One sequenced frame (BATCH or END) the card has not acknowledged yet.

    Times [s] on the driver's clock; ``leaves_s`` is when the last byte of the newest copy
    should have left the line (infinite until the copy is written), ``end_offset`` the count
    of bytes written up to and including that copy.
    """

    seq: int  #: sequence number, unwrapped (the wire carries it modulo 2¹⁶)
    data: bytes
    periods: int
    written_s: float = math.inf  #: when the first copy was written
    leaves_s: float = math.inf
    prev_leaves_s: float = math.inf  #: ``leaves_s`` of the copy before the newest
    end_offset: int = 0
    copies: int = 0  #: copies written
    queued: bool = False  #: a copy waits in the outbox
    position_naks: int = 0  #: NAKs saying it does not continue from where the card stands


@dataclass
class Counters:
    """What happened on the link (for the report)."""

    frames_sent: int = 0
    bytes_sent: int = 0
    bytes_received: int = 0
    retransmits: int = 0
    timeouts: int = 0
    naks_received: int = 0
    crc_errors: int = 0
    protocol_errors: int = 0
    polls: int = 0
    max_in_flight: int = 0
    frames_acked: int = 0  #: sequenced frames the card acknowledged
    copies_acked: int = 0  #: copies written of those frames
    frames_received: int = 0  #: valid frames from the card
    bytes_acked: int = 0  #: bytes of one copy of each acknowledged frame

    @property
    def frame_error_rate(self) -> float:
        """Lost or damaged copies of the acknowledged frames over all their copies."""
        if not self.copies_acked:
            return 0.0
        return (self.copies_acked - self.frames_acked) / self.copies_acked

    def byte_error_rate(self) -> float:
        """The line's chance of damaging or losing one byte, for a line that damages bytes
        alike (a frame of L bytes arrives whole with probability (1 − e)^L): the larger of
        what the card's damaged frames imply (their mean length) and what the lost copies
        of the acknowledged frames imply (their mean length, plus an answer's)."""
        seen = self.frames_received + self.crc_errors
        reply_bytes = self.bytes_received / seen if seen else 0.0
        e = 0.0
        if self.crc_errors and self.frames_received:
            e = 1.0 - (self.frames_received / seen) ** (1.0 / max(1.0, reply_bytes))
        if self.frames_acked and self.copies_acked > self.frames_acked:
            trip_bytes = self.bytes_acked / self.frames_acked + reply_bytes
            e = max(e, 1.0 - (1.0 - self.frame_error_rate) ** (1.0 / trip_bytes))
        return e

    def reply_bytes(self) -> float:
        """The mean length of the card's frames [bytes] (15: an ACK, before any)."""
        seen = self.frames_received + self.crc_errors
        return self.bytes_received / seen if seen else 15.0

    def round_trip_error(self, frame_bytes: int) -> float:
        """The chance that a copy of a ``frame_bytes`` frame or its answer is lost: the
        measured :attr:`frame_error_rate`, or, when larger, 1 − (1 − e)^(L + answer) from
        :meth:`byte_error_rate` (before any frame is acknowledged, the only one known)."""
        e = self.byte_error_rate()
        whole = (1.0 - e) ** (frame_bytes + self.reply_bytes())
        return max(self.frame_error_rate, 1.0 - whole)


@dataclass
class Outgoing:
    """A frame waiting to be written; ``record`` its window entry (BATCH or END), else None."""

    data: bytes
    record: InFlight | None = None


@dataclass
class LinkState:
    """Everything the link knows, in one place."""

    phase: Phase = Phase.HANDSHAKE
    caps: p.Caps | None = None
    status: p.Status | None = None
    alarm: p.Alarm | None = None
    # sequenced frames: [base, nxt) are unacknowledged, in_flight their periods
    base: int = 0
    nxt: int = 0
    window: dict[int, InFlight] = field(default_factory=dict)
    in_flight: int = 0
    credit: int = 0
    # timers [s]
    started_s: float = 0.0
    last_rx_s: float = 0.0
    last_progress_s: float = 0.0  #: when the card last acknowledged a new frame
    last_poll_s: float = -math.inf
    last_hello_s: float = -math.inf
    hellos: int = 0
    hello_leaves_s: float = math.inf
    last_ctl_s: float = -math.inf
    last_resend_s: float = -math.inf
    line_free_s: float = 0.0
    stop_deadline_s: float = math.inf
    last_abort_s: float = -math.inf
    zero_sent_s: float = -math.inf  #: when SET_POSITION was last sent (``zero`` handshake)
    # requests (set from signal handlers)
    abort_requested: bool = False
    want_hold: bool | None = None
    # the end
    error: StreamError | None = None  #: why the link is stopping or failed
    abort_confirmed: bool = False
    report: StreamReport | None = None
