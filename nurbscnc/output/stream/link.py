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

The state and records are in :mod:`~.linkstate`, the retransmission timeout in
:mod:`~.roundtrip`, the check of the card's CAPS in :mod:`~.cardcheck`.
"""

from __future__ import annotations

import math

import numpy as np

from nurbscnc.errors import StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.cardcheck import alarm_name, check_caps
from nurbscnc.output.stream.linkstate import (
    STREAMING_STATES,
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
from nurbscnc.output.stream.quantise import PulseProgram
from nurbscnc.output.stream.roundtrip import RoundTrip


class Link:
    """The host side of the protocol for one ``program`` (see the module docstring).

    ``byte_s``: seconds per byte on the line (0: an instantaneous link). ``ignore_credit``
    disables flow control; it exists only so the tests can show that the card catches a
    sender that overruns its buffer. ``session_id``: the card's session the stream must
    continue (a later section of one job: another id means the card reset in between).
    ``zero``: declare the card's position to be the program's start (SET_POSITION, protocol
    version 3) before streaming, instead of refusing a card that stands elsewhere.
    """

    def __init__(self, program: PulseProgram, options: SenderOptions | None = None,
                 byte_s: float = 0.0, ignore_credit: bool = False,
                 session_id: int | None = None, zero: bool = False):  # fmt: skip
        self.program = program
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
        self.per_frame = 1
        self.n_batches = 0

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
                times.append(max(st.last_progress_s, oldest.written_s) + opt.timeout_s + eps)
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
        return Progress(n, self.sent_periods, min(st.base * self.per_frame, n), executed,
                        status.fill_periods if status else 0,
                        st.caps.buffer_periods if st.caps else 0, line)  # fmt: skip

    @property
    def sent_periods(self) -> int:
        """Periods framed so far (sent or queued to be sent): they can no longer be changed."""
        if self.state.phase is Phase.HANDSHAKE:
            return 0
        return min(self.state.nxt * self.per_frame, self.program.periods)

    @property
    def end_framed(self) -> bool:
        """END has been framed: the stream's motion is fixed."""
        return self.state.phase is not Phase.HANDSHAKE and self.state.nxt > self.n_batches

    def replace_unsent(self, program: PulseProgram) -> None:
        """Stream ``program`` instead: its first :attr:`sent_periods` periods must be the ones
        already framed (a feed hold or an override replaces only what the card has not been
        sent). Raises StreamError when END was framed already or the prefix differs."""
        k = self.sent_periods
        old = self.program
        if self.end_framed:
            raise StreamError("the stream's end has been sent already: nothing to replace")
        if (program.periods < k or not np.array_equal(program.start_steps, old.start_steps)
                or not np.array_equal(program.pulses[:k], old.pulses[:k])):  # fmt: skip
            raise StreamError("the replacement does not continue the periods already sent")
        axes = len(program.start_steps)
        if program.periods and self.per_frame > p.max_batch_periods(
                axes, p.pulse_width_bytes(program.peak_pulses)):  # fmt: skip
            raise StreamError("the replacement needs wider pulse counts than the frames have")
        self.program = program
        if self.state.phase is not Phase.HANDSHAKE:
            self._layout()

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
        self._outbox.append(Outgoing(p.encode_message(msg) if record is None else record.data,
                                 record))  # fmt: skip

    def _resend_oldest(self, now: float) -> None:
        st = self.state
        st.last_resend_s = now
        self._send(None, st.window[st.base])
        self.count.retransmits += 1

    # -- handshake ---------------------------------------------------------------------------
    def _handshake_timers(self, now: float) -> None:
        st = self.state
        if st.zero_sent_s > -math.inf:  # SET_POSITION until a STATUS confirms it
            if now - st.zero_sent_s >= self.options.rto_s:
                self._send(p.SetPosition(tuple(int(v) for v in self.program.start_steps)))
                st.zero_sent_s = now
        elif now - st.last_hello_s >= self.options.rto_s:
            self._send(p.Hello())
            st.last_hello_s = now
            st.hellos += 1
        if now - st.last_rx_s > self.options.timeout_s:
            # The card may have opened a stream on a HELLO whose CAPS was lost: abort it.
            self._stop(StreamError(
                f"lost communication with card: no answer to HELLO for "
                f"{self.options.timeout_s:g} s (is it a card speaking protocol version "
                f"{p.PROTOCOL_VERSION}?)"), now)  # fmt: skip

    def _on_caps_in_handshake(self, caps: p.Caps, now: float) -> None:
        st = self.state
        if st.hellos == 1:  # an unambiguous round trip seeds the timeout
            self.rtt.sample(max(0.0, now - st.hello_leaves_s))
        st.caps = caps
        if self.session_id is not None and caps.session_id != self.session_id:
            self._finish_error(StreamError(
                f"the card reset between two parts of the program (session "
                f"{self.session_id:08x} → {caps.session_id:08x}): its position is lost"))
            return  # fmt: skip
        start = tuple(int(v) for v in self.program.start_steps)
        try:
            check_caps(caps, self.program, position=not self.zero)
            lead = self.options.lead_periods
            if lead is not None and lead < caps.buffer_periods // 2:
                raise StreamError(f"--lead {lead} is less than half the card's buffer of "
                                  f"{caps.buffer_periods} periods: the card would wait for "
                                  "periods the sender holds back")  # fmt: skip
            if self.zero and tuple(caps.position_steps) != start and caps.version < 3:
                raise StreamError(f"--zero needs a card speaking protocol version 3; it "
                                  f"speaks {caps.version}")  # fmt: skip
        except StreamError as exc:
            self._finish_error(exc)
            return
        if self.zero and tuple(caps.position_steps) != start:
            self._send(p.SetPosition(start))  # confirmed by a STATUS at the start
            st.zero_sent_s = now
            return
        self._start_streaming(now)

    def _start_streaming(self, now: float) -> None:
        st = self.state
        self.zero = False
        width = p.pulse_width_bytes(max(self.program.peak_pulses, self.peak_pulses))
        self.per_frame = max(1, min(self.options.batch_periods,
                                    p.max_batch_periods(st.caps.axes, width)))  # fmt: skip
        self._layout()
        st.credit = self._credit(st.caps.buffer_periods)
        st.phase = Phase.STREAMING
        st.last_rx_s = st.last_progress_s = now

    def _layout(self) -> None:
        """Batches of the program: their count and where each starts [steps]."""
        prog, k, axes = self.program, self.per_frame, len(self.program.start_steps)
        self.n_batches = -(-prog.periods // k)
        # Where each batch starts: the program's start plus every pulse before it [steps].
        sums = (np.add.reduceat(prog.pulses, np.arange(0, prog.periods, k), axis=0)
                if prog.periods else np.zeros((0, axes), dtype=np.int64))  # fmt: skip
        self._batch_starts = prog.start_steps + np.vstack(
            [np.zeros((1, axes), dtype=np.int64), np.cumsum(sums, axis=0)])

    # -- streaming: input handlers -----------------------------------------------------------
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
            self._stop(StreamError(
                f"the card reset during the stream (session {st.caps.session_id:08x} → "
                f"{msg.session_id:08x}): its buffer and position are lost; not resuming"),
                now)  # fmt: skip

    def _on_acknowledgement(self, msg, now: float) -> None:
        """ACK, NAK and STATUS name the next frame the card expects and its free buffer."""
        st = self.state
        ahead = p.seq_ahead(st.base % p.SEQ_MODULO, msg.next_seq)
        if ahead > st.nxt - st.base:  # stale or bogus: ignore it whole
            return
        if ahead == 0:
            # No progress although the oldest frame should have arrived long ago: it was lost
            # (and so was its NAK, or no later frame raised one). A NAK resends anyway.
            oldest = st.window.get(st.base)
            if (not isinstance(msg, p.Nak) and oldest is not None
                    and now - oldest.leaves_s > self.rtt.stale_s):  # fmt: skip
                self._fast_retransmit(now)
        else:
            newest = st.window[st.base + ahead - 1]
            # Karn: no samples from retransmitted frames, nor from frames whose
            # acknowledgement waited for a retransmission before them.
            if newest.copies == 1 and newest.written_s > st.last_resend_s:
                self.rtt.sample(max(0.0, now - newest.leaves_s))
            self._correct_line_model(now, newest)
            self.rtt.progress()
            for seq in range(st.base, st.base + ahead):
                st.in_flight -= st.window.pop(seq).periods
            st.base += ahead
            st.last_progress_s = now
        st.credit = self._credit(msg.free_periods)

    def _credit(self, free: int) -> int:
        """Periods the sender may have in flight: the card's free buffer, less what the lead
        limit keeps back (buffered = buffer − free; buffered + in flight ≤ lead)."""
        lead = self.options.lead_periods
        if lead is None or self.state.caps is None:
            return free
        return max(0, min(free, lead - (self.state.caps.buffer_periods - free)))

    def _on_nak(self, msg: p.Nak, now: float) -> None:
        st = self.state
        self.count.naks_received += 1
        if msg.reason == p.NakReason.STATE:
            st.last_poll_s = -math.inf  # ask what state the card is in
            return
        oldest = st.window.get(st.base)
        if msg.reason == p.NakReason.POSITION and oldest is not None:
            oldest.position_naks += 1
            if oldest.position_naks >= 2:  # two copies refused: not a damaged copy
                what = "END" if oldest.seq >= self.n_batches else f"batch {oldest.seq + 1}"
                self._stop(StreamError(
                    f"the card refused {what} twice: it does not continue from where the "
                    "card's accepted frames end (the card's position is not the program's)"),
                    now)  # fmt: skip
                return
        self._fast_retransmit(now)

    def _fast_retransmit(self, now: float) -> None:
        """Resend the oldest frame; a frame already sent again only when its new copy should
        have arrived (older NAKs may still be on their way)."""
        st = self.state
        oldest = st.window.get(st.base)
        if oldest is None or oldest.queued or oldest.copies == 0:
            return
        if oldest.copies == 1 or now - oldest.leaves_s > self.rtt.stale_s:
            self._resend_oldest(now)

    def _on_status(self, msg: p.Status, now: float) -> None:
        st = self.state
        st.status = msg
        if msg.state == p.CardState.DONE:
            self._finish_done(now)
        elif msg.state == p.CardState.ALARM:
            text = st.alarm.text if st.alarm else "(no text received)"
            self._stop(StreamError(f"card alarm {alarm_name(msg.alarm)}: {text}"), now)
        elif msg.state == p.CardState.ABORTED:
            self._stop(StreamError("the card aborted the stream"), now)
        elif msg.state == p.CardState.IDLE:
            self._stop(StreamError("the card reset during the stream (it reports no open "
                                   "stream): its buffer and position are lost; not resuming"),
                       now)  # fmt: skip

    def _correct_line_model(self, now: float, newest: InFlight) -> None:
        """Frame ``newest`` has arrived: at most the bytes written after it are still queued."""
        st = self.state
        done = newest.end_offset
        st.line_free_s = min(st.line_free_s, now + (self.count.bytes_sent - done) * self.byte_s)
        for seq in range(newest.seq + 1, st.nxt):
            rec = st.window[seq]
            if rec.copies:
                rec.leaves_s = min(rec.leaves_s,
                                   now + max(0, rec.end_offset - done) * self.byte_s)  # fmt: skip

    # -- streaming: timers -------------------------------------------------------------------
    def _fill_window(self, now: float) -> None:
        """New frames, as far as the credit goes."""
        st = self.state
        total = self.n_batches + (0 if self.program_open else 1)  # the batches, then END
        while st.nxt < total:
            periods = min(self.per_frame, self.program.periods - st.nxt * self.per_frame)
            if self.program_open and periods < self.per_frame:
                break  # a partial batch waits for the periods that follow it
            if not self.ignore_credit and st.in_flight + max(periods, 0) > st.credit:
                break
            rec = st.window[st.nxt] = self._record(st.nxt)
            self._send(None, rec)
            st.in_flight += rec.periods
            self.count.max_in_flight = max(self.count.max_in_flight, st.in_flight)
            st.nxt += 1

    def _record(self, i: int) -> InFlight:
        """Frame ``i``: a BATCH (with the position it starts from) or, after the last, END."""
        prog, k = self.program, self.per_frame
        if i < self.n_batches:
            block = prog.pulses[i * k : i * k + k]
            msg = p.Batch(block, tuple(int(v) for v in self._batch_starts[i]))
            return InFlight(i, p.encode_message(msg, seq=i), len(block))
        end = p.End(prog.periods, tuple(int(v) for v in prog.end_steps))
        return InFlight(i, p.encode_message(end, seq=i), 0)

    def _retransmit_timer(self, now: float) -> None:
        """No progress for RTO: send the oldest frame again and double the timeout."""
        st = self.state
        oldest = st.window.get(st.base)
        if oldest is not None and not oldest.queued and now - oldest.leaves_s > self.rtt.rto:
            self.count.timeouts += 1
            self._resend_oldest(now)
            self.rtt.back_off()

    def _hold_resume(self, now: float) -> None:
        """Feed hold / resume, repeated until the card's state confirms it."""
        st = self.state
        if st.want_hold is None or now - st.last_ctl_s <= self.options.rto_s:
            return
        card = st.status.state if st.status else None
        if card is not None and (card == p.CardState.HOLD) == st.want_hold:
            st.want_hold = None
        else:
            self._send(p.Hold() if st.want_hold else p.Resume())
            st.last_ctl_s = now

    def _poll(self, now: float) -> None:
        st = self.state
        if now - max(st.last_rx_s, st.last_poll_s) > self.options.poll_s:
            self._send(p.StatusRequest())
            self.count.polls += 1
            st.last_poll_s = now

    def _check_contact(self, now: float, what: str) -> None:
        """No valid frame for the timeout; or frames in flight and none acknowledged for it
        although the card answers (a line too noisy to carry a frame)."""
        st, timeout = self.state, self.options.timeout_s
        if now - st.last_rx_s > timeout:
            self._stop(StreamError(f"lost communication with card: no answer {what} for "
                                   f"{timeout:g} s"), now)  # fmt: skip
        elif st.base < st.nxt and now - max(st.last_progress_s,
                                            st.window[st.base].written_s) > timeout:
            self._stop(StreamError(f"the card acknowledged no frame for {timeout:g} s though it "
                                   "answers: the line is too noisy"), now)  # fmt: skip

    # -- the end -----------------------------------------------------------------------------
    def _stop(self, error: StreamError, now: float) -> None:
        """Something failed (or the user aborts): ABORT now, repeated until confirmed."""
        st = self.state
        st.error = error
        st.phase = Phase.STOPPING
        self._outbox.clear()  # frames not written yet must not reach the card first
        self.flush_port = True
        st.stop_deadline_s = now + self.options.abort_wait_s
        st.last_abort_s = now
        self._send(p.Abort())

    def _abort_timers(self, now: float) -> None:
        st = self.state
        if now >= st.stop_deadline_s:
            self._finish_unconfirmed()
        elif now - st.last_abort_s >= self.options.abort_retry_s:
            self._send(p.Abort())
            st.last_abort_s = now

    def _on_message_stopping(self, msg, now: float) -> None:
        st = self.state
        if isinstance(msg, p.Alarm):
            st.alarm = msg
        if not isinstance(msg, p.Status):
            return
        st.status = msg
        if msg.state == p.CardState.DONE:
            self._finish_done(now)
        elif msg.state not in STREAMING_STATES:
            st.abort_confirmed = True
            where = f"the card stopped at {list(msg.position_steps)} steps"
            self._finish_error(_with_suffix(st.error, where))

    def _finish_unconfirmed(self) -> None:
        wait = f"{self.options.abort_wait_s:g} s"
        self._finish_error(_with_suffix(self.state.error,
                                        f"no confirmation of the abort from the card within "
                                        f"{wait}"))  # fmt: skip

    def _finish_done(self, now: float) -> bool:
        """The card says DONE: success if it ran the program's periods to its end position."""
        st, prog = self.state, self.program
        status = st.status
        final = tuple(int(v) for v in status.position_steps)
        expected = tuple(int(v) for v in prog.end_steps)
        if final != expected or status.executed_periods != prog.periods:
            self._finish_error(StreamError(
                f"the card ended at {list(final)} steps after {status.executed_periods} "
                f"periods; the program ends at {list(expected)} steps after {prog.periods}"))
            return False  # fmt: skip
        c = self.count
        st.report = StreamReport(
            periods=prog.periods, frames_sent=c.frames_sent, bytes_sent=c.bytes_sent,
            bytes_received=c.bytes_received, retransmits=c.retransmits, timeouts=c.timeouts,
            naks_received=c.naks_received, crc_errors=c.crc_errors, polls=c.polls,
            executed_periods=status.executed_periods, final_position_steps=final,
            expected_position_steps=expected, max_in_flight_periods=c.max_in_flight,
            buffer_periods=st.caps.buffer_periods, session_id=st.caps.session_id,
            duration_s=now - st.started_s,
        )  # fmt: skip
        st.error = None
        st.phase = Phase.FINISHED
        self._outbox.clear()
        return True

    def _finish_error(self, error: StreamError) -> None:
        self.state.error = error
        self.state.phase = Phase.FINISHED
        self._outbox.clear()


def _with_suffix(error: StreamError | None, text: str) -> StreamError:
    """The same kind of error, its message extended by ``text``."""
    error = error or StreamError("the stream failed")
    out = type(error)(f"{error.message}, {text}" if isinstance(error, StreamInterrupted)
                      else f"{error.message}; {text}")  # fmt: skip
    return out

