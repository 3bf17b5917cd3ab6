"""The sender's protocol logic, free of I/O and clocks: bytes and times in, frames out.

:class:`Link` is the host side of ``docs/protocol.md`` as a set of small handlers over one
state: every input is a call with the time it happened (``on_bytes(data, now)``,
``on_time(now)``), every output is a frame waiting in :meth:`Link.take_writes`. The driver
(:class:`~.sender.Sender` on a serial port, or :func:`~.simlink.simulate` in virtual time) only
moves bytes and reads a clock, so the whole protocol runs in the tests without a port, a thread
or a sleep. (Klipper's ``serialqueue.c`` is built the same way: one queue state, a handler per
event.)

What it does:

- **Handshake**: HELLO every ``rto_s`` until a CAPS comes; the card must fit the program.
- **Selective repeat**: one :class:`InFlight` record per BATCH/END the card has not
  acknowledged (its bytes, its periods, when its last copy should have left the line, how often
  it was sent). The card acknowledges cumulatively; a NAK — or an ACK/STATUS without progress
  although the oldest frame should long have arrived — sends the oldest frame again at once
  (fast retransmit; a frame already sent again is resent only when its new copy should have
  arrived); with no progress for the retransmission timeout the oldest frame is sent again
  and the timeout doubles (RFC 6298 estimate, Karn's rule, capped back-off).
- **Line model**: a frame's timers count from when its last byte should have left the line
  (10 bits per byte at the baud rate, after the bytes queued before it), corrected by every
  acknowledgement (the card has every byte up to the acknowledged frame).
- **Credit**: the periods in unacknowledged frames never exceed the free buffer the card last
  reported.
- **Continuity**: every BATCH names the position it starts from; a card that refuses the same
  frame twice for that (NAK reason POSITION) does not stand where the program says: the stream
  fails.
- **Stopping**: any failure after the handshake, and :meth:`Link.request_abort`, drop the
  frames not yet written and send ABORT every ``abort_retry_s`` until a STATUS shows the card
  stopped, or ``abort_wait_s`` passed. The card's final state decides: a STATUS saying DONE
  with the program's period count and end position is success whatever failed before.

This module holds the driver interface, the output queue and the dispatch of the card's
messages; the handlers of each phase are in :mod:`~.linkhandshake`, :mod:`~.linkstreaming` and
:mod:`~.linkstop` (mixins of :class:`Link`), the state and records in :mod:`~.linkstate`, the
retransmission timeout in :mod:`~.roundtrip`, the check of the card's CAPS in
:mod:`~.cardcheck`.
"""

from __future__ import annotations

import math

import numpy as np

from nurbscnc.errors import StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.cardcheck import alarm_name
from nurbscnc.output.stream.linkhandshake import HandshakeHandlers
from nurbscnc.output.stream.linkstate import (
    Counters,
    InFlight,
    LinkState,
    Outgoing,
    Phase,
    Progress,
    SenderOptions,
    StreamInterrupted,
    StreamReport,
)
from nurbscnc.output.stream.linkstop import StoppingHandlers
from nurbscnc.output.stream.linkstreaming import StreamingHandlers
from nurbscnc.output.stream.quantise import PulseProgram
from nurbscnc.output.stream.roundtrip import RoundTrip


