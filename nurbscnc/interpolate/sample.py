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

Long programs are sampled in windows (:func:`sample_chunks`, :func:`reference_chunks`): the
rows k0…k1−1 of the whole reference, window after window, bit-identical to the whole arrays,
so the memory is that of one window whatever the motion time.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from nurbscnc.geometry.path import Kind, equal_runs
from nurbscnc.interpolate.taylor import taylor_nurbs, taylor_params
from nurbscnc.plan.options import Interpolator  # noqa: F401  (re-exported)
from nurbscnc.plan.sampler import ReferenceSampler
from nurbscnc.plan.timing import (
    SLAB,
    Reference,
    Samples,
    exact_reference,
    rows_of,
    sample_count,
    servo_clock,
)
from nurbscnc.program.columns import DWELL, PAUSE

#: Rows per window of :func:`sample_chunks` (64 Ki rows ≈ 6 MB of samples): large enough
#: that the per-window work (servo clock, dwells, Python overhead) is negligible, small
#: enough that a window's temporaries stay in the caches' neighbourhood.
CHUNK = 1 << 16

INTERPOLATORS = tuple(m.value for m in Interpolator)


class InterpolatorSampler(ReferenceSampler):
    """The :class:`~nurbscnc.plan.sampler.ReferenceSampler` of an interpolator: the plan's
    exact reference, with the NURBS points replaced by the Taylor recurrence's for
    ``"taylor"``. Windowed unless it runs the Taylor recurrence (sequential: a window would
    restart it)."""

    def __init__(self, interpolator="exact"):
        self.interpolator = Interpolator.parse(interpolator)
        self.windowed = self.interpolator != Interpolator.TAYLOR

    def __call__(
        self, pieces, profile, period_s: float, k0: int = 0, k1: int | None = None
    ) -> Reference:
        ref = exact_reference(pieces, profile, period_s, k0, k1)
        if self.interpolator == Interpolator.TAYLOR:
            taylor_nurbs(
                pieces.path, ref.piece, ref.tau_s, ref.v_mm_s, ref.a_mm_s2, ref.points_mm, ref.param
            )
        return ref


def reference_sampler(interpolator="exact") -> InterpolatorSampler:
    """The sampler (pieces, profile, period_s, k0=0, k1=None) →
    :class:`~nurbscnc.plan.timing.Reference` of this interpolator (samples k0…k1−1; default
    all), :class:`InterpolatorSampler`. The look-ahead planner's dynamics check runs on it
    (:func:`nurbscnc.plan.lookahead.plan_checked`), so the check sees the points that will be
    output."""
    return InterpolatorSampler(interpolator)


def samples_of(reference, pieces, interpolator="exact") -> Samples:
    """The :class:`Samples` of a reference made by :func:`reference_sampler`."""
    r = reference
    return Samples(
        r.t_s,
        r.tau_s,
        r.s_mm,
        r.v_mm_s,
        r.a_mm_s2,
        r.piece,
        r.points_mm,
        r.param,
        np.take(pieces.line, r.piece),
        Interpolator.parse(interpolator).value,
        abc_deg=r.abc_deg,
        rotary_axes=pieces.rotary.axes if getattr(pieces, "rotary", None) is not None else (),
    )


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
    """The reference points of a :class:`~nurbscnc.plan.plans.Plan` (:func:`sample_plan`)."""
    return sample_plan(plan.pieces, plan.profile, period_s, interpolator)


def reference_chunks(
    pieces, profile, period_s: float, interpolator="exact", chunk: int = CHUNK
) -> Iterator:
    """The plan's reference (:func:`reference_sampler`'s) window by window: one
    :class:`~nurbscnc.plan.timing.Reference` per ``chunk`` consecutive rows, k = 0 … N−1
    (N = :func:`~nurbscnc.plan.timing.sample_count`), bit-identical to the rows of the whole
    reference. Exact points are placed per row (no state); the Taylor recurrence carries
    its state from one window to the next (:class:`_TaylorCarry`)."""
    chunk = int(chunk)
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1 row, got {chunk}")
    how = Interpolator.parse(interpolator)
    n = sample_count(pieces, profile, period_s)
    carry = _TaylorCarry(pieces, profile, period_s, n) if how == Interpolator.TAYLOR else None
    for k0 in range(0, n, chunk):
        ref = exact_reference(pieces, profile, period_s, k0, min(k0 + chunk, n))
        if carry is not None:
            carry.apply(ref, k0)
        yield ref


