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

from dataclasses import replace

import numpy as np

#: Most moves merged into one line, as LinuxCNC (emccanon.cc ``linkable``: a chain of more
#: than 100 points takes no more); it also bounds the cost of the distance checks.
MAX_CHAIN = 101


def _mergeable(seg) -> bool:
    return seg.kind == "line" and getattr(seg, "naive_mm", 0.0) > 0.0


def _same_move(a, b) -> bool:
    """Same feed, path-control values and Q: the moves differ only in their end points."""
    return (a.feed_mm_s == b.feed_mm_s and a.blend_mm == b.blend_mm
            and a.naive_mm == b.naive_mm)  # fmt: skip


#: Chains grow one move at a time (pure-Python check) up to this many moves, then by
#: galloping (doubling steps, then bisection; vectorised checks).
STEPWISE = 16


def _fits_py(pts: list, a: int, e: int, tol2: float) -> bool:
    """Every vertex a+1 … e−1 of ``pts`` (tuples) within √tol2 of segment a–e (exact)."""
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
    """:func:`_fits_py` on an array of vertices (long chains)."""
    d = v[e] - v[a]
    dd = float(d @ d)
    rel = v[a + 1 : e] - v[a]
    t = np.clip(rel @ d / dd, 0.0, 1.0) if dd > 0.0 else np.zeros(e - a - 1)
    off = rel - t[:, None] * d
    return float(np.einsum("ij,ij->i", off, off).max()) <= tol2


def _chains(pts: list, tol_mm: float) -> list[tuple[int, int]]:
    """Chains over a polyline's vertices ``pts`` (m + 1 tuples) [mm]: (first, last) vertex
    indices of each merged line, in order. A chain from vertex a ends at vertex b only if
    every vertex a + 1 … b − 1 is within ``tol_mm`` of the segment from a to b. It grows one
    move at a time while that holds (greedy, as LinuxCNC), for up to :data:`STEPWISE`
    moves; beyond, by doubling steps until a check fails and then bisection between the
    last end that fitted and the first that did not (the result always fits; a longer
    chain may exist past a failed end, as the check is not monotone)."""
    out = []
    m = len(pts) - 1
    tol2 = tol_mm * tol_mm
    v = None
    a = 0
    while a < m:
        b = a + 1
        while b < m and b - a < min(STEPWISE, MAX_CHAIN) and _fits_py(pts, a, b + 1, tol2):
            b += 1
        if b - a == STEPWISE and b < m:
            v = np.asarray(pts, dtype=float) if v is None else v
            good, step, bad = b, STEPWISE, None
            while bad is None and good < min(m, a + MAX_CHAIN):
                e = min(good + step, m, a + MAX_CHAIN)
                if _fits_np(v, a, e, tol2):
                    good, step = e, 2 * step
                else:
                    bad = e
            while bad is not None and bad - good > 1:
                mid = (good + bad) // 2
                if _fits_np(v, a, mid, tol2):
                    good = mid
                else:
                    bad = mid
            b = good
        out.append((a, b))
        a = b
    return out


def merge_collinear(segments) -> tuple[list, np.ndarray]:
    """The segments with runs of nearly collinear feed lines merged (module doc), and for
    each segment of the result the index of the (last) original segment it came from.

    Runs of consecutive mergeable moves (feed lines with Q > 0, same feed, mode and Q) are
    found first; the chains are grown on each run's vertices (:func:`_chains`)."""
    segs = list(segments)
    mergeable = [_mergeable(s) for s in segs]
    if not any(mergeable):
        return segs, np.arange(len(segs))
    out: list = []
    origin: list[int] = []
    n = len(segs)
    i = 0
    while i < n:
        if not mergeable[i]:
            out.append(segs[i])
            origin.append(i)
            i += 1
            continue
        j = i + 1
        while j < n and mergeable[j] and _same_move(segs[j - 1], segs[j]):
            j += 1
        run = segs[i:j]
        pts = [tuple(map(float, run[0].start_mm))] + [tuple(map(float, s.end_mm)) for s in run]
        for a, b in _chains(pts, run[0].naive_mm):
            last = run[b - 1]
            out.append(last if b - a == 1 else replace(last, start_mm=run[a].start_mm))
            origin.append(i + b - 1)
        i = j
    return out, np.asarray(origin, dtype=np.int64)