class Link(HandshakeHandlers, StreamingHandlers, StoppingHandlers):
    """The host side of the protocol for one ``program`` (see the module docstring).

    ``byte_s``: seconds per byte on the line (0: an instantaneous link). ``ignore_credit``
    disables flow control; it exists only so the tests can show that the card catches a
    sender that overruns its buffer. ``session_id``: the card's session the stream must
    continue (a later section of one job: another id means the card reset in between).
    ``zero``: declare the card's position to be the program's start (SET_POSITION, protocol
    version 3) before streaming, instead of refusing a card that stands elsewhere.
    """

    def __init__(
        self,
        program: PulseProgram,
        options: SenderOptions | None = None,
        byte_s: float = 0.0,
        ignore_credit: bool = False,
        session_id: int | None = None,
        zero: bool = False,
    ):
        self.program = program
        #: (CAPS, positions of the axes the program does not carry) once the card answered
        self.card_fit = None
        self.session_id = session_id
        self.zero = zero
        #: the most pulses per period a replacement may bring (sets the frame size)
        self.peak_pulses = program.peak_pulses
        #: more periods will follow (:meth:`replace_unsent`): no END, no partial batch yet
        self.program_open = False
        self.options = options or SenderOptions()
        self.byte_s = byte_s
        self.ignore_credit = ignore_credit
        self.state = LinkState()
        self.count = Counters()
        self.rtt = RoundTrip(self.options)
        self.decoder = p.FrameDecoder(gap_s=self.options.gap_s)
        self.flush_port = False  #: the driver should drop what the port has queued (abort)
        self._outbox: list[Outgoing] = []
        #: periods per BATCH frame from now on: ``batch_limit``, fewer on a noisy line
        self.per_frame = 1
        #: most periods per BATCH frame (``batch_periods``, capped by the 255-byte payload)
        self.batch_limit = 1
        self._frame_starts: list[int] = []  #: first period of every sequenced frame framed
        self._framed_periods = 0  #: periods framed so far
        self._framed_position: np.ndarray | None = None  #: where the next batch starts [steps]
        self._end_seq: int | None = None  #: END's sequence number once framed

    # -- driver interface --------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Begin the handshake at ``now``."""
        self.state.started_s = self.state.last_rx_s = now
        self.on_time(now)

    @property
    def finished(self) -> bool:
        return self.state.phase is Phase.FINISHED

    def request_abort(self) -> None:
        """Abort at the next event: ABORT bypasses every frame not yet written."""
        self.state.abort_requested = True

    def request_hold(self) -> None:
        """Feed hold: the card stops at the next period boundary, keeps its buffer."""
        self.state.want_hold = True

    def request_resume(self) -> None:
        """Leave a feed hold."""
        self.state.want_hold = False

    def on_bytes(self, data: bytes, now: float) -> None:
        """Bytes from the card, arrived at ``now``."""
        self.count.bytes_received += len(data)
        for ev in self.decoder.feed(data, now):
            if isinstance(ev, p.BadFrame):
                self.count.crc_errors += 1
                continue
            self.state.last_rx_s = now
            self.count.frames_received += 1
            try:
                msg = p.decode_message(ev)
            except p.ProtocolError:
                self.count.protocol_errors += 1
                continue
            self._dispatch(msg, now)
            if self.finished:
                return

    def on_time(self, now: float) -> None:
        """Timers: requests, retransmission, polls, lost contact, the handshake's HELLOs."""
        st = self.state
        for ev in self.decoder.expire(now):  # a reply that stopped arriving
            self.count.crc_errors += isinstance(ev, p.BadFrame)
        if st.abort_requested and st.phase is not Phase.FINISHED:
            st.abort_requested = False
            if st.phase is not Phase.STOPPING:
                self._stop(StreamInterrupted("interrupted: abort sent"), now)
        if st.phase is Phase.HANDSHAKE:
            self._handshake_timers(now)
        elif st.phase is Phase.STREAMING:
            self._hold_resume(now)  # before new batches: a hold must not wait behind them
            self._fill_window(now)
            self._retransmit_timer(now)
            self._poll(now)
            self._check_contact(now, "from the card")
        elif st.phase is Phase.STOPPING:
            self._abort_timers(now)

    def take_writes(self, now: float, queued_bytes: int = 0) -> list[bytes]:
        """Frames to write now, in order; ``queued_bytes`` the port still holds (line model)."""
        st = self.state
        writes = []
        for item in self._outbox:
            start = max(now + queued_bytes * self.byte_s, st.line_free_s)
            st.line_free_s = start + len(item.data) * self.byte_s
            self.count.frames_sent += 1
            self.count.bytes_sent += len(item.data)
            rec = item.record
            if rec is not None:
                rec.queued = False
                rec.copies += 1
                rec.written_s = min(rec.written_s, now)
                rec.prev_leaves_s = rec.leaves_s
                rec.leaves_s = st.line_free_s
                rec.end_offset = self.count.bytes_sent
            elif item.data[4] == p.MsgType.HELLO:
                st.hello_leaves_s = st.line_free_s
            writes.append(item.data)
        self._outbox.clear()
        return writes

    def next_wakeup_s(self, now: float) -> float:
        """The latest time the driver should call :meth:`on_time` again (a timer's expiry)."""
        st, opt = self.state, self.options
        eps = 1e-9  # the timers fire strictly after their interval
        times = [now + opt.poll_s]
        if st.phase in (Phase.HANDSHAKE, Phase.STREAMING):
            times.append(st.last_rx_s + opt.timeout_s + eps)
        if self.decoder.expires_s is not None:
            times.append(self.decoder.expires_s)
        if st.abort_requested:
            times.append(now)
        if st.phase is Phase.HANDSHAKE:
            times.append(st.last_hello_s + opt.rto_s)
        elif st.phase is Phase.STREAMING:
            times.append(max(st.last_rx_s, st.last_poll_s) + opt.poll_s + eps)
            if st.base < st.nxt:
                oldest = st.window[st.base]
                times.append(oldest.leaves_s + self.rtt.rto + eps)
                times.append(self._stall_deadline_s(now) + eps)
            if st.want_hold is not None:
                times.append(st.last_ctl_s + opt.rto_s + eps)
        elif st.phase is Phase.STOPPING:
            times.append(min(st.last_abort_s + opt.abort_retry_s, st.stop_deadline_s))
        return max(now, min(times))

    def progress(self) -> Progress:
        st = self.state
        n = self.program.periods
        status = st.status
        executed = status.executed_periods if status else 0
        line = int(self.program.line[min(executed, n - 1)]) if n else 0
        return Progress(
            n,
            self.sent_periods,
            min(self._acked_periods(), n),
            executed,
            status.fill_periods if status else 0,
            st.caps.buffer_periods if st.caps else 0,
            line,
            position_steps=tuple(status.position_steps) if status else (),
            axes=self.program.axes,
        )

    @property
    def sent_periods(self) -> int:
        """Periods framed so far (sent or queued to be sent): they can no longer be changed."""
        if self.state.phase is Phase.HANDSHAKE:
            return 0
        return min(self._framed_periods, self.program.periods)

    def _acked_periods(self) -> int:
        """Periods in the frames the card has acknowledged."""
        base = self.state.base
        return self._frame_starts[base] if base < len(self._frame_starts) else self._framed_periods

    @property
    def end_framed(self) -> bool:
        """END has been framed: the stream's motion is fixed."""
        return self.state.phase is not Phase.HANDSHAKE and self._end_seq is not None

    def replace_unsent(self, program: PulseProgram) -> None:
        """Stream ``program`` instead: its first :attr:`sent_periods` periods must be the ones
        already framed (a feed hold or an override replaces only what the card has not been
        sent). Raises StreamError when END was framed already or the prefix differs."""
        k = self.sent_periods
        old = self.program
        program = self.fitted(program)
        if self.end_framed:
            raise StreamError("the stream's end has been sent already: nothing to replace")
        if (
            program.periods < k
            or not np.array_equal(program.start_steps, old.start_steps)
            or not np.array_equal(program.pulses[:k], old.pulses[:k])
        ):
            raise StreamError("the replacement does not continue the periods already sent")
        axes = len(program.start_steps)
        if program.periods and self.batch_limit > p.max_batch_periods(
            axes, p.pulse_width_bytes(program.peak_pulses)
        ):
            raise StreamError("the replacement needs wider pulse counts than the frames have")
        self.program = program  # the frames to come start where the framed ones end

    def result(self) -> StreamReport:
        """The report of a successful stream; raises the stream's error otherwise."""
        st = self.state
        if st.phase is not Phase.FINISHED:
            raise StreamError("the stream has not finished")
        if st.report is None:
            raise st.error or StreamError("the stream failed")
        return st.report

    # -- output ------------------------------------------------------------------------------
    def _send(self, msg, record: InFlight | None = None) -> None:
        if record is not None:
            record.queued = True
        self._outbox.append(
            Outgoing(p.encode_message(msg) if record is None else record.data, record)
        )

    def _resend_oldest(self, now: float) -> None:
        st = self.state
        st.last_resend_s = now
        self._send(None, st.window[st.base])
        self.count.retransmits += 1

    # -- input ---------------------------------------------------------------------------------
    def _dispatch(self, msg, now: float) -> None:
        st = self.state
        if st.phase is Phase.HANDSHAKE:
            if isinstance(msg, p.Caps) and st.zero_sent_s == -math.inf:
                self._on_caps_in_handshake(msg, now)
            elif isinstance(msg, p.Nak) and st.zero_sent_s > -math.inf:
                self._stop(StreamError("the card refused the new position (--zero)"), now)
            elif isinstance(msg, p.Status) and st.zero_sent_s > -math.inf:
                start = tuple(int(v) for v in self.program.start_steps)
                if tuple(msg.position_steps) == start:
                    self._start_streaming(now)
            return
        if st.phase is Phase.STOPPING:
            self._on_message_stopping(msg, now)
            return
        if isinstance(msg, (p.Ack, p.Nak, p.Status)):
            self._on_acknowledgement(msg, now)
        if isinstance(msg, p.Nak):
            self._on_nak(msg, now)
        elif isinstance(msg, p.Status):
            self._on_status(msg, now)
        elif isinstance(msg, p.Alarm):
            st.alarm = msg
            self._stop(StreamError(f"card alarm {alarm_name(msg.code)}: {msg.text}"), now)
        elif isinstance(msg, p.Caps) and msg.session_id != st.caps.session_id:
            self._stop(
                StreamError(
                    f"the card reset during the stream (session {st.caps.session_id:08x} → "
                    f"{msg.session_id:08x}): its buffer and position are lost; not resuming"
                ),
                now,
            )
