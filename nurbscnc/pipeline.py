"""The whole pipeline for one program: plan (or a baseline), interpolate, check soft limits.

program → geometry → plan (pieces, profile, dynamics check) → interpolate (reference points).
The CLI builds the option objects and calls :func:`run_program`; the outputs and reports
are made from the :class:`Run` it returns. No I/O here.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, fields, replace

import numpy as np

from nurbscnc.errors import ConfigError
from nurbscnc.interpolate.baselines import baseline_program_samples
from nurbscnc.interpolate.sample import (
    Interpolator,
    Samples,
    reference_sampler,
    sample_plan,
    samples_of,
)
from nurbscnc.machine.profile import AxisServo, Machine
from nurbscnc.plan.dynamics import PathIndex, path_response, windowed_contour_mm
from nurbscnc.plan.limits import check_before_work
from nurbscnc.plan.lookahead import Check, Plan, plan_checked
from nurbscnc.plan.options import Algorithm, Dynamics, LookaheadOptions, parse_choice
from nurbscnc.plan.report import check_soft_limits
from nurbscnc.plan.timing import Reference
from nurbscnc.servo.model import AxisModel
from nurbscnc.servo.precompensate import (
    REFERENCE_TOLERANCE_MM,
    Compensated,
    along_path_offset_mm,
    limit_to_path,
    perturbed_model,
    precompensate_points,
)


@dataclass(frozen=True)
class RunOptions:
    """Everything a command may choose about planning and interpolation (validated on
    construction): the ``algorithm``, the look-ahead planner's options (``lookahead``, not
    used by a baseline), the ``interpolator`` of NURBS pieces, and ``precompensate``: feed
    the servo the ZPETC pre-compensated reference (:mod:`nurbscnc.servo.precompensate`;
    the dynamics check then simulates it, and it is the output), kept within
    ``reference_tolerance_mm`` of the path (inf: no limit)."""

    algorithm: Algorithm = Algorithm.PH_LOOKAHEAD
    lookahead: LookaheadOptions = field(default_factory=LookaheadOptions)
    interpolator: Interpolator = Interpolator.EXACT
    precompensate: bool = False
    reference_tolerance_mm: float = REFERENCE_TOLERANCE_MM

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
    """One program through the pipeline: its reference ``samples``; for the look-ahead
    planner also the ``plan`` and its dynamics ``check`` (None when the check was off); a
    baseline has neither (``plan`` is None)."""

    algorithm: Algorithm
    samples: Samples
    plan: Plan | None = None
    check: Check | None = None
    precompensation: Precompensation | None = None

    @property
    def cycle_time_s(self) -> float:
        """Cycle time [s] including dwells: the plan's (plus the pre-compensation's held
        start, when on), or a baseline's last sample time."""
        if self.plan is not None:
            lead = self.precompensation.lead_s if self.precompensation is not None else 0.0
            return self.plan.cycle_time_s + lead
        return float(self.samples.t_s[-1])


#: The ±10 % model errors of the sensitivity report: (label, loop gain per axis x, y, z,
#: bandwidth per axis) — :func:`~nurbscnc.servo.precompensate.perturbed_model`: the loop gain
#: moves the closed-loop poles (zeros kept), the bandwidth scales poles and zeros; each both
#: ways on every axis, and with x and y off in opposite directions (what distorts a contour).
SENSITIVITY_CASES = (
    ("loop gain -10 %", (0.9, 0.9, 0.9), (1.0, 1.0, 1.0)),
    ("loop gain +10 %", (1.1, 1.1, 1.1), (1.0, 1.0, 1.0)),
    ("loop gain x -10 %, y, z +10 %", (0.9, 1.1, 1.1), (1.0, 1.0, 1.0)),
    ("loop gain x +10 %, y, z -10 %", (1.1, 0.9, 0.9), (1.0, 1.0, 1.0)),
    ("bandwidth -10 %", (1.0, 1.0, 1.0), (0.9, 0.9, 0.9)),
    ("bandwidth +10 %", (1.0, 1.0, 1.0), (1.1, 1.1, 1.1)),
    ("bandwidth x -10 %, y, z +10 %", (1.0, 1.0, 1.0), (0.9, 1.1, 1.1)),
    ("bandwidth x +10 %, y, z -10 %", (1.0, 1.0, 1.0), (1.1, 0.9, 0.9)),
)