def sample_chunks(
    pieces, profile, period_s: float, interpolator="exact", chunk: int = CHUNK
) -> Iterator[Samples]:
    """:func:`sample_plan` window by window: :class:`Samples` of ``chunk`` consecutive rows
    (the last window shorter), bit-identical to the rows of the whole samples; memory is one
    window's, whatever the motion time."""
    for ref in reference_chunks(pieces, profile, period_s, interpolator, chunk):
        yield samples_of(ref, pieces, interpolator)


def slice_samples(samples: Samples, k0: int, k1: int) -> Samples:
    """Rows k0…k1−1 of whole samples (views, no copy)."""
    return rows_of(samples, slice(k0, k1))


def chunks_of(samples: Samples, chunk: int = CHUNK) -> Iterator[Samples]:
    """Whole samples as windows of ``chunk`` rows (views), as :func:`sample_chunks` gives."""
    n = samples.t_s.size
    for k0 in range(0, n, max(int(chunk), 1)):
        yield slice_samples(samples, k0, min(k0 + max(int(chunk), 1), n))


class _TaylorCarry:
    """The Taylor recurrence (SPEC §3, eq. 4–5) across windows, so that windowed Taylor points
    are bit-identical to :func:`~nurbscnc.interpolate.taylor.taylor_nurbs` on the whole
    reference.

    The whole computation runs one recurrence per run of consecutive samples on one NURBS
    curve, from the exact u of the run's first sample, with u kept in [u_a of the run's first
    piece, u_b of its last]. A window that continues the previous window's run therefore
    needs: the last sample's Taylor u, feed, acceleration and profile time (the recurrence's
    step from it to the window's first sample is prepended), the run's u_min (known where it
    began) and its u_max — the piece of the run's last sample, which may lie windows ahead:
    found once per run by evaluating only the profile's piece index ahead (no placement)."""

    def __init__(self, pieces, profile, period_s: float, n: int):
        self.pieces, self.profile, self.period_s, self.n = pieces, profile, period_s, n
        self.curve = -1  # curve of the previous window's last sample (-1: not on a NURBS)
        self.u = self.v = self.a = self.tau = 0.0  # its Taylor u, feed, accel, profile time
        self.u_min = 0.0  # u_a of the current run's first piece
        self.u_max: float | None = None  # u_b of its last piece, once looked up

    def _curves(self, piece: np.ndarray) -> np.ndarray:
        path = self.pieces.path
        kind = np.take(path.kind, piece)
        return np.where(kind == Kind.NURBS, np.take(path.obj_id, piece), -1)

    def _run_u_max(self, curve: int, k: int, last_piece: int) -> float:
        """u_b of the piece of the last sample of the run on ``curve`` whose sample k − 1 is
        on piece ``last_piece``: scan rows k, k+1, … (the profile's piece index only, a slab
        at a time) to the run's end."""
        for k0 in range(k, self.n, SLAB):
            _, tau = servo_clock(self.pieces, self.profile, self.period_s, k0, k0 + SLAB)
            piece = self.profile.sample(tau)[4]
            other = np.flatnonzero(self._curves(piece) != curve)
            if other.size:
                if other[0] > 0:
                    last_piece = int(piece[other[0] - 1])
                break
            last_piece = int(piece[-1])
        return float(self.pieces.path.u_b[last_piece])

    def apply(self, ref, k0: int) -> None:
        """Replace the exact NURBS points of window ``ref`` (rows k0…) by the Taylor
        recurrence's, in place, continuing the previous window's run."""
        path = self.pieces.path
        piece, param = ref.piece, ref.param
        curves = self._curves(piece)
        m = curves.size
        if m == 0:
            return
        for a_, z in equal_runs(curves):
            c = int(curves[a_])
            if c < 0:
                continue
            carried = a_ == 0 and c == self.curve
            if not carried:  # a new run: from the exact u of its first sample
                self.u_min = float(path.u_a[piece[a_]])
                self.u_max = None
            if z < m or k0 + m == self.n:  # the run ends in this window
                u_max = float(path.u_b[piece[z - 1]])
            else:  # it goes on into the next window: its end lies ahead
                if self.u_max is None:
                    self.u_max = self._run_u_max(c, k0 + m, int(piece[z - 1]))
                u_max = self.u_max
            pf = path.objects[c].power_form
            v, acc, tau, rest = ref.v_mm_s[a_:z], ref.a_mm_s2[a_:z], ref.tau_s[a_:z], param[a_:z]
            if carried:  # one step from the previous window's last sample first
                v, acc = np.r_[self.v, v], np.r_[self.a, acc]
                tau, rest = np.r_[self.tau, tau], np.r_[self.u, rest]
                u0 = self.u
            else:
                u0 = param[a_]
            u, spans = taylor_params(pf, u0, v, acc, np.diff(tau), self.u_min, u_max, u_rest=rest)
            if carried:
                u, spans = u[1:], spans[1:]
            ref.points_mm[a_:z] = pf.point(u, spans)
            param[a_:z] = u
        self.curve = int(curves[-1])
        if self.curve >= 0:
            self.u, self.v = float(param[-1]), float(ref.v_mm_s[-1])
            self.a, self.tau = float(ref.a_mm_s2[-1]), float(ref.tau_s[-1])


