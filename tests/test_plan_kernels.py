"""The compiled kernels of the plan stage (``nurbscnc/plan/_kernels.c``) and of the geometry
(``nurbscnc/geometry/_kernels.c``), built by setup.py, against their Python reference
implementations, bit for bit:

- the gated flank (:func:`nurbscnc.plan.gated.gated_rise_py`),
- the time at which a profile reaches a length (:func:`~nurbscnc.plan.profile._time_at_length_py`),
- the point-to-segments distance of the contour check
  (:func:`~nurbscnc.geometry.distance._segment_distances_py`),
- a piece's peak speed (:func:`nurbscnc.plan.feedrate._peak_speed_py`),
- the B-spline basis functions' derivatives
  (:func:`nurbscnc.geometry.bspline._basis_derivatives_py`),
- the step of the safeguarded Newton iteration of the PH quintics' foot points and arc-length
  inversion (:func:`nurbscnc.geometry.ph._newton_step_py`).

The reference implementations are the specification (and what runs where no C compiler
built the kernels); the kernels must give the same floats, so a plan never depends on
whether the package was compiled. The inputs are random (seeded) and the ones the planner
asks for on a repeated airfoil and its nose, where the gated flanks and the bisections work
hardest. Where the kernels were not built, the tests skip, saying so, and the fallback is
what ran everywhere else.
"""

from __future__ import annotations

import numpy as np
import pytest

import nurbscnc.geometry.distance as distance
import nurbscnc.plan.gated as gated
import nurbscnc.plan.profile as profile
from nurbscnc.plan.profile_plan import plan_profile

pytestmark = pytest.mark.skipif(
    profile._kernels is None,
    reason="nurbscnc.plan._kernels was not built (no C compiler at install): the Python "
    "implementations ran instead",
)


def _bits(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64).view(np.int64)


def _random_flank(rng):
    n = int(rng.integers(1, 14))
    d = np.cumsum(rng.uniform(0.001, 2.0, n) * 10.0 ** rng.integers(-2, 2))
    c = np.sort(rng.uniform(0.5, 80.0, n))
    if rng.random() < 0.3:  # unsorted caps: a staircase that dips
        c = rng.permutation(c)
    v0 = float(rng.uniform(0.0, c[0] * 1.05))
    v_top = float(rng.uniform(c[-1] * 0.9, 120.0))
    a = float(rng.choice([2450.0, 800.0, 50.0, 1e4]))
    j = float(rng.choice([5e4, 1e4, 1e6, 3000.0]))
    dt = float(rng.choice([gated.GATE_STEP_S, 1e-3, 3e-5]))
    return v0, v_top, d, c, a, j, dt


def test_gated_rise_kernel_is_the_python_flank_bit_for_bit():
    """400 random flanks (gates of 1–13 caps, rising or dipping, speeds that start below
    or above the first cap, four accelerations and jerks, three time steps): the same
    phase durations, jerks and distance (or None) from the kernel and from Python. (With
    this seed 320 flanks are found and 80 have none: both outcomes of every branch; the
    planner's own flanks on the airfoil are compared below.)"""
    rng = np.random.default_rng(20261128)
    found = none = 0
    for _ in range(400):
        v0, v_top, d, c, a, j, dt = _random_flank(rng)
        ref = gated.gated_rise_py(v0, v_top, d, c, a, j, dt)
        got = gated.gated_rise(v0, v_top, d, c, a, j, dt)
        if ref is None:
            assert got is None
            none += 1
            continue
        found += 1
        assert got[0] == ref[0] and got[1] == ref[1] and got[2] == ref[2]
        assert all(type(x) is float for x in got[0] + got[1])
        # the memo's merging (gated.merged_phases, rising and reversed) compiled too
        merged = gated._kernels.gated_rise_merged(
            v0,
            v_top,
            d.tobytes(),
            c.tobytes(),
            a,
            j,
            dt,
            gated.GATE_MIN_STEP_S,
            gated.GATE_GALLOP,
            gated.GATE_MAX_STEPS,
        )
        assert (merged[0], merged[1]) == gated.merged_phases(ref[0], ref[1])
        assert (merged[2], merged[3]) == gated.merged_phases(ref[0][::-1], ref[1][::-1])
        assert merged[4] == ref[2]
    assert found > 250 and none > 50  # both outcomes exercised


def _profiles(rng):
    """Profiles of random piece staircases (gated flanks, splits, stops and cruises)."""
    for _ in range(60):
        k = int(rng.integers(2, 120))
        length = rng.uniform(0.01, 5.0, k) * 10.0 ** rng.integers(-2, 2, k)
        caps = rng.uniform(1.0, 80.0, k)
        jcap = np.full(k + 1, np.inf)
        jcap[[0, -1]] = 0.0
        jcap[rng.random(k + 1) < 0.1] = 0.0
        yield plan_profile(profile.ProfileInput(length, caps, jcap, 2450.0, 5e4))


def test_time_at_length_kernel_is_the_python_inversion_bit_for_bit():
    """60 random profiles, each asked at its piece starts and ends, its phase starts, random
    lengths, lengths before 0 and past the end, and a length a few ulps off each phase
    start: the same times from the kernel and from Python."""
    rng = np.random.default_rng(7)
    for prof in _profiles(rng):
        bounds = np.append(prof.piece_start_mm, prof.total_length_mm)
        s0 = np.asarray(prof.phase_s0_mm)
        s = np.concatenate(
            (
                bounds,
                s0,
                np.nextafter(s0, np.inf),
                np.nextafter(s0, -np.inf),
                rng.uniform(-0.1, prof.total_length_mm * 1.01, 500),
            )
        )
        assert np.array_equal(
            _bits(profile.time_at_length(prof, s)), _bits(profile._time_at_length_py(prof, s))
        )


@pytest.mark.skipif(distance._kernels is None, reason="nurbscnc.geometry._kernels was not built")
def test_segment_distances_kernel_is_the_numpy_pairs_bit_for_bit():
    """500 random sets of points and segments over twelve orders of magnitude, with
    zero-length segments, empty and partial ranges: the same distances (inf where a point
    has no segment) from the kernel and from numpy."""
    rng = np.random.default_rng(3)
    for _ in range(500):
        n, m = int(rng.integers(1, 80)), int(rng.integers(1, 50))
        scale = 10.0 ** rng.integers(-6, 6)
        a = rng.standard_normal((n, 3)) * scale
        d = rng.standard_normal((n, 3)) * scale * 10.0 ** rng.integers(-4, 2)
        d[rng.random(n) < 0.1] = 0.0
        q = a[rng.integers(0, n, m)] + rng.standard_normal((m, 3)) * scale * 1e-3
        lo = rng.integers(0, n + 1, m)
        hi = np.minimum(lo + rng.integers(-3, n, m), n)
        got = distance.segment_distances(q, a, d, lo, hi)
        ref = distance._segment_distances_py(q, a, d, lo, hi)
        assert np.array_equal(_bits(got), _bits(ref))
        assert np.all(np.isinf(got[hi <= lo])) and np.all(np.isfinite(got[hi > lo]))


def test_peak_speed_kernel_is_the_python_bisection_bit_for_bit():
    """300 random sets of pieces (zero lengths, stops, short pieces that cannot reach their
    cap, per-piece or scalar limits, descents with their own limits): the same peak speeds
    from the kernel and from numpy."""
    from nurbscnc.plan import feedrate

    rng = np.random.default_rng(13)
    for _ in range(300):
        n = int(rng.integers(1, 300))
        v_s = rng.uniform(0, 60, n) * (rng.random(n) < 0.8)
        v_e = rng.uniform(0, 60, n) * (rng.random(n) < 0.8)
        length = rng.uniform(0, 5, n) * 10.0 ** rng.integers(-4, 2, n)
        length[rng.random(n) < 0.05] = 0.0
        cap = np.maximum(np.maximum(v_s, v_e), rng.uniform(0, 120, n))
        a = rng.choice([2450.0, 800.0, 1e4], n)
        j = rng.choice([5e4, 1e4, 1e6], n)
        a_dn, j_dn = rng.choice([2450.0, 800.0, 1e4], n), rng.choice([5e4, 1e4, 1e6], n)
        for lims in ((a, j, a_dn, j_dn), (a, j), (2450.0, 5e4)):
            assert np.array_equal(
                _bits(feedrate.peak_speed_unchecked(v_s, v_e, length, cap, *lims)),
                _bits(feedrate._peak_speed_py(v_s, v_e, length, cap, *lims)),
            )


