"""G64 Q: LinuxCNC's naive CAM detector (collinear merging) on the interpreted segments.

CAM output often writes a straight or nearly straight stretch as many short G1 moves. Under
``G64 P- Q-`` LinuxCNC collapses consecutive linear feed moves at the same feed into one
line while every intermediate vertex stays within Q of it (Q defaults to P; ``G64`` alone
and ``Q0`` turn the detector off; LinuxCNC 2.9 g-code docs, "G64"). :func:`merge_collinear`
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

#: Most moves merged into one line: bounds the cost of the distance checks (O(chain) each)
#: on pathological programs (a 100,000-move straight line becomes lines of ≤ 256 moves).
MAX_CHAIN = 256


def _mergeable(seg) -> bool:
    return seg.kind == "line" and getattr(seg, "naive_mm", 0.0) > 0.0


def _same_move(a, b) -> bool:
    """Same feed, path-control values and Q: the moves differ only in their end points."""
    return (a.feed_mm_s == b.feed_mm_s and a.blend_mm == b.blend_mm
            and a.naive_mm == b.naive_mm)  # fmt: skip


def _within(start: np.ndarray, end: np.ndarray, vertices: np.ndarray, tol_mm: float) -> bool:
    """Every row of ``vertices`` (m, 3) within ``tol_mm`` of the segment start–end [mm]."""
    d = end - start
    dd = float(d @ d)
    rel = vertices - start
    t = np.clip(rel @ d / dd, 0.0, 1.0) if dd > 0.0 else np.zeros(len(vertices))
    off = rel - t[:, None] * d
    return bool(np.einsum("ij,ij->i", off, off).max() <= tol_mm * tol_mm)


def merge_collinear(segments) -> tuple[list, np.ndarray]:
    """The segments with runs of nearly collinear feed lines merged (module doc), and for
    each segment of the result the index of the (last) original segment it came from."""
    segs = list(segments)
    if not any(_mergeable(s) for s in segs):
        return segs, np.arange(len(segs))
    out: list = []
    origin: list[int] = []
    chain: list[int] = []  # indices of the moves being merged

    def flush() -> None:
        if not chain:
            return
        first, last = segs[chain[0]], segs[chain[-1]]
        out.append(last if len(chain) == 1 else replace(last, start_mm=first.start_mm))
        origin.append(chain[-1])
        chain.clear()

    for i, seg in enumerate(segs):
        if not _mergeable(seg):
            flush()
            out.append(seg)
            origin.append(i)
            continue
        if chain and len(chain) < MAX_CHAIN and _same_move(segs[chain[-1]], seg):
            start = np.asarray(segs[chain[0]].start_mm, dtype=float)
            vertices = np.array([segs[j].end_mm for j in chain], dtype=float)
            if _within(start, np.asarray(seg.end_mm, dtype=float), vertices, seg.naive_mm):
                chain.append(i)
                continue
        flush()
        chain.append(i)
    flush()
    return out, np.asarray(origin, dtype=np.int64)
