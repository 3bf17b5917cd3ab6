"""The operator of a stream: feed hold, continue, feed override and abort, asked by signal
or by a key on the terminal, routed to the running job or to the card's sender."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

from nurbscnc.output.background import signals_to_main_thread


class Operator:
    """What the operator asks, by signal or key: SIGUSR1 / space feed hold, SIGUSR2 / Enter
    continue (after a program stop or a hold), + / - feed override, SIGINT/SIGTERM abort (the
    last two only once the port is open; before, they end the command as usual).

    With a :class:`Job` (a planned program) hold and continue go to the job (a decelerating
    hold along the path); for a point file to the card (HOLD/RESUME: the card stops at the
    next period). A hold asked while the program is still being planned is kept, with a
    message: the stream then waits at the start until continued.
    """

    def __init__(self) -> None:
        self.sender = None
        self.job = None
        self.hold: bool | None = None  # asked before the sender existed

    def attach_job(self, job) -> None:
        self.job = job
        if job is not None and self.hold:
            job.request_hold()
            self.hold = None

    def attach(self, sender) -> None:
        self.sender = sender
        if self.hold is not None and self.job is None:
            (sender.request_hold if self.hold else sender.request_resume)()

    def on_hold(self, *_args) -> None:
        self._feed(True)

    def on_resume(self, *_args) -> None:
        self._feed(False)

    def on_abort(self, *_args) -> None:
        self.sender.request_abort()

    def on_key(self, key: bytes) -> None:
        if key in (b" ", b"h"):
            self._feed(True)
        elif key in (b"\n", b"\r", b"c"):
            self._feed(False)
        elif key in (b"+", b"=", b"-", b"_") and self.job is not None:
            self.job.step_override(1 if key in (b"+", b"=") else -1)

    def _feed(self, hold: bool) -> None:
        if self.job is not None:
            self.job.request_hold() if hold else self.job.resume()
            return
        if self.sender is not None:
            (self.sender.request_hold if hold else self.sender.request_resume)()
            return
        self.hold = hold
        text = (
            "feed hold asked while planning: the stream will wait at the start "
            "(SIGUSR2 continues)\n"
            if hold
            else "resume asked while planning: no feed hold when the stream opens\n"
        )
        # os.write, not print: a signal handler may interrupt a print in progress.
        with contextlib.suppress(OSError):
            os.write(2, b"stream: " + text.encode())


@contextlib.contextmanager
def routed_signals(operator: Operator, names: tuple[str, ...]):
    """Route the named signals to ``operator`` (main thread only); restore them after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    actions = {
        "SIGUSR1": operator.on_hold,
        "SIGUSR2": operator.on_resume,
        "SIGINT": operator.on_abort,
        "SIGTERM": operator.on_abort,
    }
    previous = {}
    try:
        for name in names:
            if hasattr(signal, name):
                sig = getattr(signal, name)
                previous[sig] = signal.signal(sig, actions[name])
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


@contextlib.contextmanager
def key_reader(operator: Operator, enabled: bool):
    """Read single keys from a terminal on stdin (cbreak mode, restored after) in a thread."""
    if not enabled:
        yield
        return
    import select
    import termios
    import tty

    fd = sys.stdin.fileno()
    try:
        saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
    except (termios.error, OSError):
        yield
        return
    stop = threading.Event()

    def read_keys() -> None:
        signals_to_main_thread()
        while not stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.1)
            if ready:
                key = os.read(fd, 1)
                if not key:
                    return
                operator.on_key(key)

    thread = threading.Thread(target=read_keys, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(1.0)
        with contextlib.suppress(termios.error, OSError):
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)


#: The most of a user M-code's output shown [bytes] (its last part: where errors are).
USER_M_OUTPUT_BYTES = 16384