@pytest.mark.skipif(distance._kernels is None, reason="nurbscnc.geometry._kernels was not built")
def test_newton_step_kernel_is_the_numpy_step_bit_for_bit():
    """500 random Newton steps (values of both signs, zero, NaN and within the tolerance;
    derivatives positive, zero, negative and NaN; brackets wide, tight and collapsed; x near
    0 and far from it): the same finished values in x, the same compacted x, brackets and
    indices, and the same count from the kernel and from numpy."""
    from nurbscnc.geometry import ph

    rng = np.random.default_rng(35)
    for _ in range(500):
        n = int(rng.integers(1, 60))
        total = n + int(rng.integers(0, 20))
        scale = 10.0 ** rng.integers(-3, 4)
        width = 10.0 ** rng.integers(-17, 0, n).astype(float) * scale
        a = rng.uniform(-1.0, 1.0, n) * scale
        b = a + width * (rng.random(n) < 0.95)
        xa = a + (b - a) * rng.random(n)
        f = rng.standard_normal(n) * 10.0 ** rng.integers(-16, 2, n)
        f[rng.random(n) < 0.05] = 0.0
        f[rng.random(n) < 0.03] = np.nan
        df = rng.standard_normal(n) * 10.0 ** rng.integers(-3, 3, n)
        df[rng.random(n) < 0.05] = 0.0
        df[rng.random(n) < 0.03] = np.nan
        ftol = float(rng.choice([0.0, 1e-13, 1e-6]))
        idx = rng.permutation(total)[:n].astype(np.int64)
        x0 = rng.standard_normal(total)
        got = [xa.copy(), a.copy(), b.copy(), idx.copy(), x0.copy()]
        ref = [xa.copy(), a.copy(), b.copy(), idx.copy(), x0.copy()]
        m_got = distance._kernels.newton_step(f, df, *got, ftol)
        m_ref = ph._newton_step_py(f, df, *ref, ftol)
        assert m_got == m_ref
        for g, r in zip(got[:3], ref[:3]):
            assert np.array_equal(_bits(g[:m_got]), _bits(r[:m_ref]))
        assert np.array_equal(got[3][:m_got], ref[3][:m_ref])
        assert np.array_equal(_bits(got[4]), _bits(ref[4]))


@pytest.mark.skipif(distance._kernels is None, reason="nurbscnc.geometry._kernels was not built")
def test_basis_derivatives_kernel_is_the_numpy_recurrence_bit_for_bit():
    """400 random clamped knot vectors (degrees 0–7, repeated inner knots, spans from 1e-6 to
    1e3 wide), parameters inside, on knots, at and beyond both ends, 0–8 derivatives: the
    same spans and derivative tables (zeros above the degree included) from the kernel and
    from numpy, in the same layout."""
    from nurbscnc.geometry import bspline

    rng = np.random.default_rng(37)
    for _ in range(400):
        p = int(rng.integers(0, 8))
        inner = np.sort(rng.random(int(rng.integers(0, 12))))
        if inner.size > 2 and rng.random() < 0.3:
            inner[1] = inner[0]  # a repeated knot
        scale = 10.0 ** rng.integers(-6, 4)
        knots = np.concatenate((np.zeros(p + 1), inner, np.ones(p + 1))) * scale
        m = int(rng.integers(1, 40))
        u = rng.uniform(-0.1, 1.1, m) * scale
        on_knot = rng.random(m) < 0.2
        u[on_knot] = rng.choice(knots, int(on_knot.sum()))
        n_ders = int(rng.integers(0, 9))
        spans, got = bspline.basis_derivatives(knots, p, u, n_ders)
        ref = bspline._basis_derivatives_py(knots, p, u, bspline.find_span(knots, p, u), n_ders)
        assert np.array_equal(spans, bspline.find_span(knots, p, u))
        assert got.shape == ref.shape and got.strides == ref.strides
        assert np.array_equal(_bits(got), _bits(ref))


