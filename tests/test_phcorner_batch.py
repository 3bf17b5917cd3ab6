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

from nurbscnc.geometry.phcorner import _segment_distance, polyline_distance


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