def user_m_runner(timeout_s: float, err, aborted=lambda: False, poll_s: float = 0.05):
    """A callable running a user M-code's stop (``stop.argv``: the executable, then P and Q
    as text) as LinuxCNC does: no shell, the stream waiting for it to end, killed after
    ``timeout_s`` [s], or at once when ``aborted()`` (Ctrl-C / SIGTERM: StreamInterrupted,
    exit 130). Its output (stdout and stderr, to a temporary file so a chatty script
    cannot fill memory; the last :data:`USER_M_OUTPUT_BYTES` kept) is shown on ``err`` (a
    rich console, as plain text). Returns a :class:`~nurbscnc.controller.run.UserMResult`."""
    import subprocess
    import tempfile

    from nurbscnc.controller.run import UserMResult
    from nurbscnc.errors import StreamError
    from nurbscnc.output.stream.linkstate import StreamInterrupted

    def run(stop) -> UserMResult:
        err.print(
            f"stream: {stop.code} at line {stop.line}: running {' '.join(stop.argv)}",
            markup=False,
            highlight=False,
        )
        with tempfile.TemporaryFile() as out:
            try:
                proc = subprocess.Popen(
                    list(stop.argv), stdin=subprocess.DEVNULL, stdout=out, stderr=out
                )
            except OSError as exc:
                raise StreamError(
                    f"line {stop.line}: {stop.code}: cannot run {stop.argv[0]}: "
                    f"{exc.strerror or exc}"
                ) from None
            code = _wait_bounded(proc, timeout_s, aborted, poll_s)
            if aborted():
                raise StreamInterrupted(
                    f"interrupted while {stop.code} at line {stop.line} ran: it was killed"
                )
            size = out.seek(0, os.SEEK_END)
            out.seek(max(0, size - USER_M_OUTPUT_BYTES))
            text = out.read().decode("utf-8", errors="replace")
        if text.strip():
            err.print(text.rstrip("\n"), markup=False, highlight=False)
        return UserMResult(code, text, timeout_s)

    return run


def _wait_bounded(proc, timeout_s: float, aborted, poll_s: float) -> int | None:
    """Wait for ``proc`` at most ``timeout_s`` [s], checking ``aborted()`` every ``poll_s``;
    kill it at the timeout or the abort (then None)."""
    import subprocess
    import time

    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return proc.wait(timeout=max(min(poll_s, deadline - time.monotonic()), 0.0))
        except subprocess.TimeoutExpired:
            if aborted() or time.monotonic() >= deadline:
                proc.kill()
                proc.wait()
                return None


@contextlib.contextmanager
def card_port(link: dict):
    """The card's port (``link``: ``port``, ``baud``, ``allow_url``, ``timeout_s``), opened
    once for a whole command and closed at its end: reading where the card stands and
    streaming share it, since a port opened anew may reset a card (an Arduino-style board
    resets when the host asserts DTR on open) and another program could take the port
    between two openings."""
    from nurbscnc.output.stream.sender import open_port

    ser = open_port(
        link["port"],
        baud=link["baud"],
        allow_url=link["allow_url"],
        write_timeout_s=link["timeout_s"],
    )
    try:
        yield ser
    finally:
        with contextlib.suppress(Exception):
            ser.close()


def card_at_rest(ser, timeout_s: float) -> list[int]:
    """The card's position [steps], read on the open port ``ser`` (replies awaited at most
    ``timeout_s``): where ``mdi``, ``jog`` and ``stream`` start. StreamError (nothing sent)
    when a stream runs on the card (FILLING, RUNNING, HOLD) or it is in ALARM."""
    from nurbscnc.errors import StreamError
    from nurbscnc.output.stream import protocol as p
    from nurbscnc.output.stream.sender import card_position

    status = card_position(ser, None, timeout_s)
    state = p.CardState(status.state)
    if state in (p.CardState.FILLING, p.CardState.RUNNING, p.CardState.HOLD):
        raise StreamError(f"the card is {state.name}: a stream runs on it; nothing was sent")
    if state == p.CardState.ALARM:
        raise StreamError("the card is in ALARM: clear it first; nothing was sent")
    return list(status.position_steps)
