"""The sender on a serial port: :class:`~.link.Link` (the protocol, free of I/O and clocks)
driven by a pyserial port and the monotonic clock.

:class:`Sender` moves bytes between the port and the link and reads the clock; everything the
protocol decides (selective repeat, retransmission timeouts, credit flow control, hold/resume,
abort, what ends the stream) is in :mod:`.link` and described in ``docs/protocol.md``.
:meth:`Sender.request_abort` / ``request_hold`` / ``request_resume`` are safe to call from a
signal handler. The sender is the only code here that does I/O (through a pyserial port).
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable

import serial

from nurbscnc.errors import ConfigError, StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.link import Link
from nurbscnc.output.stream.linkstate import (
    Progress,
    SenderOptions,
    StreamInterrupted,
    StreamReport,
)
from nurbscnc.output.stream.quantise import PulseProgram

__all__ = [
    "Sender",
    "SenderOptions",
    "StreamInterrupted",
    "StreamReport",
    "Progress",
    "open_port",
    "URL_SCHEMES",
]

#: URL schemes accepted with ``--allow-url`` (pyserial URL handlers; both unauthenticated).
URL_SCHEMES = ("socket", "rfc2217")


def open_port(
    port: str,
    baud: int = 115200,
    allow_url: bool = False,
    write_timeout_s: float = 2.0,
    read_wait_s: float = 0.001,
):
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
                raise ConfigError(
                    f"--port: URL scheme {scheme!r} is not one of "
                    f"{', '.join(s + '://' for s in URL_SCHEMES)}"
                )
            return serial.serial_for_url(
                port, baudrate=baud, timeout=read_wait_s, write_timeout=write_timeout_s
            )
        return serial.Serial(
            port=port,
            baudrate=baud,
            timeout=read_wait_s,
            write_timeout=write_timeout_s,
            exclusive=True,
        )
    except serial.SerialException as exc:
        text = str(exc)
        if "exclusively lock" in text:
            raise StreamError(f"port {port} is busy: another program has it open") from None
        raise StreamError(f"cannot open port {port}: {text}") from None
    except (OSError, ValueError) as exc:
        raise StreamError(f"cannot open port {port}: {exc}") from None


class Sender:
    """Streams pulse programs over an open pyserial ``port``.

    ``progress`` is called with a :class:`Progress` about ten times a second.
    ``_ignore_credit`` disables flow control (tests only: the card must catch it).
    ``clock`` is the time source [s] (monotonic).
    """

    def __init__(
        self,
        port,
        options: SenderOptions | None = None,
        progress: Callable[[Progress], None] | None = None,
        _ignore_credit: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.port = port
        self.options = options or SenderOptions()
        self.progress = progress
        self._ignore_credit = _ignore_credit
        self._clock = clock
        self.link: Link | None = None
        self._requests: list[str] = []  # before the link exists
        self._abort = False  # asked while no link runs (a job waiting between sections)
        self.job = None
        # The line model needs a real line: a device's baud rate (or link_baud). A URL port
        # (a TCP socket) has no baud rate, so it is modelled as instantaneous.
        baud = self.options.link_baud or (
            port.baudrate if isinstance(port, serial.Serial) else None
        )
        self.byte_s = p.BITS_PER_BYTE_8N1 / float(baud) if baud else 0.0

    # -- requests (safe to call from a signal handler or another thread) ----------------------
    def request_abort(self) -> None:
        """Abort: ABORT bypasses every queued frame; the stream ends with exit code 130."""
        self._request("abort")

    def request_hold(self) -> None:
        """Feed hold: the card stops at the next period boundary, keeps its buffer."""
        self._request("hold")

    def request_resume(self) -> None:
        """Leave a feed hold."""
        self._request("resume")

    def _request(self, what: str) -> None:
        if what == "abort":
            self._abort = True
        if self.link is None:
            self._requests.append(what)
        else:
            getattr(self.link, f"request_{what}")()

    @property
    def abort_requested(self) -> bool:
        """Ctrl-C / SIGTERM was asked (a job's work between sections stops for it)."""
        return self._abort

    @property
    def abort_confirmed(self) -> bool:
        return self.link is not None and self.link.state.abort_confirmed

    # -- streaming ---------------------------------------------------------------------------
    def stream(self, program: PulseProgram, zero: bool = False) -> StreamReport:
        """Handshake and stream ``program``; the card's final state decides the outcome.
        ``zero``: declare the card's position to be the program's start first.

        Raises StreamInterrupted (exit 130) after :meth:`request_abort`, StreamError when the
        stream failed (the card was sent ABORT until it confirmed, or for a bounded time).
        """
        link = Link(
            program, self.options, self.byte_s, ignore_credit=self._ignore_credit, zero=zero
        )
        for what in self._requests:
            getattr(link, f"request_{what}")()
        self._requests.clear()
        self.link = link
        with contextlib.suppress(Exception):
            self.port.reset_input_buffer()
        link.start(self._clock())
        try:
            return self._loop(link)
        except BaseException:
            if not link.finished:  # the port failed under the link: a best-effort ABORT
                with contextlib.suppress(Exception):
                    self.port.write(p.encode_message(p.Abort()))
            raise

    def _loop(self, link: Link, hook=None) -> StreamReport:
        last_progress = -1.0
        while True:
            self._write(link)
            if link.finished:
                break
            data = self._read()
            now = self._clock()
            if data:
                link.on_bytes(data, now)
            link.on_time(now)
            if hook is not None:
                hook(link)
            if (
                self.progress is not None
                and now - last_progress > 0.1
                and link.state.caps is not None
            ):
                last_progress = now
                self._report_progress(link.progress())
        return link.result()

    def _report_progress(self, pr: Progress) -> None:
        job = self.job
        if job is not None:
            pr = dataclasses.replace(
                pr,
                executed=job.executed_before + pr.executed,
                periods=job.executed_before + pr.periods,
                note=job.note(pr.executed),
            )
        self.progress(pr)

    # -- a job's sections (the controller decides them: nurbscnc.controller.run) -------------
    def stream_section(
        self,
        program: PulseProgram,
        *,
        session_id=None,
        zero: bool = False,
        peak_pulses: int | None = None,
        program_open: bool = False,
        hook=None,
    ) -> StreamReport:
        """Stream one section of a job (HELLO … END, the card DONE at rest at its end) in the
        session ``session_id`` (None: a new one); ``hook(link)`` is called on every turn of
        the loop (the controller's changes while the section streams). Raises like
        :meth:`stream`."""
        link = Link(
            program,
            self.options,
            self.byte_s,
            ignore_credit=self._ignore_credit,
            session_id=session_id,
            zero=zero,
        )
        if peak_pulses is not None:
            link.peak_pulses = peak_pulses
        link.program_open = program_open
        if self._abort:
            link.request_abort()
        self.link = link
        with contextlib.suppress(Exception):
            self.port.reset_input_buffer()
        link.start(self._clock())
        try:
            return self._loop(link, hook=hook)
        except BaseException:
            if not link.finished:
                with contextlib.suppress(Exception):
                    self.port.write(p.encode_message(p.Abort()))
            raise

    def wait_idle(self, job, reports: list, idle_s: float = 0.02) -> None:
        """The card is DONE at rest between sections: wait until the job no longer waits
        (the operator's continue, the next planned window) or an abort (StreamInterrupted,
        naming the card's position), reporting progress meanwhile."""
        self.job = job
        last = -1.0
        while job.waiting is not None:
            job.poll()  # a planning hold ends when the next window is planned
            if job.waiting is None:
                break
            if self._abort:
                where = (
                    f"; the card stands at {list(reports[-1].final_position_steps)} steps"
                    if reports
                    else ""
                )
                raise StreamInterrupted(f"interrupted while waiting ({job.waiting}){where}")
            now = self._clock()
            if self.progress is not None and now - last > 0.1:
                last = now
                self._report_progress(Progress(0, 0, 0, 0, 0, 0, job.last_line))
            time.sleep(idle_s)

    def _write(self, link: Link) -> None:
        if link.flush_port:  # an abort: queued batches must not reach the card first
            link.flush_port = False
            with contextlib.suppress(Exception):
                self.port.reset_output_buffer()
        try:
            queued = self.port.out_waiting  # bytes ahead of these frames (TIOCOUTQ)
        except Exception:  # noqa: BLE001 - URL ports have no queue count: take it as empty
            queued = 0
        for frame in link.take_writes(self._clock(), queued):
            try:
                self.port.write(frame)
            except serial.SerialTimeoutException:
                raise StreamError(
                    f"lost communication with card: the port took no data for "
                    f"{self.options.timeout_s:g} s"
                ) from None
            except (serial.SerialException, OSError) as exc:
                raise StreamError(f"lost the port: {exc}") from None

    def _read(self) -> bytes:
        try:
            waiting = self.port.in_waiting
            return self.port.read(waiting if waiting > 1 else 4096)
        except (serial.SerialException, OSError) as exc:
            raise StreamError(f"lost the port: {exc}") from None


def card_position(port, set_to=None, timeout_s: float = 2.0, retry_s: float = 0.1) -> p.Status:
    """Read the card's state and position (STATUS_REQUEST), or set its position first
    (SET_POSITION, protocol version 3; refused while a stream runs). Returns the STATUS that
    answers; StreamError when the card refuses or does not answer within ``timeout_s``."""
    msg = p.SetPosition(tuple(int(v) for v in set_to)) if set_to is not None else p.StatusRequest()
    frame = p.encode_message(msg)
    decoder = p.FrameDecoder()
    deadline = time.monotonic() + timeout_s
    last = -float("inf")
    with contextlib.suppress(Exception):
        port.reset_input_buffer()
    while time.monotonic() < deadline:
        now = time.monotonic()
        if now - last >= retry_s:
            port.write(frame)
            last = now
        for ev in decoder.feed(port.read(4096)):
            if isinstance(ev, p.BadFrame):
                continue
            try:
                reply = p.decode_message(ev)
            except p.ProtocolError:
                continue
            if isinstance(reply, p.Nak) and set_to is not None:
                raise StreamError(
                    "the card refused the new position: a stream is open on it "
                    "(FILLING, RUNNING or HOLD), or it has another axis count"
                )
            if isinstance(reply, p.Status) and (
                set_to is None or tuple(reply.position_steps) == tuple(msg.position_steps)
            ):
                return reply
    what = (
        "SET_POSITION (does the card speak protocol version 3?)"
        if set_to is not None
        else "STATUS_REQUEST"
    )
    raise StreamError(f"lost communication with card: no answer to {what} for {timeout_s:g} s")
