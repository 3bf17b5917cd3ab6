"""The reliable sender: streams a :class:`~.quantise.PulseProgram` to a card over a port.

Selective repeat over the framed protocol (``docs/protocol.md``):

- BATCH and END frames carry sequence numbers; the card runs them strictly in order (it keeps
  frames that arrive after a gap until the gap is filled, drops duplicates) and acknowledges
  cumulatively (ACK: next expected sequence number and free buffer), so every batch runs
  exactly once and in order.
- A NAK (CRC failure or a gap) names the frame the card expects: it is sent again at once
  (fast retransmit; once more only when the new copy should have arrived). With no progress for
  the retransmission timeout the oldest unacknowledged frame is sent again and the timeout
  doubles (exponential back-off, capped; progress ends the back-off). The timeout follows the
  measured
  round trip as TCP's does (RFC 6298: SRTT + 4·RTTVAR, samples only from frames sent once,
  the first one from HELLO → CAPS), counted from when the frame's last byte should have left
  the line, so a queue of frames is not mistaken for a loss. That time comes from a model of
  the line at its baud rate (10 bits per byte): the bytes written before the frame, or those
  the port reports still queued (``out_waiting``) if more; every ACK corrects the model (the
  card has every byte up to the acknowledged frame, so at most the bytes written after it
  are still on their way), which keeps it right on links faster than their nominal baud. A
  STATUS or ACK that shows no progress although the oldest frame should long have arrived
  counts as a NAK (the card's periodic STATUS then recovers a loss whose NAK was lost too).
- Credit-based flow control: the periods in unacknowledged frames never exceed the free buffer
  the card last reported, so the card's buffer cannot overflow.
- No valid frame from the card for ``timeout_s`` ends the stream ("lost communication with
  card"); a CAPS with a new session id (the card reset) is fatal, never resumed; an ALARM
  (e.g. buffer underrun) ends the stream with its code and text.
- :meth:`Sender.request_abort` (from a signal handler) makes the loop flush what is queued in
  the port, send ABORT at once, wait briefly for the card to confirm, and raise
  :class:`StreamInterrupted` (exit code 130).

The sender is the only code here that does I/O (through a pyserial port object).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import serial

from nurbscnc.errors import EXIT_INTERRUPTED, ConfigError, StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.quantise import PulseProgram

#: URL schemes accepted with ``--allow-url`` (pyserial URL handlers; both unauthenticated).
URL_SCHEMES = ("socket", "rfc2217")
_STREAMING = (p.CardState.FILLING, p.CardState.RUNNING, p.CardState.HOLD)


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
    abort_wait_s: float = 0.5  #: how long to wait for the card to confirm an abort
    read_wait_s: float = 0.001  #: port read timeout: the loop's idle tick
    link_baud: int | None = None  #: line rate for the queue model (None: the port's baudrate)

    def __post_init__(self) -> None:
        if self.batch_periods < 1:
            raise ConfigError(f"--batch must be >= 1 period, got {self.batch_periods}")
        if not self.timeout_s > 0.0:
            raise ConfigError(f"--timeout must be > 0 s, got {self.timeout_s}")


@dataclass(frozen=True)
class Progress:
    """A progress snapshot [periods]."""

    periods: int
    sent: int
    acked: int
    executed: int
    fill: int
    buffer: int


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

    def to_json(self) -> dict:
        out = asdict(self)
        out["final_position_steps"] = list(self.final_position_steps)
        out["expected_position_steps"] = list(self.expected_position_steps)
        return out


def open_port(port: str, baud: int = 115200, allow_url: bool = False,
              write_timeout_s: float = 2.0, read_wait_s: float = 0.001):  # fmt: skip
    """Open ``port`` exclusively: a device path, or a pyserial URL only with ``allow_url``.

    URLs (``socket://``, ``rfc2217://``) reach a card over the network without any
    authentication, so they need an explicit opt-in. Raises ConfigError (a URL without
    ``allow_url``, an unknown scheme) or StreamError (cannot open, port busy).
    """
    try:
        if "://" in port:
            scheme = port.split("://", 1)[0].lower()
            if not allow_url:
                raise ConfigError(
                    f"--port {port!r} is a URL; URLs are unauthenticated network connections, "
                    "give --allow-url to use one (or a device path such as /dev/ttyUSB0)"
                )
            if scheme not in URL_SCHEMES:
                raise ConfigError(f"--port: URL scheme {scheme!r} is not one of "
                                  f"{', '.join(s + '://' for s in URL_SCHEMES)}")  # fmt: skip
            return serial.serial_for_url(port, baudrate=baud, timeout=read_wait_s,
                                         write_timeout=write_timeout_s)  # fmt: skip
        return serial.Serial(port=port, baudrate=baud, timeout=read_wait_s,
                             write_timeout=write_timeout_s, exclusive=True)  # fmt: skip
    except serial.SerialException as exc:
        text = str(exc)
        if "exclusively lock" in text:
            raise StreamError(f"port {port} is busy: another program has it open") from None
        raise StreamError(f"cannot open port {port}: {text}") from None
    except (OSError, ValueError) as exc:
        raise StreamError(f"cannot open port {port}: {exc}") from None


class Sender:
    """Streams pulse programs over an open pyserial ``port`` (see the module docstring).

    ``progress`` is called with a :class:`Progress` about ten times a second.
    ``_ignore_credit`` disables flow control; it exists only so the tests can show that the
    card catches a sender that overruns its buffer.
    """

    def __init__(self, port, options: SenderOptions | None = None,
                 progress: Callable[[Progress], None] | None = None,
                 _ignore_credit: bool = False):  # fmt: skip
        self.port = port
        self.options = options or SenderOptions()
        self.progress = progress
        self._ignore_credit = _ignore_credit
        self._decoder = p.FrameDecoder()
        self._abort_requested = False
        self._want_hold: bool | None = None
        self.caps: p.Caps | None = None
        self.status: p.Status | None = None
        self.alarm: p.Alarm | None = None
        self.abort_confirmed = False
        self.frames_sent = self.bytes_sent = self.bytes_received = 0
        self.retransmits = self.timeouts = self.naks_received = self.crc_errors = 0
        self.polls = self.protocol_errors = self.max_in_flight = 0
        self._last_rx = time.monotonic()
        # The line model needs a real line: a device's baud rate (or link_baud). A URL port
        # (a TCP socket) has no baud rate, so it is modelled as instantaneous.
        baud = self.options.link_baud or (port.baudrate if isinstance(port, serial.Serial)
                                          else None)  # fmt: skip
        self._byte_s = p.BITS_PER_BYTE_8N1 / float(baud) if baud else 0.0
        self._last_resend_s = -math.inf
        self._line_free = 0.0  # when the line will have sent everything written (model)
        self._first_rtt_s: float | None = None

    # -- requests (safe to call from a signal handler or another thread) ----------------------
    def request_abort(self) -> None:
        """Abort at the next loop turn: ABORT bypasses every queued frame."""
        self._abort_requested = True

    def request_hold(self) -> None:
        """Feed hold: the card stops at the next period boundary, keeps its buffer."""
        self._want_hold = True

    def request_resume(self) -> None:
        """Leave a feed hold."""
        self._want_hold = False

    # -- port --------------------------------------------------------------------------------
    def _write(self, data: bytes) -> float:
        """Write one frame; return when its last byte should be on the line [monotonic s]."""
        try:
            queued = self.port.out_waiting  # bytes ahead of this frame (TIOCOUTQ)
        except Exception:  # noqa: BLE001 - URL ports have no queue count: take it as empty
            queued = 0
        now = time.monotonic()
        start = max(now + queued * self._byte_s, self._line_free)
        done_s = self._line_free = start + len(data) * self._byte_s
        try:
            self.port.write(data)
        except serial.SerialTimeoutException:
            raise StreamError(
                f"lost communication with card: the port took no data for "
                f"{self.options.timeout_s:g} s"
            ) from None
        except (serial.SerialException, OSError) as exc:
            raise StreamError(f"lost the port: {exc}") from None
        self.frames_sent += 1
        self.bytes_sent += len(data)
        return done_s

    def _read(self) -> list:
        try:
            waiting = self.port.in_waiting
            data = self.port.read(waiting if waiting > 1 else 4096)
        except (serial.SerialException, OSError) as exc:
            raise StreamError(f"lost the port: {exc}") from None
        self.bytes_received += len(data)
        return self._decoder.feed(data) if data else []

    def _messages(self) -> list:
        """Decoded messages read now; counts bad frames; refreshes the lost-contact timer."""
        out = []
        for ev in self._read():
            if isinstance(ev, p.BadFrame):
                self.crc_errors += 1
                continue
            self._last_rx = time.monotonic()
            try:
                out.append(p.decode_message(ev))
            except p.ProtocolError:
                self.protocol_errors += 1
        return out

    def _check_contact(self, now: float, what: str) -> None:
        if now - self._last_rx > self.options.timeout_s:
            raise StreamError(
                f"lost communication with card: no answer {what} for "
                f"{self.options.timeout_s:g} s"
            )

    # -- handshake ---------------------------------------------------------------------------
    def handshake(self, program: PulseProgram) -> p.Caps:
        """HELLO until a CAPS comes; check the card can run ``program`` from where it is."""
        import contextlib

        with contextlib.suppress(Exception):
            self.port.reset_input_buffer()
        self._last_rx = time.monotonic()
        last_hello = -math.inf
        hellos = 0
        caps = None
        while caps is None:
            if self._abort_requested:
                self._abort()
            now = time.monotonic()
            if now - last_hello >= self.options.rto_s:
                hello_done = self._write(p.encode_message(p.Hello()))
                last_hello = now
                hellos += 1
            for msg in self._messages():
                if isinstance(msg, p.Caps):
                    caps = msg
                    if hellos == 1:  # an unambiguous round trip seeds the timeout
                        self._first_rtt_s = max(0.0, time.monotonic() - hello_done)
            self._check_contact(time.monotonic(), "to HELLO")
        self.caps = caps
        self._check_caps(caps, program)
        return caps

    def _check_caps(self, caps: p.Caps, prog: PulseProgram) -> None:
        axes = prog.pulses.shape[1] if prog.pulses.ndim == 2 else len(prog.start_steps)
        problems = []
        if caps.version != p.PROTOCOL_VERSION:
            problems.append(f"it speaks protocol version {caps.version}, nurbscnc speaks "
                            f"{p.PROTOCOL_VERSION}")  # fmt: skip
        if caps.axes != axes:
            problems.append(f"it has {caps.axes} axes, the program has {axes}")
        period_us = round(prog.period_s * 1e6)
        if caps.period_us != period_us:
            problems.append(f"its period is {caps.period_us} µs, the machine's servo period "
                            f"is {period_us} µs")  # fmt: skip
        if prog.peak_pulses > caps.max_pulses_per_period:
            problems.append(f"it takes at most {caps.max_pulses_per_period} pulses per period, "
                            f"the program needs {prog.peak_pulses}")  # fmt: skip
        if caps.state in (p.CardState.RUNNING, p.CardState.HOLD):
            problems.append(f"it is busy ({p.CardState(caps.state).name}) with another stream")
        if problems:
            raise StreamError("the card cannot run this program: " + "; ".join(problems))
        start = tuple(int(v) for v in prog.start_steps)
        if tuple(caps.position_steps) != start:
            raise StreamError(
                f"the card is at {list(caps.position_steps)} steps, the program starts at "
                f"{list(start)} steps: move or zero the card first"
            )

    # -- streaming ---------------------------------------------------------------------------
    def stream(self, program: PulseProgram) -> StreamReport:
        """Handshake, then :meth:`run`; on a failure after the handshake, try to send ABORT."""
        t0 = time.monotonic()
        self.handshake(program)
        try:
            return self.run(program, t0)
        except StreamInterrupted:
            raise
        except BaseException:
            # Whatever went wrong, a card that may still be running should stop.
            try:
                self.port.write(p.encode_message(p.Abort()))
            except Exception:  # noqa: BLE001 - best effort on a port that may be gone
                pass
            raise

    def run(self, program: PulseProgram, t0: float | None = None) -> StreamReport:
        """Stream every period of ``program`` after a successful :meth:`handshake`."""
        caps = self.caps
        if caps is None:
            raise StreamError("no handshake with the card")
        t0 = time.monotonic() if t0 is None else t0
        opt = self.options
        pulses = program.pulses
        axes = caps.axes
        width = p.pulse_width_bytes(program.peak_pulses)
        per_frame = max(1, min(opt.batch_periods, p.max_batch_periods(axes, width)))
        n_periods = program.periods
        n_batches = -(-n_periods // per_frame)
        total = n_batches + 1  # the batches, then END

        def periods_of(i: int) -> int:
            return 0 if i >= n_batches else min(per_frame, n_periods - i * per_frame)

        def encode(i: int) -> bytes:
            if i < n_batches:
                block = pulses[i * per_frame : i * per_frame + per_frame]
                return p.encode_message(p.Batch(block), seq=i)
            end = tuple(int(v) for v in program.end_steps)
            return p.encode_message(p.End(n_periods, end), seq=i)

        base = nxt = in_flight = 0
        credit = caps.buffer_periods
        frames: dict[int, bytes] = {}
        sent_at: dict[int, float] = {}  # when the last copy of the frame left the line
        end_off: dict[int, int] = {}  # bytes_sent just after that copy
        written_at: dict[int, float] = {}  # when the first copy was written
        resent: set[int] = set()
        rtt = _RoundTrip(opt)
        if self._first_rtt_s is not None:
            rtt.sample(self._first_rtt_s)
        last_poll = last_progress = last_ctl = -math.inf
        self._last_rx = time.monotonic()

        def resend_oldest() -> None:
            self._last_resend_s = time.monotonic()
            sent_at[base] = self._write(frames[base])
            end_off[base] = self.bytes_sent
            resent.add(base)
            self.retransmits += 1

        while True:
            if self._abort_requested:
                self._abort()
            now = time.monotonic()
            for msg in self._messages():
                resend = False
                if isinstance(msg, (p.Ack, p.Nak, p.Status)):
                    ahead = p.seq_ahead(base % p.SEQ_MODULO, msg.next_seq)
                    # No progress although the oldest frame should have arrived long ago:
                    # it was lost (and so was its NAK, or no later frame raised one).
                    resend = ahead == 0 and base < nxt and now - sent_at[base] > rtt.stale_s
                    if ahead <= nxt - base:  # else stale or bogus: ignore it whole
                        if ahead:
                            newest = base + ahead - 1
                            # Karn: no samples from retransmitted frames, nor from frames
                            # whose acknowledgement waited for a retransmission before them.
                            if newest not in resent and written_at[newest] > self._last_resend_s:
                                rtt.sample(max(0.0, now - sent_at[newest]))
                            self._correct_line_model(now, newest, nxt, sent_at, end_off)
                            rtt.progress()
                        for i in range(base, base + ahead):
                            in_flight -= periods_of(i)
                            del frames[i], sent_at[i], end_off[i], written_at[i]
                            resent.discard(i)
                        base += ahead
                        credit = msg.free_periods
                if isinstance(msg, p.Nak):
                    self.naks_received += 1
                    if msg.reason == p.NakReason.STATE:
                        last_poll = -math.inf  # ask what state the card is in
                    else:
                        resend = True
                # Fast retransmit; a frame already sent again is sent once more only when its
                # new copy should have arrived (older NAKs may still be on their way).
                if resend and base < nxt and (base not in resent
                                              or now - sent_at[base] > rtt.stale_s):  # fmt: skip
                    resend_oldest()
                if isinstance(msg, p.Status):
                    self.status = msg
                    self._check_state(msg)
                elif isinstance(msg, p.Alarm):
                    self.alarm = msg
                    raise StreamError(f"card alarm {_alarm_name(msg.code)}: {msg.text}")
                elif isinstance(msg, p.Caps) and msg.session_id != caps.session_id:
                    raise StreamError(
                        f"the card reset during the stream (session {caps.session_id:08x} → "
                        f"{msg.session_id:08x}): its buffer and position are lost; not resuming"
                    )
            now = time.monotonic()
            self._check_contact(now, "from the card")

            # New frames, as far as the credit goes.
            while nxt < total and (self._ignore_credit
                                   or in_flight + periods_of(nxt) <= credit):  # fmt: skip
                frames[nxt] = encode(nxt)
                written_at[nxt] = time.monotonic()
                sent_at[nxt] = self._write(frames[nxt])
                end_off[nxt] = self.bytes_sent
                in_flight += periods_of(nxt)
                self.max_in_flight = max(self.max_in_flight, in_flight)
                nxt += 1

            # Retransmission timeout with back-off.
            if base < nxt and now - sent_at[base] > rtt.rto:
                self.timeouts += 1
                resend_oldest()
                rtt.back_off()

            # Feed hold / resume until the card's state confirms it.
            if self._want_hold is not None and now - last_ctl > opt.rto_s:
                st = self.status.state if self.status else None
                if (st == p.CardState.HOLD) == self._want_hold and st is not None:
                    self._want_hold = None
                else:
                    self._write(p.encode_message(p.Hold() if self._want_hold else p.Resume()))
                    last_ctl = now

            if now - max(self._last_rx, last_poll) > opt.poll_s:
                self._write(p.encode_message(p.StatusRequest()))
                self.polls += 1
                last_poll = now

            st = self.status
            if self.progress is not None and now - last_progress > 0.1:
                last_progress = now
                self.progress(Progress(n_periods, min(nxt * per_frame, n_periods),
                                       min(base * per_frame, n_periods),
                                       st.executed_periods if st else 0,
                                       st.fill_periods if st else 0,
                                       caps.buffer_periods))  # fmt: skip
            if base == total and st is not None and st.state == p.CardState.DONE:
                break

        return self._finish(program, t0)

    def _correct_line_model(self, now, newest, nxt, sent_at, end_off) -> None:
        """Frame ``newest`` has arrived: at most the bytes written after it are still queued."""
        done = end_off[newest]
        self._line_free = min(self._line_free, now + (self.bytes_sent - done) * self._byte_s)
        for i in range(newest + 1, nxt):
            sent_at[i] = min(sent_at[i], now + max(0, end_off[i] - done) * self._byte_s)

    def _check_state(self, st: p.Status) -> None:
        if st.state == p.CardState.ALARM:
            text = self.alarm.text if self.alarm else "(no text received)"
            raise StreamError(f"card alarm {_alarm_name(st.alarm)}: {text}")
        if st.state == p.CardState.ABORTED:
            raise StreamError("the card aborted the stream")
        if st.state == p.CardState.IDLE:
            raise StreamError("the card reset during the stream (it reports no open stream): "
                              "its buffer and position are lost; not resuming")  # fmt: skip

    def _finish(self, program: PulseProgram, t0: float) -> StreamReport:
        st = self.status
        final = tuple(int(v) for v in st.position_steps)
        expected = tuple(int(v) for v in program.end_steps)
        if final != expected or st.executed_periods != program.periods:
            raise StreamError(
                f"the card ended at {list(final)} steps after {st.executed_periods} periods; "
                f"the program ends at {list(expected)} steps after {program.periods}"
            )
        return StreamReport(
            periods=program.periods, frames_sent=self.frames_sent, bytes_sent=self.bytes_sent,
            bytes_received=self.bytes_received, retransmits=self.retransmits,
            timeouts=self.timeouts, naks_received=self.naks_received,
            crc_errors=self.crc_errors, polls=self.polls,
            executed_periods=st.executed_periods, final_position_steps=final,
            expected_position_steps=expected, max_in_flight_periods=self.max_in_flight,
            buffer_periods=self.caps.buffer_periods, session_id=self.caps.session_id,
            duration_s=time.monotonic() - t0,
        )  # fmt: skip

    # -- abort -------------------------------------------------------------------------------
    def _abort(self) -> None:
        """Flush the port's queue, send ABORT now, wait briefly for the card, raise."""
        import contextlib

        self._abort_requested = False
        with contextlib.suppress(Exception):
            self.port.reset_output_buffer()  # queued batches must not reach the card first
        t0 = last = time.monotonic()
        try:
            self._write(p.encode_message(p.Abort()))
            while time.monotonic() - t0 < self.options.abort_wait_s:
                for msg in self._messages():
                    if isinstance(msg, p.Status):
                        self.status = msg
                        if msg.state not in _STREAMING:
                            self.abort_confirmed = True
                if self.abort_confirmed:
                    break
                if time.monotonic() - last > 0.1:
                    self._write(p.encode_message(p.Abort()))
                    last = time.monotonic()
        except StreamError:
            pass
        if self.abort_confirmed:
            where = f" at {list(self.status.position_steps)} steps"
            raise StreamInterrupted(f"interrupted: abort sent, the card stopped{where}")
        raise StreamInterrupted(
            f"interrupted: abort sent, no confirmation from the card within "
            f"{self.options.abort_wait_s:g} s"
        )


class _RoundTrip:
    """Retransmission timeout from round-trip samples (RFC 6298, α = 1/8, β = 1/4, K = 4)."""

    def __init__(self, opt: SenderOptions):
        self._opt = opt
        self._srtt: float | None = None
        self._rttvar = 0.0
        self._backoff = 1.0

    def sample(self, r_s: float) -> None:
        """A round trip of a frame sent once: update the estimate."""
        if self._srtt is None:
            self._srtt, self._rttvar = r_s, r_s / 2.0
        else:
            self._rttvar = 0.75 * self._rttvar + 0.25 * abs(self._srtt - r_s)
            self._srtt = 0.875 * self._srtt + 0.125 * r_s

    def back_off(self) -> None:
        self._backoff *= 2.0

    def progress(self) -> None:
        """The card acknowledged something new: the line works, end the back-off."""
        self._backoff = 1.0

    @property
    def stale_s(self) -> float:
        """Time after which a frame's missing acknowledgement means it was lost."""
        srtt = self._opt.rto_s if self._srtt is None else self._srtt
        return max(2.0 * srtt + 4.0 * self._rttvar, self._opt.rto_min_s / 2.0)

    @property
    def rto(self) -> float:
        opt = self._opt
        base = opt.rto_s if self._srtt is None else self._srtt + 4.0 * self._rttvar
        return min(opt.rto_max_s, max(opt.rto_min_s, base) * self._backoff)


def _alarm_name(code: int) -> str:
    try:
        return p.AlarmCode(code).name
    except ValueError:
        return f"#{code}"

