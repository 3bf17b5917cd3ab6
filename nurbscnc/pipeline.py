"""The whole pipeline for one program: plan (or a baseline), interpolate, check soft limits.

program → geometry → plan (pieces, profile, dynamics check) → interpolate (reference points).
The CLI builds the option objects and calls :func:`run_program`; the outputs and reports
are made from the :class:`Run` it returns. No I/O here.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from nurbscnc.errors import ConfigError
from nurbscnc.interpolate.baselines import baseline_program_samples
from nurbscnc.interpolate.sample import (
    CHUNK,
    Interpolator,
    Samples,
    chunks_of,
    has_motion,
    reference_sampler,
    rest_samples,
    rest_seconds,
    sample_chunks,
    sample_plan,
    samples_of,
)
from nurbscnc.machine.profile import Machine, SoftLimits
from nurbscnc.plan.limits import check_before_work
from nurbscnc.plan.lookahead import Check, Plan, plan_checked, plan_windows
from nurbscnc.plan.options import Algorithm, Dynamics, LookaheadOptions, parse_choice
from nurbscnc.plan.report import check_rotary_limits, check_soft_limits
from nurbscnc.plan.sampler import ForwardingSampler
from nurbscnc.plan.timing import sample_count
from nurbscnc.program.columns import SegmentColumns, segment_columns
from nurbscnc.servo.precompensate import REFERENCE_TOLERANCE_MM

if TYPE_CHECKING:
    from nurbscnc.precompensation import Precompensation

# Start-up: the pre-compensation stage (its modules and their scipy.sparse, scipy.optimize
# and scipy.signal imports) is imported by the run that asks for it (_run_precompensated).


@dataclass(frozen=True)
class RunOptions:
    """Everything a command may choose about planning and interpolation (validated on
    construction): the ``algorithm``, the look-ahead planner's options (``lookahead``, not
    used by a baseline), the ``interpolator`` of NURBS pieces, and ``precompensate``: feed
    the servo the ZPETC pre-compensated reference (:mod:`nurbscnc.servo.precompensate`;
    the dynamics check then simulates it, and it is the output), kept within
    ``reference_tolerance_mm`` of the path (inf: no limit). ``keep_reference``: the
    dynamics check keeps its whole reference and servo response (the predicted contour plot
    needs them; memory then grows with the motion time); without it the check keeps only
    the over-limit samples and its statistics (memory of the program only), and the
    points are made window by window as the output is written."""

    algorithm: Algorithm = Algorithm.PH_LOOKAHEAD
    lookahead: LookaheadOptions = field(default_factory=LookaheadOptions)
    interpolator: Interpolator = Interpolator.EXACT
    precompensate: bool = False
    reference_tolerance_mm: float = REFERENCE_TOLERANCE_MM
    keep_reference: bool = False

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "algorithm", parse_choice(Algorithm, self.algorithm, "algorithm"))
        set_(self, "interpolator", parse_choice(Interpolator, self.interpolator, "interpolator"))
        tol = float(self.reference_tolerance_mm)
        if not tol >= 0.0:
            raise ConfigError(f"reference tolerance must be >= 0 mm, got {tol!r}")
        set_(self, "reference_tolerance_mm", tol)


@dataclass(frozen=True, eq=False)
class Run:
    """One program through the pipeline: its reference points (:meth:`chunks` window by
    window, :attr:`samples` whole); for the look-ahead planner also the ``plan`` and its
    dynamics ``check`` (None when the check was off); a baseline has neither (``plan`` is
    None).

    ``whole``: the reference points as whole arrays when the stage that made them had them
    anyway (a baseline, the pre-compensated reference, the check's kept reference), checked
    against the soft limits already. None: the plan's points are made on demand, window by
    window, with the ``interpolator`` at ``period_s``, each window checked against
    ``soft_limits`` as it is made — so writing an hours-long program needs one window of
    memory."""

    algorithm: Algorithm
    whole: Samples | None = None
    plan: Plan | None = None
    check: Check | None = None
    precompensation: Precompensation | None = None
    interpolator: Interpolator = Interpolator.EXACT
    period_s: float | None = None
    soft_limits: SoftLimits | None = None
    #: The program's segments as columns (read once for the checks before work; the
    #: summary's lower bound reads them again).
    columns: SegmentColumns | None = None
    #: A program with no motion: how long it holds the tool at rest [s] (its dwells; the
    #: points of ``whole`` last till the first servo period at or after it). None: it moves.
    rest_s: float | None = None
    #: The machine's rotary axes (:attr:`~nurbscnc.machine.model.Machine.rotary_axes`): their
    #: soft limits are checked on each window as the soft limits are.
    rotary_axes: dict = field(default_factory=dict)

    @property
    def cycle_time_s(self) -> float:
        """Cycle time [s] including dwells: the plan's (plus the pre-compensation's held
        start, when on), a program without motion's dwells, or a baseline's last sample
        time."""
        if self.rest_s is not None:
            return self.rest_s
        if self.plan is not None:
            lead = self.precompensation.lead_s if self.precompensation is not None else 0.0
            return self.plan.cycle_time_s + lead
        return float(self.whole.t_s[-1])

    @property
    def sample_count(self) -> int:
        """Number of reference points N (one per servo period, the end at rest included),
        known without making them."""
        if self.whole is not None:
            return int(self.whole.t_s.size)
        return sample_count(self.plan.pieces, self.plan.profile, self.period_s)

    def chunks(self, chunk: int | None = None) -> Iterator[Samples]:
        """The reference points as :class:`Samples` of ``chunk`` consecutive rows (None:
        :data:`~nurbscnc.interpolate.sample.CHUNK`; the last window shorter), in order:
        slices of the whole arrays when there are any (or once :attr:`samples` has made
        them), else the plan re-sampled window by window
        (:func:`~nurbscnc.interpolate.sample.sample_chunks`, bit-identical to the whole).
        A window outside the soft limits raises PlanningError naming the first offending
        point's line, before the window is yielded."""
        chunk = CHUNK if chunk is None else chunk
        made = self.whole if self.whole is not None else self.__dict__.get("samples")
        if made is not None:
            yield from chunks_of(made, chunk)
            return
        for window in sample_chunks(
            self.plan.pieces, self.plan.profile, self.period_s, self.interpolator, chunk
        ):
            check_soft_limits(window.points_mm, window.line, self.soft_limits)
            check_rotary_limits(window.abc_deg, window.line, self.rotary_axes)
            yield window

    @cached_property
    def samples(self) -> Samples:
        """All reference points as whole arrays, made once (plots, simulate, compare,
        explain, the stream's pulses need them whole); N rows of memory."""
        if self.whole is not None:
            return self.whole
        whole = sample_plan(self.plan.pieces, self.plan.profile, self.period_s, self.interpolator)
        check_soft_limits(whole.points_mm, whole.line, self.soft_limits)
        check_rotary_limits(whole.abc_deg, whole.line, self.rotary_axes)
        return whole


