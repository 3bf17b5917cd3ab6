"""G64 Q: LinuxCNC's naive CAM detector (collinear merging) on the interpreted segments.

CAM output often writes a straight or nearly straight stretch as many short G1 moves. Under
``G64 P- Q-`` LinuxCNC collapses consecutive linear feed moves at the same feed into one
line while every intermediate vertex stays within Q of it (Q defaults to P; ``G64`` alone
and ``Q0`` turn the detector off, and it only works in continuous mode; LinuxCNC 2.9 g-code
docs, "G64", and its canonical layer, emccanon.cc). :func:`merge_collinear`
does the same, greedily from the first move of a run: a move joins the current chain when
every vertex of the chain (its interior end points) lies within Q of the segment from the
chain's start to the move's end (exact point-to-segment distances: a vertex beyond either
end, as in a reversal, is not "near the line"). The merged line keeps the last move's
source line and path-control values. LinuxCNC also splits small G17 arcs into two lines to
merge them; nurbscnc keeps arcs as they are (their blends handle the joints).
"""

from __future__ import annotations

from dataclasses import fields
from itertools import chain

import numpy as np

from nurbscnc.plan.rotary import moves_rotary

#: Most moves merged into one line, as LinuxCNC (emccanon.cc ``linkable``: a chain of more
#: than 100 points takes no more); it also bounds the cost of the distance checks.
MAX_CHAIN = 101


def _with_start(seg, start_mm):
    """``dataclasses.replace(seg, start_mm=start_mm)`` with the field names looked up once
    per class (replace looks them up on every call: thousands of merged lines)."""
    names = _INIT_FIELDS.get(type(seg))
    if names is None:
        names = _INIT_FIELDS.setdefault(type(seg), tuple(f.name for f in fields(seg) if f.init))
    kw = {n: getattr(seg, n) for n in names}
    kw["start_mm"] = start_mm
    return type(seg)(**kw)


_INIT_FIELDS: dict = {}


#: Chains grow one move at a time up to this many moves, then by galloping (doubling steps,
#: then bisection).
STEPWISE = 16


def _fits_py(pts: list, a: int, e: int, tol2: float) -> bool:
    """Every vertex a+1 … e−1 of ``pts`` (tuples) within √tol2 of segment a–e (exact): the
    scalar check of the stepwise phase (the reference the whole-array check falls back to)."""
    sx, sy, sz = pts[a]
    ex, ey, ez = pts[e]
    dx, dy, dz = ex - sx, ey - sy, ez - sz
    dd = dx * dx + dy * dy + dz * dz
    for k in range(a + 1, e):
        px, py, pz = pts[k]
        rx, ry, rz = px - sx, py - sy, pz - sz
        t = (rx * dx + ry * dy + rz * dz) / dd if dd > 0.0 else 0.0
        t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        ox, oy, oz = rx - t * dx, ry - t * dy, rz - t * dz
        if ox * ox + oy * oy + oz * oz > tol2:
            return False
    return True


def _fits_np(v: np.ndarray, a: int, e: int, tol2: float) -> bool:
    """:func:`_fits_py` on an array of vertices: the check of the galloping phase (matrix
    products: the same distances to a few ulps)."""
    d = v[e] - v[a]
    dd = float(d @ d)
    rel = v[a + 1 : e] - v[a]
    t = np.clip(rel @ d / dd, 0.0, 1.0) if dd > 0.0 else np.zeros(e - a - 1)
    off = rel - t[:, None] * d
    return float(np.einsum("ij,ij->i", off, off).max()) <= tol2


#: Half-width of the band around Q² [mm²], in units of eps·(|r|² + Q²) with r a vertex
#: relative to the chain start, inside which a whole-array distance is not trusted to decide
#: (the scalar and matrix checks above round differently, by a few ulps of |r|·|offset|):
#: those few checks are redone by the reference function of their phase, so the chains are
#: exactly the ones of the one-chain-at-a-time algorithm.
_BAND_EPS = 256.0


def _offsets2(start, end, pts):
    """Squared distances [mm²] of points ``pts`` (R, W, 3) to the segments ``start``–``end``
    (R, 3) (the arithmetic of :func:`_fits_py`, elementwise), and |pts − start|² (R, W)."""
    dx, dy, dz = (end[:, c : c + 1] - start[:, c : c + 1] for c in range(3))
    dd = dx * dx + dy * dy + dz * dz
    rx, ry, rz = (pts[..., c] - start[:, c : c + 1] for c in range(3))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(dd > 0.0, (rx * dx + ry * dy + rz * dz) / dd, 0.0)
    t = np.clip(t, 0.0, 1.0)
    ox, oy, oz = rx - t * dx, ry - t * dy, rz - t * dz
    return ox * ox + oy * oy + oz * oz, rx * rx + ry * ry + rz * rz


