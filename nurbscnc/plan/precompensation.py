"""Pre-compensation of a plan's reference (``--precompensate``, issue 13) and its report.

The ZPETC inverse itself (:mod:`nurbscnc.servo.precompensate`) works on points; here it is
applied to a plan's :class:`~nurbscnc.plan.timing.Reference` (kept near the path, padded so
the dynamics check maps every sample to its piece), wrapped as the reference sampler the
planner's check simulates, and reported on: the compensated reference's own deviation from
the path and the contour error under ±10 % model errors.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.path import Kind
from nurbscnc.machine.profile import AxisServo, Machine
from nurbscnc.plan.dynamics import PathIndex, path_response, windowed_contour_mm
from nurbscnc.plan.lookahead import Plan
from nurbscnc.plan.timing import Reference
from nurbscnc.servo.model import AxisModel, contour_error_true
from nurbscnc.servo.precompensate import (
    REFERENCE_TOLERANCE_MM,
    Compensated,
    along_path_offset_mm,
    limit_to_path,
    perturbed_model,
    precompensate_points,
)

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
    ``tail_s`` periods added after the planned stop [s] (none: the inverse's tail is
    blended in, ``end_step_mm`` [mm] over the last ``end_blend_s`` [s]);
    ``reference_deviation_max_mm`` the compensated points' largest distance from the path
    [mm] (cutting samples), kept within ``reference_tolerance_mm``; ``sensitivity`` (label,
    worst contour error [mm]) of the same reference simulated through each model error of
    :data:`SENSITIVITY_CASES`."""

    lead_s: float
    tail_s: float
    reference_deviation_max_mm: float
    sensitivity: tuple[tuple[str, float], ...]
    reference_tolerance_mm: float = float("inf")
    end_step_mm: float = 0.0
    end_blend_s: float = 0.0

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
                "end_step_um": self.end_step_mm * 1000.0, "end_blend_s": self.end_blend_s,
                "sensitivity_contour_max_um": self.sensitivity_max_mm * 1000.0,
                "sensitivity": [{"model_error": k, "contour_max_um": e * 1000.0}
                                for k, e in self.sensitivity]}  # fmt: skip


def _models(machine: Machine) -> list:
    servo = machine.servo
    return [servo.x, servo.y, servo.z]


#: Spacing of the programmed curve's points where the reference tolerance is measured
#: against it (:func:`_fit_margin_mm`) [mm]; the sagitta of the chords is added.
_CURVE_SPACING_MM = 1e-3


def _fit_margin_mm(pieces, piece: np.ndarray, foot_mm: np.ndarray,
                   fit_tolerance_mm: float) -> np.ndarray:  # fmt: skip
    """How far each foot (M, 3) [mm] may be from the programmed path (M,) [mm]: 0 on every
    piece of the programmed path itself; on a PH corner piece of a NURBS (SPEC §6: a fit
    within e of the curve, not on it) its distance to the NURBS span the fit replaces
    (a dense polyline of the curve, exact point-to-segment distance, plus the chords'
    sagitta κ_max c²/8), or ``fit_tolerance_mm`` e where that span is not known.
    Line-line blends (``pieces.ph_rows``) leave the programmed corner by design: there the
    planned path is the path."""
    fit = pieces.kind == Kind.PH
    fit[pieces.ph_rows] = False
    margin = np.zeros(piece.size)
    rows = np.flatnonzero(fit)
    if not rows.size:
        return margin
    # Runs of consecutive fit rows of one segment: one corner region each.
    breaks = np.flatnonzero((np.diff(rows) != 1)
                            | (pieces.segment[rows[1:]] != pieces.segment[rows[:-1]]))
    for group in np.split(rows, breaks + 1):
        sel = np.flatnonzero((piece >= group[0]) & (piece <= group[-1]))
        if not sel.size:
            continue
        lo, hi = pieces.objects.get(group[0] - 1), pieces.objects.get(group[-1] + 1)
        seg = pieces.segment[group[0]]
        lo = lo if group[0] > 0 and pieces.segment[group[0] - 1] == seg else None
        hi = hi if group[-1] + 1 < len(pieces) and pieces.segment[group[-1] + 1] == seg else None
        curve = next((o[0] for o in (lo, hi) if o is not None and isinstance(o[0], NurbsCurve)),
                     None)  # fmt: skip
        if curve is None:
            margin[sel] = fit_tolerance_mm
            continue
        u_lo = lo[2] if lo is not None and lo[0] is curve else curve.u_start
        u_hi = hi[1] if hi is not None and hi[0] is curve else curve.u_end
        length = float(pieces.length_mm[group].sum())
        m = int(np.clip(np.ceil(length / _CURVE_SPACING_MM), 64, 100_000)) + 1
        dense = curve.point(np.linspace(u_lo, u_hi, m))
        chord = float(np.linalg.norm(np.diff(dense, axis=0), axis=1).max())
        kappa = float(pieces.kappa_max_per_mm[group].max())
        sagitta = kappa * chord * chord / 8.0 if np.isfinite(kappa) else chord
        margin[sel] = contour_error_true(foot_mm[sel], dense) + sagitta
    return margin