def has_motion(columns) -> bool:
    """Does a program move at all? Any line, rapid, arc or NURBS among its segment columns
    (:func:`~nurbscnc.program.columns.segment_columns`; the interpreter drops moves that go
    nowhere, so a program of offsets, tool changes, dwells and stops has none)."""
    return bool(np.any((columns.kind != DWELL) & (columns.kind != PAUSE)))


def rest_samples(program, columns, period_s: float) -> Samples:
    """The reference points of a program with no motion (:func:`has_motion` False): the
    tool at rest at the program's start point ``program.start_mm`` from t = 0 through its
    dwells, t_k = k·T_s for k = 0 … N−1 with N = ⌈ΣT_dwell / T_s⌉ + 1, the rule of a plan
    (:func:`~nurbscnc.plan.timing.sample_count`): one row at t = 0 when nothing dwells.
    Feed, acceleration and path length are 0; ``piece`` is 0 (there is none, as for a
    baseline); ``line`` is the source line of the dwell in progress at t_k (the last
    dwell's after the last one ends; the first segment's, or 0 for a program without
    segments, at t = 0 before any dwell). A program that holds rotary axes keeps them at
    ``program.start_abc_deg``."""
    dwells = columns.rows(DWELL)
    ends_s = np.cumsum(_dwell_seconds(program, dwells))
    total_s = float(ends_s[-1]) if ends_s.size else 0.0
    n = int(np.ceil(total_s / period_s - 1e-9)) + 1
    t = np.arange(n) * period_s
    if dwells.size:
        lines = columns.lines[dwells][
            np.minimum(np.searchsorted(ends_s, t, "right"), dwells.size - 1)
        ]
    else:
        lines = np.full(n, columns.lines[0] if columns.lines.size else 0)
    zeros = np.zeros(n)
    return Samples(
        t_s=t,
        tau_s=t.copy(),
        s_mm=zeros,
        v_mm_s=zeros.copy(),
        a_mm_s2=zeros.copy(),
        piece=np.zeros(n, dtype=np.int64),
        points_mm=np.repeat(np.asarray(program.start_mm, dtype=float)[None, :], n, axis=0),
        param=None,
        line=lines.astype(np.int64),
        abc_deg=_rest_abc_deg(program, n),
        rotary_axes=tuple(getattr(program, "rotary_axes", ())),
    )


def _rest_abc_deg(program, n: int) -> np.ndarray | None:
    """A B C [deg] (n, 3) of a program at rest: where it starts them (None without rotary
    axes)."""
    if not getattr(program, "rotary_axes", ()):
        return None
    return np.repeat(np.asarray(program.start_abc_deg, dtype=float)[None, :], n, axis=0)


def _dwell_seconds(program, dwells: np.ndarray) -> np.ndarray:
    """The durations [s] of the dwell segments at indexes ``dwells``."""
    return np.array([program.segments[k].seconds for k in dwells], dtype=float)


def rest_seconds(program, columns) -> float:
    """How long a program with no motion holds the tool at rest [s]: the sum of its dwells
    (exact; :func:`rest_samples` ends at the first servo period at or after it)."""
    return float(np.sum(_dwell_seconds(program, columns.rows(DWELL))))
