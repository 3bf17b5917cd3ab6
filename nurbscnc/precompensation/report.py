"""The report of a pre-compensated reference (``run --precompensate``): its own deviation
from the path and the contour error under ±10 % model errors (:func:`precompensation_report`,
:class:`Precompensation`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from nurbscnc.geometry.distance import PathIndex, windowed_contour_mm
from nurbscnc.machine.profile import AxisServo, Machine
from nurbscnc.plan.dynamics import path_response
from nurbscnc.plan.lookahead import Plan
from nurbscnc.plan.timing import Reference
from nurbscnc.servo.model import AxisModel
from nurbscnc.servo.precompensate import (
    REFERENCE_TOLERANCE_MM,
    Compensated,
    axis_models,
    perturbed_model,
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
        return {
            "method": "zpetc",
            "lead_s": self.lead_s,
            "tail_s": self.tail_s,
            "reference_tolerance_um": tol * 1000.0 if np.isfinite(tol) else None,
            "reference_deviation_max_um": self.reference_deviation_max_mm * 1000.0,
            "end_step_um": self.end_step_mm * 1000.0,
            "end_blend_s": self.end_blend_s,
            "sensitivity_contour_max_um": self.sensitivity_max_mm * 1000.0,
            "sensitivity": [
                {"model_error": k, "contour_max_um": e * 1000.0} for k, e in self.sensitivity
            ],
        }


def _servo_of(model: AxisModel) -> AxisServo:
    """An eq.-25 :class:`AxisServo` holding ``model`` (degrees ≤ 2 over ≤ 4)."""
    num = np.zeros(3)
    den = np.zeros(5)
    n = np.trim_zeros(np.asarray(model.numerator, dtype=float), "f")
    d = np.trim_zeros(np.asarray(model.denominator, dtype=float), "f")
    num[3 - n.size :] = n
    den[5 - d.size :] = d
    return AxisServo(
        a0=den[4], a1=den[3], a2=den[2], a3=den[1], a4=den[0], b0=num[2], b1=num[1], b2=num[0]
    )


def precompensation_report(
    plan: Plan,
    planned: Reference,
    compensated: Reference,
    comp: Compensated,
    machine: Machine,
    tolerance_mm: float = REFERENCE_TOLERANCE_MM,
) -> Precompensation:
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
        models = {
            a: None if m is None else _servo_of(perturbed_model(m, k, lam))
            for a, m, k, lam in zip("xyz", axis_models(machine), gains, bandwidths)
        }
        perturbed = replace(machine, servo=replace(servo, **models))
        resp = path_response(
            compensated, pieces, profile, perturbed, refine_above_mm=eps, index=index
        )
        tail = np.full(resp.contour_mm.size - u.shape[0], not pieces.rapid[-1])
        cutting = np.append(cut, tail)
        err = resp.contour_mm[cutting]
        rows.append((label, float(err.max()) if err.size else 0.0))
    period = machine.servo.period_s
    return Precompensation(
        comp.lead_samples * period,
        0.0,
        deviation,
        tuple(rows),
        tolerance_mm,
        comp.end_step_mm,
        comp.end_blend_samples * period,
    )
