"""The link's end: ABORT repeated until the card confirms it stopped, and the card's final
state deciding between the report of a successful stream and the error."""

from __future__ import annotations

from nurbscnc.errors import StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.linkstate import (
    STREAMING_STATES,
    Phase,
    StreamInterrupted,
    StreamReport,
)


class StoppingHandlers:
    """The stopping phase's handlers (a mixin of :class:`~.link.Link`: it provides
    ``state``, ``options``, ``program``, ``count``, ``_outbox`` and ``_send``)."""

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
        self._finish_error(
            _with_suffix(
                self.state.error, f"no confirmation of the abort from the card within {wait}"
            )
        )

    def _finish_done(self, now: float) -> bool:
        """The card says DONE: success if it ran the program's periods to its end position."""
        st, prog = self.state, self.program
        status = st.status
        final = tuple(int(v) for v in status.position_steps)
        expected = tuple(int(v) for v in prog.end_steps)
        if final != expected or status.executed_periods != prog.periods:
            self._finish_error(
                StreamError(
                    f"the card ended at {list(final)} steps after {status.executed_periods} "
                    f"periods; the program ends at {list(expected)} steps after {prog.periods}"
                )
            )
            return False
        c = self.count
        st.report = StreamReport(
            periods=prog.periods,
            frames_sent=c.frames_sent,
            bytes_sent=c.bytes_sent,
            bytes_received=c.bytes_received,
            retransmits=c.retransmits,
            timeouts=c.timeouts,
            naks_received=c.naks_received,
            crc_errors=c.crc_errors,
            polls=c.polls,
            executed_periods=status.executed_periods,
            final_position_steps=final,
            expected_position_steps=expected,
            max_in_flight_periods=c.max_in_flight,
            buffer_periods=st.caps.buffer_periods,
            session_id=st.caps.session_id,
            duration_s=now - st.started_s,
            frame_error_rate=c.frame_error_rate,
            batch_periods=self.per_frame,
            axes=prog.axes,
        )
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
    out = type(error)(
        f"{error.message}, {text}"
        if isinstance(error, StreamInterrupted)
        else f"{error.message}; {text}"
    )
    return out
