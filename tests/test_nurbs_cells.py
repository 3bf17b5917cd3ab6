"""NURBS cells' curvature peaks (plan/curved_pieces.py ``_nurbs_stretch`` / ``_peak_kappa``): each
cell's κ_max, which sets its cap √(A/κ), against the full three-round refinement it
shortcuts and against dense sampling with an independent evaluator (scipy's B-spline on
homogeneous coordinates, tests/test_nurbs.py), on random rational curves with weights from
0.05 to 20 (sharp, near-cusp peaks)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan import curved_pieces as pc
from tests.test_nurbs import random_curve, scipy_derivatives


def _every_cell_three_rounds(curve, u, kappa, rounds=3):
    """The refinement without the shortcut: every cell, every round."""
    m, n = u.shape
    rows, best = np.arange(m), kappa.max(axis=1)
    for _ in range(rounds):
        k = np.argmax(kappa, axis=1)
        lo, hi = u[rows, np.maximum(k - 1, 0)], u[rows, np.minimum(k + 1, n - 1)]
        u = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, 17)[None, :]
        kappa = curve.curvature(u.ravel()).reshape(u.shape)
        kappa = np.where(np.isfinite(kappa), kappa, 0.0)
        best = np.maximum(best, kappa.max(axis=1))
        n = u.shape[1]
    return best


def _curves(count: int, seed: int = 5):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        c = random_curve(rng, int(rng.integers(2, 4)))
        yield NurbsCurve(
            c.degree, c.knots, c.control_points_mm, rng.uniform(0.05, 20.0, c.weights.size)
        )


def test_cell_peaks_as_refining_every_cell(monkeypatch):
    machine, seg = load_machine(), SimpleNamespace(line=1)
    short, full = [], []
    for curve in _curves(20):
        args = (curve, curve.u_start, curve.u_end, seg, 0, machine, 58.3, 0.0)
        short += [p.kappa_max_per_mm for p in pc._nurbs_stretch(*args)]
        with monkeypatch.context() as mp:
            mp.setattr(pc, "_peak_kappa", _every_cell_three_rounds)
            full += [p.kappa_max_per_mm for p in pc._nurbs_stretch(*args)]
    short, full = np.array(short), np.array(full)
    assert short.size > 10_000
    assert np.all(short <= full)  # the shortcut only skips samples
    np.testing.assert_allclose(short, full, rtol=1e-6)  # measured: one cell, 2.3e-7


def test_cell_peaks_against_dense_independent_curvature():
    machine, seg = load_machine(), SimpleNamespace(line=1)
    for curve in _curves(6, seed=9):
        cells = pc._nurbs_stretch(curve, curve.u_start, curve.u_end, seg, 0, machine, 58.3, 0.0)
        for p in cells[:: max(1, len(cells) // 60)]:
            u = np.linspace(p.u_a, p.u_b, 401)
            d = scipy_derivatives(curve, u, 2)
            cross = np.linalg.norm(np.cross(d[1], d[2]), axis=1)
            speed = np.linalg.norm(d[1], axis=1)
            dense = float(np.max(cross / speed**3))
            # Never far below the densely sampled peak (the cell's cap is no higher than
            # its curvature allows), and never above the true peak by more than rounding.
            assert p.kappa_max_per_mm >= dense * (1.0 - 1e-3), (p.kappa_max_per_mm, dense)
