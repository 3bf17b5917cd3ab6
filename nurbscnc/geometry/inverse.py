"""The fast arc-length inversion u(s) (SPEC §10): piecewise quintic Hermite interpolation in
s, each interval split until it meets the tolerance, the rest left to the exact Newton
inversion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.powerform import BLOCK, blocks

#: Target of the fast inversion [mm]: |s(u) − s| at the check points of every interval.
INVERSE_TOL_MM = 1e-11
#: Initial interval length [mm] of the inversion table (then split where needed).
INVERSE_START_MM = 0.25
#: Bisections of one initial interval before it is left to the exact Newton inversion.
INVERSE_MAX_DEPTH = 40
#: Most intervals a table may have [count], at least 16 per initial interval: where the
#: splitting would pass it, every interval still failing is left to the exact Newton
#: inversion (bounded memory whatever the curve). A weight of 140,164 among weights of 1
#: holds u(s) away from the quintics below 0.1 µm: unbounded, the intervals would double at
#: every level (3.8 million at depth 35, 24 GB).
INVERSE_MAX_INTERVALS = 1 << 17


def _hermite_quintic(y0, d0, a0, y1, d1, a1) -> np.ndarray:
    """Monomial coefficients (6, m) of the quintic on t ∈ [0, 1] with value, first and second
    derivative y, d, a given at t = 0 and t = 1 (already scaled to t)."""
    dy = y1 - y0
    return np.array(
        [
            y0,
            d0,
            0.5 * a0,
            10.0 * dy - 6.0 * d0 - 4.0 * d1 - 1.5 * a0 + 0.5 * a1,
            -15.0 * dy + 8.0 * d0 + 7.0 * d1 + 1.5 * a0 - a1,
            6.0 * dy - 3.0 * (d0 + d1) - 0.5 * (a0 - a1),
        ]
    )


def _horner(coeffs: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Σ_k coeffs[k] t^k, elementwise (coeffs (K, m), t (m,))."""
    acc = coeffs[-1].copy()
    for k in range(coeffs.shape[0] - 2, -1, -1):
        acc *= t
        acc += coeffs[k]
    return acc


def _blockwise(f, *columns: np.ndarray) -> np.ndarray:
    """``f(*columns)`` of an elementwise ``f``, evaluated :func:`blocks` at a time: the same
    values, with the temporaries of one block (a Gauss–Legendre arc length holds 16 nodes ×
    4 homogeneous rows per point)."""
    n = columns[0].size
    if n <= BLOCK:
        return f(*columns)
    return np.concatenate([f(*(c[b] for c in columns)) for b in blocks(n)])


