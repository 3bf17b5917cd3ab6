"""plan/naive.py: the whole-array G64 Q chains equal the one-chain-at-a-time greedy algorithm.

The reference below is the scalar algorithm the module had before it was vectorised (issue 14):
one run at a time, one chain at a time, growing stepwise to 16 moves with the scalar check, then
galloping and bisecting with the matrix check. The vectorised version must give the same chains
(the same merged segments, the same origins) on random near-collinear polylines, on points
exactly at the tolerance (where the two checks' roundings differ) and across runs broken by
feed, mode and Q changes and by other segments.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.geometry.segments import Line
from nurbscnc.plan import naive
from nurbscnc.plan.naive import MAX_CHAIN, STEPWISE, _fits_np, _fits_py, merge_collinear


def _reference_chains(pts: list, tol_mm: float) -> list[tuple[int, int]]:
    out = []
    m = len(pts) - 1
    tol2 = tol_mm * tol_mm
    v = np.asarray(pts, dtype=float)
    a = 0
    while a < m:
        b = a + 1
        while b < m and b - a < min(STEPWISE, MAX_CHAIN) and _fits_py(pts, a, b + 1, tol2):
            b += 1
        if b - a == STEPWISE and b < m:
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


def _reference_merge(segs: list) -> tuple[list[tuple], list[int]]:
    """(start, end) of every merged segment and its origin, by the scalar algorithm."""

    def mergeable(s):
        return s.kind == "line" and getattr(s, "naive_mm", 0.0) > 0.0

    out, origin, i, n = [], [], 0, len(segs)
    while i < n:
        if not mergeable(segs[i]):
            out.append((tuple(segs[i].start_mm), tuple(segs[i].end_mm)))
            origin.append(i)
            i += 1
            continue
        j = i + 1
        while (
            j < n
            and mergeable(segs[j])
            and (segs[j].feed_mm_s, segs[j].blend_mm, segs[j].naive_mm)
            == (segs[j - 1].feed_mm_s, segs[j - 1].blend_mm, segs[j - 1].naive_mm)
        ):
            j += 1
        run = segs[i:j]
        pts = [tuple(run[0].start_mm)] + [tuple(s.end_mm) for s in run]
        for a, b in _reference_chains(pts, run[0].naive_mm):
            out.append((tuple(run[a].start_mm), tuple(run[b - 1].end_mm)))
            origin.append(i + b - 1)
        i = j
    return out, origin


def _lines(pts: np.ndarray, feed: np.ndarray, q: np.ndarray, rapid_at=()) -> list:
    segs = []
    for k in range(len(pts) - 1):
        segs.append(
            Line(
                tuple(map(float, pts[k])),
                tuple(map(float, pts[k + 1])),
                float(feed[k]),
                k + 1,
                rapid=k in rapid_at,
                blend_mm=0.01,
                naive_mm=float(q[k]),
            )
        )
    return segs


def _assert_same(segs: list) -> None:
    got, origin = merge_collinear(segs)
    ref, ref_origin = _reference_merge(segs)
    assert origin.tolist() == ref_origin
    assert [(tuple(s.start_mm), tuple(s.end_mm)) for s in got] == ref
    for s, o in zip(got, origin.tolist()):  # the merged line keeps its last move's data
        assert (s.line, s.feed_mm_s, s.naive_mm) == (
            segs[o].line,
            segs[o].feed_mm_s,
            segs[o].naive_mm,
        )


def _spiral(n: int, chord_mm: float, r0_mm: float, noise_mm: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    theta = np.cumsum(np.full(n, chord_mm / r0_mm))
    r = r0_mm + 0.05 * theta
    pts = np.stack([r * np.cos(theta), r * np.sin(theta), np.zeros(n)], axis=1)
    return np.round(pts + rng.uniform(-noise_mm, noise_mm, pts.shape), 4)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(2, 400),
    chord=st.floats(0.005, 0.5),
    r0=st.floats(1.0, 200.0),
    noise=st.floats(0.0, 0.02),
    q=st.sampled_from([0.001, 0.005, 0.01, 0.05]),
    seed=st.integers(0, 2**31),
    cuts=st.integers(0, 6),
)
def test_chains_equal_the_scalar_algorithm(n, chord, r0, noise, q, seed, cuts):
    pts = _spiral(n + 1, chord, r0, noise, seed)
    rng = np.random.default_rng(seed + 1)
    feed = np.full(n, 20.0)
    qs = np.full(n, q)
    # Runs broken by feed changes, Q changes (one Q off) and a rapid.
    for k in rng.integers(0, n, cuts):
        feed[k:] += 5.0
    if cuts and n > 3:
        qs[rng.integers(0, n)] = 0.0
    _assert_same(_lines(pts, feed, qs, rapid_at=set(rng.integers(0, n, cuts // 3).tolist())))


def test_long_runs_gallop_and_bisect_as_the_scalar_algorithm():
    # A large-radius spiral: chains of up to MAX_CHAIN moves (galloping and bisection), one
    # run of 5,000 moves and many short runs.
    pts = _spiral(5001, 0.05, 400.0, 0.0, 3)
    feed = np.where(np.arange(5000) < 2500, 20.0, 20.0 + (np.arange(5000) // 37))
    segs = _lines(pts, feed, np.full(5000, 0.01))
    _assert_same(segs)
    got, _ = merge_collinear(segs)
    assert max(s.line for s in got[1:]) and len(got) < 600  # merging happened


def test_vertices_at_the_tolerance_are_decided_as_the_scalar_algorithm():
    # Zig-zags whose vertices are at Q from the chord up to rounding (Q = 0.01 not binary):
    # the whole-array distances fall in the rounding band and are redone by the scalar checks.
    q = 0.01
    x = np.arange(0.0, 40.0, 0.1)
    for amp in (q, 2 * q, q * (1 + 1e-15), q * (1 - 1e-15)):
        y = np.where(np.arange(x.size) % 2 == 0, 0.0, amp)
        pts = np.stack([x, y, np.zeros_like(x)], axis=1)
        _assert_same(_lines(pts, np.full(x.size - 1, 20.0), np.full(x.size - 1, q)))
    # Collinear points exactly (distance 0), and repeated points (zero-length moves).
    pts = np.repeat(np.stack([x, 0.5 * x, 0 * x], axis=1), 2, axis=0)
    _assert_same(_lines(pts, np.full(len(pts) - 1, 20.0), np.full(len(pts) - 1, q)))


def test_band_checks_use_the_reference_functions(monkeypatch):
    # A zig-zag of amplitude exactly Q: the middle vertex of every 2-move chain is at Q from
    # the chord (off² = Q·Q, the tolerance²): inside the rounding band, so the stepwise check
    # is redone by the scalar reference, which accepts it (≤).
    calls = []
    real = naive._fits_py
    monkeypatch.setattr(naive, "_fits_py", lambda *a: calls.append(a) or real(*a))
    x = np.arange(0.0, 2.0, 0.1)
    y = np.where(np.arange(x.size) % 2 == 0, 0.0, 0.01)
    pts = np.stack([x, y, np.zeros_like(x)], axis=1)
    segs = _lines(pts, np.full(x.size - 1, 20.0), np.full(x.size - 1, 0.01))
    _assert_same(segs)
    assert calls and len(merge_collinear(segs)[0]) < len(segs)


def test_no_q_returns_the_segments_unchanged():
    pts = _spiral(50, 0.1, 10.0, 0.0, 1)
    segs = _lines(pts, np.full(49, 20.0), np.zeros(49))
    got, origin = merge_collinear(segs)
    assert all(a is b for a, b in zip(got, segs)) and origin.tolist() == list(range(49))