def _verdicts(off2, rr2, inside, tol2):
    """Per row (axis −1 of ``off2``): True (every inside vertex within Q), False (one beyond)
    or None-like −1 where a distance lies in the rounding band (int8: 1, 0, −1)."""
    band = _BAND_EPS * np.finfo(float).eps * (rr2 + tol2[..., None])
    over = inside & (off2 > tol2[..., None] + band)
    near = inside & ~(off2 < tol2[..., None] - band) & ~over
    out = np.where(over.any(axis=-1), 0, np.where(near.any(axis=-1), -1, 1))
    return out.astype(np.int8)


#: Rows per block of the whole-array checks (bounds their temporaries to a few MB).
ROWS = 2048


def _by_blocks(fn, v, *rows):
    """``fn(v, *rows)`` over blocks of :data:`ROWS` rows, concatenated."""
    n = rows[0].size
    if n <= ROWS:
        return fn(v, *rows)
    return np.concatenate([fn(v, *(r[i : i + ROWS] for r in rows)) for i in range(0, n, ROWS)])


def _fits_rows(v, a, e, tol2) -> np.ndarray:
    """:func:`_fits_np` for many chains at once: rows a (R,) → ends e (R,) (vertex indices
    into ``v``), tolerances² ``tol2`` (R,)."""
    return _by_blocks(_fits_block, v, a, e, tol2)


def _fits_block(v, a, e, tol2) -> np.ndarray:
    width = int((e - a).max()) - 1
    if width <= 0:
        return np.ones(a.size, dtype=bool)
    idx = a[:, None] + np.arange(1, width + 1)
    inside = idx < e[:, None]
    pts = v[np.minimum(idx, e[:, None])]
    off2, rr2 = _offsets2(v[a], v[e], pts)
    verdict = _verdicts(off2, rr2, inside, tol2)
    for r in np.flatnonzero(verdict < 0).tolist():
        verdict[r] = _fits_np(v, int(a[r]), int(e[r]), float(tol2[r]))
    return verdict.astype(bool)


def _stepwise(v, a, last, tol2) -> np.ndarray:
    """End vertex b of the stepwise phase for chains starting at ``a`` (R,): the chain grows
    while b < last, b − a < STEPWISE and vertices a+1 … b lie within Q of a–(b+1).
    All STEPWISE − 1 checks of every row at once ((R, ends, vertices) table)."""
    return _by_blocks(_stepwise_block, v, a, last, tol2)


def _stepwise_block(v, a, last, tol2) -> np.ndarray:
    k = np.arange(2, STEPWISE + 1)  # ends a + k
    j = np.arange(1, STEPWISE)  # vertices a + j
    span = np.minimum(a[:, None] + np.arange(STEPWISE + 1), last[:, None])
    p = v[span]  # (R, STEPWISE + 1, 3)
    start = p[:, 0]
    ends = p[:, 2:]  # (R, K, 3)
    rows, kk = a.size, k.size
    # Every (row, end) pair as one row of _offsets2: vertices j = 1 … STEPWISE − 1.
    off2, rr2 = _offsets2(
        np.repeat(start, kk, axis=0), ends.reshape(-1, 3), np.repeat(p[:, 1:STEPWISE], kk, axis=0)
    )
    inside = np.broadcast_to(j[None, :] < np.tile(k, rows)[:, None], off2.shape)
    tol_rows = np.repeat(tol2, kk)
    verdict = _verdicts(off2, rr2, inside, tol_rows).reshape(rows, kk)
    valid = a[:, None] + k[None, :] <= last[:, None]  # the loop tests b + 1 only while b < m
    for r, c in zip(*np.nonzero((verdict < 0) & valid)):
        lo = int(a[r])
        seg = v[lo : lo + int(k[c]) + 1].tolist()
        verdict[r, c] = _fits_py(seg, 0, int(k[c]), float(tol2[r]))
    ok = (verdict > 0) & valid
    # Leading run of successes: b = a + 1 + their count.
    return a + 1 + np.cumprod(ok, axis=1).sum(axis=1)


