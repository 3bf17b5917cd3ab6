"""The motion-card simulator: speaks the card side of the protocol (``nurbscnc card-sim``).

:class:`CardSim` is the card itself, without I/O: bytes go in with :meth:`CardSim.on_bytes`,
time goes in with :meth:`CardSim.advance`, reply bytes come out of :meth:`CardSim.take_output`.
It keeps the position in steps, a buffer of periods, the state machine of
:class:`~nurbscnc.output.stream.protocol.CardState`, and a log of every executed period.
Fault injection (:class:`Faults`) sits between the wire and the card's decoder, and between the
card's encoder and the wire: frames are dropped or get one bit flipped, replies are delayed,
and the card can reset (new session id, position lost) or stall (stops answering) after a
number of frames.

:func:`~.endpoints.serve` runs a card on an endpoint — a pseudo-terminal
(:class:`~.endpoints.PtyEndpoint`) or a loopback TCP socket (:class:`~.endpoints.TcpEndpoint`)
— until told to stop; :class:`~.wire.Wire` optionally limits the byte rate to a serial line's
(10 bits per byte at the given baud rate). The card's configuration and faults are in
:mod:`~.cardconfig`; its execution of the buffer in :mod:`~.cardmotion` and the fault
injection in :mod:`~.cardfaults` (mixins of :class:`CardSim`, over its one state); this
module holds the protocol handling and the replies.
"""

from __future__ import annotations

import collections
import random

import numpy as np

from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.axes import mask_of
from nurbscnc.output.stream.cardconfig import CardConfig as CardConfig
from nurbscnc.output.stream.cardconfig import Faults as Faults
from nurbscnc.output.stream.cardfaults import FaultInjection
from nurbscnc.output.stream.cardmotion import Execution
from nurbscnc.output.stream.endpoints import PtyEndpoint as PtyEndpoint
from nurbscnc.output.stream.endpoints import TcpEndpoint as TcpEndpoint
from nurbscnc.output.stream.endpoints import parse_listen as parse_listen
from nurbscnc.output.stream.endpoints import serve as serve

# The "X as X" imports re-export the card's configuration and endpoints: the CLI's
# ``card-sim`` imports them from here with the card.

_HALF_SEQ = p.SEQ_MODULO // 2


#: The simulated card's counters, all 0 at the start and in its report.
COUNTERS = (
    "bytes_received",
    "frames_received",
    "crc_errors",
    "protocol_errors",
    "dropped_in",
    "corrupted_in",
    "dropped_out",
    "corrupted_out",
    "duplicates",
    "overflows",
    "naks_sent",
    "acks_sent",
    "aborts_received",
    "holds_received",
    "resets",
    "max_fill",
    "executed_periods",
    "frames_sent",
    "position_naks",
    "positions_set",
)


