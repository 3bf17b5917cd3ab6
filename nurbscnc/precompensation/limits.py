"""The limits on the samples of a compensated reference: the caps of its differences
(:class:`SampleLimits`), their excess, the frame about the path the offsets are written in
(:func:`path_frame`), and the projection of a reference onto the caps by linear programmes
(:func:`project_onto_limits`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.geometry.polyline import chord_kappa_per_mm
from nurbscnc.machine.profile import Machine
from nurbscnc.precompensation.frame import plane_normal

# The ZPETC inverse of a jerk-limited profile is not jerk-limited: F ≈ 1 + c_1 s + c_2 s² + …
# adds the planned velocity, acceleration and jerk (scaled) to the reference, so every jerk
# switch of the plan becomes a snap impulse of the compensated one, and the clip into the tube
# adds kinks where it bites (per axis, many times the machine's J on the samples). The
# written reference must keep the machine's limits on its samples, so the compensated points
# are projected onto them before anything else looks at them.
#
# The offset δ = u − r from the planned reference r (the planner's output: within the limits,
# on the path) is micrometres, and every limit is linear in it per sample row:
#
#   |Δ²(r + δ)_c| ≤ Ā_i,  |Δ³(r + δ)_c| ≤ J̄_i  (per axis c),  |Δ(r + δ)_c| ≤ V̄_c,i,
#   |Δ(r + δ)| ≤ V̄_i  (the step length: linearised along the step, then checked exactly),
#
# the caps the limit (A T², J T³, V T, per axis the smaller of the path's and the axis' own),
# or where the planned reference is above it already (a path-limited machine keeps A and J
# along the path; per axis its curvature terms can exceed them), its own difference there:
# never rougher than the plan. δ is written in the frame of the path at r_k,
# δ_k = α_k m_k + β_k t_k (m the in-plane normal, t the tangent), and kept in the tube
# exactly: P(s_k + β) = r_k + β t_k + R with |R| ≤ κ β²/2 (κ the largest curvature within
# |β| along the path, no break in between), so dist(r_k + δ_k, path) ≤ |α_k| + κβ̄²/2:
#
#   |β_k| ≤ β̄_k,   |α_k| ≤ τ_k − κ_k β̄_k²/2.
#
# δ = 0 satisfies everything, so the linear programme
#
#   min Σ |α_k − α*_k| + |β_k − β*_k|   (α*, β*: the clipped ZPETC offset in that frame)
#
# always has a solution; it is solved over windows around the rows the ZPETC reference breaks
# (the rest kept as it is, rows reaching out of a window with their fixed samples), a window
# that cannot be solved with its ends fixed grown until it can (at worst the whole reference,
# whose first and last samples are the plan's).

#: The LP's unit of length [mm] (1 nm): the caps are 0.05 µm (J T³) and HiGHS' feasibility
#: tolerance is absolute.
_LP_UNIT_MM = 1e-6
#: Share of a limit the LPs keep free (the solver's tolerance, rounding): the samples stay
#: within (1 − LIMIT_MARGIN) of the limit where the plan is within it.
LIMIT_MARGIN = 1e-7
#: Samples either side of a row over the caps that its window moves (first try; ×4 a try).
PROJECT_PAD = 40
#: Largest move along the path of the projection [mm] ...
PROJECT_ALONG_MM = 0.1
#: ... and at most the move whose bend off the path (κ β²/2) is this share of the tube.
PROJECT_BEND = 0.5
#: Sides of the polygon in the disc across a path out of the XY plane (path_frame).
TUBE_SIDES = 8
#: Most simplex iterations of one projection LP, per unknown of the LP (at least
#: PROJECT_LP_MIN_ITER): an iteration count, not a time limit, so that whether a window is
#: solved does not depend on how busy the machine is (HiGHS needs at most ~2.5 per unknown
#: on the test programs; a window that runs out counts as failed).
PROJECT_LP_ITER_PER_UNKNOWN = 10
PROJECT_LP_MIN_ITER = 10_000
#: Most samples one projection LP moves (memory: HiGHS' grows fast with the window, to
#: gigabytes for a long program's whole segment): longer windows are solved in pieces, and
#: windows grow no further (where rows are still broken then, the reference is the plan's
#: own, within the caps).
PROJECT_MAX_WINDOW = 4096


@dataclass(frozen=True, eq=False)
class SampleLimits:
    """The limits on a reference's samples [mm], each a row of differences (np.diff):
    ``step`` (N−1,) the step length (path speed V T), ``axis_step`` (N−1, 3) each axis'
    step (its V_i T; inf: none), ``second`` (N−2, 3) and ``third`` (N−3, 3) each axis'
    second and third differences (A T², J T³, the smaller of the path's and the axis' own),
    every one raised to the planned reference's own difference where that is above the
    limit (:func:`sample_limits`); ``limits`` the machine's (V T, (V_i T), (A_i T²),
    (J_i T³)) the rows were raised from, ``own`` the planned reference's |differences| (its
    step lengths and the |Δ^k| of each axis, k = 1, 2, 3)."""

    step: np.ndarray
    axis_step: np.ndarray
    second: np.ndarray
    third: np.ndarray
    limits: tuple
    own: tuple

    def rows(self, order: int) -> np.ndarray:
        """The per-axis caps of the ``order``-th differences (1, 2, 3) [mm]."""
        return (self.axis_step, self.second, self.third)[order - 1]

    def lp_rows(self, order: int) -> np.ndarray:
        """The caps an LP uses: LIMIT_MARGIN below the limit, never below the plan's own (so
        the plan's points are a solution)."""
        limit = np.asarray(self.limits[order], dtype=float)
        return np.maximum(limit * (1.0 - LIMIT_MARGIN), self.own[order])

    def lp_step(self) -> np.ndarray:
        """The step-length caps an LP uses (as :meth:`lp_rows`)."""
        return np.maximum(float(self.limits[0]) * (1.0 - LIMIT_MARGIN), self.own[0])


