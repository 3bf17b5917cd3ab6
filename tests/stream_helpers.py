"""Shared fixtures of the stream tests: a card simulator serving in a thread."""

from __future__ import annotations

import contextlib
import threading

from nurbscnc.output.stream.card import CardConfig, CardSim, PtyEndpoint, TcpEndpoint, serve


@contextlib.contextmanager
def card_on(kind: str, config: CardConfig | None = None, seed: int = 1):
    """A card serving on a pty ("pty") or a loopback TCP port ("tcp") in a thread; yields
    (card, endpoint) and stops it on exit."""
    card = CardSim(config or CardConfig(speed=None), seed=seed)
    endpoint = PtyEndpoint() if kind == "pty" else TcpEndpoint("127.0.0.1", 0)
    stop = threading.Event()
    thread = threading.Thread(target=serve, args=(card, endpoint, stop), daemon=True)
    thread.start()
    try:
        yield card, endpoint
    finally:
        stop.set()
        thread.join(5.0)
        endpoint.close()