class CardSim(FaultInjection, Execution):
    """One simulated card (single-threaded: call it from one thread at a time).

    Counters (attributes) for tests and the ``--report``: ``bytes_received``,
    ``frames_received`` (frames on the wire, before fault injection), ``crc_errors``,
    ``dropped_in``/``corrupted_in``/``dropped_out``/``corrupted_out``, ``duplicates``,
    ``overflows`` (batches refused for lack of room: a flow-control violation),
    ``position_naks`` (frames refused: they do not continue the accepted ones), ``naks_sent``,
    ``acks_sent``, ``aborts_received``, ``holds_received``, ``resets``, ``max_fill`` (most
    periods held at once, buffer and early frames together).
    """

    def __init__(self, config: CardConfig | None = None, seed: int | None = None):
        self.config = cfg = config or CardConfig()
        self._rng = random.Random(seed)
        self.session_id = self._rng.getrandbits(32)
        self.position = np.asarray(cfg.position_steps, dtype=np.int64).copy()
        self.state = p.CardState.IDLE
        self.alarm = p.AlarmCode.NONE
        self.alarm_text = ""
        self._period_wall_s = None if cfg.speed is None else cfg.period_s / cfg.speed
        # The wire is split into frames so that faults are injected per frame; frames damaged
        # before they reach the card go straight to it, intact ones pass the fault injection
        # and the card's own decoder.
        self._wire = p.FrameDecoder(gap_s=cfg.gap_s)
        self._decoder = p.FrameDecoder()
        self._out: collections.deque[tuple[float, bytes]] = collections.deque()
        self._log: list[np.ndarray] = []
        self.stalled = False
        for name in COUNTERS:
            setattr(self, name, 0)
        self._open_stream(0.0)
        self.state = p.CardState.IDLE

    # -- state -------------------------------------------------------------------------------
    def _open_stream(self, now: float) -> None:
        self.state = p.CardState.FILLING
        self.alarm, self.alarm_text = p.AlarmCode.NONE, ""
        self.expected = 0  # next sequence number, unwrapped
        self._buffer: collections.deque[np.ndarray] = collections.deque()
        self.fill = 0
        self._end: p.End | None = None
        self._started = False
        self._next_due = now
        self._early: dict[int, p.Batch | p.End] = {}  # frames after a gap, by sequence
        self._early_periods = 0
        self._since_status = 0
        self.stream_executed = 0
        # Where the card will stand after every accepted period, and how many there are: a
        # BATCH must start there, END must name them (the continuity check).
        self._tail = self.position.copy()
        self._accepted_periods = 0

    @property
    def free(self) -> int:
        """Free buffer [periods] reported to the sender: early frames are not subtracted.

        The sender counts every unacknowledged frame (early ones included) against this
        credit, so buffer + early frames can never exceed the buffer size.
        """
        return self.config.buffer_periods - self.fill

    @property
    def finished(self) -> bool:
        """The stream has ended (DONE, ABORTED or ALARM)."""
        return self.state in (p.CardState.DONE, p.CardState.ABORTED, p.CardState.ALARM)

    def executed_pulses(self) -> np.ndarray:
        """Every executed period since power-up, in order: (n, axes) int64."""
        if not self._log:
            return np.zeros((0, self.config.axes), dtype=np.int64)
        return np.vstack(self._log)

    def take_log(self, start: int) -> np.ndarray:
        """Executed periods from index ``start`` on (for an incremental log file)."""
        return self.executed_pulses()[start:]

    def caps(self) -> p.Caps:
        cfg = self.config
        return p.Caps(
            cfg.version,
            cfg.axes,
            cfg.max_pulses_per_period,
            cfg.buffer_periods,
            round(cfg.period_s * 1e6),
            self.session_id,
            int(self.state),
            tuple(int(v) for v in self.position),
            mask_of(cfg.axis_names) if cfg.version >= p.MASK_VERSION else p.XYZ_MASK,
        )

    def status(self) -> p.Status:
        return p.Status(
            int(self.state),
            int(self.alarm),
            self.expected % p.SEQ_MODULO,
            self.free,
            self.fill,
            self.stream_executed,
            tuple(int(v) for v in self.position),
        )

    # -- input -------------------------------------------------------------------------------
    def on_bytes(self, data: bytes, now: float) -> None:
        """Bytes from the wire at time ``now`` [s]."""
        self.bytes_received += len(data)
        if self.stalled:
            return
        self._from_wire(self._wire.feed(data, now), now)

    def _handle(self, ev, now: float) -> None:
        streaming = self.state in (p.CardState.FILLING, p.CardState.RUNNING, p.CardState.HOLD)
        if isinstance(ev, p.BadFrame):
            self.crc_errors += 1
            if streaming:
                self._nak(p.NakReason.CRC, now)
            return
        try:
            msg = p.decode_message(ev)
        except p.ProtocolError:
            self.protocol_errors += 1
            return
        if isinstance(msg, (p.Batch, p.End)):
            self._sequenced(ev.seq, msg, now)
        elif isinstance(msg, p.Hello):
            if self.state not in (p.CardState.RUNNING, p.CardState.HOLD):
                # Nothing has moved in FILLING, so a new HELLO may also replace an open stream
                # whose sender went away before the card started.
                self._open_stream(now)
            self._send(self.caps(), now)
        elif isinstance(msg, p.StatusRequest):
            self._send(self.status(), now)
        elif isinstance(msg, p.Abort):
            self.aborts_received += 1
            if streaming:
                self._buffer.clear()
                self._early.clear()
                self.fill = self._early_periods = 0
                self.state = p.CardState.ABORTED
            self._send(self.status(), now)
        elif isinstance(msg, p.Hold):
            self.holds_received += 1
            if self.state in (p.CardState.FILLING, p.CardState.RUNNING):
                self.state = p.CardState.HOLD
            self._send(self.status(), now)
        elif isinstance(msg, p.SetPosition):
            # Allowed outside a stream, and in a stream that has accepted nothing yet (a
            # HELLO opened it: nothing can have moved).
            fresh = self.state is p.CardState.FILLING and self.expected == 0 and not self._early
            if (streaming and not fresh) or len(msg.position_steps) != self.config.axes:
                self._nak(p.NakReason.STATE, now)
                return
            self.position[:] = msg.position_steps
            self._tail = self.position.copy()
            self.positions_set += 1
            self._send(self.status(), now)
        elif isinstance(msg, p.Resume):
            if self.state is p.CardState.HOLD:
                self.state = p.CardState.RUNNING if self._started else p.CardState.FILLING
                self._next_due = now  # no catch-up burst after a hold
                self._maybe_start(now)
                self._run_fast(now)
                self._maybe_finish(now)
            self._send(self.status(), now)
        # Card → host messages arriving at the card are ignored.

    def _nak(self, reason: int, now: float) -> None:
        self.naks_sent += 1
        self._send(p.Nak(self.expected % p.SEQ_MODULO, self.free, int(reason)), now)

    def _sequenced(self, seq: int, msg, now: float) -> None:
        """A BATCH or END: accept it in order, keep it if it is early, re-ACK a duplicate.

        Early frames (after a gap) are kept (selective repeat) as long as they fit beside the
        buffer, so recovering a lost frame costs one retransmission, not a window of them;
        they run only once every frame before them has arrived.
        """
        if self.state is p.CardState.IDLE:
            self._send(self.caps(), now)  # "I was reset": the sender must not go on
            return
        if self.state is p.CardState.ALARM:
            self._send(p.Alarm(int(self.alarm), self.alarm_text), now)
            self._send(self.status(), now)
            return
        if self.state not in (p.CardState.FILLING, p.CardState.RUNNING, p.CardState.HOLD):
            self._nak(p.NakReason.STATE, now)
            return
        ahead = p.seq_ahead(self.expected % p.SEQ_MODULO, seq)
        if ahead >= _HALF_SEQ:  # behind: a retransmission of a frame already accepted
            self.duplicates += 1
            self._ack(now)
            return
        size = len(msg.pulses) if isinstance(msg, p.Batch) else 0
        if ahead > 0:  # early: a frame before it was lost
            key = self.expected + ahead
            if key in self._early:
                self.duplicates += 1
            elif self.fill + self._early_periods + size > self.config.buffer_periods:
                self.overflows += 1
                self._nak(p.NakReason.FULL, now)
                return
            else:
                self._early[key] = msg
                self._early_periods += size
                self.max_fill = max(self.max_fill, self.fill + self._early_periods)
            self._nak(p.NakReason.SEQUENCE, now)
            return
        if self.fill + self._early_periods + size > self.config.buffer_periods:
            self.overflows += 1
            self._nak(p.NakReason.FULL, now)
            return
        verdict = self._accept(msg, now)
        if verdict == "refused":
            self._nak(p.NakReason.POSITION, now)
        if verdict != "ok":
            return
        while self.expected in self._early:  # the gap is filled: take the frames kept
            kept = self._early.pop(self.expected)
            self._early_periods -= len(kept.pulses) if isinstance(kept, p.Batch) else 0
            verdict = self._accept(kept, now)
            if verdict == "alarm":
                return
            if verdict == "refused":  # dropped: the sender sends it again
                break
        self._maybe_start(now)
        self._run_fast(now)
        self._ack(now)
        if verdict == "refused":
            self._nak(p.NakReason.POSITION, now)
        elif self._early:  # another gap after the frames taken
            self._nak(p.NakReason.SEQUENCE, now)
        self._maybe_finish(now)

    def _accept(self, msg, now: float) -> str:
        """Put the next frame in order into the buffer (or take END).

        Returns "ok", "refused" (it does not continue from the accepted frames: the BATCH's
        start position is not where they end, or END's period count or position is not
        theirs; nothing changes, the caller NAKs) or "alarm".
        """
        if self._end is not None:
            self._raise_alarm(p.AlarmCode.PROTOCOL, "sequenced frame after END", now)
            return "alarm"
        tail = tuple(int(v) for v in self._tail)
        if isinstance(msg, p.Batch):
            pulses = msg.pulses
            if pulses.shape[1] != self.config.axes:
                self._raise_alarm(
                    p.AlarmCode.PROTOCOL,
                    f"batch of {pulses.shape[1]} axes, card has {self.config.axes}",
                    now,
                )
                return "alarm"
            if tuple(msg.start_steps) != tail:
                self.position_naks += 1
                return "refused"
            peak = int(np.abs(pulses).max())
            if peak > self.config.max_pulses_per_period:
                self._raise_alarm(
                    p.AlarmCode.PULSE_LIMIT,
                    f"{peak} pulses in one period, limit {self.config.max_pulses_per_period}",
                    now,
                )
                return "alarm"
            self._buffer.append(pulses)
            self.fill += len(pulses)
            self._tail += pulses.sum(axis=0)
            self._accepted_periods += len(pulses)
            self.max_fill = max(self.max_fill, self.fill + self._early_periods)
        else:
            if msg.periods != self._accepted_periods or tuple(msg.position_steps) != tail:
                self.position_naks += 1
                return "refused"
            self._end = msg
        self.expected += 1
        return "ok"

    def _ack(self, now: float) -> None:
        self.acks_sent += 1
        self._send(p.Ack(self.expected % p.SEQ_MODULO, self.free), now)

    # -- output ------------------------------------------------------------------------------
    def _send(self, msg, now: float) -> None:
        self.frames_sent += 1
        raw = self._inject(p.encode_message(msg), "out")
        if raw is not None:
            self._out.append((now + self.config.faults.delay_s, raw))

    def take_output(self, now: float) -> bytes:
        """Reply bytes due by ``now`` (delayed ones stay queued)."""
        return b"".join(self.take_frames(now))

    def take_frames(self, now: float) -> list[bytes]:
        """Reply frames due by ``now``, one bytes object each (delayed ones stay queued)."""
        if self.stalled:
            self._out.clear()
            return []
        frames = []
        while self._out and self._out[0][0] <= now:
            frames.append(self._out.popleft()[1])
        return frames

    def next_event_s(self) -> float | None:
        """When something happens next without input: a period or a delayed reply."""
        times = []
        if self._out:
            times.append(self._out[0][0])
        if self._wire.expires_s is not None and not self.stalled:
            times.append(self._wire.expires_s)
        if (
            self.state is p.CardState.RUNNING
            and self._period_wall_s is not None
            and not self.stalled
        ):
            times.append(self._next_due)
        return min(times) if times else None

    def report(self) -> dict:
        """Counters and final state, JSON-able."""
        out = {k: int(getattr(self, k)) for k in COUNTERS}
        out.update(
            state=self.state.name,
            alarm=self.alarm.name,
            alarm_text=self.alarm_text,
            position_steps=[int(v) for v in self.position],
            buffer_periods=self.config.buffer_periods,
            session_id=self.session_id,
            stalled=self.stalled,
        )
        return out
