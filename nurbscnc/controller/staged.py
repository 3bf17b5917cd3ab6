"""A program planned whole, streamed section by section: it waits at its stops.

A program that moves a rotary axis is planned whole before the port opens (its samples carry
A B C beside X Y Z; the controller's re-planning follows the XYZ path length, which stands
still while only A B C turn). :class:`StagedJob` streams those pulses through the section
loop (:func:`~.run.run_job`) like a :class:`~.job.Job`: a section ends at every program stop
that waits — M0, M60, M1 with ``optional_stop``, a tool change M6, a user M-code M100–M199 —
where the plan already brings the tool (and the rotary axes) to rest; the operator's
continue (or the user M-code's executable) starts the next. A feed hold is the card's own
HOLD (it stops at the next period boundary; RESUME goes on), as for a points file; the feed
override stays at 100 % (the pulses are fixed). No I/O, no clock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.controller.stops import Stop, describe_stop
from nurbscnc.output.stream.quantise import PulseProgram


@dataclass(frozen=True)
class StagedSection:
    """The ``pulses`` up to a ``stop`` (None: the program's end); ``pulses`` None when
    nothing moves before it."""

    pulses: PulseProgram | None
    stop: Stop | None = None


@dataclass(frozen=True)
class PlanTime:
    """The planned motion time [s] (``cycle_time_s``), as a :class:`~.job.Job`'s plan has it."""

    cycle_time_s: float


class StagedJob:
    """The sections of a program planned whole (see the module docstring) for
    :func:`~.run.run_job`, the sender's progress and the operator's keys."""

    def __init__(
        self,
        sections,
        period_s: float,
        optional_stop: bool = False,
        tools: dict | None = None,
    ) -> None:
        self.parts = list(sections)
        self.period_s = float(period_s)
        self.optional_stop = optional_stop
        self.tools = tools
        periods = sum(s.pulses.periods for s in self.parts if s.pulses is not None)
        self.plan = PlanTime(periods * self.period_s)
        self.peak_pulses = max(
            (s.pulses.peak_pulses for s in self.parts if s.pulses is not None), default=0
        )
        self.feed = None  #: no planner thread: everything is planned already
        self.override = 1.0
        self.section_open = False  #: every section is whole: END follows its last batch
        self.finished = False
        self.waiting: str | None = None
        self.at_stop: Stop | None = None
        self.executed_before = 0
        self.last_line = 0
        self.sections = 0  #: sections streamed
        self.notes: list[str] = []
        self._index = 0  #: the part streamed next, or whose stop comes next
        self._streamed = False  #: the part ``_index``'s pulses have run
        self._card_hold: bool | None = None  #: HOLD (True) / RESUME (False) for the card
        self._held = False

    # -- requests (plain attribute writes: safe from a signal handler) -----------------------
    def request_hold(self) -> None:
        if not self.finished:
            self._card_hold = True

    def resume(self) -> None:
        """Continue after a program stop, or leave the card's feed hold."""
        if self.waiting is not None:
            self.waiting = None
            self.at_stop = None
            self._card_hold = None if not self._held else False
            return
        self._card_hold = False

    def step_override(self, steps: int) -> float:
        """+/- keys: the pulses are fixed, the override stays at 100 % (said once)."""
        note = "feed override: a program planned whole (rotary axes) runs at 100 %"
        if steps and note not in self.notes:
            self.notes.append(note)
        return 1.0

    # -- the section loop --------------------------------------------------------------------
    def next_section(self) -> PulseProgram | None:
        """The pulses of the next section, or None (finished, or waiting at a stop)."""
        while self.waiting is None and not self.finished:
            if self._index >= len(self.parts):
                self.finished = True
                break
            part = self.parts[self._index]
            if self._card_hold:  # a hold between sections: wait at rest
                self._card_hold = None
                self.waiting = "feed hold"
                break
            if not self._streamed and part.pulses is not None and part.pulses.periods:
                self._streamed = True
                if part.pulses.line.size:
                    self.last_line = int(part.pulses.line[-1])
                return part.pulses
            self._index += 1
            self._streamed = False
            stop = part.stop
            if stop is not None and (stop.code != "M1" or self.optional_stop):
                self.at_stop = stop
                self.last_line = stop.line
                self.waiting = describe_stop(stop, self.tools)
        return None

    def section_done(self, executed_periods: int) -> None:
        self.executed_before += int(executed_periods)
        self.sections += 1
        self._held = False

    def poll(self, link=None) -> None:
        """Nothing is planned while the card runs."""

    def update(self, link) -> None:
        """The hook on every turn of the sender's loop: the operator's hold or resume goes to
        the card (HOLD / RESUME)."""
        want, self._card_hold = self._card_hold, None
        if want is True:
            link.request_hold()
            self._held = True
        elif want is False:
            link.request_resume()
            self._held = False

    # -- what the operator sees ---------------------------------------------------------------
    def note(self, executed_in_section: int | None = None) -> str:
        """The progress line's words: why the job waits, or that the card holds."""
        if self.waiting:
            return f"waiting: {self.waiting}"
        return "waiting: feed hold" if self._held else ""

    def report(self) -> dict:
        """JSON-able summary, the shape of a :class:`~.job.Job`'s: sections, notes."""
        return {
            "sections": self.sections,
            "feed_override": 1.0,
            "holds": [],
            "notes": [{"line": None, "message": n} for n in self.notes],
        }


def split_pulses(program: PulseProgram, ends) -> list[PulseProgram | None]:
    """``program`` cut after the periods ``ends`` (increasing counts; the last its
    ``periods``): one program per part, each starting where the one before ends (the same
    quantisation, so the card's position is continuous); None for a part of no period."""
    out: list[PulseProgram | None] = []
    start_steps = np.asarray(program.start_steps, dtype=np.int64)
    k0 = 0
    for k1 in ends:
        k1 = int(k1)
        if k1 <= k0:
            out.append(None)
            continue
        pulses = program.pulses[k0:k1]
        end = start_steps + pulses.sum(axis=0)
        out.append(
            PulseProgram(
                start_steps.copy(), end, pulses, program.period_s, program.line[k0:k1], program.axes
            )
        )
        start_steps, k0 = end, k1
    return out
