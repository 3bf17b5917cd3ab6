"""The spiral sides' polyline distance of the PH corner blends as one (chords, points) array
(nurbscnc.geometry.phcorner.polyline_distance): the same bits as the chord-by-chord loop it
replaces (kept here as the reference), and the true distance to the polyline.

The reference loop is the previous code, word for word: the least over the chords of
``_segment_distance``. An independent check: the distance to each chord by projection in
real coordinates, to rounding.
"""

from __future__ import annotations

import numpy as np
import pytest

from nurbscnc.geometry.ph import PHQuintic
from nurbscnc.geometry.phcorner import (
    _cdiv_real,
    _segment_distance,
    _w1,
    _w_g2,
    _w_line,
    polyline_distance,
)


def chord_by_chord(q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """The reference: one chord at a time (the code the batch replaced)."""
    return np.min([_segment_distance(q, a, b) for a, b in zip(pts[:-1], pts[1:])], axis=0)


def projection_distance(q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Independent: the foot on each chord in real (x, y) coordinates, longdouble sums."""
    qx, qy = q.real.astype(np.longdouble), q.imag.astype(np.longdouble)
    best = np.full(q.size, np.inf, dtype=np.longdouble)
    for a, b in zip(pts[:-1], pts[1:]):
        ax, ay = np.longdouble(a.real), np.longdouble(a.imag)
        dx, dy = np.longdouble(b.real) - ax, np.longdouble(b.imag) - ay
        den = dx * dx + dy * dy
        f = np.zeros(q.size, dtype=np.longdouble)
        if den > 0:
            f = np.clip(((qx - ax) * dx + (qy - ay) * dy) / den, 0, 1)
        ex, ey = qx - ax - f * dx, qy - ay - f * dy
        best = np.minimum(best, np.sqrt(ex * ex + ey * ey))
    return best.astype(float)


def _spiral_side(rng, n: int = 33):
    """A spiral arc's 33-point side far from the origin (800 mm coordinates, as on a table),
    radii from micrometres to metres, sometimes a repeated (zero-length) chord."""
    scale = 10.0 ** rng.uniform(-3.0, 3.0)
    offset = complex(*rng.uniform(-800.0, 800.0, 2))
    theta = np.linspace(0.0, rng.uniform(0.05, 3.0), n)
    pts = offset + scale * (1.0 + 0.2 * theta) * np.exp(1j * (theta + rng.uniform(0, 6.3)))
    if rng.uniform() < 0.2:
        k = int(rng.integers(1, n - 1))
        pts[k] = pts[k - 1]
    q = offset + scale * (rng.normal(size=int(rng.integers(1, 120))) * (1 + 1j))
    q += scale * rng.normal(size=q.size) * 1j
    return q, pts


@pytest.mark.parametrize("seed", range(40))
def test_batch_equals_the_chord_by_chord_loop_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    for _ in range(25):
        q, pts = _spiral_side(rng)
        assert np.array_equal(polyline_distance(q, pts), chord_by_chord(q, pts))


def test_batch_is_the_distance_to_the_polyline():
    rng = np.random.default_rng(7)
    for _ in range(50):
        q, pts = _spiral_side(rng)
        got = polyline_distance(q, pts)
        want = projection_distance(q, pts)
        scale = np.abs(pts - pts[0]).max() + 1.0
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * (scale + 800.0))


def test_points_on_the_polyline_are_at_distance_zero_and_a_kink_is_measured():
    pts = np.array([0.0, 1.0, 1.0 + 1.0j])
    q = np.array([0.5, 1.0 + 0.25j, 1.0, 2.0, 0.5 + 0.5j])
    # on the chords; the vertex; beyond the first chord's end (1 from the vertex); inside
    np.testing.assert_array_equal(polyline_distance(q, pts)[:3], 0.0)
    assert polyline_distance(q, pts)[3] == 1.0
    assert polyline_distance(q, pts)[4] == 0.5


# --- the G2 Newton solve in Python scalars --------------------------------------------------


def _w1_numpy(e0, e2, k0, k1, a, b):
    return (0.25 * k0 * a**3 * e2 + 0.25 * k1 * b**3 * e0) / (e0.conjugate() * e2).imag


def w_g2_numpy(dp, e0, e2, k0, k1, ab0, max_iter=30):
    """The reference: the solve on numpy complex128 scalars (the code the scalar one
    replaced, word for word)."""
    s = (e0.conjugate() * e2).imag
    scale = 5.0 * abs(dp)

    def residual(a, b):
        w0, w1, w2 = a * e0, _w1_numpy(e0, e2, k0, k1, a, b), b * e2
        f = w0 * w0 + w0 * w1 + (2.0 * w1 * w1 + w0 * w2) / 3.0 + w1 * w2 + w2 * w2 - 5.0 * dp
        return f, w0, w1, w2

    a, b = ab0
    f, w0, w1, w2 = residual(a, b)
    for _ in range(max_iter):
        if abs(f) <= 1e-14 * scale:
            return a, b
        fw1 = w0 + 4.0 * w1 / 3.0 + w2
        dfa = (2.0 * w0 + w1 + w2 / 3.0) * e0 + fw1 * (0.75 * k0 * a * a * e2 / s)
        dfb = (w0 / 3.0 + w1 + 2.0 * w2) * e2 + fw1 * (0.75 * k1 * b * b * e0 / s)
        det = dfa.real * dfb.imag - dfb.real * dfa.imag
        if not (np.isfinite(det) and det != 0.0):
            return None
        da = -(f.real * dfb.imag - dfb.real * f.imag) / det
        db = -(dfa.real * f.imag - f.real * dfa.imag) / det
        step = 1.0
        for _ in range(20):
            an, bn = a + step * da, b + step * db
            if an > 0.0 and bn > 0.0:
                trial = residual(an, bn)
                if abs(trial[0]) < abs(f):
                    break
            step *= 0.5
        else:
            return None
        a, b = an, bn
        f, w0, w1, w2 = trial
    return (a, b) if abs(f) <= 1e-10 * scale else None


def _g2_corners(rng, n):
    """Corners as the search meets them: unit end tangents turning by up to 170°, a chord
    inside their cone 0.01–5 mm long at 800 mm from the origin, end curvatures of arcs
    (0 or ±1/r, r from a fifth of the chord to 1000 chords)."""
    for _ in range(n):
        heading = rng.uniform(-np.pi, np.pi)
        turn = rng.uniform(-3.0, 3.0)
        t0, t1 = np.exp(1j * heading), np.exp(1j * (heading + turn))
        u0, u2 = np.sqrt(np.complex128(t0)), np.sqrt(np.complex128(t1))
        if (u0.conjugate() * u2).real < 0.0:
            u2 = -u2
        if abs((u0.conjugate() * u2).imag) < 1e-12:
            continue
        size = 10.0 ** rng.uniform(-2.0, 0.7)
        z_a = complex(rng.uniform(-800.0, 800.0), rng.uniform(-800.0, 800.0))
        dp = complex(size * (rng.uniform(0.1, 1.0) * t0 + rng.uniform(0.1, 1.0) * t1))
        dp = complex(z_a + dp) - z_a  # the rounding of plane coordinates
        curv = [
            0.0
            if rng.random() < 0.3
            else rng.choice([-1, 1]) / (size * 10.0 ** rng.uniform(-0.7, 3.0))
            for _ in range(2)
        ]
        ab = _w_line(dp, u0, u2)
        if ab is not None:
            yield dp, u0, u2, float(curv[0]), float(curv[1]), ab


def test_g2_solve_in_python_scalars_gives_the_bits_of_numpy_scalars():
    rng = np.random.default_rng(21)
    solved = failed = 0
    for dp, u0, u2, k0, k1, ab in _g2_corners(rng, 6000):
        for lam in (1.0, 0.5):
            ref = w_g2_numpy(dp, u0, u2, lam * k0, lam * k1, ab)
            got = _w_g2(dp, u0, u2, lam * k0, lam * k1, ab)
            if ref is None:
                assert got is None
                failed += 1
                continue
            solved += 1
            assert (
                got is not None
                and float(got[0]) == float(ref[0])
                and float(got[1]) == float(ref[1])
            )
            # Independent: the PH quintic of (α, β) meets the chord and both end curvatures.
            a, b = got
            w0, w2 = a * u0, b * u2
            w1 = _w1(u0, u2, lam * k0, lam * k1, a, b)
            ph = PHQuintic(np.array([w0, w1, w2]), 0.0)
            assert abs(complex(ph.point(np.array([1.0]))[0]) - dp) <= 1e-9 * abs(dp)
            kap = ph.curvature(np.array([0.0, 1.0]))
            assert kap[0] == pytest.approx(lam * k0, rel=1e-6, abs=1e-9 / abs(dp))
            assert kap[1] == pytest.approx(lam * k1, rel=1e-6, abs=1e-9 / abs(dp))
    assert solved > 3000 and failed > 50  # both outcomes are exercised


def test_numpy_division_by_a_real_is_reproduced():
    rng = np.random.default_rng(4)
    for _ in range(20000):
        z = complex(*(rng.normal(size=2) * 10.0 ** rng.uniform(-8, 8)))
        d = float(rng.normal() * 10.0 ** rng.uniform(-8, 8))
        assert _cdiv_real(z, d) == complex(np.complex128(z) / d)