@dataclass(frozen=True)
class Precompensation:
    """What pre-compensation did to a plan's reference (``run --precompensate``).

    ``lead_s`` how much later than planned the tool moves: the inverse's look-ahead, taken
    as a delay so nothing moves before t = 0 [s] (counted in the cycle time);
    ``tail_s`` the periods after the planned stop while the compensation decays [s];
    ``reference_deviation_max_mm`` the compensated points' largest distance from the path
    [mm] (cutting samples), kept within ``reference_tolerance_mm``; ``sensitivity`` (label,
    worst contour error [mm]) of the same reference simulated through each model error of
    :data:`SENSITIVITY_CASES`."""

    lead_s: float
    tail_s: float
    reference_deviation_max_mm: float
    sensitivity: tuple[tuple[str, float], ...]
    reference_tolerance_mm: float = float("inf")

    @property
    def sensitivity_max_mm(self) -> float:
        """The worst contour error [mm] over the model errors."""
        return max((e for _, e in self.sensitivity), default=0.0)

    def as_json(self) -> dict:
        """The ``precompensation`` object of ``plan``/``run --json`` (µm, s; a tolerance of
        None is no limit)."""
        tol = self.reference_tolerance_mm
        return {"method": "zpetc", "lead_s": self.lead_s, "tail_s": self.tail_s,
                "reference_tolerance_um": tol * 1000.0 if np.isfinite(tol) else None,
                "reference_deviation_max_um": self.reference_deviation_max_mm * 1000.0,
                "sensitivity_contour_max_um": self.sensitivity_max_mm * 1000.0,
                "sensitivity": [{"model_error": k, "contour_max_um": e * 1000.0}
                                for k, e in self.sensitivity]}  # fmt: skip


def _models(machine: Machine) -> list:
    servo = machine.servo
    return [servo.x, servo.y, servo.z]


def precompensate_reference(ref: Reference, pieces, profile, machine: Machine,
                            tolerance_mm: float = REFERENCE_TOLERANCE_MM,
                            ) -> tuple[Reference, Compensated]:  # fmt: skip
    """The ZPETC pre-compensated version of a plan's reference (SPEC eq. 25 inverted,
    :func:`~nurbscnc.servo.precompensate.precompensate_points`), kept within
    ``tolerance_mm`` of the path (inf: no limit): each compensated point u_k is limited to
    that distance from the path point its lead d_t
    (:func:`~nurbscnc.servo.precompensate.along_path_offset_mm`) ahead of the planned point,
    placed exactly at path length s_k + d_t (clamped to the program's ends, so the
    reference is never led past the end point along the path;
    :func:`~nurbscnc.servo.precompensate.limit_to_path`). Every other per-sample column is
    padded to the new length (the start repeated ``lead_samples`` times, the end through the
    tail), so the dynamics check maps each sample to its piece and path length as before.
    Wall times restart at 0 with the servo period."""
    period = machine.servo.period_s
    comp = precompensate_points(_models(machine), ref.points_mm, period)
    pad = (comp.lead_samples, comp.tail_samples)

    def edge(x):
        return np.pad(x, pad, mode="edge") if x.ndim == 1 else np.pad(x, (pad, (0, 0)), "edge")

    points = comp.points_mm
    s_mm = edge(ref.s_mm)
    if np.isfinite(tolerance_mm):
        lead_mm = along_path_offset_mm(points, edge(ref.points_mm))
        s_foot = np.clip(s_mm + lead_mm, 0.0, profile.total_length_mm)
        starts = profile.piece_start_mm
        piece = np.clip(np.searchsorted(starts, s_foot, side="right") - 1, 0, starts.size - 1)
        foot = pieces.path.place(starts, np.minimum(s_foot, starts[piece]
                                                    + pieces.length_mm[piece]), piece)[0]
        points = limit_to_path(points, foot, tolerance_mm)
        comp = replace(comp, points_mm=points)
    n_in, n = ref.points_mm.shape[0], points.shape[0]
    # Every per-sample column padded alike (whatever columns the Reference has).
    columns = {f.name: edge(getattr(ref, f.name)) for f in fields(ref)
               if isinstance(getattr(ref, f.name), np.ndarray)
               and getattr(ref, f.name).shape[:1] == (n_in,)}  # fmt: skip
    columns.update(t_s=np.arange(n) * period, points_mm=points)
    return replace(ref, **columns), comp


