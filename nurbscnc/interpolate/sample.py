"""The interpolator: one reference point per servo period T_s (SPEC §3, §4, §10).

Given a planned profile s(t) over the pieces, the reference point at t_k = k·T_s is the point
of the path at arc length s(t_k), placed exactly: PH pieces by Newton on their closed-form
arc length (SPEC §4, eq. 10–12), NURBS pieces by the quintic Hermite inversion table of the
curve (SPEC §10; within 1e-9 mm of the exact arc-length inverse, every point C(u) on the
curve), lines and arcs in closed form. Dwells hold the point for their duration. Or, with
``interpolator="taylor"``, NURBS pieces by the paper's 2nd-order Taylor recurrence (SPEC §3,
eq. 4–5), which is sequential by nature (a tight scalar loop per run of NURBS samples).

Per-sample work is whole-array numpy over all pieces of a kind at once (PH pieces and arcs
are evaluated together through per-piece coefficient tables, lines in one step, NURBS once per
curve); the Python loops run over piece kinds, curves and cache-sized blocks of samples.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from math import comb, sqrt

import numpy as np
from numpy.polynomial import polynomial as npoly

from nurbscnc.errors import ConfigError
from nurbscnc.geometry.nurbs import BLOCK, PowerForm

#: Kind codes of the per-piece arrays.
LINE, ARC, SPIRAL, PH, NURBS = 0, 1, 2, 3, 4
_KIND_CODE = {"line": LINE, "rapid": LINE, "arc": ARC, "ph": PH, "nurbs": NURBS}
INTERPOLATORS = ("exact", "taylor")


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


def dwell_schedule(pieces, profile) -> tuple[np.ndarray, np.ndarray]:
    """Profile times [s] at which dwells start and their durations [s] (sorted)."""
    at, dur = [], []
    for i, p in enumerate(pieces):
        if p.dwell_after_s > 0.0:
            t = profile.piece_start_time_s[i + 1] if i + 1 < len(pieces) else profile.duration_s
            at.append(float(t))
            dur.append(float(p.dwell_after_s))
    return np.asarray(at, dtype=float), np.asarray(dur, dtype=float)


def total_time_s(profile, dwell_durations_s: np.ndarray) -> float:
    """Cycle time [s]: the profile's duration plus all dwells."""
    return float(profile.duration_s + dwell_durations_s.sum())


def wall_to_profile_time(t_wall: np.ndarray, dwell_at_s: np.ndarray, dwell_s: np.ndarray):
    """Map wall-clock times to profile times: during a dwell the profile time stands still."""
    if dwell_at_s.size == 0:
        return t_wall
    offsets = np.concatenate(([0.0], np.cumsum(dwell_s)))
    wall_start = dwell_at_s + offsets[:-1]  # wall time at which dwell j begins
    j = np.searchsorted(wall_start, t_wall, side="right") - 1  # last dwell begun, or -1
    tau = t_wall.copy()
    has = j >= 0
    jj = j[has]
    inside = t_wall[has] < wall_start[jj] + dwell_s[jj]
    tau_has = np.where(inside, dwell_at_s[jj], t_wall[has] - offsets[jj + 1])
    tau[has] = tau_has
    return tau


# ---------------------------------------------------------------------------------------------
# Per-piece coefficient tables (built once per call, O(pieces))
# ---------------------------------------------------------------------------------------------


def _centred_bernstein_matrix(n: int) -> np.ndarray:
    """M (n+1, n+1) with B_i^n(½ + x) = Σ_k M[i, k] x^k: Bernstein → power basis about ξ = ½.

    The entries are dyadic rationals, exact in floating point. Centred monomials on
    x ∈ [−½, ½] keep the PH polynomials' power coefficients small (well conditioned)."""
    m = np.zeros((n + 1, n + 1))
    for i in range(n + 1):
        poly = npoly.polymul(npoly.polypow([0.5, 1.0], i), npoly.polypow([0.5, -1.0], n - i))
        m[i, : poly.size] = comb(n, i) * poly
    m.setflags(write=False)
    return m


_B4, _B5 = _centred_bernstein_matrix(4), _centred_bernstein_matrix(5)