def _announcing(sampler, say):
    """``sampler`` with a ``check_begins(k0)`` that says which pass of the planner's dynamics
    check begins (the checker calls it as each check of a plan begins at sample k0: from
    sample 0, the first check, then once per re-plan). Sampling passes through; so does
    what the planner reads of the sampler (``windowed``, ``interpolator``), so the check
    runs in windows as without it."""
    passes = itertools.count()

    def check_begins(k0: int) -> None:
        if k0 == 0:
            n = next(passes)
            say("dynamics check" if n == 0 else f"dynamics check, re-plan {n}")

    return ForwardingSampler(sampler, check_begins)


def run_program(program, machine: Machine, options: RunOptions | None = None, progress=None) -> Run:
    """Plan (or run a baseline on) an interpreted program, interpolate it at the servo period
    and refuse reference points outside the soft limits (PlanningError at the first one:
    here when the points are made here, else as :meth:`Run.chunks` or :attr:`Run.samples`
    make them).
    Before any of that: the segments' boxes inside the soft limits, and the motion time's
    lower bound within ``limits.max_points`` (:mod:`nurbscnc.plan.limits`).

    ``progress``: None, or a function called with a short text as each stage starts
    (checking, planning, each dynamics check, interpolating) — the CLI's progress display;
    the stages know nothing of it."""
    options = options or RunOptions()
    say = progress or (lambda _stage: None)
    if options.precompensate:
        if options.algorithm != Algorithm.PH_LOOKAHEAD:
            raise ConfigError(
                "pre-compensation needs the look-ahead planner (--algorithm "
                "ph-lookahead), not a baseline"
            )
        if not machine.contour_check:
            raise ConfigError(
                f"pre-compensation needs a servo model: the machine profile "
                f"{machine.source} has no [servo.x], [servo.y] or [servo.z]"
            )
        if program.rotary_axes:  # the servo model and ZPETC inverse are X Y Z only
            axes = " ".join(a.upper() for a in program.rotary_axes)
            raise ConfigError(
                f"pre-compensation models the X Y Z servos only; this program uses {axes} "
                "(run it without --precompensate)"
            )
    # Checks before work: the geometry inside the soft limits, the motion short enough for
    # limits.max_points, before anything is planned or sampled.
    say("checking limits")
    columns = segment_columns(program.segments, program.start_abc_deg)
    check_before_work(program.segments, machine, columns, program.frames)
    if not has_motion(columns):
        # Offsets, tool changes, dwells only (LinuxCNC runs such programs): nothing to plan;
        # the output holds the tool at its start point through the dwells, as any algorithm.
        rest = rest_samples(program, columns, machine.servo.period_s)
        run = Run(options.algorithm, rest, rest_s=rest_seconds(program, columns))
    elif options.algorithm == Algorithm.PH_LOOKAHEAD:
        lookahead = options.lookahead
        if not machine.contour_check:
            # No servo model in the profile: there is no contour error to check.
            lookahead = replace(lookahead, dynamics=Dynamics.OFF)
        # The check runs on the interpolator's own points; its final reference is the output.
        sampler = reference_sampler(options.interpolator)
        if progress is not None:
            sampler = _announcing(sampler, say)
        say("planning")
        if options.precompensate:
            run = _run_precompensated(program, machine, lookahead, options, sampler)
        else:
            plan, check = plan_checked(
                program,
                machine,
                lookahead,
                sampler,
                keep_reference=options.keep_reference,
                columns=columns,
            )
            say("interpolating")
            kept = getattr(check, "reference", None)
            # The check's reference, when it kept one, is the output (no second sampling);
            # else the points are made window by window as the output is written.
            whole = None if kept is None else samples_of(kept, plan.pieces, options.interpolator)
            run = Run(
                options.algorithm,
                whole,
                plan,
                check,
                None,
                options.interpolator,
                machine.servo.period_s,
                machine.soft_limits,
            )
    else:
        say(f"interpolating ({options.algorithm.value})")
        samples = baseline_program_samples(options.algorithm.value, program, machine)
        run = Run(options.algorithm, samples)
    if run.whole is not None:  # made already: checked now (a lazy run checks each window)
        check_soft_limits(run.whole.points_mm, run.whole.line, machine.soft_limits)
        check_rotary_limits(run.whole.abc_deg, run.whole.line, machine.rotary_axes)
    return replace(run, columns=columns, rotary_axes=machine.rotary_axes)