def sample_limits(planned_mm: np.ndarray, machine: Machine) -> SampleLimits:
    """The caps of :class:`SampleLimits` for references of the length of ``planned_mm``
    (N, 3) [mm] (the plan's reference, lead-padded): the machine's path limits ``limits``
    and per-axis limits ``axis_limits`` per period T, each row raised to the plan's own."""
    t = machine.servo.period_s
    lim = machine.limits
    v_i, a_i, j_i = machine.axis_limits.as_arrays()
    v = lim.v_max_mm_s * t
    axis_v = v_i * t
    axis_a = np.minimum(lim.a_max_mm_s2, a_i) * t**2
    axis_j = np.minimum(lim.j_max_mm_s3, j_i) * t**3
    r = np.asarray(planned_mm, dtype=float)
    d1, d2, d3 = (np.diff(r, n, axis=0) for n in (1, 2, 3))
    own = (np.sqrt(np.einsum("ij,ij->i", d1, d1)), np.abs(d1), np.abs(d2), np.abs(d3))
    return SampleLimits(
        np.maximum(v, own[0]),
        np.maximum(axis_v, own[1]),
        np.maximum(axis_a, own[2]),
        np.maximum(axis_j, own[3]),
        (v, axis_v, axis_a, axis_j),
        own,
    )


def limit_excess(points_mm: np.ndarray, caps: SampleLimits) -> np.ndarray:
    """Per sample (N,): the largest excess [mm] of a difference row it is in over its cap,
    beyond rounding (1e-9 of the cap, and 2^k ulps of the largest coordinate for a k-th
    difference); ≤ 0: every row within its cap."""
    u = np.asarray(points_mm, dtype=float)
    n = u.shape[0]
    out = np.full(n, -np.inf)
    if n < 2:
        return np.zeros(n)
    ulp = float(np.spacing(np.abs(u).max()))
    d1 = np.diff(u, axis=0)
    rows = [(np.sqrt(np.einsum("ij,ij->i", d1, d1)) - caps.step * (1.0 + 1e-9) - 2.0 * ulp, 1)]
    rows += [
        (
            (np.abs(np.diff(u, k, axis=0)) - caps.rows(k) * (1.0 + 1e-9) - 2.0**k * ulp).max(
                axis=1
            ),
            k,
        )
        for k in (1, 2, 3)
        if n > k
    ]
    for over, k in rows:
        for lag in range(k + 1):  # row i covers samples i … i + k
            out[lag : lag + over.size] = np.maximum(out[lag : lag + over.size], over)
    return out


#: The last path's breaks (:func:`_break_lengths_mm`: every segment and joint of a check asks
#: them, and they cost a tangent evaluation per piece): (path, its piece starts' bytes,
#: breaks).
_BREAKS: list = []


def _break_lengths_mm(pieces, profile) -> np.ndarray:
    """Path lengths [mm] (sorted) where the path's tangent jumps (a break between two pieces),
    and its two ends (kept for the last path and piece starts)."""
    starts = profile.piece_start_mm
    key = np.ascontiguousarray(starts).tobytes()
    if _BREAKS and _BREAKS[0] is pieces.path and _BREAKS[1] == key:
        return _BREAKS[2]
    out = _breaks_of(pieces, starts, profile.total_length_mm)
    _BREAKS[:] = [pieces.path, key, out]
    return out


def _breaks_of(pieces, starts: np.ndarray, total_mm: float) -> np.ndarray:
    """:func:`_break_lengths_mm` computed."""
    k = starts.size
    rows = np.arange(k)
    t0 = pieces.path.tangents(rows, np.zeros(k))
    t1 = pieces.path.tangents(rows, pieces.length_mm[:k])
    jump = np.sqrt(np.sum((t1[:-1] - t0[1:]) ** 2, axis=1)) > 1e-9
    ends = np.concatenate([[0.0], starts[1:][jump], [total_mm]])
    return np.unique(ends)