def precompensated_sampler(sampler, machine: Machine,
                           tolerance_mm: float = REFERENCE_TOLERANCE_MM):  # fmt: skip
    """The reference sampler (pieces, profile, period_s) → Reference of ``sampler`` followed
    by :func:`precompensate_reference`: what the dynamics check simulates with
    ``--precompensate`` (it needs no hook in the planner)."""

    def sample(pieces, profile, period_s: float):
        ref = sampler(pieces, profile, period_s)
        return precompensate_reference(ref, pieces, profile, machine, tolerance_mm)[0]

    sample.interpolator = getattr(sampler, "interpolator", None)
    return sample


def _servo_of(model: AxisModel) -> AxisServo:
    """An eq.-25 :class:`AxisServo` holding ``model`` (degrees ≤ 2 over ≤ 4)."""
    num = np.zeros(3)
    den = np.zeros(5)
    n = np.trim_zeros(np.asarray(model.numerator, dtype=float), "f")
    d = np.trim_zeros(np.asarray(model.denominator, dtype=float), "f")
    num[3 - n.size :] = n
    den[5 - d.size :] = d
    return AxisServo(a0=den[4], a1=den[3], a2=den[2], a3=den[1], a4=den[0], b0=num[2],
                     b1=num[1], b2=num[0])  # fmt: skip


def precompensation_report(plan: Plan, planned: Reference, compensated: Reference,
                           comp: Compensated, machine: Machine,
                           tolerance_mm: float = REFERENCE_TOLERANCE_MM) -> Precompensation:
    """The reference's own deviation from the path and the ±10 % model-error sensitivity.

    Deviation: the distance of each compensated point u_k from the path, measured near the
    planned point r_k of the same period (on the path; W = 2|u_k − r_k|,
    :func:`~nurbscnc.plan.dynamics.windowed_contour_mm`: never below the true distance), and
    where that exceeds the tolerance, to the whole path (:class:`PathIndex`).
    Sensitivity: the compensated points simulated through each model of
    :data:`SENSITIVITY_CASES` (:func:`~nurbscnc.plan.dynamics.path_response`, true distance
    to the path), the largest contour error on cutting samples, as the dynamics check counts
    it."""
    pieces, profile = plan.pieces, plan.profile
    pad = (comp.lead_samples, comp.tail_samples)
    r = np.pad(planned.points_mm, (pad, (0, 0)), mode="edge")
    u = compensated.points_mm
    lag = np.sqrt(np.sum((u - r) ** 2, axis=1))
    cut = ~pieces.rapid[compensated.piece]
    dev = windowed_contour_mm(u, lag, compensated.s_mm, pieces, profile)
    index = PathIndex(pieces)
    # Above the tolerance, the distance to the whole path (the window may miss a nearer
    # stretch of path, e.g. the other leg of a hairpin): the true distance.
    sel = np.flatnonzero(dev > min(tolerance_mm, float(lag.max())))
    if sel.size:
        dev[sel] = index.distance_mm(u[sel], dev[sel])
    deviation = float(dev[cut].max()) if cut.any() else 0.0
    eps = machine.limits.contour_tolerance_mm
    rows = []
    for label, gains, bandwidths in SENSITIVITY_CASES:
        servo = machine.servo
        models = {a: None if m is None else _servo_of(perturbed_model(m, k, lam))
                  for a, m, k, lam in zip("xyz", _models(machine), gains, bandwidths)}
        perturbed = replace(machine, servo=replace(servo, **models))
        resp = path_response(compensated, pieces, profile, perturbed, refine_above_mm=eps,
                             index=index)  # fmt: skip
        tail = np.full(resp.contour_mm.size - u.shape[0], not pieces.rapid[-1])
        cutting = np.append(cut, tail)
        err = resp.contour_mm[cutting]
        rows.append((label, float(err.max()) if err.size else 0.0))
    period = machine.servo.period_s
    return Precompensation(comp.lead_samples * period, comp.tail_samples * period, deviation,
                           tuple(rows), tolerance_mm)  # fmt: skip