@dataclass(frozen=True, eq=False)
class PieceTable:
    """Arrays over the pieces that the vectorised placement gathers from (one row a piece).

    ``kind`` codes (LINE, ARC, SPIRAL, PH, NURBS); ``length_mm``; ``s_a_mm`` (NURBS: curve
    arc length at the piece start); ``curve_id`` (NURBS: index of the piece's curve in
    ``curves``, else −1); ``line`` source lines; ``start_mm``/``end_mm`` (lines, (3, k));
    arcs: ``origin_mm``, ``e1``, ``e2``, ``normal`` (3, k), ``radius_mm``, ``angle_rad``,
    ``helix_mm``; PH: ``ph_s``/``ph_sigma``/``ph_x``/``ph_y`` power coefficients in ξ − ½
    of s(ξ) [mm], σ(ξ) [mm] and the plane point (x, y) [mm], rows (6|5, k), with the plane
    frame in ``origin_mm``, ``e1``, ``e2``. Build with :meth:`of`.
    """

    kind: np.ndarray
    length_mm: np.ndarray
    s_a_mm: np.ndarray
    curve_id: np.ndarray
    curves: tuple
    line: np.ndarray
    start_mm: np.ndarray
    end_mm: np.ndarray
    origin_mm: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    normal: np.ndarray
    radius_mm: np.ndarray
    angle_rad: np.ndarray
    helix_mm: np.ndarray
    ph_s: np.ndarray
    ph_sigma: np.ndarray
    ph_x: np.ndarray
    ph_y: np.ndarray

    @classmethod
    def of(cls, pieces) -> PieceTable:
        """Collect the arrays (one pass over the pieces)."""
        k = len(pieces)
        kind = np.empty(k, dtype=np.int8)
        length = np.empty(k)
        s_a = np.zeros(k)
        curve_id = np.full(k, -1, dtype=np.intp)
        line = np.empty(k, dtype=np.int64)
        vec = {name: np.zeros((k, 3)) for name in ("start", "end", "origin", "e1", "e2", "n")}
        radius, angle, helix = np.zeros(k), np.zeros(k), np.zeros(k)
        ph_rows: list[int] = []
        ph_s, ph_sigma, ph_pts = [], [], []
        curves: dict[int, int] = {}
        curve_list = []
        for i, p in enumerate(pieces):
            g = p.geometry
            code = _KIND_CODE[p.kind]
            length[i] = p.length_mm
            line[i] = p.line
            if code == LINE:
                vec["start"][i], vec["end"][i] = g.start_mm, g.end_mm
            elif code == ARC:
                if g.is_spiral:
                    code = SPIRAL
                vec["origin"][i], vec["e1"][i], vec["e2"][i] = g.origin_mm, g.e1, g.e2
                vec["n"][i] = g.normal
                radius[i], angle[i], helix[i] = g.radius_start_mm, g.angle_rad, g.helix_mm
            elif code == PH:
                vec["origin"][i], vec["e1"][i], vec["e2"][i] = g.origin_mm, g.e1, g.e2
                ph_rows.append(i)
                ph_s.append(g.s_coeffs)
                ph_sigma.append(g.sigma_coeffs)
                ph_pts.append(g.control_points)
            else:
                s_a[i] = p.s_a_mm
                curve_id[i] = curves.setdefault(id(g), len(curve_list))
                if curve_id[i] == len(curve_list):
                    curve_list.append(g)
            kind[i] = code
        ph = (np.zeros((6, k)), np.zeros((5, k)), np.zeros((6, k)), np.zeros((6, k)))
        if ph_rows:
            rows = np.array(ph_rows)
            pts = np.array(ph_pts)
            ph[0][:, rows] = (np.array(ph_s) @ _B5).T
            ph[1][:, rows] = (np.array(ph_sigma) @ _B4).T
            ph[2][:, rows] = (pts.real @ _B5).T
            ph[3][:, rows] = (pts.imag @ _B5).T
        t = {name: np.ascontiguousarray(v.T) for name, v in vec.items()}
        arrays = (kind, length, s_a, curve_id, line, *t.values(), radius, angle, helix, *ph)
        for a in arrays:
            a.setflags(write=False)
        return cls(kind, length, s_a, curve_id, tuple(curve_list), line, t["start"], t["end"],
                   t["origin"], t["e1"], t["e2"], t["n"], radius, angle, helix, *ph)  # fmt: skip


