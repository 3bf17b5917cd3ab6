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


def write_mixed_steps_machine(folder, monkeypatch):
    """The bundled machine profile with 800 / 1000 / 400 steps per mm on X / Y / Z (a
    mixed-up axis or a steps-per-mm slip shows in the card's counters), written to
    ``folder/m.toml``; the discovery variables cleared and ``folder`` made the working
    directory. Returns ``folder``."""
    from pathlib import Path

    import nurbscnc

    for name in ("NURBSCNC_MACHINE", "NURBSCNC_VAR", "XDG_CONFIG_HOME"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.chdir(folder)
    bundled = Path(nurbscnc.__file__).parent / "data" / "default_machine.toml"
    text = bundled.read_text()
    steps = "[steps.per_mm]\n"
    head, tail = text.split(steps)
    tail = tail.replace("x = 1000.0", "x = 800.0", 1).replace("z = 1000.0", "z = 400.0", 1)
    (Path(folder) / "m.toml").write_text(head + steps + tail)
    return folder


def continue_when_at_rest(sim, position: list, seen: dict, timeout_s: float, settle_s: float):
    """Start a thread that waits (at most ``timeout_s``) for the card ``sim`` to be DONE at
    ``position`` (a program stop: the card at rest), watches it stay there ``settle_s``,
    records what it saw as ``seen["still"]`` (state name, position) and then continues the
    stream as the operator does (SIGUSR2). Returns the started thread."""
    import os
    import signal
    import time

    def watch() -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if sim.state.name == "DONE" and sim.position.tolist() == position:
                time.sleep(settle_s)
                seen["still"] = (sim.state.name, sim.position.tolist())
                os.kill(os.getpid(), signal.SIGUSR2)
                return
            time.sleep(0.01)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread
