"""The bundled sample programs (programs/*.nc, SPEC §9) and their generator.

The G6.2 files are read by a tiny regex reader here (not the project's parser) and evaluated
with scipy's BSpline as the oracle; the NACA 2415 geometry is recomputed here from the closed
form, written independently of the generator (unit camber normal instead of atan).
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import BSpline

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
NAMES = [
    "naca2415.nc",
    "naca2415_rot45.nc",
    "naca2415_rot-45.nc",
    "naca2415_c40.nc",
    "butterfly.nc",
    "corners.nc",
]
NUM = r"(-?\d+(?:\.\d+)?)"
AIRFOIL_PER_SURFACE = 40
BUTTERFLY_SAMPLES = 360
BUTTERFLY_SCALE_MM = 8.6


def load_generator():
    spec = importlib.util.spec_from_file_location("make_programs", PROGRAMS / "make_programs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_nurbs(name: str) -> dict:
    """G0 point, order, feed, knots, control points (strings and floats), weights of a file."""
    text = (PROGRAMS / name).read_text(encoding="ascii")
    out = {"knots": [], "ctrl_text": [], "weights": [], "knot_only": 0}
    for raw in text.splitlines():
        line = raw.strip()
        if m := re.fullmatch(rf"G0 X{NUM} Y{NUM}", line):
            out["g0_text"] = m.groups()
        elif m := re.fullmatch(rf"F{NUM}", line):
            out["feed_mm_min"] = float(m.group(1))
        elif m := re.fullmatch(rf"G6\.2 P(\d+) K{NUM} X{NUM} Y{NUM} R{NUM}", line):
            out["order"] = int(m.group(1))
            k, x, y, r = m.groups()[1:]
            out["knots"].append(float(k))
            out["ctrl_text"].append((x, y))
            out["weights"].append(float(r))
        elif m := re.fullmatch(rf"K{NUM} X{NUM} Y{NUM} R{NUM}", line):
            assert out["knot_only"] == 0, "control point after the knot-only blocks"
            k, x, y, r = m.groups()
            out["knots"].append(float(k))
            out["ctrl_text"].append((x, y))
            out["weights"].append(float(r))
        elif m := re.fullmatch(rf"K{NUM}", line):
            out["knots"].append(float(m.group(1)))
            out["knot_only"] += 1
    out["knots"] = np.array(out["knots"])
    out["ctrl"] = np.array(out["ctrl_text"], dtype=float)
    out["spline"] = BSpline(out["knots"], out["ctrl"], out["order"] - 1)
    return out


# ----------------------------------------------------------------- independent NACA 2415


def naca_half_thickness(x):
    return 0.75 * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1036 * x**4)


def naca_camber(x):
    x = np.asarray(x, dtype=float)
    front = (0.02 / 0.16) * (0.8 * x - x**2)
    back = (0.02 / 0.36) * (0.2 + 0.8 * x - x**2)
    slope = np.where(x < 0.4, (0.02 / 0.16) * (0.8 - 2 * x), (0.02 / 0.36) * (0.8 - 2 * x))
    return np.where(x < 0.4, front, back), slope


def naca_samples_mm(chord_mm):
    """TE → upper → LE → lower → TE, 40 cosine-spaced x per surface, unit normal offset."""
    x = 0.5 * (1 - np.cos(np.pi * np.arange(AIRFOIL_PER_SURFACE) / (AIRFOIL_PER_SURFACE - 1)))
    yc, slope = naca_camber(x)
    normal = np.column_stack([-slope, np.ones_like(x)]) / np.hypot(slope, 1.0)[:, None]
    mid = np.column_stack([x, yc])
    yt = naca_half_thickness(x)[:, None]
    upper, lower = mid + yt * normal, mid - yt * normal
    return chord_mm * np.vstack([upper[::-1], lower[1:]])


def chord_params(points):
    u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    return u / u[-1]


def test_naca_reference_matches_published_properties():
    # NACA 4-digit: max camber m = 2 % at p = 0.4; thickness about 15 % at x = 0.3; closed TE.
    assert naca_camber(0.4)[0] == pytest.approx(0.02, abs=1e-15)
    assert 2 * naca_half_thickness(0.3) == pytest.approx(0.15, abs=1e-4)
    assert naca_half_thickness(1.0) == pytest.approx(0.0, abs=1e-15)


# ----------------------------------------------------------------- reproducibility, format


_NUMBER = re.compile(r"-?\d+\.?\d*")


def test_regenerating_gives_the_committed_files(tmp_path):
    # Same text word for word; numbers equal to 1e-10 mm. The 12th decimal of a spline control
    # point depends on the numpy/scipy build (LAPACK rounding), so bytes are not comparable
    # across machines; the programs' geometry is.
    written = load_generator().write_programs(tmp_path)
    assert sorted(p.name for p in written) == sorted(NAMES)
    for name in NAMES:
        new = (tmp_path / name).read_text()
        old = (PROGRAMS / name).read_text()
        assert _NUMBER.sub("#", new) == _NUMBER.sub("#", old), name
        a = np.array([float(x) for x in _NUMBER.findall(new)])
        b = np.array([float(x) for x in _NUMBER.findall(old)])
        assert a.shape == b.shape, name
        assert np.max(np.abs(a - b), initial=0.0) < 1e-10, name


@pytest.mark.parametrize("name", NAMES)
def test_header_comment_and_end(name):
    lines = (PROGRAMS / name).read_text(encoding="ascii").splitlines()
    assert lines[0].startswith("; ") and "programs/make_programs.py" in lines[0]
    assert lines[-1] == "M2"
    assert "G21 G17 G90 G94" in lines


@pytest.mark.parametrize(
    "name, feed",
    [(n, 3500.0) for n in NAMES[:4]] + [("butterfly.nc", 2000.0)],
)
def test_nurbs_structure(name, feed):
    prog = read_nurbs(name)
    n = len(prog["ctrl"])
    assert prog["order"] == 4
    assert len(prog["knots"]) == n + 4
    assert prog["knot_only"] == 4
    assert np.all(np.diff(prog["knots"]) >= 0)
    assert np.all(prog["knots"][:4] == 0.0) and np.all(prog["knots"][-4:] == 1.0)
    assert np.all(np.array(prog["weights"]) == 1.0)
    assert prog["feed_mm_min"] == feed
    # The curve starts at the current position: same text, hence the same float.
    assert prog["g0_text"] == prog["ctrl_text"][0]
    assert np.array_equal(np.array(prog["g0_text"], dtype=float), prog["ctrl"][0])
    # Closed: the clamped curve ends on its last control point, which is the first.
    assert prog["ctrl_text"][-1] == prog["ctrl_text"][0]


# ----------------------------------------------------------------- airfoil geometry


@pytest.mark.parametrize("name, chord_mm", [("naca2415.nc", 9.0), ("naca2415_c40.nc", 40.0)])
def test_airfoil_passes_through_cosine_samples(name, chord_mm):
    prog = read_nurbs(name)
    samples = naca_samples_mm(chord_mm)
    assert len(prog["ctrl"]) == len(samples) == 2 * AIRFOIL_PER_SURFACE - 1
    u = chord_params(samples)
    err_mm = np.abs(prog["spline"](u) - samples).max()
    assert err_mm < 1e-9
    # Start = end = trailing edge (chord, 0); leading edge (0, 0) strictly inside the curve.
    np.testing.assert_array_equal(prog["ctrl"][[0, -1]], [[chord_mm, 0.0], [chord_mm, 0.0]])
    le = AIRFOIL_PER_SURFACE - 1
    assert 0.4 < u[le] < 0.6
    np.testing.assert_allclose(prog["spline"](u[le]), [0.0, 0.0], atol=1e-9)


@pytest.mark.parametrize("j", [3, 10, 17, 25, 32])
def test_airfoil_thickness_and_camber_closed_form(j):
    """Upper and lower points at x_j: midpoint on the camber line, half-gap = y_t, gap ⟂ camber."""
    chord_mm = 9.0
    prog = read_nurbs("naca2415.nc")
    u = chord_params(naca_samples_mm(chord_mm))
    le = AIRFOIL_PER_SURFACE - 1
    upper, lower = prog["spline"]([u[le - j], u[le + j]])
    x = 0.5 * (1 - np.cos(np.pi * j / (AIRFOIL_PER_SURFACE - 1)))
    yc, slope = naca_camber(x)
    np.testing.assert_allclose((upper + lower) / 2, chord_mm * np.array([x, yc]), atol=1e-9)
    gap = upper - lower
    assert np.linalg.norm(gap) / 2 == pytest.approx(chord_mm * naca_half_thickness(x), abs=1e-9)
    assert abs(gap @ np.array([1.0, slope])) < 1e-9


def test_airfoil_curvature_single_peak_at_leading_edge():
    """Convex (κ keeps its sign); only one κ peak over κ̄ = 1/mm, at the LE, near 1/r_LE."""
    prog = read_nurbs("naca2415.nc")
    s = prog["spline"]
    u = np.linspace(0.0, 1.0, 20001)
    d1, d2 = s.derivative(1)(u), s.derivative(2)(u)
    kappa = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3
    assert np.all(kappa > 0)  # counter-clockwise TE → upper → LE → lower, no inflection
    over = kappa > 1.0
    assert np.count_nonzero(np.diff(over.astype(int)) == 1) == 1  # one contiguous region
    peak = np.argmax(kappa)
    assert np.linalg.norm(s(u[peak])) < 0.02  # at the leading edge (0, 0)
    # LE radius of the 4-digit series, r = 1.1019 t^2 c, = 0.2231 mm at c = 9 mm; the cubic
    # interpolant's second derivative is accurate to a few per cent there.
    assert kappa[peak] == pytest.approx(1.0 / (1.1019 * 0.15**2 * 9.0), rel=0.1)


@pytest.mark.parametrize(
    "name, angle_deg", [("naca2415_rot45.nc", 45.0), ("naca2415_rot-45.nc", -45.0)]
)
def test_rotated_airfoils_are_rotations_of_the_base(name, angle_deg):
    base, rot = read_nurbs("naca2415.nc"), read_nurbs(name)
    a = np.deg2rad(angle_deg)
    matrix = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    np.testing.assert_array_equal(rot["knots"], base["knots"])
    assert np.abs(base["ctrl"] @ matrix.T - rot["ctrl"]).max() < 1e-9


# ----------------------------------------------------------------- butterfly, corners


def butterfly_mm(t):
    r = np.exp(np.cos(t)) - 2 * np.cos(4 * t)
    return BUTTERFLY_SCALE_MM * np.column_stack([r * np.sin(t), r * np.cos(t)])


def test_butterfly_interpolates_and_closes_smoothly():
    prog = read_nurbs("butterfly.nc")
    s = prog["spline"]
    samples = butterfly_mm(np.linspace(0, 2 * np.pi, BUTTERFLY_SAMPLES + 1))
    samples[-1] = samples[0]
    assert np.abs(s(chord_params(samples)) - samples).max() < 1e-9
    # End derivatives set equal (C1 closure), along the analytic tangent at t = 0:
    # d/dt (r sin t, r cos t) at t = 0 is (r(0), r'(0)) = (e − 2, 0), i.e. +x.
    d_start, d_end = s.derivative(1)([0.0, 1.0])
    np.testing.assert_allclose(d_end, d_start, rtol=1e-9, atol=1e-9 * np.linalg.norm(d_start))
    assert abs(d_start[1]) < 1e-9 * np.linalg.norm(d_start) and d_start[0] > 0
    dense = s(np.linspace(0, 1, 20001))
    width_mm = np.ptp(dense[:, 0])
    assert width_mm == pytest.approx(50.0, abs=0.05)  # 8.6 × 2 × 2.9063


def test_corners_program():
    lines = (PROGRAMS / "corners.nc").read_text(encoding="ascii").splitlines()
    code = [ln for ln in lines if not ln.startswith(";")]
    assert code.index("G64 P0.01") < next(i for i, ln in enumerate(code) if ln.startswith("G0 "))
    assert "F3000" in code
    pos = np.zeros(2)
    moves = []
    for ln in code:
        if m := re.fullmatch(rf"(G[0-3]) X{NUM} Y{NUM}(?: I{NUM} J{NUM})?", ln):
            g, x, y, i, j = m.groups()
            end = np.array([float(x), float(y)])
            if g in ("G2", "G3"):
                center = pos + [float(i), float(j)]
                r0, r1 = np.linalg.norm(pos - center), np.linalg.norm(end - center)
                assert r0 == pytest.approx(r1, abs=1e-12)
            moves.append((g, pos, end))
            pos = end
    kinds = [g for g, _, _ in moves]
    assert {"G0", "G1", "G2", "G3"} <= set(kinds)
    # The star: ten G1 edges after the last rapid, closing on its first vertex, tips at
    # radius 15 and notches at radius 6 about (70, 20) (printed to 4 decimals).
    last_rapid = max(i for i, g in enumerate(kinds) if g == "G0")
    star = moves[last_rapid + 1 :]
    assert len(star) == 10 and all(g == "G1" for g, _, _ in star)
    np.testing.assert_array_equal(star[-1][2], moves[last_rapid][2])
    radii = np.array([np.linalg.norm(e - [70.0, 20.0]) for _, _, e in star])
    np.testing.assert_allclose(radii, [6, 15] * 5, atol=1e-4)