@pytest.mark.skipif(distance._kernels is None, reason="nurbscnc.geometry._kernels was not built")
def test_ph_foot_points_and_inversion_same_with_and_without_the_kernel(monkeypatch):
    """The PH quintics' foot points (:meth:`~nurbscnc.geometry.ph.PHQuintic.closest_param`)
    and arc-length inversion of 100 random curves, points near them and far, the same
    bits with the compiled Newton step and with numpy's."""
    from nurbscnc.geometry import ph

    rng = np.random.default_rng(36)
    cases = []
    for _ in range(100):
        p0 = complex(*rng.standard_normal(2)) * 500.0
        chord = complex(*rng.standard_normal(2)) * 10.0 ** rng.integers(-2, 2)
        d0, d1 = (complex(*rng.standard_normal(2)) * abs(chord) for _ in range(2))
        curve = ph.hermite_ph(p0, p0 + chord, d0, d1)
        m = int(rng.integers(1, 300))
        q = curve.point(np.sort(rng.random(m))) + (
            rng.standard_normal(m) + 1j * rng.standard_normal(m)
        ) * float(rng.choice([1e-7, 1e-3, 1.0])) * abs(chord)
        cases.append((curve, q, rng.random(m) * curve.length_mm))

    def run():
        return [(c.closest_param(q), c.param_at_length(s)) for c, q, s in cases]

    compiled = run()
    monkeypatch.setattr(ph, "_kernels", None)
    for got, ref in zip(compiled, run()):
        for g, r in zip(got, ref):
            assert np.array_equal(_bits(g), _bits(r))