def _chains_all(v, first, last, tol2):
    """Chains of every run at once: run r's vertices are ``v[first[r] : last[r] + 1]`` [mm]
    and its tolerance² ``tol2[r]`` [mm²]. Returns (chain starts, chain ends) as vertex
    indices into ``v``, in order. Each round advances every unfinished run by one chain,
    greedily as LinuxCNC from the end of the previous one: stepwise up to :data:`STEPWISE`
    moves, then by doubling steps until a check fails and bisection between the last end
    that fitted and the first that did not (the result always fits; a longer chain may
    exist past a failed end, as the check is not monotone), at most :data:`MAX_CHAIN` moves."""
    a = first.copy()
    live = np.flatnonzero(a < last)
    starts, ends = [], []
    while live.size:
        aa, lim, t2 = a[live], last[live], tol2[live]
        b = _stepwise(v, aa, lim, t2)
        cap = np.minimum(lim, aa + MAX_CHAIN)
        gallop = np.flatnonzero((b - aa == STEPWISE) & (b < lim))
        if gallop.size:
            ga, gc, gt = aa[gallop], cap[gallop], t2[gallop]
            good, step = b[gallop], np.full(gallop.size, STEPWISE)
            bad = np.full(gallop.size, -1)
            run = np.flatnonzero(good < gc)
            while run.size:
                e = np.minimum(good[run] + step[run], gc[run])
                fit = _fits_rows(v, ga[run], e, gt[run])
                good[run[fit]], step[run[fit]] = e[fit], 2 * step[run[fit]]
                bad[run[~fit]] = e[~fit]
                run = run[fit]
                run = run[good[run] < gc[run]]
            run = np.flatnonzero((bad >= 0) & (bad - good > 1))
            while run.size:
                mid = (good[run] + bad[run]) // 2
                fit = _fits_rows(v, ga[run], mid, gt[run])
                good[run[fit]] = mid[fit]
                bad[run[~fit]] = mid[~fit]
                run = run[bad[run] - good[run] > 1]
            b[gallop] = good
        starts.append(aa)
        ends.append(b)
        a[live] = b
        live = live[b < lim]
    s, e = np.concatenate(starts), np.concatenate(ends)
    order = np.argsort(s, kind="stable")
    return s[order], e[order]


def merge_collinear(segments) -> tuple[list, np.ndarray]:
    """The segments with runs of nearly collinear feed lines merged (module doc), and for
    each segment of the result the index of the (last) original segment it came from.

    Runs of consecutive mergeable moves (feed lines with Q > 0, same feed, mode and Q) are
    found with array operations; every run's chains are grown together (:func:`_chains_all`)."""
    segs = list(segments)
    # One attribute pass (CAM programs hold millions of moves): Q first, as most segments
    # of most programs have none.
    mine = np.flatnonzero(
        np.fromiter(
            (
                getattr(s, "naive_mm", 0.0) > 0.0 and s.kind == "line" and not moves_rotary(s)
                for s in segs
            ),
            dtype=bool,
            count=len(segs),
        )
    )
    if not mine.size:
        return segs, np.arange(len(segs))
    sub = [segs[i] for i in mine.tolist()]
    keys = np.fromiter(
        chain.from_iterable((s.feed_mm_s, s.blend_mm, s.naive_mm) for s in sub),
        dtype=float,
        count=3 * len(sub),
    ).reshape(-1, 3)
    feed, blend, q = keys.T
    # A run breaks at a gap (a non-mergeable segment between) or where feed, mode or Q change.
    same = (
        (mine[1:] == mine[:-1] + 1)
        & (feed[1:] == feed[:-1])
        & (blend[1:] == blend[:-1])
        & (q[1:] == q[:-1])
    )
    rs = np.concatenate(([0], np.flatnonzero(~same) + 1))  # run starts (positions in sub)
    re = np.concatenate((rs[1:], [mine.size]))
    runs = np.arange(rs.size)
    # Vertices of run r: start of its first move, then every move's end; laid out run after
    # run, so run r's vertices are v[rs[r] + r : re[r] + r + 1].
    end_mm = np.fromiter(
        chain.from_iterable(s.end_mm for s in sub), dtype=float, count=3 * len(sub)
    ).reshape(-1, 3)
    start_mm = np.array([sub[i].start_mm for i in rs.tolist()], dtype=float).reshape(-1, 3)
    v = np.insert(end_mm, rs, start_mm, axis=0)
    first = rs + runs
    ca, cb = _chains_all(v, first, re + runs, q[rs] * q[rs])
    # Back to positions in sub: vertex index − run number (run of each chain by its start).
    run_of = np.searchsorted(first, ca, side="right") - 1
    pa, pb = ca - run_of, cb - run_of  # chain over sub moves pa … pb − 1
    keep = np.ones(len(segs), dtype=bool)
    keep[mine] = False
    last_seg = mine[pb - 1]
    origin = np.sort(np.concatenate((np.flatnonzero(keep), last_seg)))
    first_of = dict(zip(last_seg[pb - pa > 1].tolist(), mine[pa[pb - pa > 1]].tolist()))
    out = []
    for k in origin.tolist():
        f = first_of.get(k)
        out.append(segs[k] if f is None else _with_start(segs[k], segs[f].start_mm))
    return out, origin.astype(np.int64)
