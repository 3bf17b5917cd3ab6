"""A job streamed to a simulated card in virtual time, through the controller's own section
loop (:func:`~.run.run_job`): the tests' and the benchmark's stand-in for ``stream``."""

from __future__ import annotations

from dataclasses import dataclass

from nurbscnc.controller.run import run_job
from nurbscnc.errors import StreamError
from nurbscnc.output.stream.card import CardConfig, CardSim
from nurbscnc.output.stream.linkstate import SenderOptions
from nurbscnc.output.stream.simlink import SimCard


@dataclass
class JobSimResult:
    """How a simulated job ended: the card, every section's report, the waits
    (start [s], end [s] or None when still waiting, reason), the error if any."""

    card: CardSim
    reports: list
    waits: list
    error: StreamError | None
    elapsed_s: float

    @property
    def completed(self) -> bool:
        return (
            self.error is None
            and bool(self.reports)
            and not (self.waits and self.waits[-1][1] is None)
        )


class _StillWaiting(Exception):
    """The job waits for the operator and no event is left: the run ends there."""


def simulate_job(
    job,
    config: CardConfig | None = None,
    *,
    options: SenderOptions | None = None,
    baud: int | None = 115200,
    seed: int = 1,
    events=(),
    max_time_s: float = 600.0,
    zero: bool = False,
    run_user_m=None,
) -> JobSimResult:
    """Stream a :class:`~.job.Job` to a simulated card in virtual time, section by section.

    ``events``: (time [s], action(job, card)) pairs — the operator's hold, resume, override.
    While the job waits (a program stop, a feed hold) virtual time jumps to the next event;
    with none left the run ends, still waiting. ``zero``: the first section declares the
    card's position to be its start (``stream --zero``). ``run_user_m``: as
    :func:`~.run.run_job`'s.
    """
    card = CardSim(config or CardConfig(speed=1.0), seed=seed)
    sim = SimCard(
        card,
        options=options,
        baud=baud,
        events=events,
        run_event=lambda ev: ev[1](job, card),
        max_time_s=max_time_s,
    )
    feed = getattr(job, "feed", None)
    if feed is not None:  # a scheduled feed releases windows in virtual time

        def on_turn(now_s: float) -> None:
            feed.now_s = now_s

        sim.on_turn = on_turn
    waits: list = []

    def wait(job, _reports) -> None:
        waits.append([sim.t, None, job.waiting])
        if job.waiting == "planning":  # until the planner has the next window
            sim.advance(job.feed.next_ready_s(sim.t))
            job.feed.now_s = sim.t
            job.poll()
        while job.waiting is not None and sim.pending:
            event = sim.pending.pop(0)
            sim.advance(event[0])
            sim.run_event(event)
        if job.waiting is not None:
            raise _StillWaiting
        waits[-1][1] = sim.t

    try:
        run_job(job, sim, wait, zero=zero, run_user_m=run_user_m)
    except _StillWaiting:
        pass
    except StreamError as exc:
        return JobSimResult(card, sim.reports, waits, exc, sim.t)
    return JobSimResult(card, sim.reports, waits, None, sim.t)
