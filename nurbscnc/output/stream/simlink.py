"""A sender and a card simulator joined by a faulty serial line, in virtual time.

:func:`simulate` runs :class:`~.link.Link` (the sender's protocol) against
:class:`~.card.CardSim` over two :class:`~.card.Wire` objects paced at the baud rate, with a
:class:`Relay` on each direction that damages frames (bits flipped, frames or runs of bytes
lost). Nothing waits: time jumps from one event to the next (a byte arriving, a card period, a
sender timer), so a stream of seconds runs in milliseconds, the same way every time for a
seed. The link tests and the stream fault matrix (``bench/stream_bench.py``) use it.
:class:`SimCard` streams a job's sections the same way, for the controller's simulation
(:func:`nurbscnc.controller.simulate.simulate_job`).
"""

from __future__ import annotations

import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from nurbscnc.errors import StreamError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.card import CardConfig, CardSim
from nurbscnc.output.stream.link import Link
from nurbscnc.output.stream.linkstate import SenderOptions, StreamReport
from nurbscnc.output.stream.quantise import PulseProgram
from nurbscnc.output.stream.wire import Wire


@dataclass
class Relay:
    """A faulty relay on one direction of the line; every write (one frame) passes it.

    With probability ``corrupt_rate`` a frame gets 1–4 of its bits flipped (uniformly many,
    at uniform places); with probability ``drop_rate`` it is lost: half of the time whole, else
    a run of its bytes (a cut frame). Counters: ``frames``, ``corrupted``, ``dropped``, ``cut``.
    """

    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    seed: int = 0
    frames: int = 0
    corrupted: int = 0
    dropped: int = 0
    cut: int = 0
    rng: random.Random = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.rng = random.Random(self.seed)

    def __call__(self, frame: bytes) -> bytes:
        self.frames += 1
        r = self.rng.random()
        if r < self.drop_rate:
            if len(frame) < 2 or self.rng.random() < 0.5:
                self.dropped += 1
                return b""
            self.cut += 1
            start = self.rng.randrange(len(frame) - 1)
            stop = self.rng.randrange(start + 1, len(frame))
            return frame[:start] + frame[stop:]
        if r < self.drop_rate + self.corrupt_rate:
            self.corrupted += 1
            damaged = bytearray(frame)
            for bit in self.rng.sample(range(8 * len(frame)), self.rng.randint(1, 4)):
                damaged[bit // 8] ^= 1 << (bit % 8)
            return bytes(damaged)
        return frame


class SimLine:
    """A card and the two directions of its line, driven in virtual time."""

    def __init__(self, card: CardSim, to_card, to_host, baud: int | None):
        self.card, self.to_card, self.to_host = card, to_card, to_host
        self.down, self.up = Wire(baud), Wire(baud)
        self.now_s = 0.0  #: the virtual time of the turn being driven

    def drive(
        self, link: Link, t: float, limit: float, pending: list, run_event, hook=None
    ) -> float:
        """Run ``link`` from virtual time ``t`` until it finishes (or ``limit``): events
        from ``pending`` when their time comes (``run_event(event)``), ``hook(link)`` after
        every turn. Returns the time it ended."""
        card, down, up = self.card, self.down, self.up
        link.start(t)
        same_time = 0
        while not link.finished and t <= limit:
            while pending and pending[0][0] <= t:
                run_event(pending.pop(0))
            data = down.pop(t)
            if data:
                card.on_bytes(data, t)
            card.advance(t)
            for frame in card.take_frames(t):
                up.push(self.to_host(frame), t)
            data = up.pop(t)
            if data:
                link.on_bytes(data, t)
            link.on_time(t)
            self.now_s = t
            if hook is not None:
                hook(link)
            if link.flush_port:
                link.flush_port = False
                down.drop_unsent(t)
            for frame in link.take_writes(t, down.queued_bytes(t)):
                down.push(self.to_card(frame), t)
            if link.finished:
                break
            wake = [
                link.next_wakeup_s(t),
                card.next_event_s(),
                down.done_s(),
                up.done_s(),
                pending[0][0] if pending else None,
            ]
            t_next = min(w for w in wake if w is not None)
            # Instantaneous lines deliver at the same time: a few turns at one time, then on.
            same_time = same_time + 1 if t_next <= t else 0
            t = t_next if t_next > t else (t if same_time < 8 else t + 1e-6)
        return t


@dataclass
class SimResult:
    """How a simulated stream ended: the sender's report or error, the card, virtual time."""

    report: StreamReport | None
    error: StreamError | None
    card: CardSim
    link: Link
    elapsed_s: float  #: virtual time when the sender ended
    state_at_end: p.CardState  #: the card's state then (the card is settled afterwards)

    @property
    def completed(self) -> bool:
        """The sender reported success."""
        return self.report is not None

    def exact(self, program: PulseProgram) -> bool:
        """The card executed exactly the program's pulses and is DONE."""
        return self.card.state is p.CardState.DONE and np.array_equal(
            self.card.executed_pulses(), program.pulses
        )

    def stopped_cleanly(self, program: PulseProgram) -> bool:
        """The card does not move (any more), and what it executed is a prefix of the program.

        Judged after the card was left alone for its whole buffer's time: a card the sender's
        ABORT did not reach stops by itself (an underrun) once its buffer is empty; a FILLING
        or HOLD card executes nothing.
        """
        ran = self.card.executed_pulses()
        return self.card.state is not p.CardState.RUNNING and np.array_equal(
            ran, program.pulses[: len(ran)]
        )


def simulate(  # noqa: PLR0913 - a test harness with everything optional
    program: PulseProgram,
    config: CardConfig | None = None,
    *,
    options: SenderOptions | None = None,
    to_card: Callable[[bytes], bytes] | None = None,
    to_host: Callable[[bytes], bytes] | None = None,
    baud: int | None = 115200,
    seed: int = 1,
    events: Sequence[tuple[float, Callable[[Link, CardSim], None]]] = (),
    max_time_s: float | None = None,
    ignore_credit: bool = False,
) -> SimResult:
    """Stream ``program`` to a simulated card over a simulated line; see the module docstring.

    ``events``: (time [s], action(link, card)) pairs run when virtual time reaches them (an
    operator's hold, a relay going dead). ``to_card`` / ``to_host`` pass every frame written in
    that direction (a :class:`Relay`, or any bytes → bytes function). ``max_time_s`` bounds
    the run (default: 3 × the program's duration + 10 s); a run that reaches it ends with a
    StreamError. After the sender ends, the card is left alone for its buffer's time.
    """
    card = CardSim(config or CardConfig(speed=1.0), seed=seed)
    byte_s = p.BITS_PER_BYTE_8N1 / baud if baud else 0.0
    link = Link(program, options, byte_s, ignore_credit=ignore_credit)
    line = SimLine(card, to_card or Relay(), to_host or Relay(), baud)
    pending = sorted(events, key=lambda e: e[0])
    limit = max_time_s if max_time_s is not None else 3.0 * program.periods * program.period_s + 10
    t = line.drive(link, 0.0, limit, pending, lambda ev: ev[1](link, card))
    at_end = card.state
    # Leave the card alone for its buffer's time: whatever it still holds runs (or it stops).
    cfg = card.config
    card.advance(t + cfg.buffer_periods * cfg.period_s / (cfg.speed or 1.0) + 0.05)
    if not link.finished:
        return SimResult(
            None, StreamError(f"simulation did not finish in {limit:g} s"), card, link, t, at_end
        )
    try:
        return SimResult(link.result(), None, card, link, t, at_end)
    except StreamError as exc:
        return SimResult(None, exc, card, link, t, at_end)


class SimCard:
    """A card simulator on a simulated line (no faults), streamed section by section in
    virtual time: the ``card`` of :func:`nurbscnc.controller.run.run_job` in simulations
    (:func:`nurbscnc.controller.simulate.simulate_job`). ``events``: (time [s], event)
    pairs, each run by ``run_event(event)`` when virtual time reaches it; ``on_turn(now_s)``
    is called on every turn before the section's hook. ``t`` is the virtual time [s]."""

    def __init__(
        self,
        card: CardSim,
        *,
        options: SenderOptions | None = None,
        baud: int | None = 115200,
        events=(),
        run_event=None,
        max_time_s: float = 600.0,
    ):
        self.card, self.options, self.max_time_s = card, options, max_time_s
        self.byte_s = p.BITS_PER_BYTE_8N1 / baud if baud else 0.0
        self.line = SimLine(card, Relay(), Relay(), baud)
        self.pending = sorted(events, key=lambda e: e[0])
        self.run_event = run_event
        self.on_turn = None
        self.t = 0.0
        self.reports: list[StreamReport] = []

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
        """Stream one section (as :meth:`~.sender.Sender.stream_section`); raises
        StreamError when it failed."""
        link = Link(program, self.options, self.byte_s, session_id=session_id, zero=zero)
        if peak_pulses is not None:
            link.peak_pulses = peak_pulses
        link.program_open = program_open

        def turn(lk: Link) -> None:
            if self.on_turn is not None:
                self.on_turn(self.line.now_s)
            if hook is not None:
                hook(lk)

        self.t = self.line.drive(
            link, self.t, self.t + self.max_time_s, self.pending, self.run_event, hook=turn
        )
        report = link.result()
        self.reports.append(report)
        return report

    def advance(self, t_s: float) -> None:
        """Let virtual time reach ``t_s`` (the card runs meanwhile)."""
        self.t = max(self.t, t_s)
        self.card.advance(self.t)