def _range_max(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """max(values[lo_i … hi_i]) (inclusive) for each i: a sparse table, whole-array."""
    table = [np.asarray(values, dtype=float)]
    while 2 ** len(table) <= table[0].size:
        prev, half = table[-1], 2 ** (len(table) - 1)
        table.append(np.maximum(prev[:-half], prev[half:]))
    level = np.floor(np.log2(np.maximum(hi - lo + 1, 1))).astype(int)
    out = np.empty(lo.size)
    for k in np.unique(level):
        sel = level == k
        out[sel] = np.maximum(table[k][lo[sel]], table[k][hi[sel] - 2**k + 1])
    return out


def path_frame(
    planned_mm: np.ndarray,
    s_mm: np.ndarray,
    piece: np.ndarray,
    pieces,
    profile,
    offset_mm: np.ndarray,
    tube_mm: np.ndarray,
):
    """The frame of the projection (module comment above) at each planned point (N, 3) [mm]
    at path length ``s_mm`` on ``piece``: the basis (N, 2, 3) (in-plane normal m, tangent t
    of the path there), the bounds (N, 2) low and high of (α, β) [mm] keeping r + α m + β t
    within ``tube_mm`` (N,) [mm] of the path, exactly (no break and at most
    κ β̄²/2 ≤ PROJECT_BEND τ of bend within β̄ along it; ``offset_mm`` (N, 3) the wanted
    offset, whose along-path part β̄ need not exceed by more than τ). Where the path or
    the offsets leave the XY plane (a helix, a plunge, a G18/G19 arc: an offset the plane's
    (m, t) cannot hold, so a window's samples could not join the fixed ones beside it),
    a third direction w = t × m (m any normal of a vertical tangent): basis (N, 3, 3) of
    (m, t, w), bounds (N, 3) of (α, β, γ), the LP holding |α| + |γ| within α's bound
    (:func:`project_window`: within the tube exactly)."""
    starts = profile.piece_start_mm
    loc = s_mm - starts[piece]
    t = pieces.path.tangents(piece, loc)
    m = plane_normal(t)
    # The largest curvature of the pieces within PROJECT_ALONG_MM along the path (NURBS
    # cells' estimate doubled, as _local_polyline).
    kappa = chord_kappa_per_mm(pieces.kind, pieces.kappa_max_per_mm)
    kappa = np.nan_to_num(kappa, nan=np.inf)
    lo_p = np.clip(
        np.searchsorted(starts, s_mm - PROJECT_ALONG_MM, side="right") - 1, 0, starts.size - 1
    )
    hi_p = np.clip(
        np.searchsorted(starts, s_mm + PROJECT_ALONG_MM, side="right") - 1, 0, starts.size - 1
    )
    k_near = _range_max(kappa[: starts.size], lo_p, hi_p)
    tube = np.maximum(np.asarray(tube_mm, dtype=float), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        b_cap = np.minimum(PROJECT_ALONG_MM, np.sqrt(2.0 * PROJECT_BEND * tube / k_near))
    b_cap = np.nan_to_num(b_cap, nan=0.0)
    along = np.abs(np.einsum("ij,ij->i", offset_mm, t))
    b_bar = np.minimum(b_cap, along + tube)
    # No break between r_k and r_k + β t: β within the distance to the nearest break (or
    # end of the path) on its side.
    brk = _break_lengths_mm(pieces, profile)
    i = np.clip(np.searchsorted(brk, s_mm, side="right"), 1, brk.size - 1)
    ahead = np.maximum(brk[i] - s_mm, 0.0)
    behind = np.maximum(s_mm - brk[i - 1], 0.0)
    room = np.maximum(tube - 0.5 * np.where(b_bar > 0.0, k_near, 0.0) * b_bar**2, 0.0)
    has_m = np.any(m != 0.0, axis=1)
    if np.any(t[:, 2] != 0.0) or np.any(np.asarray(offset_mm)[:, 2] != 0.0):
        # A third direction (docstring): m any unit normal of a vertical tangent.
        x = np.array([1.0, 0.0, 0.0])
        m_v = x - np.outer(t @ x, np.ones(3)) * t
        m_v /= np.maximum(np.linalg.norm(m_v, axis=1), 1e-300)[:, None]
        m = np.where(has_m[:, None], m, m_v)
        w = np.cross(t, m)
        w /= np.maximum(np.linalg.norm(w, axis=1), 1e-300)[:, None]
        lower = np.column_stack([-room, -np.minimum(b_bar, behind), -room])
        upper = np.column_stack([room, np.minimum(b_bar, ahead), room])
        return np.stack([m, t, w], axis=1), lower, upper
    lower = np.column_stack([np.where(has_m, -room, 0.0), -np.minimum(b_bar, behind)])
    upper = np.column_stack([np.where(has_m, room, 0.0), np.minimum(b_bar, ahead)])
    return np.stack([m, t], axis=1), lower, upper


def _windows(bad: np.ndarray, pad: int, n: int) -> list[tuple[int, int]]:
    """Windows [j0, j1) of movable samples (1 … n − 2) ``pad`` either side of the samples
    ``bad`` (N,) bool; overlapping ones merged."""
    idx = np.flatnonzero(bad)
    if idx.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(idx) > 2 * pad + 1) + 1
    return [
        (max(int(g[0]) - pad, 1), min(int(g[-1]) + pad + 1, n - 1)) for g in np.split(idx, cuts)
    ]


def _difference_matrix(order: int, weights: np.ndarray, j0: int, j1: int, n: int, nx: int):
    """Rows i (touching the window j0 … j1−1 of a reference of ``n`` samples) of the
    ``order``-th difference Σ_l c_l (weights · x)_{i+l} of the window's unknowns x (``nx``
    of them, D per sample): ``weights`` (j1 − j0, D) per window sample and direction; the
    rows' indices."""
    from scipy.sparse import coo_matrix

    dims = weights.shape[1]
    coef = np.diff(np.eye(order + 1), n=order, axis=0)[0]
    rows = np.arange(max(j0 - order, 0), min(j1 - 1, n - 1 - order) + 1)
    ri, ci, vals = [], [], []
    for lag, c in enumerate(coef):
        k = rows + lag
        ok = (k >= j0) & (k < j1)
        for d in range(dims):
            ri.append(np.flatnonzero(ok))
            ci.append((k[ok] - j0) * dims + d)
            vals.append(c * weights[k[ok] - j0, d])
    mat = coo_matrix(
        (np.concatenate(vals), (np.concatenate(ri), np.concatenate(ci))), shape=(rows.size, nx)
    ).tocsr()
    return mat, rows


def _difference_constraints(
    base: np.ndarray, caps: SampleLimits, basis: np.ndarray, j0: int, j1: int
) -> tuple[list, list]:
    """The rows of the window's LP keeping every first, second and third difference on each
    axis within the caps (:meth:`SampleLimits.lp_rows`, the window's samples at ``base``
    plus the move): blocks (rows, 2 nx) [LP units] and their right-hand sides."""
    from scipy.sparse import csr_matrix, hstack

    n = base.shape[0]
    b = basis[j0:j1]
    nx = (j1 - j0) * basis.shape[1]
    blocks, rhs = [], []
    for order in (1, 2, 3):
        cap = caps.lp_rows(order)
        diffs = np.diff(base, order, axis=0)
        for c in range(3):
            if not np.any(basis[j0:j1, :, c]) or not np.any(np.isfinite(cap[:, c])):
                continue
            mat, rows = _difference_matrix(order, b[:, :, c], j0, j1, n, nx)
            keep = np.isfinite(cap[rows, c])
            mat, rows = mat[keep], rows[keep]
            zeros = csr_matrix((rows.size, nx))
            blocks += [hstack([mat, zeros]), hstack([-mat, zeros])]
            rhs += [
                (cap[rows, c] - diffs[rows, c]) / _LP_UNIT_MM,
                (cap[rows, c] + diffs[rows, c]) / _LP_UNIT_MM,
            ]
    return blocks, rhs


def _polygon_constraints(
    want: np.ndarray, upper: np.ndarray, j0: int, j1: int, nx: int
) -> tuple[list, list]:
    """The tube across the path with a third direction (:func:`path_frame`): (α, γ) within
    the regular TUBE_SIDES-gon inscribed in the disc of α's bound, turned so that a corner
    is the target's direction ``want`` (the clip puts targets on the disc's edge: each stays
    a solution, and so do its neighbours' nearly). Blocks (rows, 2 nx) [LP units] and their
    right-hand sides. (No tube: the axes' frame, nothing across.)"""
    from scipy.sparse import coo_matrix

    size = j1 - j0
    room = upper[j0:j1, 0] / _LP_UNIT_MM
    k = np.flatnonzero(np.isfinite(room))
    room = room[k]
    pair = want.reshape(size, 3)[k]
    phi = np.arctan2(pair[:, 2], pair[:, 0])
    half = np.pi / TUBE_SIDES
    blocks, rhs = [], []
    for side in range(TUBE_SIDES):
        ang = phi + (2 * side + 1) * half
        mat = coo_matrix(
            (
                np.concatenate([np.cos(ang), np.sin(ang)]),
                (np.tile(np.arange(k.size), 2), np.concatenate([3 * k, 3 * k + 2])),
            ),
            shape=(k.size, 2 * nx),
        ).tocsr()
        blocks.append(mat)
        rhs.append(room * np.cos(half))
    return blocks, rhs


def _step_rows(
    rows: np.ndarray,
    direction: np.ndarray,
    basis: np.ndarray,
    step_cap: np.ndarray,
    d1: np.ndarray,
    j0: int,
    j1: int,
):
    """Rows unit_i · Δ(δ)_i of the steps ``rows`` along ``direction`` (rows, 3) of the
    window j0 … j1−1 (the step length linearised along it), and their caps ``step_cap``
    less the fixed part unit_i · Δ(base)_i (``d1`` the steps of the base reference)
    [LP units]."""
    from scipy.sparse import coo_matrix, csr_matrix, hstack

    dims = basis.shape[1]
    nx = (j1 - j0) * dims
    unit = (
        direction
        / np.maximum(np.sqrt(np.einsum("ij,ij->i", direction, direction)), 1e-300)[:, None]
    )
    ri, ci, vals = [], [], []
    for lag, c in enumerate((-1.0, 1.0)):
        k = rows + lag
        ok = (k >= j0) & (k < j1)
        proj = np.einsum("kdc,kc->kd", basis[k[ok]], unit[ok])
        for d in range(dims):
            ri.append(np.flatnonzero(ok))
            ci.append((k[ok] - j0) * dims + d)
            vals.append(c * proj[:, d])
    mat = coo_matrix(
        (np.concatenate(vals), (np.concatenate(ri), np.concatenate(ci))), shape=(rows.size, nx)
    ).tocsr()
    cap = (step_cap[rows] - np.einsum("ij,ij->i", unit, d1[rows])) / _LP_UNIT_MM
    return hstack([mat, csr_matrix((rows.size, nx))]), cap


def project_window(
    u: np.ndarray,
    r: np.ndarray,
    target: np.ndarray,
    caps: SampleLimits,
    basis: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    j0: int,
    j1: int,
) -> np.ndarray | None:
    """The LP of one window (module comment above): samples j0 … j1−1 of ``u`` (N, 3) moved to
    r + Σ_d x_d basis_d, nearest ``target`` in L1 of the frame's coordinates, every
    difference row touching them within the caps, the others as they are; the new
    samples (j1 − j0, 3) [mm], or None (no solution, or the solver gave up)."""
    from scipy.sparse import eye, hstack

    n = u.shape[0]
    size, dims = j1 - j0, basis.shape[1]
    b = basis[j0:j1]
    nx = size * dims
    want = np.einsum("kdc,kc->kd", b, target[j0:j1] - r[j0:j1]).ravel() / _LP_UNIT_MM
    base = u.copy()
    base[j0:j1] = r[j0:j1]  # x = 0: the plan's points in the window
    blocks, rhs = [], []
    # |x − x*| ≤ e
    ident = eye(nx, format="csr")
    blocks += [hstack([ident, -ident]), hstack([-ident, -ident])]
    rhs += [want, -want]
    more_blocks, more_rhs = _difference_constraints(base, caps, basis, j0, j1)
    blocks += more_blocks
    rhs += more_rhs
    if dims == 3:
        more_blocks, more_rhs = _polygon_constraints(want, upper, j0, j1, nx)
        blocks += more_blocks
        rhs += more_rhs
    # The step length, linearised along the ZPETC reference's step (else the plan's); the
    # solution is checked exactly, and a row it breaks is cut again along its own step (the
    # second-order remainder |w⊥|²/2|w| of a move across the step: sub-nanometre here).
    step_cap = caps.lp_step()
    d1 = np.diff(base, axis=0)
    rows = np.arange(max(j0 - 1, 0), min(j1 - 1, n - 2) + 1)
    d_target = np.diff(target, axis=0)[rows]
    direction = np.where(np.any(d_target != 0.0, axis=1)[:, None], d_target, d1[rows])
    moving = np.any(direction != 0.0, axis=1)  # (a row between two samples at rest: none)
    rows, direction = rows[moving], direction[moving]
    mat, cap = _step_rows(rows, direction, basis, step_cap, d1, j0, j1)
    blocks.append(mat)
    rhs.append(cap)
    bounds = np.column_stack(
        [
            np.concatenate([lower[j0:j1].ravel() / _LP_UNIT_MM, np.zeros(nx)]),
            np.concatenate([upper[j0:j1].ravel() / _LP_UNIT_MM, np.full(nx, np.inf)]),
        ]
    )
    return _solve_window(u, r, blocks, rhs, bounds, basis, step_cap, d1, j0, j1)


def _solve_window(
    u: np.ndarray,
    r: np.ndarray,
    blocks: list,
    rhs: list,
    bounds: np.ndarray,
    basis: np.ndarray,
    step_cap: np.ndarray,
    d1: np.ndarray,
    j0: int,
    j1: int,
) -> np.ndarray | None:
    """The window's LP (min Σ e over the unknowns (x, e), ``blocks`` · (x, e) ≤ ``rhs``
    within ``bounds``) solved by HiGHS, its step lengths then checked exactly: a step over
    its cap is cut again along its own direction (:func:`_step_rows`) and the LP solved
    again, up to four times. The moved samples (j1 − j0, 3) [mm], or None."""
    from scipy.optimize import linprog
    from scipy.sparse import vstack

    n = u.shape[0]
    size, dims = j1 - j0, basis.shape[1]
    b = basis[j0:j1]
    nx = size * dims
    cost = np.concatenate([np.zeros(nx), np.ones(nx)])
    maxiter = max(PROJECT_LP_MIN_ITER, PROJECT_LP_ITER_PER_UNKNOWN * cost.size)
    for _try in range(4):
        res = linprog(
            cost,
            A_ub=vstack(blocks).tocsr(),
            b_ub=np.concatenate(rhs),
            bounds=bounds,
            method="highs",
            options={"maxiter": maxiter, "primal_feasibility_tolerance": 1e-9},
        )
        if res.status != 0:
            return None
        x = res.x[:nx].reshape(size, dims) * _LP_UNIT_MM
        moved = r[j0:j1] + np.einsum("kd,kdc->kc", x, b)
        trial = u.copy()
        trial[j0:j1] = moved
        lo, hi = max(j0 - 1, 0), min(j1, n - 1)
        d = np.diff(trial[lo : hi + 1], axis=0)
        over = np.sqrt(np.einsum("ij,ij->i", d, d)) > step_cap[lo:hi] * (1.0 + 1e-12)
        if not over.any():
            return moved
        mat, cap = _step_rows(np.arange(lo, hi)[over], d[over], basis, step_cap, d1, j0, j1)
        blocks.append(mat)
        rhs.append(cap)
    return None


def project_onto_limits(
    target_mm: np.ndarray,
    planned_mm: np.ndarray,
    caps: SampleLimits,
    basis: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    held: int = 1,
) -> np.ndarray:
    """``target_mm`` (N, 3) [mm] moved, where its differences break ``caps``, to the nearest
    reference (L1 in the frame ``basis`` (N, D, 3) about ``planned_mm``, offsets within
    ``lower`` … ``upper`` (N, D) [mm]) whose differences keep them (module comment above);
    the first and last ``held`` samples, and samples no broken row reaches, as they are. The plan's
    own reference (δ = 0) keeps them, so there is always a solution: if the solver fails
    on the whole reference, or on windows grown to PROJECT_MAX_WINDOW samples (an LP that
    runs out of its iterations, PROJECT_LP_ITER_PER_UNKNOWN, counts as failed), the planned
    points are returned."""
    r = np.asarray(planned_mm, dtype=float)
    u = np.array(target_mm, dtype=float)
    n = u.shape[0]
    if n < 3:
        return u
    pad = PROJECT_PAD
    m = n - held + 1  # the movable samples: 1 … m − 2
    while True:
        bad = limit_excess(u, caps) > 0.0
        bad[0] = False
        bad[m - 1 :] = False
        windows = _windows(bad, pad, m)
        if not windows:
            return u
        for j0, j1 in windows:
            # (a longer window in pieces of PROJECT_MAX_WINDOW, one after the other)
            for c0 in range(j0, j1, PROJECT_MAX_WINDOW):
                c1 = min(c0 + PROJECT_MAX_WINDOW, j1)
                moved = project_window(u, r, target_mm, caps, basis, lower, upper, c0, c1)
                if moved is not None:
                    u[c0:c1] = moved
        if windows == [(1, m - 1)] or 2 * pad > PROJECT_MAX_WINDOW:
            bad = limit_excess(u, caps) > 0.0
            return u if not bad.any() else r.copy()
        pad *= 4