def _tube_mm(pieces, piece: np.ndarray, foot_mm: np.ndarray, tolerance_mm: float,
             fit_tolerance_mm: float) -> np.ndarray:  # fmt: skip
    """The reference tolerance about each foot [mm] (M,): ``tolerance_mm`` less the foot's
    own distance from the programmed path (:func:`_fit_margin_mm`), so that the reference
    is within ``tolerance_mm`` of the *programmed* path (the triangle inequality)."""
    margin = _fit_margin_mm(pieces, piece, foot_mm, fit_tolerance_mm)
    return np.maximum(tolerance_mm - margin, 0.0)


def precompensate_reference(ref: Reference, pieces, profile, machine: Machine,
                            tolerance_mm: float = REFERENCE_TOLERANCE_MM,
                            fit_tolerance_mm: float | None = None,
                            ) -> tuple[Reference, Compensated]:  # fmt: skip
    """The ZPETC pre-compensated version of a plan's reference (SPEC eq. 25 inverted,
    :func:`~nurbscnc.servo.precompensate.precompensate_points`; F's tail blended in within
    the machine's acceleration and jerk, so it ends with the plan), kept within
    ``tolerance_mm`` of the path (inf: no limit): each compensated point u_k is projected
    onto the ball of that radius (less the foot's own distance from the programmed curve on
    PH corner pieces of a NURBS, :func:`_tube_mm`; the fit tolerance ``fit_tolerance_mm``,
    default the profile's e, where that is not known) about the path point
    its lead d_t (:func:`~nurbscnc.servo.precompensate.along_path_offset_mm`) ahead of the
    planned point, placed exactly at path length s_k + d_t (clamped to the program's ends,
    so the reference is never led past the end point along the path;
    :func:`~nurbscnc.servo.precompensate.limit_to_path`). Every other per-sample column is
    padded to the new length (the start repeated ``lead_samples`` times), so the dynamics
    check maps each sample to its piece and path length as before. Wall times restart at
    0 with the servo period."""
    period = machine.servo.period_s
    lim = machine.limits
    comp = precompensate_points(_models(machine), ref.points_mm, period,
                                a_max_mm_s2=lim.a_max_mm_s2, j_max_mm_s3=lim.j_max_mm_s3)
    pad = (comp.lead_samples, 0)

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
        fit = lim.ph_tolerance_mm if fit_tolerance_mm is None else fit_tolerance_mm
        points = limit_to_path(points, foot, _tube_mm(pieces, piece, foot, tolerance_mm, fit))
        comp = replace(comp, points_mm=points)
    n_in, n = ref.points_mm.shape[0], points.shape[0]
    # Every per-sample column padded alike (whatever columns the Reference has).
    columns = {f.name: edge(getattr(ref, f.name)) for f in fields(ref)
               if isinstance(getattr(ref, f.name), np.ndarray)
               and getattr(ref, f.name).shape[:1] == (n_in,)}  # fmt: skip
    columns.update(t_s=np.arange(n) * period, points_mm=points)
    return replace(ref, **columns), comp


def precompensated_sampler(sampler, machine: Machine,
                           tolerance_mm: float = REFERENCE_TOLERANCE_MM,
                           fit_tolerance_mm: float | None = None):  # fmt: skip
    """The reference sampler (pieces, profile, period_s) → Reference of ``sampler`` followed
    by :func:`precompensate_reference`: what the dynamics check simulates with
    ``--precompensate`` (it needs no hook in the planner)."""

    def sample(pieces, profile, period_s: float):
        ref = sampler(pieces, profile, period_s)
        return precompensate_reference(ref, pieces, profile, machine, tolerance_mm,
                                       fit_tolerance_mm)[0]

    sample.interpolator = getattr(sampler, "interpolator", None)
    # The inverse filters the whole reference (its state runs from the start): the planner
    # evaluates this sampler whole, not in windows of samples k0…k1.
    sample.windows = False
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
    pad = (comp.lead_samples, 0)
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
    return Precompensation(comp.lead_samples * period, 0.0, deviation, tuple(rows),
                           tolerance_mm, comp.end_step_mm,
                           comp.end_blend_samples * period)  # fmt: skip
