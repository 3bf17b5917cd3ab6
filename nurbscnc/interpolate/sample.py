"""The interpolator: one reference point per servo period T_s (SPEC §3, §4, §10).

Given a planned profile s(t) over the pieces, the reference point at t_k = k·T_s is the point
of the path at arc length s(t_k), placed exactly: PH pieces by Newton on their closed-form
arc length (SPEC §4, eq. 10–12), NURBS pieces by the quintic Hermite inversion table of the
curve (SPEC §10; within 1e-9 mm of the exact arc-length inverse, every point C(u) on the
curve), lines and arcs in closed form. Dwells hold the point for their duration. Or, with
``interpolator="taylor"``, NURBS pieces by the paper's 2nd-order Taylor recurrence (SPEC §3,
eq. 4–5), which is sequential by nature (a tight scalar loop per run of NURBS samples).

The exact points come from the plan's reference (:func:`nurbscnc.plan.timing.exact_reference`,
through the path model :class:`~nurbscnc.geometry.path.PathTable`): the dynamics check saw
exactly these points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.interpolate.taylor import taylor_nurbs
from nurbscnc.plan.options import Interpolator  # noqa: F401  (re-exported)
from nurbscnc.plan.timing import exact_reference

INTERPOLATORS = tuple(m.value for m in Interpolator)


@dataclass(frozen=True, eq=False)
class Samples:
    """Reference points at the servo period.

    ``t_s`` (N,) [s] = k·T_s; ``points_mm`` (N, 3) [mm]; ``s_mm`` path length [mm];
    ``v_mm_s`` planned feed [mm/s]; ``a_mm_s2`` tangential acceleration [mm/s²];
    ``piece`` index of the piece; ``line`` source line of that piece; ``param`` (N,) the
    parameter of each point on its piece's geometry (NURBS u, PH ξ, line/arc u [mm]);
    ``interpolator`` "exact" or "taylor".
    """

    t_s: np.ndarray
    points_mm: np.ndarray
    s_mm: np.ndarray
    v_mm_s: np.ndarray
    a_mm_s2: np.ndarray
    piece: np.ndarray
    line: np.ndarray
    param: np.ndarray | None = None
    interpolator: str = "exact"


def reference_sampler(interpolator="exact"):
    """The function (pieces, profile, period_s, k0=0, k1=None) →
    :class:`~nurbscnc.plan.timing.Reference` of this interpolator (samples k0…k1−1; default
    all): the plan's exact reference, with the NURBS points replaced by the
    Taylor recurrence's for ``"taylor"``. The look-ahead planner's dynamics check runs on it
    (:func:`nurbscnc.plan.lookahead.plan_checked`), so the check sees the points that will be
    output."""
    how = Interpolator.parse(interpolator)

    def sample(pieces, profile, period_s: float, k0: int = 0, k1: int | None = None):
        ref = exact_reference(pieces, profile, period_s, k0, k1)
        if how == Interpolator.TAYLOR:
            taylor_nurbs(pieces.path, ref.piece, ref.tau_s, ref.v_mm_s, ref.a_mm_s2,
                         ref.points_mm, ref.param)  # fmt: skip
        return ref

    sample.interpolator = how
    return sample


def samples_of(reference, pieces, interpolator="exact") -> Samples:
    """The :class:`Samples` of a reference made by :func:`reference_sampler`."""
    r = reference
    return Samples(r.t_s, r.points_mm, r.s_mm, r.v_mm_s, r.a_mm_s2, r.piece,
                   np.take(pieces.line, r.piece), r.param,
                   Interpolator.parse(interpolator).value)  # fmt: skip


def sample_plan(pieces, profile, period_s: float, interpolator="exact") -> Samples:
    """Reference points at t_k = k·T_s from 0 until the end (SPEC §1, interpolator).

    The last sample is the first k·T_s at or after the end of motion: the tool is at rest at
    the programmed end point there, and every pair of consecutive samples is T_s apart.
    ``interpolator`` (:class:`Interpolator`): "exact" (arc-length exact everywhere, SPEC §10)
    or "taylor" (NURBS pieces by the paper's Taylor recurrence, SPEC §3; PH pieces, lines
    and arcs exact).
    """
    ref = reference_sampler(interpolator)(pieces, profile, period_s)
    return samples_of(ref, pieces, interpolator)


def interpolate(plan, period_s: float, interpolator="exact") -> Samples:
    """The reference points of a :class:`~nurbscnc.plan.lookahead.Plan` (:func:`sample_plan`)."""
    return sample_plan(plan.pieces, plan.profile, period_s, interpolator)