# ---------------------------------------------------------------------------------------------
# Exact placement, one kind at a time
# ---------------------------------------------------------------------------------------------


def _take3(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
    return np.take(a, idx, axis=1)


def _place_lines(tab: PieceTable, idx, loc, out, param) -> None:
    """C = start (1 − f) + end f, f = s/L: exact at both ends (SPEC: lines in closed form)."""
    for b in _blocks(idx.size):
        i = idx[b]
        length = np.take(tab.length_mm, i)
        with np.errstate(invalid="ignore", divide="ignore"):
            f = np.where(length > 0.0, loc[b] / length, 0.0)
        out[b] = (_take3(tab.start_mm, i) * (1.0 - f) + _take3(tab.end_mm, i) * f).T
        param[b] = loc[b]


def _place_arcs(tab: PieceTable, idx, loc, out, param) -> None:
    """Constant-radius arcs (and helices), u = s: C = O + r (cos θ e1 + sin θ e2) + t H n with
    t = s/L, θ = t Δθ (the same formula as :class:`ArcGeometry`)."""
    for b in _blocks(idx.size):
        i = idx[b]
        length = np.take(tab.length_mm, i)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(length > 0.0, loc[b] / length, 0.0)
        theta = t * np.take(tab.angle_rad, i)
        r = np.take(tab.radius_mm, i)
        pts = (_take3(tab.origin_mm, i) + (r * np.cos(theta)) * _take3(tab.e1, i)
               + (r * np.sin(theta)) * _take3(tab.e2, i)
               + (t * np.take(tab.helix_mm, i)) * _take3(tab.normal, i))  # fmt: skip
        out[b] = pts.T
        param[b] = loc[b]


def _horner_rows(coeffs: np.ndarray, i: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Σ_k coeffs[k, i] x^k (coeffs (K, pieces), gathered per sample)."""
    acc = np.take(coeffs[-1], i)
    for k in range(coeffs.shape[0] - 2, -1, -1):
        acc *= x
        acc += np.take(coeffs[k], i)
    return acc


#: Newton iterations on PH pieces before the bracketed fallback (3–4 are typical).
PH_MAX_NEWTON = 12


def _place_ph(tab: PieceTable, pieces, idx, loc, out, param) -> None:
    """PH pieces by Newton on the closed-form arc length (SPEC §4, eq. 10–12), all pieces at
    once: ξ ← ξ − (s(ξ) − s)/σ(ξ) from ξ = s/L, to |s(ξ) − s| ≤ max(1e-13 mm, 8 ulp L);
    any sample not there after :data:`PH_MAX_NEWTON` steps (never seen) is solved by the
    piece's safeguarded Newton–bisection."""
    eps = np.finfo(float).eps
    for b in _blocks(idx.size):
        i = idx[b]
        s = loc[b]
        length = np.take(tab.length_mm, i)
        tol = np.maximum(1e-13, 8.0 * eps * length)
        with np.errstate(invalid="ignore", divide="ignore"):
            xi = np.where(length > 0.0, s / length, 0.0)
        converged = False
        for _ in range(PH_MAX_NEWTON):
            x = xi - 0.5
            f = _horner_rows(tab.ph_s, i, x) - s
            if np.all(np.abs(f) <= tol):
                converged = True
                break
            xi -= f / _horner_rows(tab.ph_sigma, i, x)
            np.clip(xi, 0.0, 1.0, out=xi)
        if not converged:
            x = xi - 0.5
            bad = np.flatnonzero(np.abs(_horner_rows(tab.ph_s, i, x) - s) > tol)
            for j in np.unique(i[bad]):
                sel = bad[i[bad] == j]
                xi[sel] = pieces[j].geometry.param_at_length(s[sel])
        x = xi - 0.5
        px, py = _horner_rows(tab.ph_x, i, x), _horner_rows(tab.ph_y, i, x)
        pts = _take3(tab.origin_mm, i) + px * _take3(tab.e1, i) + py * _take3(tab.e2, i)
        out[b] = pts.T
        param[b] = xi


def _blocks(n: int, size: int = BLOCK):
    """Slices covering range(n) in blocks of ``size``."""
    return (slice(i, min(i + size, n)) for i in range(0, n, size))


#: Samples per slab in :func:`sample_plan` (profile evaluation and placement).
SLAB = 1 << 16


def _runs(keys: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of the runs of equal consecutive values of ``keys``."""
    if keys.size == 0:
        return []
    cuts = np.flatnonzero(keys[1:] != keys[:-1]) + 1
    edges = np.concatenate(([0], cuts, [keys.size]))
    return list(zip(edges[:-1].tolist(), edges[1:].tolist()))


def _place(pieces, tab: PieceTable, starts_mm: np.ndarray, s_mm: np.ndarray,
           piece_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Exact points (N, 3) [mm] and parameters (N,) at path lengths ``s_mm`` on pieces
    ``piece_idx`` (non-decreasing along the samples for NURBS runs to be long)."""
    n = s_mm.size
    out = np.empty((n, 3))
    param = np.empty(n)
    if n == 0:
        return out, param
    loc = np.clip(s_mm - np.take(starts_mm, piece_idx), 0.0, np.take(tab.length_mm, piece_idx))
    kind = np.take(tab.kind, piece_idx)
    present = np.unique(kind)
    for code in present.tolist():
        if present.size == 1:  # one kind only: no gather/scatter
            sel, idx, ls, o, prm = slice(None), piece_idx, loc, out, param
        else:
            sel = np.flatnonzero(kind == code)
            idx, ls = piece_idx[sel], loc[sel]
            o, prm = np.empty((idx.size, 3)), np.empty(idx.size)
        if code == LINE:
            _place_lines(tab, idx, ls, o, prm)
        elif code == ARC:
            _place_arcs(tab, idx, ls, o, prm)
        elif code == PH:
            _place_ph(tab, pieces, idx, ls, o, prm)
        elif code == NURBS:
            cid = np.take(tab.curve_id, idx)
            s_curve = np.take(tab.s_a_mm, idx) + ls
            for a, z in _runs(cid):
                curve = tab.curves[int(cid[a])]
                o[a:z], prm[a:z] = curve.points_at_length(s_curve[a:z])
        else:  # spiral arcs: their own arc-length table, one call per piece
            for a, z in _runs(idx):
                g = pieces[int(idx[a])].geometry
                prm[a:z] = g.param_at_length(ls[a:z])
                o[a:z] = g.point(prm[a:z])
        if present.size > 1:
            out[sel], param[sel] = o, prm
    return out, param


def place_points(pieces, profile, s_mm: np.ndarray, piece_idx: np.ndarray,
                 table: PieceTable | None = None) -> np.ndarray:  # fmt: skip
    """Exact points [mm] (N, 3) at path lengths ``s_mm`` on pieces ``piece_idx``.

    Every point is on its piece's geometry: lines and arcs in closed form, PH pieces by
    Newton on their polynomial arc length, NURBS by the curve's inversion table
    (:meth:`NurbsCurve.points_at_length`, arc length within 1e-9 mm of the exact inverse).
    ``table``: ``PieceTable.of(pieces)`` if the caller already has it (it depends only on
    the pieces' geometry, so one table serves every re-plan).
    """
    s = np.asarray(s_mm, dtype=float)
    idx = np.asarray(piece_idx, dtype=np.intp)
    tab = PieceTable.of(pieces) if table is None else table
    return _place(pieces, tab, profile.piece_start_mm, s, idx)[0]


# ---------------------------------------------------------------------------------------------
# The paper's Taylor interpolator on NURBS pieces (SPEC §3, eq. 4–5)
# ---------------------------------------------------------------------------------------------


def taylor_params(
    pf: PowerForm,
    u0: float,
    v_mm_s: np.ndarray,
    a_mm_s2: np.ndarray,
    dt_s: np.ndarray,
    u_min: float,
    u_max: float,
    u_rest=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Parameters u_k of the 2nd-order Taylor interpolator (SPEC §3, eq. 4–5) and their spans.

    u_{k+1} = u_k + V_k Δt_k/|C′| + (Δt_k²/2)(A_k/|C′| − V_k² (C′·C″)/|C′|⁴), C′, C″ at u_k,
    from u_0 = ``u0``; ``v_mm_s``, ``a_mm_s2`` (n,) the feed and tangential acceleration at
    step k, ``dt_s`` (n − 1,) the profile time between samples (T_s, less across a dwell).
    u is kept in [``u_min``, ``u_max``]. Where the profile is at rest (V = A = 0) the next
    step would not move, and if ``u_rest`` (n,) is given u is re-synchronised there to
    ``u_rest`` (the exact parameter): the controller knows where a stopped tool must be.

    The recurrence is sequential, so this is a tight loop over samples with Python floats;
    C′ and C″ come from the knot span's power form (Horner with derivatives, 4 homogeneous
    components) and the quotient rule.
    """
    n = int(np.size(v_mm_s))
    us = [0.0] * n
    js = [0] * n
    if n == 0:
        return np.empty(0), np.empty(0, dtype=np.intp)
    p = pf.degree
    breaks = pf.breaks.tolist()
    centers = pf.centers.tolist()
    last = len(centers) - 1
    # Per span: coefficient rows (x, y, z, w) from degree p − 1 down to 0; the top row apart.
    rows = np.transpose(pf.coeffs, (2, 0, 1))  # (span, k, component)
    top = [tuple(r) for r in rows[:, p, :].tolist()]
    lower = [[tuple(r) for r in span_rows[p - 1 :: -1]] for span_rows in rows.tolist()]
    vs, acs, dts = v_mm_s.tolist(), a_mm_s2.tolist(), dt_s.tolist()
    rest = u_rest.tolist() if u_rest is not None else None
    u = min(max(float(u0), u_min), u_max)
    j = min(max(bisect_right(breaks, u) - 1, 0), last)
    for k in range(n):
        v, acc = vs[k], acs[k]
        if rest is not None and v == 0.0 and acc == 0.0 and u != rest[k]:
            u = rest[k]
            j = min(max(bisect_right(breaks, u) - 1, 0), last)
        us[k] = u
        js[k] = j
        if k == n - 1:
            break
        dt = dts[k]
        x = u - centers[j]
        # Horner with first and second derivative (X2 holds A''/2), 4 components.
        x0, y0, z0, w0 = top[j]
        x1 = y1 = z1 = w1 = x2 = y2 = z2 = w2 = 0.0
        for cx, cy, cz, cw in lower[j]:
            x2 = x2 * x + x1
            y2 = y2 * x + y1
            z2 = z2 * x + z1
            w2 = w2 * x + w1
            x1 = x1 * x + x0
            y1 = y1 * x + y0
            z1 = z1 * x + z0
            w1 = w1 * x + w0
            x0 = x0 * x + cx
            y0 = y0 * x + cy
            z0 = z0 * x + cz
            w0 = w0 * x + cw
        # Quotient rule: C = A/w, C' = (A' − w'C)/w, C''/2 = (A''/2 − w'C' − (w''/2) C)/w.
        iw = 1.0 / w0
        cx, cy, cz = x0 * iw, y0 * iw, z0 * iw
        dx, dy, dz = (x1 - w1 * cx) * iw, (y1 - w1 * cy) * iw, (z1 - w1 * cz) * iw
        ex = (x2 - w1 * dx - w2 * cx) * iw
        ey = (y2 - w1 * dy - w2 * cy) * iw
        ez = (z2 - w1 * dz - w2 * cz) * iw
        speed2 = dx * dx + dy * dy + dz * dz
        speed = sqrt(speed2)
        dot = 2.0 * (dx * ex + dy * ey + dz * ez)  # C'·C''
        u += v * dt / speed + 0.5 * dt * dt * (acc / speed - v * v * dot / (speed2 * speed2))
        if u > u_max:
            u = u_max
        elif u < u_min:
            u = u_min
        while j < last and u >= breaks[j + 1]:
            j += 1
        while j > 0 and u < breaks[j]:
            j -= 1
    return np.array(us), np.array(js, dtype=np.intp)


def _taylor_nurbs(tab: PieceTable, pieces, samples_piece, tau, v, a, out, param) -> None:
    """Replace the exact NURBS points by the Taylor interpolator's: one recurrence per run of
    consecutive samples on one curve, started at the exact u of the run's first sample."""
    kind = np.take(tab.kind, samples_piece)
    cid = np.where(kind == NURBS, np.take(tab.curve_id, samples_piece), -1)
    dt = np.diff(tau)
    for a_, z in _runs(cid):
        c = int(cid[a_])
        if c < 0:
            continue
        curve = tab.curves[c]
        pf = curve.power_form
        u_min = pieces[int(samples_piece[a_])].u_a
        u_max = pieces[int(samples_piece[z - 1])].u_b
        u, spans = taylor_params(pf, param[a_], v[a_:z], a[a_:z], dt[a_ : z - 1], u_min,
                                 u_max, u_rest=param[a_:z])  # fmt: skip
        out[a_:z] = pf.point(u, spans)
        param[a_:z] = u


# ---------------------------------------------------------------------------------------------
# Sampling a plan
# ---------------------------------------------------------------------------------------------


def sample_plan(pieces, profile, period_s: float, dwell_at_s=None, dwell_s=None,
                interpolator: str = "exact", table: PieceTable | None = None,
                ) -> Samples:  # fmt: skip
    """Reference points at t_k = k·T_s from 0 until the end (SPEC §1, interpolator).

    The last sample is the first k·T_s at or after the end of motion: the tool is at rest at
    the programmed end point there, and every pair of consecutive samples is T_s apart.
    ``interpolator``: "exact" (arc-length exact everywhere, SPEC §10) or "taylor" (NURBS
    pieces by the paper's Taylor recurrence, SPEC §3; PH pieces, lines and arcs exact).
    ``table``: ``PieceTable.of(pieces)`` if the caller already has it (see
    :func:`place_points`).
    """
    if interpolator not in INTERPOLATORS:
        raise ConfigError(f"interpolator must be one of {INTERPOLATORS}, not {interpolator!r}")
    if dwell_at_s is None:
        dwell_at_s, dwell_s = dwell_schedule(pieces, profile)
    total = total_time_s(profile, dwell_s)
    n = int(np.ceil(total / period_s - 1e-9)) + 1
    t = np.arange(n) * period_s
    tau = wall_to_profile_time(t, dwell_at_s, dwell_s)
    tab = PieceTable.of(pieces) if table is None else table
    s, v, a = np.empty(n), np.empty(n), np.empty(n)
    piece = np.empty(n, dtype=np.intp)
    points, param = np.empty((n, 3)), np.empty(n)
    # Profile and placement a slab of samples at a time: flat memory, cache-friendly
    # temporaries; the cost stays linear in the number of samples.
    for b in _blocks(n, SLAB):
        s[b], v[b], a[b], _, piece[b] = profile.sample(tau[b])
        points[b], param[b] = _place(pieces, tab, profile.piece_start_mm, s[b], piece[b])
    if interpolator == "taylor":
        _taylor_nurbs(tab, pieces, piece, tau, v, a, points, param)
    return Samples(t, points, s, v, a, piece, np.take(tab.line, piece), param, interpolator)


def nurbs_step_lengths(pieces, samples: Samples) -> tuple[np.ndarray, np.ndarray]:
    """True arc lengths of the servo steps on NURBS pieces, for the feed fluctuation.

    Returns ``(k, ds_mm)``: the indices k of the steps k → k+1 with both samples on the same
    NURBS curve, and Δs_true = s(u_{k+1}) − s(u_k) [mm] from the curves' exact arc-length
    tables (SPEC §3: fluctuation |Δs/(V T_s) − 1| "measured with true arc length")."""
    tab = PieceTable.of(pieces)
    kind = np.take(tab.kind, samples.piece)
    cid = np.where(kind == NURBS, np.take(tab.curve_id, samples.piece), -1)
    s_true = np.full(samples.piece.size, np.nan)
    for a, z in _runs(cid):
        if cid[a] >= 0:
            s_true[a:z] = tab.curves[int(cid[a])].arc_length(samples.param[a:z])
    k = np.flatnonzero((cid[:-1] >= 0) & (cid[:-1] == cid[1:]))
    return k, s_true[k + 1] - s_true[k]
