"""The stream as a controller: program stops, feed hold, feed override, the line executing.

:class:`Job` sits between a plan and the protocol's :class:`~.link.Link`, free of I/O and
clocks like the link. It cuts the program into *sections*, each streamed to the card as one
stream (HELLO … END, the card DONE at rest at its end):

- a section ends at a program stop that waits — M0, M60, M1 with ``optional_stop``, a tool
  change M6, a user M-code M100–M199 (:mod:`.stops`; the section loop :mod:`.run` runs its
  executable) — or at the end of the program. The planner already brings the tool to rest
  there (SPEC §7: a stop is a junction of speed 0), and the card is DONE only once its
  buffer has drained to that point: the job then *waits* until :meth:`Job.resume` (Enter or
  SIGUSR2 in the CLI).
- a **feed hold** (:meth:`Job.request_hold`) is applied by :meth:`Job.update` to the running
  link: the periods not yet framed are replaced by the shortest jerk-limited stop along the
  path from the state of the first of them (:func:`~.motion.stop_phases`), then END. What the
  card has buffered runs first: that is the hold's latency, measured and reported
  (:class:`HoldRecord`). On resume the rest of the program is re-planned from rest at the
  hold point (:func:`~.motion.resume_motion`).
- a **feed override** change (:meth:`Job.set_override`) re-times the periods not yet framed:
  the earliest quintic ramp of the override that keeps |a| ≤ A and |j| ≤ J on every period
  (:func:`~.motion.ramp_fits`); none within the section: it applies from the next section.
  Above 100 %: the rest is re-planned from the next rest ahead (:mod:`.override`).

A section's periods are computed in chunks (:data:`CHUNK_PERIODS`) ahead of what the link
frames (the link holds END back meanwhile: ``Link.program_open``), so a hold or an override
change re-times a bounded number of periods however long the section. Every section's
periods are quantised to pulses (:func:`~.quantise.quantise`) with the same
rounding, and each section starts at the exact point where the previous one ended, so the
card's position is continuous across sections.

Streaming while planning. With a ``feed`` (:class:`~.feed.WindowFeed`: the cut
windows of :func:`~nurbscnc.plan.lookahead.plan_windows` as they become final) the job starts
on the first window's plan and adopts each later one as it arrives (:meth:`Job.poll`): the
periods framed never go beyond the *horizon*, the end of the last final window, a rest (the
profile is 0 there and nothing after it can change what comes before). A chunk is cut at the
horizon and the section kept open; when the link has framed every period up to it and the
next window is still not planned, the section ends there at rest (the card DONE, standing):
a *planning hold*, until the window arrives. For each window adopted while the card moves,
the margin is how long the card still had to run to the old horizon; the least of them, the
holds and the time held are reported (:meth:`Job.report`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbscnc.controller.motion import (
    Motion,
    Rate,
    Track,
    plan_motion,
    play,
    stop_track,
)
from nurbscnc.controller.override import (
    OVERRIDE_MAX,
    OVERRIDE_MIN,
    OVERRIDE_STEP,
    apply_override,
    cut_at_rest,
    replan_raised,
)
from nurbscnc.controller.stops import Stop, describe_stop, program_stops
from nurbscnc.output.stream.quantise import PulseProgram, quantise
from nurbscnc.plan.profile import time_at_length

#: A section's periods are computed in chunks of this many, ahead of what the link frames, so
#: a hold or an override change re-times a bounded number of periods however long it is.
CHUNK_PERIODS = 4096


@dataclass
class HoldRecord:
    """One feed hold: asked when the card had executed ``asked_period`` periods of the
    section, the deceleration begins after period ``decel_start_period`` (the periods
    already framed run first) and lasts ``decel_periods``; ``latency_s`` from the request to
    the start of the deceleration, ``stop_s`` to rest."""

    asked_period: int
    decel_start_period: int
    decel_periods: int
    period_s: float
    s_mm: float = 0.0

    @property
    def latency_s(self) -> float:
        return (self.decel_start_period - self.asked_period) * self.period_s

    @property
    def stop_s(self) -> float:
        return self.latency_s + self.decel_periods * self.period_s

    def to_json(self) -> dict:
        return {
            "latency_s": round(self.latency_s, 6),
            "stop_s": round(self.stop_s, 6),
            "stopped_at_mm": round(self.s_mm, 6),
        }


@dataclass
class Section:
    """The section being streamed: its track, pulses and how it ends."""

    track: Track
    program: PulseProgram
    tau_b: float
    rate: Rate  #: the override law; its motion time is 0 at the track's ``rate_u0_s``
    ends_at: int | None  #: index of the stop it ends at (None: the program's end)
    complete: bool = True  #: the track reaches the section's end (else more chunks follow)
    rate_u0_s: float = 0.0
    held: bool = False  #: a feed hold replaced its end
    hold_wait_s: float = 0.0  #: a dwell interrupted by the hold: what is left of it [s]
    override_deferred: bool = False  #: no ramp fitted: the override waits for the next one
    blocked: bool = False  #: the track stops at the planning horizon (more when planned)
    blocked_at: int | None = None  #: the horizon (first piece not planned) it stops at
    at_horizon: bool = False  #: closed at the planning horizon (a planning hold follows)
    rescale: bool = False  #: cut at a rest: the next section re-plans at a new override


class Job:
    """A planned program streamed as a controller; see the module docstring.

    ``plan`` a :class:`~nurbscnc.plan.lookahead.Plan` of ``program``; ``machine`` its
    machine; ``override`` the starting feed override (fraction, 0.1–2: above 1 the rest is
    re-planned with raised caps, :mod:`.override`). ``feed``: the plan's cut windows as they
    are planned (module docstring; ``plan`` is then ignored: the first window's plan is
    used). ``tools``: the tool table ``{number: Tool}``, named at a tool change.
    """

    def __init__(
        self,
        plan,
        program,
        machine,
        *,
        optional_stop: bool = False,
        override: float = 1.0,
        lookahead_pieces: int | None = None,
        feed=None,
        tools: dict | None = None,
    ):
        self.feed = feed
        self.program = program
        self.horizon = None  #: first piece not planned yet (None: the whole plan is final)
        self.motion_horizon = None  #: the horizon the current motion was made with
        self.planning = {"windows": 0, "margins_s": [], "holds": 0, "held_s": 0.0}
        self._hold_since = None
        self.feed_error = None
        if feed is not None:
            first = feed.first()
            plan = first.plan
            self.horizon = None if first.end >= len(plan.pieces) else first.end
            self.motion_horizon = self.horizon
            self.planning["windows"] = 1
        self.plan, self.machine = plan, machine
        self.period_s = machine.servo.period_s
        self.steps_per_mm = machine.steps.per_mm
        self.a_max = machine.limits.a_max_mm_s2
        self.j_max = machine.limits.j_max_mm_s3
        self.lookahead_pieces = lookahead_pieces
        self.optional_stop = optional_stop
        self.override = self._clamp(override)
        self.scale = 1.0  #: the motion's feed scale: max(override, 1) when it was planned
        self.pending_override: float | None = None  #: applies at the next rest (above 100 %)
        self.motion: Motion | None = plan_motion(plan)
        self.tau = 0.0  #: where the next section starts, in the motion's profile time
        self.first_section = True
        self.motion_is_plan = True  #: the motion is the plan's own (no feed hold yet)
        self.stops = tuple(program_stops(program, plan))
        self.next_stop = 0  #: the first stop not waited at yet
        self.section: Section | None = None
        self.waiting: str | None = None  #: why the job waits for the operator
        self.at_stop: Stop | None = None  #: the program stop the card stands at
        self.tools = tools  #: the tool table {number: Tool}, named at a tool change
        self.finished = False
        self.last_point: np.ndarray | None = None
        self.hold_wanted = False
        self.resume_early = False  #: continue asked while a hold was still decelerating
        self.override_wanted: float | None = None
        self.holds: list[HoldRecord] = []
        self.notes: list[str] = []
        self.sections = 0
        self.executed_before = 0  #: periods of the finished sections
        self.last_line = 0  #: source line of the last period of the finished sections
        self.last_steps: np.ndarray | None = None  #: where the last section ended [steps]
        self.last_s_mm = 0.0  #: and its path length [mm]
        self._steps_at = (0, 0, None)  #: (section, periods, steps) of the last progress
        # The frames' count width must fit the fastest section: the plan's peak speed (a hold
        # or an override ≤ 100 % only slows down; a re-plan above 100 % widens it).
        self.peak_pulses = self._peak_pulses(plan.profile)

    # -- requests (plain attribute writes: safe from a signal handler) -----------------------
    def request_hold(self) -> None:
        if not self.finished:
            self.hold_wanted = True

    def resume(self) -> None:
        """Continue after a program stop or a feed hold (or cancel a hold not yet applied;
        during a hold's deceleration: go on as soon as the card stands)."""
        self.hold_wanted = False
        self.resume_early = self.section is not None and self.section.held
        self.waiting = None
        self.at_stop = None

    def set_override(self, fraction: float) -> None:
        self.override_wanted = self._clamp(fraction)

    def step_override(self, steps: int) -> float:
        """+/- keys: change the wanted override by ``steps`` × 10 %; returns it."""
        base = next(
            r for r in (self.override_wanted, self.pending_override, self.override) if r is not None
        )
        self.set_override(round(base + steps * OVERRIDE_STEP, 6))
        return self.override_wanted

    def _clamp(self, fraction: float) -> float:
        return float(min(max(fraction, OVERRIDE_MIN), OVERRIDE_MAX))

    # -- sections ----------------------------------------------------------------------------
    def next_section(self) -> PulseProgram | None:
        """The pulses of the next section, or None (finished, or waiting for the operator)."""
        self.poll()
        if self.feed_error is not None and not self.finished and self._horizon_tau() <= self.tau:
            raise self.feed_error
        if self.finished or self.waiting is not None:
            return None
        if self.hold_wanted:  # a hold between sections: wait at rest
            self.hold_wanted = False
            self.waiting = "feed hold"
            return None
        if self.pending_override is not None:  # at rest: the part above 100 % too
            self.override, self.pending_override = self.pending_override, None
        if self.override_wanted is not None:  # at rest: a new override applies at once
            self.override, self.override_wanted = self.override_wanted, None
        if max(self.override, 1.0) != self.scale:
            self.scale = max(self.override, 1.0)
            s_now = float(self.motion.state(np.array([self.tau]))[0][0])
            self._replan(s_now, self.motion.wait_s if self.tau == 0.0 else 0.0)
            if self.motion is None:
                self.finished = True
                return None
        motion = self.motion
        stop = self._next_waiting_stop()
        tau_b = self._end_tau(stop)
        rate = Rate(min(self.override, 1.0))
        track, complete = play(
            motion,
            self.tau,
            tau_b,
            rate,
            self.period_s,
            wait_s=motion.wait_s if self.tau == 0.0 else 0.0,
            dwell_at_start=self.first_section,
            max_samples=CHUNK_PERIODS,
        )
        track, blocked = self._within_horizon(track, tau_b)
        if self.last_point is not None:
            track.points_mm[0] = self.last_point  # exactly where the card stands
        self.section = Section(
            track,
            self._pulses(track),
            tau_b,
            rate,
            stop,
            complete and not blocked,
            blocked=blocked,
            blocked_at=self.motion_horizon,
        )
        self.first_section = False
        self.sections += 1
        return self.section.program

    def _next_waiting_stop(self) -> int | None:
        """Index of the next stop this section ends at (M1 only with ``optional_stop``)."""
        s_now = float(self.motion.state(np.array([self.tau]))[0][0])
        end = self.motion.end_mm
        for i in range(self.next_stop, len(self.stops)):
            stop = self.stops[i]
            if stop.s_mm < s_now - 1e-9 or (stop.code == "M1" and not self.optional_stop):
                continue
            if stop.s_mm > end + 1e-9:
                break
            return i
        return None

    @property
    def section_open(self) -> bool:
        """The section's periods are not all computed yet: END must wait (``program_open``
        of the link)."""
        return self.section is not None and not self.section.complete

    def _pulses(self, track: Track, k: int = 0, program: PulseProgram | None = None):
        """The pulses of ``track``: those of ``program`` up to sample ``k``, then the track's
        own from there (quantised alike: the same point gives the same steps)."""
        line = np.take(self.plan.pieces.line, track.piece[k:])
        tail = quantise(track.points_mm[k:], self.steps_per_mm, self.period_s, line)
        if program is None or k == 0:
            return tail
        return PulseProgram(
            program.start_steps,
            tail.end_steps,
            np.concatenate([program.pulses[:k], tail.pulses]),
            self.period_s,
            np.concatenate([program.line[:k], tail.line]),
        )

    def _extend(self, link) -> None:
        """The next chunk of the section, once the link has framed half of the last one; at
        the planning horizon: the next chunk as soon as the horizon moved on, or the
        section's end at rest there once the link has framed every period up to it."""
        sec = self.section
        tr = sec.track
        k = len(tr) - 1
        if sec.complete:
            return
        if sec.blocked:
            if self.motion_horizon == sec.blocked_at:  # not planned further yet
                if sec.program.periods - link.sent_periods < link.per_frame:
                    self._close_at_horizon(link)
                return
            sec.blocked = False
        elif link.sent_periods < k - CHUNK_PERIODS // 2:
            return
        tail, complete = play(
            self.motion,
            float(tr.tau_s[k]),
            sec.tau_b,
            sec.rate,
            self.period_s,
            wait_s=self._wait_at(tr, k),
            u0=float(tr.u_s[k]) - sec.rate_u0_s,
            max_samples=CHUNK_PERIODS,
        )
        tail, sec.blocked = self._within_horizon(tail, sec.tau_b)
        sec.complete = complete and not sec.blocked
        tail.points_mm[0] = tr.points_mm[k]
        sec.track = tr.then(tail)
        sec.program = self._pulses(sec.track, k, sec.program)
        link.program_open = not sec.complete
        link.replace_unsent(sec.program)

    def _end_tau(self, stop: int | None) -> float:
        """Profile time [s] of the motion at which a section ending at ``stop`` (None: the
        program's end) ends."""
        if stop is None:
            return self.motion.duration_s
        return float(self.motion.time_of(self.stops[stop].s_mm)[0])

    # -- streaming while planning ----------------------------------------------------------
    def _horizon_tau(self) -> float:
        """Profile time [s] of the current motion up to which its periods may be framed:
        the start of the first piece not planned (when the motion was made) — a rest — or
        the motion's end."""
        h = self.motion_horizon
        if h is None:
            return self.motion.duration_s
        return float(self.motion.profile.piece_start_time_s[h - self.motion.first])

    def _within_horizon(self, track: Track, tau_b: float) -> tuple[Track, bool]:
        """``track`` up to its last sample not beyond the planning horizon (profile time at
        most the horizon's: those samples are final), and whether it was cut there."""
        h = self._horizon_tau()
        if h >= tau_b:
            return track, False
        if self.section is not None:
            self.section.blocked_at = self.motion_horizon
        beyond = np.flatnonzero(track.tau_s > h)
        if not beyond.size:
            return track, True
        return track.head(max(int(beyond[0]), 1)), True

    def _close_at_horizon(self, link) -> None:
        """End the section at rest at the planning horizon (the next window is not planned
        and the link has framed every period before it): the periods to the rest itself
        (what is left of a dwell there included), then END."""
        sec = self.section
        tr = sec.track
        k = len(tr) - 1
        h = self._horizon_tau()
        tail, _ = play(
            self.motion,
            float(tr.tau_s[k]),
            h,
            sec.rate,
            self.period_s,
            wait_s=self._wait_at(tr, k),
            u0=float(tr.u_s[k]) - sec.rate_u0_s,
        )
        tail.points_mm[0] = tr.points_mm[k]
        sec.track = tr.then(tail)
        sec.program = self._pulses(sec.track, k, sec.program)
        sec.tau_b, sec.complete, sec.blocked, sec.at_horizon = h, True, False, True
        link.program_open = False
        link.replace_unsent(sec.program)

    def poll(self, link=None) -> None:
        """Adopt the windows the feed has planned since the last call: the plan, the stops,
        the motion (when it is the plan's own: its periods up to the old horizon are the
        same) and the horizon; measure the margin of each (``link``: the running section's,
        for the card's executed periods) and end a planning hold."""
        if self.feed is None or self.horizon is None:
            return
        try:
            ready = self.feed.poll()
        except Exception as exc:  # noqa: BLE001 - the planner's error: raised at the horizon
            self.feed_error = exc
            ready = []
        for window, _t_ready in ready:
            self._margin(link)
            self.plan = window.plan
            self.horizon = None if window.end >= len(window.plan.pieces) else window.end
            self.stops = tuple(program_stops(self.program, window.plan))
            self.planning["windows"] += 1
            if self.motion_is_plan and self.motion is not None:
                self.motion = plan_motion(window.plan)
                self.motion_horizon = self.horizon
                sec = self.section
                if sec is not None and not (sec.held or sec.at_horizon):
                    # Its end in the new motion's time (the stop it ends at is the same).
                    sec.tau_b = self._end_tau(sec.ends_at)
        if ready and self.waiting == "planning":
            self.planning["held_s"] += self.feed.clock() - self._hold_since
            self.waiting = None
        if self.feed_error is not None and self.waiting == "planning":
            raise self.feed_error  # the card stands at rest at the last planned window's end

    def _margin(self, link) -> None:
        """How long [s] the card still had to run to the horizon when the next window came
        (a planning hold: not a margin; it is counted as held time instead)."""
        sec = self.section
        if sec is None or sec.at_horizon or link is None:
            return
        tr = sec.track
        h = self._horizon_tau()
        status = link.state.status  # None: the section's handshake, nothing executed yet
        executed = status.executed_periods if status is not None else 0
        reached = np.flatnonzero(tr.tau_s >= h)
        if reached.size:
            to_go = int(reached[0]) - executed
        else:  # beyond the chunks made so far: the rest at the override (dwells not counted)
            to_go = (
                len(tr) - 1 - executed + (h - float(tr.tau_s[-1])) / self.period_s / sec.rate.final
            )
        self.planning["margins_s"].append(max(to_go, 0) * self.period_s)

    def section_done(self, executed_periods: int) -> None:
        """The card reported DONE at the section's end: wait there, or go on."""
        sec = self.section
        self.executed_before += executed_periods
        self.last_point = sec.track.points_mm[-1].copy()
        self.last_steps, self.last_s_mm = sec.program.end_steps, float(sec.track.s_mm[-1])
        if sec.program.periods:
            self.last_line = int(sec.program.line[-1])
        self.section = None
        if sec.at_horizon:  # at rest at the planning horizon
            self.tau = sec.tau_b
            self.poll()
            if not self.motion_is_plan:  # the rest from here on the plan as planned now
                self._replan(float(sec.track.s_mm[-1]), 0.0)
            self.planning["holds"] += 1
            if self.feed_error is not None and self._horizon_tau() <= self.tau:
                raise self.feed_error
            if self.motion_horizon is not None and self._horizon_tau() <= self.tau:
                self.waiting = "planning"
                self._hold_since = self.feed.clock()
            return
        if sec.rescale:  # at a rest: the next section re-plans at the new override
            self.tau = sec.tau_b
            return
        if sec.held:
            self._replan(float(sec.track.s_mm[-1]), sec.hold_wait_s)
            self.waiting = None if self.resume_early else "feed hold"
            self.hold_wanted = self.resume_early = False
        elif sec.ends_at is not None:
            self.tau = sec.tau_b
            self.next_stop = sec.ends_at + 1
            self.at_stop = self.stops[sec.ends_at]
            self.waiting = describe_stop(self.at_stop, self.tools)
        else:
            self.motion = None
        if self.motion is None:
            self.finished = True
            self.waiting = None
        elif self.hold_wanted and self.waiting is None:
            self.hold_wanted = False
            self.waiting = "feed hold"

    def _replan(self, s_mm: float, wait_s: float) -> None:
        """The rest of the plan from rest at global path length ``s_mm`` (``wait_s``: a
        dwell still to finish there) at the current feed scale (above 100 %:
        :func:`~.override.replan_raised`); None when nothing is left."""
        self.motion = replan_raised(self, s_mm, wait_s)
        self.motion_is_plan = False
        self.motion_horizon = self.horizon
        self.tau = 0.0
        if self.motion is not None:
            self.peak_pulses = max(self.peak_pulses, self._peak_pulses(self.motion.profile))

    def _peak_pulses(self, profile) -> int:
        """The frames' count width for a profile: its peak speed's pulses per period (+2:
        rounding, a re-planned rest)."""
        v_peak = float(np.max(profile.piece_peak_speed_mm_s))
        return int(math.ceil(v_peak * self.period_s * float(np.max(self.steps_per_mm)))) + 2

    # -- changes while a section streams -------------------------------------------------------
    def update(self, link) -> None:
        """Apply a pending hold or override change to ``link`` (streaming this section), and
        compute the section's next chunk when the link needs it."""
        sec = self.section
        if sec is None:
            return
        self.poll(link)
        link.program_open = not sec.complete
        if link.state.caps is None or sec.held or link.end_framed:
            return  # END framed: a hold waits at the section's end, an override at the next
        if link.state.phase.value != "streaming":
            return
        self._extend(link)
        if self.hold_wanted:
            self._apply_hold(link)
        elif self.override_wanted is not None and not sec.override_deferred:
            self._apply_override(link)
        elif self.pending_override is not None and not sec.rescale:
            cut_at_rest(self, link)

    def _apply_hold(self, link) -> None:
        sec = self.section
        k = link.sent_periods
        executed = link.state.status.executed_periods if link.state.status else 0
        tr = sec.track
        stop = stop_track(
            self.motion, tr, k, self.a_max, self.j_max, self.period_s, float(tr.s_mm[-1])
        )
        track = tr.head(k + 1).then(stop)
        program = self._pulses(track, k, sec.program)
        sec.complete = True
        link.program_open = False
        link.replace_unsent(program)
        sec.hold_wait_s = self._wait_at(tr, k)
        sec.track, sec.program, sec.held = track, program, True
        self.holds.append(
            HoldRecord(executed, k, len(stop) - 1, self.period_s, float(track.s_mm[-1]))
        )
        self.hold_wanted = False

    def _apply_override(self, link) -> None:
        apply_override(self, link, CHUNK_PERIODS)

    # The helpers the override's module uses on the running section.
    def horizon_tau(self) -> float:
        return self._horizon_tau()

    def within_horizon(self, track: Track, tau_b: float) -> tuple[Track, bool]:
        return self._within_horizon(track, tau_b)

    def wait_at(self, tr: Track, k: int) -> float:
        return self._wait_at(tr, k)

    def pulses_of(self, track: Track, k: int, program: PulseProgram) -> PulseProgram:
        return self._pulses(track, k, program)

    def _wait_at(self, tr: Track, k: int) -> float:
        """A dwell in progress at sample ``k``: the part still to wait [s] (0: none)."""
        if tr.v_mm_s[k] != 0.0:
            return 0.0
        hit = np.flatnonzero(np.abs(self.motion.dwell_at_s - tr.tau_s[k]) <= 1e-12)
        if not hit.size:
            return 0.0
        moved = np.flatnonzero(tr.tau_s[: k + 1] != tr.tau_s[k])
        first = int(moved[-1]) + 1 if moved.size else 0
        return max(0.0, float(self.motion.dwell_s[hit[0]]) - (k - first) * self.period_s)

    # -- reporting -----------------------------------------------------------------------------
    def line_of(self, executed_in_section: int) -> int:
        """Source line of the period the card executes now."""
        sec = self.section
        if sec is None or not sec.program.periods:
            return 0
        return int(sec.program.line[min(executed_in_section, sec.program.periods - 1)])

    def progress_of(self, executed_in_section: int):
        """``(position_mm, done, left_s)`` after ``executed_in_section`` periods of the
        running section (or at rest after the last one): the card's position [mm] in machine
        coordinates (its steps over the profile's steps per mm: exact, the steps are what the
        card counts), the part of the program's path done [0–1], and the time left [s]
        (estimate: the plan's profile time from there over the override, plus the dwells
        after it). None before the first section."""
        sec = self.section
        if sec is not None and sec.program.periods:
            k = min(max(int(executed_in_section), 0), sec.program.periods)
            # Summed on from the last call's count (the periods executed are framed, never
            # changed again): a progress line costs the periods since the last one.
            n0, k0, base = self._steps_at
            if n0 != self.sections or k0 > k:
                k0, base = 0, sec.program.start_steps
            steps = base + sec.program.pulses[k0:k].sum(axis=0)
            self._steps_at = (self.sections, k, steps)
            s_mm = float(sec.track.s_mm[min(k, len(sec.track) - 1)])
        elif self.last_steps is not None:
            steps, s_mm = self.last_steps, self.last_s_mm
        else:
            return None
        position_mm = np.asarray(steps, dtype=float) / self.steps_per_mm
        pieces, profile = self.plan.pieces, self.plan.profile
        total_mm = float(np.sum(pieces.length_mm))
        done = min(max(s_mm / total_mm, 0.0), 1.0) if total_mm > 0.0 else 1.0
        t_at_s = float(time_at_length(profile, np.array([min(s_mm, total_mm)]))[0])
        ends = np.asarray(profile.piece_start_mm) + np.asarray(pieces.length_mm)
        dwells_s = float(np.sum(np.asarray(pieces.dwell_after_s)[ends > s_mm + 1e-9]))
        left_s = max(profile.duration_s - t_at_s, 0.0) / self.override + dwells_s
        return position_mm, done, left_s

    def note(self, executed_in_section: int | None = None) -> str:
        """What the progress line says besides the counts: the override, the card's
        position [mm], the part done and the time left, and why the job waits (last)."""
        parts = [f"feed {self.override:.0%}"]
        wanted = self.override_wanted if self.override_wanted is not None else None
        wanted = self.pending_override if wanted is None else wanted
        if wanted is not None:
            parts.append(f"→ {wanted:.0%}")
        where = None if executed_in_section is None else self.progress_of(executed_in_section)
        if where is not None:
            position_mm, done, left_s = where
            parts.append(" ".join(f"{a} {v:.3f}" for a, v in zip("XYZ", position_mm)) + " mm")
            left = int(round(left_s))
            parts.append(f"{done:.0%} done, {left // 60}:{left % 60:02d} left")
        if self.waiting:
            parts.append(f"waiting: {self.waiting}")
        elif self.section is not None and self.section.held:
            parts.append("holding")
        return " · ".join(parts)

    def report(self) -> dict:
        """JSON-able summary: sections, holds (latency), notes, the final override."""
        out = {
            "sections": self.sections,
            "feed_override": round(self.override, 6),
            "holds": [h.to_json() for h in self.holds],
            # The same shape as every command's notes ({line, message}); the job's notes
            # are about the stream as a whole (no source line).
            "notes": [{"line": None, "message": n} for n in self.notes],
        }
        if self.feed is not None:
            margins = self.planning["margins_s"]
            out["planning"] = {
                "windows": self.planning["windows"],
                "first_window_s": round(self.feed.first_s, 6),
                "planned_s": None if self.feed.planned_s is None else round(self.feed.planned_s, 6),
                "plan_margin_min_s": round(min(margins), 6) if margins else None,
                "holds": self.planning["holds"],
                "held_s": round(self.planning["held_s"], 6),
            }
        return out
