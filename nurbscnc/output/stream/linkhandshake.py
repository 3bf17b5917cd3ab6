"""The link's handshake: HELLO until a CAPS comes, the check that the card fits the program,
SET_POSITION for ``--zero``, and the batch layout the stream starts with."""

from __future__ import annotations

import math

import numpy as np

from nurbscnc.errors import StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.cardcheck import axes_problem, check_caps, fit_to_card
from nurbscnc.output.stream.linkstate import Phase


class HandshakeHandlers:
    """The handshake's handlers (a mixin of :class:`~.link.Link`: it provides ``state``,
    ``options``, ``program``, ``rtt``, ``_send``, ``_stop`` and ``_finish_error``)."""

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
            self._stop(
                StreamError(
                    f"lost communication with card: no answer to HELLO for "
                    f"{self.options.timeout_s:g} s (is it a card speaking protocol version "
                    f"{p.PROTOCOL_VERSION}?)"
                ),
                now,
            )

    def _on_caps_in_handshake(self, caps: p.Caps, now: float) -> None:
        st = self.state
        if st.hellos == 1:  # an unambiguous round trip seeds the timeout
            self.rtt.sample(max(0.0, now - st.hello_leaves_s))
        st.caps = caps
        if self.session_id is not None and caps.session_id != self.session_id:
            self._finish_error(
                StreamError(
                    f"the card reset between two parts of the program (session "
                    f"{self.session_id:08x} → {caps.session_id:08x}): its position is lost"
                )
            )
            return
        try:
            if axes_problem(caps, self.program) is None:
                # The card's axes the program does not move stand still where the card
                # stands (at zero with --zero): one count per driven axis in every frame.
                fixed = [0] * len(caps.position_steps) if self.zero else caps.position_steps
                self.card_fit = (caps, tuple(int(v) for v in fixed))
                self.program = self.fitted(self.program)
            check_caps(caps, self.program, position=not self.zero)
            lead = self.options.lead_periods
            if lead is not None and lead < caps.buffer_periods // 2:
                raise StreamError(
                    f"--lead {lead} is less than half the card's buffer of "
                    f"{caps.buffer_periods} periods: the card would wait for "
                    "periods the sender holds back"
                )
            start = tuple(int(v) for v in self.program.start_steps)
            if self.zero and tuple(caps.position_steps) != start and caps.version < 3:
                raise StreamError(
                    f"--zero needs a card speaking protocol version 3; it speaks {caps.version}"
                )
        except StreamError as exc:
            self._finish_error(exc)
            return
        if self.zero and tuple(caps.position_steps) != start:
            self._send(p.SetPosition(start))  # confirmed by a STATUS at the start
            st.zero_sent_s = now
            return
        self._start_streaming(now)

    def fitted(self, program):
        """``program`` widened to the axes the card drives (:func:`fit_to_card`), once the
        card's CAPS is known."""
        if self.card_fit is None:
            return program
        caps, fixed = self.card_fit
        return fit_to_card(program, caps, fixed)

    def _start_streaming(self, now: float) -> None:
        st = self.state
        self.zero = False
        width = p.pulse_width_bytes(max(self.program.peak_pulses, self.peak_pulses))
        axes = len(self.program.start_steps)
        self.batch_limit = max(
            1, min(self.options.batch_periods, p.max_batch_periods(st.caps.axes, width))
        )
        self.per_frame = self.batch_limit
        #: bytes of a BATCH frame: fixed + per period (the frame-size choice on noisy lines)
        one = p.batch_frame_bytes(1, axes, width)
        self._frame_bytes = (one - axes * width, axes * width)
        self._framed_position = np.asarray(self.program.start_steps, dtype=np.int64).copy()
        self._choose_batch()  # damaged replies in the handshake already tell of a noisy line
        st.credit = self._credit(st.caps.buffer_periods)
        st.phase = Phase.STREAMING
        st.last_rx_s = st.last_progress_s = now
