"""The link while streaming: what the card's ACK, NAK and STATUS say (selective repeat,
credit, the line model), and the timers (new frames, retransmission, hold and resume, polls,
lost contact)."""

from __future__ import annotations

import math

import numpy as np

from nurbscnc.errors import StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.cardcheck import alarm_name
from nurbscnc.output.stream.linkstate import InFlight


class StreamingHandlers:
    """The streaming phase's handlers (a mixin of :class:`~.link.Link`: it provides
    ``state``, ``options``, ``program``, ``count``, ``rtt``, ``_send``, ``_resend_oldest``,
    ``_stop`` and ``_finish_done``)."""

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
            if (
                not isinstance(msg, p.Nak)
                and oldest is not None
                and now - oldest.leaves_s > self.rtt.stale_s
            ):
                self._fast_retransmit(now)
        else:
            newest = st.window[st.base + ahead - 1]
            sample = self._round_trip_sample(msg, st.window[st.base], newest, ahead, now)
            if sample is not None:
                self.rtt.sample(sample)
            self._correct_line_model(now, newest)
            self.rtt.progress()
            for seq in range(st.base, st.base + ahead):
                rec = st.window.pop(seq)
                st.in_flight -= rec.periods
                self.count.frames_acked += 1
                self.count.copies_acked += rec.copies
                self.count.bytes_acked += len(rec.data)
            self._choose_batch()
            st.base += ahead
            st.last_progress_s = now
        st.credit = self._credit(msg.free_periods)

    def _choose_batch(self) -> None:
        """Periods per frame from now on: the size that carries the most periods per byte
        written on a line losing a fraction e of its bytes (:meth:`Counters.byte_error_rate`):
        B periods in a + b·B bytes arrive with their answer of R bytes with probability
        (1 − e)^(a + b·B + R), so B maximises B (1 − e)^(a + b·B + R) / (a + b·B), in
        1 … ``batch_limit``. A clean line keeps the largest (at e = 0 the ratio grows with B);
        at 2 % per byte 3 axes take 8 (of 23 + 3B bytes), at 5 % 4."""
        e = self.count.byte_error_rate()
        if e <= 0.0:
            self.per_frame = self.batch_limit
            return
        a, b = self._frame_bytes
        sizes = np.arange(1, self.batch_limit + 1)
        frame = a + b * sizes
        rate = sizes * (1.0 - e) ** (frame + self.count.reply_bytes()) / frame
        self.per_frame = int(sizes[np.argmax(rate)])

    def _round_trip_sample(self, msg, oldest, newest, ahead: int, now: float) -> float | None:
        """A round trip [s] measured by this acknowledgement, or None when it is ambiguous.

        Karn: none from a retransmitted frame, nor from one whose acknowledgement waited
        for a retransmission before it; nor from a STATUS or a NAK (one acknowledging a
        frame means its ACK was lost, or the frame came between two polls: no round trip).
        One exception keeps the estimate alive on a noisy line, where nearly every frame is
        sent again and Karn alone leaves no sample at all (the timeout then stays at its
        initial 0.2 s, backed off): an ACK that completes the oldest frame sooner after its
        last copy left than the copies were apart answers that last copy (an answer to the
        copy before would have come before the last one left).
        """
        st = self.state
        if not isinstance(msg, p.Ack):
            return None
        if newest.copies == 1 and (ahead == 1 or newest.written_s > st.last_resend_s):
            return max(0.0, now - newest.leaves_s)
        since = now - oldest.leaves_s
        if oldest.copies > 1 and 0.0 <= since < oldest.leaves_s - oldest.prev_leaves_s:
            return since
        return None

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
                what = "END" if oldest.seq == self._end_seq else f"batch {oldest.seq + 1}"
                self._stop(
                    StreamError(
                        f"the card refused {what} twice: it does not continue from where the "
                        "card's accepted frames end (the card's position is not the program's)"
                    ),
                    now,
                )
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
            self._stop(
                StreamError(
                    "the card reset during the stream (it reports no open "
                    "stream): its buffer and position are lost; not resuming"
                ),
                now,
            )

    def _correct_line_model(self, now: float, newest: InFlight) -> None:
        """Frame ``newest`` has arrived: at most the bytes written after it are still queued."""
        st = self.state
        done = newest.end_offset
        st.line_free_s = min(st.line_free_s, now + (self.count.bytes_sent - done) * self.byte_s)
        for seq in range(newest.seq + 1, st.nxt):
            rec = st.window[seq]
            if rec.copies:
                rec.leaves_s = min(rec.leaves_s, now + max(0, rec.end_offset - done) * self.byte_s)

    # -- streaming: timers -------------------------------------------------------------------
    def _fill_window(self, now: float) -> None:
        """New frames, as far as the credit goes: batches of :attr:`per_frame` periods
        (a partial one waits while the program is open), then END."""
        st, prog = self.state, self.program
        while self._end_seq is None:
            periods = min(self.per_frame, prog.periods - self._framed_periods)
            if self.program_open and periods < self.per_frame:
                break  # a partial batch (or END) waits for the periods that follow
            if not self.ignore_credit and st.in_flight + periods > st.credit:
                break
            rec = st.window[st.nxt] = self._record(st.nxt, periods)
            self._send(None, rec)
            st.in_flight += rec.periods
            self.count.max_in_flight = max(self.count.max_in_flight, st.in_flight)
            st.nxt += 1

    def _record(self, i: int, periods: int) -> InFlight:
        """Frame ``i``: a BATCH of the next ``periods`` periods (with the position it starts
        from), or END when none are left."""
        prog, first = self.program, self._framed_periods
        self._frame_starts.append(first)
        if periods > 0:
            block = prog.pulses[first : first + periods]
            msg = p.Batch(block, tuple(int(v) for v in self._framed_position))
            self._framed_position = self._framed_position + block.sum(axis=0)
            self._framed_periods += periods
            return InFlight(i, p.encode_message(msg, seq=i), periods)
        self._end_seq = i
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
        """No valid frame for the timeout: contact lost. Frames in flight and none
        acknowledged although the card answers: a noisy line, retried while progress is
        possible (:meth:`_too_noisy`)."""
        st, timeout = self.state, self.options.timeout_s
        if now - st.last_rx_s > timeout:
            self._stop(
                StreamError(f"lost communication with card: no answer {what} for {timeout:g} s"),
                now,
            )
            return
        verdict = self._too_noisy(now)
        if verdict is not None:
            self._stop(StreamError(verdict), now)

    def _stall_deadline_s(self, now: float) -> float:
        """When :meth:`_too_noisy` must look again with frames in flight (it also looks at
        every other event: a copy written changes its verdict)."""
        st, opt = self.state, self.options
        since = max(st.last_progress_s, st.window[st.base].written_s)
        if opt.stall_limit_s is not None:
            return since + opt.stall_limit_s
        if now <= since + opt.timeout_s:
            return since + opt.timeout_s
        return since + MAX_STALL_TIMEOUTS * opt.timeout_s

    def _too_noisy(self, now: float) -> str | None:
        """Why the stream gives up on a live line that acknowledges nothing, or None.

        The oldest frame in flight has been sent ``copies`` times since the card last
        acknowledged one. On a line that loses a fraction q of the copies (measured:
        :attr:`Counters.frame_error_rate`), all of n copies are lost with probability q^n;
        the stream gives up when that is below :data:`GIVE_UP_PROBABILITY` (n =
        :func:`attempts_needed`), and not before the timeout: no progress for a time that
        grows with the error rate (at most :data:`MAX_STALL_TIMEOUTS` timeouts). A line that
        never carried a frame gives up after the timeout; ``stall_limit_s``, when set, is the
        user's own limit instead.
        """
        st, opt = self.state, self.options
        if st.base >= st.nxt:
            return None
        oldest = st.window[st.base]
        stalled_s = now - max(st.last_progress_s, oldest.written_s)
        rate = self.count.round_trip_error(len(oldest.data))
        if opt.stall_limit_s is not None:
            if stalled_s <= opt.stall_limit_s:
                return None
        elif stalled_s <= opt.timeout_s or (
            oldest.copies < attempts_needed(rate)
            and stalled_s <= MAX_STALL_TIMEOUTS * opt.timeout_s
        ):
            return None
        measured = (
            f" ({oldest.copies} copies of one frame lost; measured round-trip error rate "
            f"{rate:.1%})"
            if rate > 0.0
            else ""
        )
        return (
            f"the card acknowledged no frame for {stalled_s:.3g} s though it answers: "
            f"the line is too noisy{measured}"
        )


#: The stream gives up on a live line when every copy sent since the last acknowledgement
#: being lost is less likely than this, at the line's measured error rate.
GIVE_UP_PROBABILITY = 1e-6
#: Longest wait for an acknowledgement on a live line, in timeouts (``--timeout``).
MAX_STALL_TIMEOUTS = 30.0


def attempts_needed(error_rate: float) -> int:
    """Copies of one frame that a line losing ``error_rate`` of them all loses with
    probability below GIVE_UP_PROBABILITY: ceil(ln P / ln q) (1 for a clean line)."""
    if error_rate <= 0.0:
        return 1
    q = min(error_rate, 0.999)
    return math.ceil(math.log(GIVE_UP_PROBABILITY) / math.log(q))
