"""nurbscnc.geometry.splinefit: scipy.interpolate's cubic B-spline results, to the bit,
without importing scipy.interpolate.

The reference is scipy.interpolate itself (``make_lsq_spline``, ``BSpline``), imported here
only: every value must be equal, not close (the smoothed runs' plans must not move). The
splines are also checked against the definition: knot insertion leaves the curve in place,
the least squares fit reproduces a cubic exactly.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.interpolate import BSpline, make_lsq_spline

from nurbscnc.geometry import splinefit


def _run(seed: int, m: int = 60, step: int = 4):
    """Noisy 3-D samples of an arc at chord-length parameters, knots every ``step``-th one,
    end weights 1e6 (as plan/smoothing.py fits a run)."""
    rng = np.random.default_rng(seed)
    theta = np.sort(rng.uniform(0.0, 3.0, m))
    y = np.column_stack((20 * np.cos(theta), 20 * np.sin(theta), 0.3 * theta))
    y += rng.normal(0.0, 1e-3, y.shape)
    s = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(y, axis=0), axis=1))))
    u = s / s[-1]
    u[-1] = 1.0
    n = m - 1
    t = np.concatenate(([0.0] * 4, u[step : n - step // 2 : step], [1.0] * 4))
    w = np.ones(m)
    w[0] = w[-1] = 1e6
    return u, y, t, w


@pytest.mark.parametrize("seed", range(12))
def test_least_squares_evaluation_and_derivative_equal_scipy_bit_for_bit(seed):
    u, y, t, w = _run(seed, m=40 + 7 * seed, step=(2, 4, 8)[seed % 3])
    ref = make_lsq_spline(u, y, t, k=3, w=w)
    c = splinefit.lsq_spline(u, y, t, w)
    assert c.shape == ref.c.shape
    assert np.array_equal(c, ref.c)
    us = np.linspace(-0.1, 1.1, 301)  # extrapolated outside [0, 1] as BSpline does
    assert np.array_equal(splinefit.evaluate(t, c, us), ref(us))
    for nu in (1, 2, 3):
        assert np.array_equal(splinefit.evaluate(t, c, us, nu), ref(us, nu))
        assert np.array_equal(splinefit.evaluate_derivative(t, c, us, nu), ref.derivative(nu)(us))
    # evaluate_derivative is the derivative spline's value, not the direct derivative: both
    # are the same function, to rounding
    np.testing.assert_allclose(
        splinefit.evaluate_derivative(t, c, us, 2), ref(us, 2), rtol=1e-9, atol=1e-9
    )


def test_least_squares_reproduces_a_cubic_exactly():
    """A cubic polynomial lies in the spline space: the fit is the polynomial itself."""
    x = np.linspace(0.0, 1.0, 50)
    y = np.column_stack((1 + 2 * x - 3 * x**2 + 0.5 * x**3, x**3 - x))
    t = np.concatenate(([0.0] * 4, [0.2, 0.45, 0.7], [1.0] * 4))
    c = splinefit.lsq_spline(x, y, t, np.ones(x.size))
    xs = np.linspace(0.0, 1.0, 97)
    want = np.column_stack((1 + 2 * xs - 3 * xs**2 + 0.5 * xs**3, xs**3 - xs))
    np.testing.assert_allclose(splinefit.evaluate(t, c, xs), want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_knot_insertion_equals_scipy_and_keeps_the_curve(seed):
    u, y, t, w = _run(seed, m=50, step=4)
    c = make_lsq_spline(u, y, t, k=3, w=w).c
    rng = np.random.default_rng(100 + seed)
    # an existing inner knot (raised to full multiplicity) or a fresh parameter
    for x in (float(t[5 + seed % 3]), float(rng.uniform(0.05, 0.95))):
        have = int(np.count_nonzero(t == x))
        m = 4 - have
        ref = BSpline(t, c, 3).insert_knot(x, m)
        tt, cc = splinefit.insert_knot(t, c, x, m)
        assert np.array_equal(tt, ref.t) and np.array_equal(cc, ref.c)
        us = np.linspace(0.0, 1.0, 201)
        np.testing.assert_allclose(BSpline(tt, cc, 3)(us), BSpline(t, c, 3)(us), rtol=0, atol=1e-12)
        t_before = t
        assert np.count_nonzero(tt == x) == 4 and tt.size == t_before.size + m


def test_bad_inputs_raise_value_error_as_scipy_does():
    u, y, t, w = _run(0)
    with pytest.raises(ValueError):
        splinefit.lsq_spline(u[::-1].copy(), y, t, w)  # decreasing parameters
    with pytest.raises(ValueError):
        splinefit.lsq_spline(u * 2.0, y, t, w)  # outside the knots' base interval
    with pytest.raises(ValueError):
        splinefit.insert_knot(t, np.zeros((t.size - 4, 3)), 1.5)


def test_using_it_imports_no_scipy_interpolate():
    code = (
        "import sys, numpy as np\n"
        "from nurbscnc.geometry import splinefit\n"
        "u = np.linspace(0.0, 1.0, 30); y = np.column_stack((np.sin(3 * u), u * u, u))\n"
        "t = np.r_[[0.0] * 4, 0.3, 0.6, [1.0] * 4]; w = np.ones(30)\n"
        "c = splinefit.lsq_spline(u, y, t, w)\n"
        "splinefit.evaluate_derivative(t, c, u, 2); splinefit.insert_knot(t, c, 0.5, 2)\n"
        "assert 'scipy.interpolate' not in sys.modules, sorted(sys.modules)\n"
        "assert 'scipy.interpolate._dierckx' in sys.modules\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