def _announcing(sampler, say):
    """``sampler`` that first says which pass of the planner's dynamics check it serves (the
    planner calls it once per plan: the first check, then once per re-plan)."""
    passes = itertools.count()

    def sample(pieces, profile, period_s):
        n = next(passes)
        say("dynamics check" if n == 0 else f"dynamics check, re-plan {n}")
        return sampler(pieces, profile, period_s)

    return sample


def run_program(program, machine: Machine, options: RunOptions | None = None,
                progress=None) -> Run:  # fmt: skip
    """Plan (or run a baseline on) an interpreted program, interpolate it at the servo period
    and refuse reference points outside the soft limits (PlanningError at the first one).
    Before any of that: the segments' boxes inside the soft limits, and the motion time's
    lower bound within ``limits.max_points`` (:mod:`nurbscnc.plan.limits`).

    ``progress``: None, or a function called with a short text as each stage starts
    (checking, planning, each dynamics check, interpolating) — the CLI's progress display;
    the stages know nothing of it."""
    options = options or RunOptions()
    say = progress or (lambda _stage: None)
    if options.precompensate:
        if options.algorithm != Algorithm.PH_LOOKAHEAD:
            raise ConfigError("pre-compensation needs the look-ahead planner (--algorithm "
                              "ph-lookahead), not a baseline")  # fmt: skip
        if not machine.contour_check:
            raise ConfigError(f"pre-compensation needs a servo model: the machine profile "
                              f"{machine.source} has no [servo.x], [servo.y] or [servo.z]")
    # Checks before work (issue 14): the geometry inside the soft limits, the motion short
    # enough for limits.max_points, before anything is planned or sampled.
    say("checking limits")
    check_before_work(program.segments, machine)
    if options.algorithm == Algorithm.PH_LOOKAHEAD:
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
            plan, check = plan_checked(program, machine, lookahead, sampler)
            say("interpolating")
            if check is not None:
                samples = samples_of(check.reference, plan.pieces, options.interpolator)
            else:
                samples = sample_plan(plan.pieces, plan.profile, machine.servo.period_s,
                                      options.interpolator)  # fmt: skip
            run = Run(options.algorithm, samples, plan, check)
    else:
        say(f"interpolating ({options.algorithm.value})")
        samples = baseline_program_samples(options.algorithm.value, program, machine)
        run = Run(options.algorithm, samples)
    check_soft_limits(run.samples.points_mm, run.samples.line, machine.soft_limits)
    return run


def _run_precompensated(program, machine: Machine, lookahead: LookaheadOptions,
                        options: RunOptions, sampler) -> Run:  # fmt: skip
    """Plan with the dynamics check on the pre-compensated reference, output that reference
    (the same transform on the interpolator's points) and report on it."""
    tol = options.reference_tolerance_mm
    plan, check = plan_checked(program, machine, lookahead,
                               precompensated_sampler(sampler, machine, tol))  # fmt: skip
    planned = sampler(plan.pieces, plan.profile, machine.servo.period_s)
    compensated, comp = precompensate_reference(planned, plan.pieces, plan.profile, machine,
                                                tol)  # fmt: skip
    samples = samples_of(compensated, plan.pieces, options.interpolator)
    report = precompensation_report(plan, planned, compensated, comp, machine, tol)
    return Run(options.algorithm, samples, plan, check, report)