@dataclass(frozen=True, eq=False)
class InverseArcTable:
    """u(s) by piecewise quintic Hermite interpolation in s (SPEC §10, the fast path).

    Interval i covers [``s_nodes_mm[i]``, ``s_nodes_mm[i+1]``] and parameters [``u_lo[i]``,
    ``u_hi[i]``] inside knot span ``spans[i]``; u = Σ_k ``coeffs[k, i]`` t^k with
    t = (s − s_i)·``inv_width[i]``, the quintic matching u, du/ds = 1/|C′| and
    d²u/ds² = −(C′·C″)/|C′|⁴ at both ends (s at the nodes exact: Gauss–Legendre). Its error
    is about Δs⁶ |u⁽⁶⁾(s)| / 46080, largest mid-interval; :meth:`build` splits every interval
    until |s(u) − s| ≤ ``tol_mm`` at three check points inside it. Intervals that cannot get
    there (a cusp, |C′| = 0, where u(s) is not smooth) are flagged ``exact``: samples in them
    are inverted by the exact Newton method. ``max_check_error_mm`` is the largest error
    seen at the check points of the accepted (non-exact) intervals.
    """

    s_nodes_mm: np.ndarray
    inv_width: np.ndarray
    coeffs: np.ndarray
    u_lo: np.ndarray
    u_hi: np.ndarray
    spans: np.ndarray
    exact: np.ndarray
    max_check_error_mm: float

    @classmethod
    def build(
        cls,
        curve,
        tol_mm: float = INVERSE_TOL_MM,
        start_mm: float = INVERSE_START_MM,
        max_depth: int = INVERSE_MAX_DEPTH,
    ) -> InverseArcTable:
        """Build the table of ``curve`` (a :class:`~nurbscnc.geometry.nurbs.NurbsCurve`: its
        power form, arc-length table and speed floor; see the class docstring); vectorised
        per level."""
        pf = curve.power_form
        arc = curve.arc_table
        eps = np.finfo(float).eps
        brk = pf.breaks
        n_span = pf.centers.size
        s_brk = arc.arc_length(brk) if brk[-1] > brk[0] else np.zeros(2)
        count = np.clip(np.ceil((s_brk[1:] - s_brk[:-1]) / start_mm), 1, 1 << 16).astype(int)
        span = np.repeat(np.arange(n_span), count)
        frac = (np.arange(span.size) - np.repeat(np.cumsum(count) - count, count)) / np.repeat(
            count, count
        )
        lo = brk[span] + frac * (brk[span + 1] - brk[span])
        hi = np.append(lo[1:], brk[-1])
        hi[np.cumsum(count) - 1] = brk[1:]  # every span ends on its own break, exactly
        s_lo, s_hi = arc.arc_length(lo), arc.arc_length(hi)
        floor = curve.speed_floor
        checks = np.array([0.25, 0.5, 0.75])
        budget = max(INVERSE_MAX_INTERVALS, 16 * span.size)
        # Node data on the interval's own span (one-sided at knots), each node evaluated once:
        # inside a span an interval's end is the next one's start (the same u, the same span;
        # the derivatives are elementwise IEEE arithmetic, so the same bits as evaluated twice).
        d_lo, d_hi = _first_level_derivatives(pf, lo, span, brk, count)

        done: list[tuple] = []
        kept = 0
        depth = 0
        worst = 0.0
        while span.size:
            # du/ds and d²u/ds² at both ends come from d_lo, d_hi.
            width = s_hi - s_lo
            coeffs, bad_data = _interval_hermite(lo, hi, width, d_lo, d_hi, floor)
            # Check points: exact s there, the quintic's u, error in mm along the curve.
            uc = lo[None, :] + checks[:, None] * (hi - lo)[None, :]
            sc = _blockwise(arc.arc_length, uc.ravel()).reshape(uc.shape)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (sc - s_lo) / width
                uh = np.array([_horner(coeffs, t[i]) for i in range(checks.size)])
            speed_c = _blockwise(pf.speed, uc.ravel(), np.tile(span, checks.size)).reshape(uc.shape)
            err = np.abs(uh - uc) * speed_c
            allow = np.maximum(tol_mm, 8.0 * eps * sc + 4.0 * np.spacing(np.abs(uc)) * speed_c)
            ok = np.all(err <= allow, axis=0) & ~bad_data
            give_up = ~ok & ((depth >= max_depth) | bad_data | (width <= 0.0))
            if kept + span.size + np.count_nonzero(~(ok | give_up)) > budget:
                give_up = ~ok  # splitting again would pass the budget: all exact from here
            keep = ok | give_up
            kept += int(np.count_nonzero(keep))
            if np.any(ok):
                worst = max(worst, float(np.max(err[:, ok])))
            done.append(
                (
                    s_lo[keep],
                    s_hi[keep],
                    lo[keep],
                    hi[keep],
                    span[keep],
                    coeffs[:, keep],
                    give_up[keep],
                )
            )
            split = ~keep
            mid_u, mid_s = uc[1, split], sc[1, split]
            if np.any(split):  # the halves share their new node: its derivatives once
                d_mid = pf.derivatives(mid_u, span[split], 2)
                d_lo = np.concatenate((d_lo[:, split], d_mid), axis=1)
                d_hi = np.concatenate((d_mid, d_hi[:, split]), axis=1)
            lo = np.concatenate((lo[split], mid_u))
            hi = np.concatenate((mid_u, hi[split]))
            s_lo = np.concatenate((s_lo[split], mid_s))
            s_hi = np.concatenate((mid_s, s_hi[split]))
            span = np.concatenate((span[split], span[split]))
            depth += 1

        s_lo, s_hi, lo, hi, span, coeffs, exact = (
            np.concatenate(parts, axis=-1) for parts in zip(*done)
        )
        order = np.argsort(lo, kind="stable")
        s_nodes = np.append(s_lo[order], s_hi[order][-1])
        width = s_hi[order] - s_lo[order]
        with np.errstate(divide="ignore"):
            inv_width = np.where(width > 0.0, 1.0 / width, 0.0)
        exact = exact[order] | (width <= 0.0)
        table = cls(
            s_nodes,
            inv_width,
            np.ascontiguousarray(coeffs[:, order]),
            lo[order],
            hi[order],
            span[order],
            exact,
            worst,
        )
        for a in (
            table.s_nodes_mm,
            table.inv_width,
            table.coeffs,
            table.u_lo,
            table.u_hi,
            table.spans,
            table.exact,
        ):
            a.setflags(write=False)
        return table

    def params(self, s_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u, span, exact) for arc lengths ``s_mm`` already clamped to the curve's range:
        the quintic's u (clamped to its interval, so u is monotone in s and never leaves the
        span), the knot span of each u, and whether the sample needs the exact inversion."""
        n = s_mm.size
        u = np.empty(n)
        spans = np.empty(n, dtype=np.intp)
        exact = np.empty(n, dtype=bool)
        last = self.inv_width.size - 1
        c = self.coeffs
        for b in blocks(n):
            s = s_mm[b]
            i = np.searchsorted(self.s_nodes_mm, s, side="right") - 1
            np.clip(i, 0, last, out=i)
            t = (s - np.take(self.s_nodes_mm, i)) * np.take(self.inv_width, i)
            acc = np.take(c[5], i)
            for k in range(4, -1, -1):
                acc *= t
                acc += np.take(c[k], i)
            np.maximum(acc, np.take(self.u_lo, i), out=acc)
            np.minimum(acc, np.take(self.u_hi, i), out=acc)
            u[b] = acc
            spans[b] = np.take(self.spans, i)
            exact[b] = np.take(self.exact, i)
        return u, spans, exact


def _first_level_derivatives(pf, lo, span, brk, count):
    """Derivative arrays (3, m, 3) at the starts ``lo`` and the ends of the first-level
    intervals (``count`` per knot span, in order): each start evaluated once, an end the next
    interval's start but at a span's last interval, whose end is its own break (one-sided)."""
    d_lo = pf.derivatives(lo, span, 2)
    last = np.cumsum(count) - 1  # each span's last interval
    d_hi = np.empty_like(d_lo)
    d_hi[:, :-1] = d_lo[:, 1:]
    d_hi[:, last] = pf.derivatives(brk[1:], span[last], 2)
    return d_lo, d_hi


def _interval_hermite(lo, hi, width, d_lo, d_hi, speed_floor):
    """Quintic coefficients (6, m) of u(t), t = (s − s_lo)/width, from derivative arrays at
    the interval ends; ``bad`` marks intervals whose end data is not finite (|C′| ≈ 0)."""

    def end_data(d):
        c1, c2 = d[1], d[2]
        v2 = np.einsum("ij,ij->i", c1, c1)
        v = np.sqrt(v2)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            du = 1.0 / v  # du/ds
            ddu = -np.einsum("ij,ij->i", c1, c2) / (v2 * v2)  # d²u/ds²
        return du, ddu, v <= speed_floor

    du0, ddu0, cusp0 = end_data(d_lo)
    du1, ddu1, cusp1 = end_data(d_hi)
    with np.errstate(invalid="ignore", over="ignore"):
        coeffs = _hermite_quintic(
            lo, du0 * width, ddu0 * width * width, hi, du1 * width, ddu1 * width * width
        )
    bad = cusp0 | cusp1 | ~np.all(np.isfinite(coeffs), axis=0)
    coeffs[:, bad] = 0.0
    return coeffs, bad
