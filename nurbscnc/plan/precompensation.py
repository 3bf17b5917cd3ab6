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

from nurbscnc.machine.profile import AxisServo, Machine
from nurbscnc.plan.dynamics import PathIndex, path_response, windowed_contour_mm
from nurbscnc.plan.lookahead import Plan
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