def _run_precompensated(
    program, machine: Machine, lookahead: LookaheadOptions, options: RunOptions, sampler
) -> Run:
    """Plan with the dynamics check on the pre-compensated reference, output that reference
    (the same transform on the interpolator's points) and report on it."""
    from nurbscnc.precompensation import (
        precompensate_reference,
        precompensated_sampler,
        precompensation_report,
    )

    tol = options.reference_tolerance_mm
    fit = lookahead.plan.tolerance_mm  # the PH fit tolerance e (None: the profile's)
    # V_cf (SPEC eq. 24) stands in for the servo error of the plain reference: the check
    # of the compensated one may raise it where that error has room.
    lookahead = replace(lookahead, raise_corner_caps=True)
    plan, check = plan_checked(
        program, machine, lookahead, precompensated_sampler(sampler, machine, tol, fit)
    )
    planned = sampler(plan.pieces, plan.profile, machine.servo.period_s)
    compensated, comp = precompensate_reference(
        planned, plan.pieces, plan.profile, machine, tol, fit
    )
    samples = samples_of(compensated, plan.pieces, options.interpolator)
    report = precompensation_report(plan, planned, compensated, comp, machine, tol)
    return Run(options.algorithm, samples, plan, check, report)


def window_plans(program, machine: Machine, options: RunOptions | None = None, each=None):
    """The look-ahead plan of an interpreted program cut window by cut window, for streaming
    while it is planned: the checks before work (the geometry inside the soft limits, the
    motion within ``limits.max_points``) run here, at once (PlanningError before
    anything is planned); then a generator of the windows of
    :func:`~nurbscnc.plan.lookahead.plan_windows`, each yielded once final and its reference
    points inside the soft limits (PlanningError at the first one outside, naming its line)
    and passed to ``each(points_mm, lines)`` when given (the stream's pulse limit). The last
    window's plan is :func:`run_program`'s (the same windows, the same levers), so the points
    streamed are ``run``'s. A baseline ``algorithm`` or pre-compensation (a reference that
    is not causal) raise ConfigError: they have no windows (the stream plans them whole,
    :func:`nurbscnc.app.stream.stream_job`)."""
    options = options or RunOptions()
    if options.algorithm != Algorithm.PH_LOOKAHEAD or options.precompensate:
        raise ConfigError(
            "planning while streaming needs the look-ahead planner without pre-compensation"
        )
    columns = segment_columns(program.segments, program.start_abc_deg)
    check_before_work(program.segments, machine, columns, program.frames)
    lookahead = options.lookahead
    if not machine.contour_check:
        lookahead = replace(lookahead, dynamics=Dynamics.OFF)
    sampler = reference_sampler(options.interpolator)
    period = machine.servo.period_s

    def windows():
        for w in plan_windows(program, machine, lookahead, sampler, columns=columns):
            last = w.end >= len(w.plan.pieces)
            ref = sampler(w.plan.pieces, w.plan.profile, period, w.k0, None if last else w.k1)
            lines = np.take(w.plan.pieces.line, ref.piece)
            check_soft_limits(ref.points_mm, lines, machine.soft_limits)
            check_rotary_limits(ref.abc_deg, lines, machine.rotary_axes)
            if each is not None:
                each(ref.points_mm, lines)
            yield w

    return windows()
