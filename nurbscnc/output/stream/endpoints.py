"""Where a simulated card listens: a pseudo-terminal (:class:`PtyEndpoint`) or a loopback TCP
socket (:class:`TcpEndpoint`), and :func:`serve`, the loop that runs a card on one until told
to stop, optionally at a serial line's byte rate (:class:`~.wire.Wire`)."""

from __future__ import annotations

import ipaddress
import os
import select
import socket
import threading
import time
import tty

import numpy as np

from nurbscnc.errors import ConfigError, StreamError
from nurbscnc.output.stream.wire import Wire


class PtyEndpoint:
    """A pseudo-terminal: the card holds the master, ``path`` is the slave the sender opens.

    The card keeps its own descriptor of the slave open (so a sender closing the port is not an
    error) and puts the line in raw mode (no echo, no line editing).
    """

    def __init__(self) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)
        os.set_blocking(self.master, False)
        self.closed = False

    def fileno(self) -> int:
        return self.master

    def read(self) -> bytes | None:
        """Available bytes; None when the endpoint is gone."""
        try:
            return os.read(self.master, 65536)
        except BlockingIOError:
            return b""
        except OSError:
            return None

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        deadline = time.monotonic() + 0.5
        while view and time.monotonic() < deadline:
            try:
                n = os.write(self.master, view)
                view = view[n:]
            except BlockingIOError:
                select.select([], [self.master], [], 0.01)
            except OSError:
                return

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            for fd in (self.master, self._slave):
                try:
                    os.close(fd)
                except OSError:
                    pass


def parse_listen(address: str) -> tuple[str, int]:
    """``HOST:PORT`` → (host, port); only loopback hosts (the protocol is unauthenticated)."""
    host, sep, port = address.rpartition(":")
    host = host.strip("[]")
    try:
        if not sep or not host:
            raise ValueError
        number = int(port)
        if not 0 <= number <= 65535 or not ipaddress.ip_address(host).is_loopback:
            raise ValueError
    except ValueError:
        raise ConfigError(
            f"--listen wants a loopback HOST:PORT such as 127.0.0.1:5555, got {address!r}"
        ) from None
    return host, number


class TcpEndpoint:
    """A loopback TCP listener (for ``socket://HOST:PORT``); one connection at a time."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0):
        if not ipaddress.ip_address(host).is_loopback:
            raise ConfigError(f"card-sim listens on loopback addresses only, not {host}")
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._server = socket.socket(family, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._server.bind((host, port))
        except OSError as exc:
            self._server.close()
            raise StreamError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
        self._server.listen(1)
        self._server.setblocking(False)
        self.host, self.port = self._server.getsockname()[:2]
        self.path = f"socket://{host}:{self.port}"
        self._conn: socket.socket | None = None
        self.connections = 0
        self.closed = False

    def fileno(self) -> int:
        return self._conn.fileno() if self._conn is not None else self._server.fileno()

    def read(self) -> bytes | None:
        if self._conn is None:
            try:
                conn, _ = self._server.accept()
            except BlockingIOError:
                return b""
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conn = conn
            self.connections += 1
            return b""
        try:
            data = self._conn.recv(65536)
        except BlockingIOError:
            return b""
        except OSError:
            data = b""
        if not data:  # the peer closed: wait for the next connection
            self._conn.close()
            self._conn = None
            return None
        return data

    def write(self, data: bytes) -> None:
        if self._conn is None:
            return
        view = memoryview(data)
        deadline = time.monotonic() + 0.5
        while view and time.monotonic() < deadline:
            try:
                view = view[self._conn.send(view) :]
            except BlockingIOError:
                select.select([], [self._conn], [], 0.01)
            except OSError:
                return

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            if self._conn is not None:
                self._conn.close()
            self._server.close()


def serve(
    card,
    endpoint,
    stop: threading.Event | None = None,
    *,
    once: bool = False,
    baud: int | None = None,
    log=None,
    linger_s: float = 0.3,
) -> None:
    """Run ``card`` (a :class:`~.card.CardSim`) on ``endpoint`` until ``stop`` is set (or,
    with ``once``, a stream ended).

    ``baud``: emulate a serial line's byte rate in both directions (None: unlimited).
    ``log``: a text file; every executed period is appended as ``period,x,y,z`` (the header is
    written first). With ``once`` the card keeps answering for ``linger_s`` after the stream
    ended (so the sender reads the final status), then returns; a TCP peer that disconnects
    after a stream started also ends a ``once`` run.
    """
    stop = stop or threading.Event()
    wire_in, wire_out = Wire(baud), Wire(baud)
    logged = 0
    if log is not None:
        names = card.config.axis_names or "xyzabcuvw"[: card.config.axes]
        log.write("period," + ",".join(names) + "\n")
    ended_at = None
    while not stop.is_set():
        now = time.monotonic()
        wake = [
            t for t in (card.next_event_s(), wire_in.next_s(), wire_out.next_s()) if t is not None
        ]
        timeout = 0.02 if not wake else min(0.02, max(0.0, min(wake) - now))
        try:
            readable, _, _ = select.select([endpoint.fileno()], [], [], timeout)
        except (OSError, ValueError):
            return
        if readable:
            data = endpoint.read()
            if data is None:
                if isinstance(endpoint, PtyEndpoint) or (once and card.frames_received):
                    return
                continue
            wire_in.push(data, time.monotonic())
        now = time.monotonic()
        incoming = wire_in.pop(now)
        if incoming:
            card.on_bytes(incoming, now)
        card.advance(now)
        wire_out.push(card.take_output(now), now)
        outgoing = wire_out.pop(now)
        if outgoing:
            endpoint.write(outgoing)
        if log is not None and card.executed_periods > logged:
            rows = card.take_log(logged)
            index = np.arange(logged + 1, logged + 1 + len(rows))
            np.savetxt(log, np.column_stack([index, rows]), fmt="%d", delimiter=",")
            logged += len(rows)
        if once:
            if card.finished and ended_at is None:
                ended_at = now
            elif not card.finished:
                ended_at = None
            if ended_at is not None and now - ended_at > linger_s:
                return