def test_segment_distance_is_the_closed_form():
    """Against the geometry itself: a point above the middle of a segment, beyond its end
    and on its line, and a zero-length segment (a point)."""
    a = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    d = np.array([[2.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    q = np.array([[1.0, 3.0, 4.0], [5.0, 0.0, 0.0], [1.0, 1.0, 4.0]])
    lo = np.array([0, 1, 2])
    hi = lo + 1
    for f in (distance.segment_distances, distance._segment_distances_py):
        assert f(q, a, d, lo, hi).tolist() == [5.0, 3.0, 3.0]


def _airfoil_twice() -> str:
    """programs/naca2415.nc's airfoil, then the same airfoil 20 mm further along X."""
    from pathlib import Path

    lines = (Path(__file__).resolve().parents[1] / "programs" / "naca2415.nc").read_text()
    lines = [ln for ln in lines.splitlines() if ln.strip() and not ln.startswith("M2")]
    moved = []
    for ln in lines[1:]:
        words = []
        for w in ln.split():
            if w[0] == "X":
                w = f"X{float(w[1:]) + 20.0:.6f}"
            words.append(w)
        moved.append(" ".join(words))
    return "\n".join([*lines, *moved, "M2"]) + "\n"


def test_airfoil_plan_is_the_same_without_the_kernels(monkeypatch):
    """programs/naca2415.nc's airfoil cut twice (gated flanks, re-plans of the contour check,
    the second cut a moved copy) planned with the kernels and with the Python loops: the
    same cycle time, junction speeds and worst contour error, bit for bit."""
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.pipeline import run_program
    from nurbscnc.program.interpret import interpret_text

    prog = interpret_text(_airfoil_twice())
    machine = load_machine()
    gated._gated_rise_memo.cache_clear()
    fast = run_program(prog, machine)
    from nurbscnc.plan import feedrate

    for module in (profile, gated, distance, feedrate):
        monkeypatch.setattr(module, "_kernels", None)
    gated._gated_rise_memo.cache_clear()
    slow = run_program(prog, machine)
    gated._gated_rise_memo.cache_clear()
    assert fast.plan.iterations > 0  # the check re-planned
    assert fast.cycle_time_s == slow.cycle_time_s
    assert np.array_equal(
        _bits(fast.plan.profile.junction_speeds_mm_s), _bits(slow.plan.profile.junction_speeds_mm_s)
    )
    assert fast.check.overs.worst_mm == slow.check.overs.worst_mm


@pytest.mark.skipif(distance._kernels is None, reason="nurbscnc.geometry._kernels was not built")
def test_nurbs_derivatives_kernel_is_the_numpy_evaluation_bit_for_bit():
    """400 random NURBS curves (degrees 1–7, rational and not, repeated inner knots, parameter
    ranges from 1e-3 to 1e2), parameters inside, on knots and beyond both ends, orders 0–5
    (above the degree included): the compiled evaluation
    (:meth:`~nurbscnc.geometry.nurbs.NurbsCurve.derivatives`) gives numpy's
    (:meth:`~nurbscnc.geometry.nurbs.NurbsCurve._derivatives_py`) bit for bit."""
    from nurbscnc.geometry.nurbs import NurbsCurve

    rng = np.random.default_rng(38)
    for _ in range(400):
        p = int(rng.integers(1, 8))
        n = p + 1 + int(rng.integers(0, 12))
        inner = np.sort(rng.random(n - p - 1))
        if inner.size > 2 and rng.random() < 0.3:
            inner[1] = inner[0]  # a repeated knot
        scale = 10.0 ** rng.integers(-3, 3)
        knots = np.concatenate((np.zeros(p + 1), inner, np.ones(p + 1))) * scale
        weights = rng.uniform(0.2, 3.0, n) if rng.random() < 0.7 else np.ones(n)
        curve = NurbsCurve(p, knots, rng.standard_normal((n, 3)) * 100.0, weights)
        m = int(rng.integers(1, 30))
        u = np.concatenate((rng.uniform(-0.1, 1.1, m) * scale, knots[rng.integers(0, n, 3)]))
        clipped = np.clip(u, curve.u_start, curve.u_end)
        for order in range(6):
            got = curve.derivatives(u, order)
            ref = curve._derivatives_py(clipped, order)
            assert got.shape == ref.shape == (order + 1, u.size, 3)
            assert np.array_equal(_bits(got), _bits(ref))


@pytest.mark.skipif(distance._kernels is None, reason="nurbscnc.geometry._kernels was not built")
def test_power_form_speed_kernel_is_the_numpy_horner_bit_for_bit():
    """400 random rational curves (degrees 0–7, parameter ranges 1e-3 to 1e2), 1–60
    parameters inside and beyond both ends: :meth:`PowerForm.speed` (compiled from two
    samples on) gives :meth:`PowerForm._speed_py`'s bits, one sample included."""
    from nurbscnc.geometry.nurbs import NurbsCurve

    rng = np.random.default_rng(39)
    for _ in range(400):
        p = int(rng.integers(0, 8))
        n = p + 1 + int(rng.integers(0, 12))
        scale = 10.0 ** rng.integers(-3, 3)
        inner = np.sort(rng.random(n - p - 1))
        knots = np.concatenate((np.zeros(p + 1), inner, np.ones(p + 1))) * scale
        curve = NurbsCurve(p, knots, rng.standard_normal((n, 3)) * 100.0, rng.uniform(0.2, 3.0, n))
        form = curve.power_form
        u = rng.uniform(-0.1, 1.1, int(rng.integers(1, 60))) * scale
        spans = form.span_of(u)
        assert np.array_equal(_bits(form.speed(u, spans)), _bits(form._speed_py(u, spans)))
