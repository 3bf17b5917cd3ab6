"""Whole programs through the look-ahead (issue 7): the corpus end to end, G64 P corner blends
on polygons, and a 100,000-segment polyline circle.

Everything is measured from the reference samples, against references built here from the
programmed segments (not from the planner's pieces): the path as a dense polyline (lines by
their end points, arcs in closed form from centre, normal and angle, NURBS by scipy's
BSpline on homogeneous coordinates), limits by finite differences of the sampled path
length (a divided difference of s is s′, s″ or an average of s‴ somewhere in between, so
it never exceeds the bound the profile keeps).

The corpus is the folder named by ``NURBSCNC_CORPUS`` (default ``../shared/corpus`` next to
the repository); without it those tests skip. Its programs run with the default machine and
the default (local) dynamics check; the whole corpus takes about a minute.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.interpolate import BSpline
from scipy.spatial import cKDTree

from nurbscnc.geometry.polyline import dense_path_mm
from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.options import LookaheadOptions, PlanOptions
from nurbscnc.program.interpret import interpret_text
from tests.servo_reference import beyond_vertex_mm, g64_vertices, lsim_actual_mm

ROOT = Path(__file__).resolve().parents[1]
MACHINE = load_machine()
LIM = MACHINE.limits
PERIOD = MACHINE.servo.period_s
EPS = np.finfo(float).eps


def plan_program(prog, machine=MACHINE, lookahead: LookaheadOptions | None = None):
    """The program through the pipeline, its plan's fields and its reference samples."""
    run = run_program(prog, machine, RunOptions(lookahead=lookahead or LookaheadOptions()))
    p = run.plan
    return SimpleNamespace(
        samples=run.samples,
        pieces=p.pieces,
        profile=p.profile,
        caps_mm_s=p.caps_mm_s,
        cycle_time_s=run.cycle_time_s,
    )


def corpus_dir() -> Path:
    return Path(os.environ.get("NURBSCNC_CORPUS") or ROOT / ".." / "shared" / "corpus").resolve()


def corpus_files() -> list[str]:
    corpus = corpus_dir()
    if not corpus.is_dir():
        return []
    return sorted(p.relative_to(corpus).as_posix() for p in corpus.rglob("*.ngc"))


# --- independent references ------------------------------------------------------------------


def _arc_points(seg, sagitta_mm: float = 1e-6) -> np.ndarray:
    """Points of an Arc segment in closed form: centre + r(t)(cos tΔθ e1 + sin tΔθ e2) + tHn,
    chords short enough that their sagitta h²/8r stays below ``sagitta_mm``."""
    n = np.asarray(seg.normal, float) / np.linalg.norm(seg.normal)
    rel = np.asarray(seg.start_mm, float) - np.asarray(seg.center_mm, float)
    axial = rel @ n
    e1 = (rel - axial * n) / np.linalg.norm(rel - axial * n)
    e2 = np.cross(n, e1)
    r0, r1 = seg.radius_start_mm, seg.radius_end_mm
    length = abs(seg.angle_rad) * max(r0, r1) + abs(seg.helix_mm)
    chord = min(0.5, np.sqrt(8.0 * sagitta_mm * min(r0, r1)))
    t = np.linspace(0.0, 1.0, max(int(np.ceil(length / chord)), 16) + 1)[:, None]
    r = r0 + t * (r1 - r0)
    th = t * seg.angle_rad
    c = np.asarray(seg.center_mm, float) + axial * n
    return c + r * (np.cos(th) * e1 + np.sin(th) * e2) + t * seg.helix_mm * n


def _nurbs_points(seg, n: int = 100_001) -> np.ndarray:
    w = np.asarray(seg.weights, float)
    hom = np.column_stack([np.asarray(seg.control_points_mm, float) * w[:, None], w])
    spl = BSpline(np.asarray(seg.knots, float), hom, seg.degree)
    u = np.linspace(seg.knots[seg.degree], seg.knots[-seg.degree - 1], n)
    h = spl(u)
    return h[:, :3] / h[:, 3:]


def programmed_path(prog) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """The programmed path: line segments (start (m, 3), end (m, 3); rapids included) and
    dense polylines of the arcs and NURBS (dwells add nothing: they sit at a segment end)."""
    starts, ends, curves = [], [], []
    for seg in prog.segments:
        if seg.kind in ("line", "rapid"):
            starts.append(seg.start_mm)
            ends.append(seg.end_mm)
        elif seg.kind == "arc":
            curves.append(_arc_points(seg))
        elif seg.kind == "nurbs":
            curves.append(_nurbs_points(seg))
    return np.array(starts, float).reshape(-1, 3), np.array(ends, float).reshape(-1, 3), curves


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p (n, 3) to segments [a, b] (m, 3): (n, m)."""
    ab = b - a
    ab2 = np.einsum("ij,ij->i", ab, ab)
    rel = p[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("nmk,mk->nm", rel, ab) / np.where(ab2 > 0, ab2, 1.0), 0.0, 1.0)
    e = rel - t[:, :, None] * ab[None, :, :]
    return np.sqrt(np.einsum("nmk,nmk->nm", e, e))


def distance_to_path(points: np.ndarray, path, reach: float = 0.01) -> np.ndarray:
    """Distance from each point to the programmed path where it is below ``reach`` [mm]
    (elsewhere a value above it, or inf): exact to the line segments; to the dense curve
    polylines the distance to the two segments next to each of the 8 nearest curve
    vertices (a bound from above, exact for these dense polylines of smooth curves)."""
    starts, ends, curves = path
    best = np.full(points.shape[0], np.inf)
    lo_l, hi_l = np.minimum(starts, ends), np.maximum(starts, ends)
    for lo in range(0, points.shape[0], 4096):
        p = points[lo : lo + 4096]
        # Only lines whose box comes within `reach` of the block's box; farther ones are
        # farther than `reach` from every point (the distances checked are far below it).
        near = np.flatnonzero(
            np.all((hi_l >= p.min(axis=0) - reach) & (lo_l <= p.max(axis=0) + reach), axis=1)
        )
        if near.size:
            best[lo : lo + 4096] = _segment_distance(p, starts[near], ends[near]).min(axis=1)
    if curves:
        verts = np.concatenate(curves)
        # A segment joins vertex j to j + 1 only inside one curve.
        inside = np.ones(len(verts), dtype=bool)
        inside[np.cumsum([len(c) for c in curves]) - 1] = False
        # Vertices beyond `reach` + the longest chord cannot bound a segment within reach.
        chord = max(float(np.linalg.norm(np.diff(c, axis=0), axis=1).max()) for c in curves)
        _, near = cKDTree(verts).query(
            points, k=min(8, len(verts)), distance_upper_bound=reach + chord
        )
        near = near.reshape(points.shape[0], -1)
        for col in range(near.shape[1]):
            found = near[:, col] < len(verts)
            for off in (-1, 0):
                j = np.clip(np.where(found, near[:, col], 0) + off, 0, len(verts) - 2)
                a, ab = verts[j], verts[j + 1] - verts[j]
                ab2 = np.einsum("ij,ij->i", ab, ab)
                t = np.clip(
                    np.einsum("ij,ij->i", points - a, ab) / np.where(ab2 > 0, ab2, 1), 0.0, 1.0
                )
                dist = np.linalg.norm(points - a - t[:, None] * ab, axis=1)
                best = np.where(found & inside[j], np.minimum(best, dist), best)
    return best


def vertex_deviation(samples_mm: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Distance from each corner vertex (m, 3) to the polyline through the samples: the
    corner deviation of the run (the Hausdorff distance of a convex blend to its corner is
    the vertex's distance to it)."""
    return _segment_distance(vertices, samples_mm[:-1], samples_mm[1:]).min(axis=1)


def _fd(s: np.ndarray, order: int) -> np.ndarray:
    d = np.asarray(s, float)
    for _ in range(order):
        d = np.diff(d)
    return d / PERIOD**order


def assert_limits(plan) -> None:
    """Feed ≤ the caps of the pieces passed, |a| ≤ A_max, |j| ≤ J_max, by finite differences
    of the sampled s (1e-6 relative, plus the rounding of s)."""
    s, piece = plan.samples.s_mm, plan.samples.piece
    caps = plan.caps_mm_s
    cap = np.maximum(caps[piece[:-1]], caps[piece[1:]])
    for k in np.flatnonzero(piece[1:] > piece[:-1] + 1):  # pieces passed between samples
        cap[k] = caps[piece[k] : piece[k + 1] + 1].max()
    rounding = 8.0 * EPS * max(1.0, float(np.abs(s).max()))
    v = _fd(s, 1)
    assert np.all(v <= cap * (1 + 1e-6) + rounding / PERIOD)
    assert np.abs(_fd(s, 2)).max() <= LIM.a_max_mm_s2 * (1 + 1e-6) + 4 * rounding / PERIOD**2
    assert np.abs(_fd(s, 3)).max() <= LIM.j_max_mm_s3 * (1 + 1e-6) + 8 * rounding / PERIOD**3


def end_point(prog) -> np.ndarray:
    last = [s for s in prog.segments if s.kind != "dwell"][-1]
    return np.asarray(last.end_mm, float)


# --- the corpus ------------------------------------------------------------------------------


def corpus_half(half: int) -> list[str]:
    """Every other corpus program from ``half`` (0 or 1) on, sorted: this file runs half 0 and
    tests/test_wholeprograms_corpus.py half 1, so that the suite's two workers (one test file
    each) share the corpus's minutes."""
    return corpus_files()[half::2] or ["(no corpus)"]


@pytest.mark.parametrize("rel", corpus_half(0))
def test_corpus_program_runs_end_to_end(rel):
    check_corpus_program(rel)


def check_corpus_program(rel: str) -> None:
    """One corpus program planned end to end, checked against the independent references."""
    corpus = corpus_dir()
    if not corpus.is_dir():
        pytest.skip(f"conformance corpus not found at {corpus}; set NURBSCNC_CORPUS")
    prog = interpret_text((corpus / rel).read_text(encoding="utf-8", errors="replace"))
    plan = plan_program(prog, MACHINE)
    smp = plan.samples
    np.testing.assert_allclose(np.diff(smp.t_s), PERIOD, rtol=0, atol=1e-9)
    assert smp.v_mm_s[0] == 0.0 and smp.v_mm_s[-1] == 0.0
    np.testing.assert_array_equal(smp.points_mm[0], prog.start_mm)
    scale = max(1.0, float(np.abs(end_point(prog)).max()))
    np.testing.assert_allclose(smp.points_mm[-1], end_point(prog), rtol=0, atol=1e-12 * scale)
    assert_limits(plan)
    # On the programmed path: NURBS corners are PH quintics within the fit tolerance e, and
    # corners under G64 without P (LinuxCNC's default mode, the corpus's) are blended within
    # the machine's path tolerance; the dense reference adds < 0.01 µm.
    d = distance_to_path(smp.points_mm, programmed_path(prog))
    assert d.max() <= max(1.5 * LIM.ph_tolerance_mm, LIM.path_tolerance_mm) + 1e-5
    # The dynamics check held: the reference through an independent servo simulation
    # (scipy.signal.lsim of eq. 25) stays within ε_max of the planned path (the programmed
    # one with its corners blended or PH-fitted, checked above) while cutting (reference on a
    # feed move; the settling tail counts as cutting), or within ε_max + P of a G64 vertex
    # (nurbscnc.plan.allowance; not on the tail after the end); the planned path as exact
    # points of its pieces every 2 µm.
    actual = lsim_actual_mm(smp.points_mm, MACHINE)
    rapid = plan.pieces.rapid
    n = smp.t_s.size
    cut = np.append(~rapid[smp.piece], np.full(actual.shape[0] - n, not rapid[-1]))
    if cut.any():  # (a program of rapids only cuts nothing)
        planned = dense_path_mm(plan.pieces, plan.profile)
        d = distance_to_path(
            actual[cut], (np.zeros((0, 3)), np.zeros((0, 3)), [planned]), reach=0.1
        )
        eps = LIM.contour_tolerance_mm + 1e-5
        over = np.flatnonzero((d > eps) & (np.flatnonzero(cut) < n))
        corners = g64_vertices(prog.segments, LIM.path_tolerance_mm)
        d[over] = np.minimum(d[over], beyond_vertex_mm(actual[cut][over], corners))
        assert d.max() <= eps


# --- polygons with and without G64 P ---------------------------------------------------------


def _polygon_program(vertices: np.ndarray, blend: str) -> str:
    lines = ["G21 G90 G17", blend, f"G0 X{vertices[0, 0]:.6f} Y{vertices[0, 1]:.6f}", "F3000"]
    lines += [f"G1 X{x:.6f} Y{y:.6f}" for x, y in vertices[1:]]
    return "\n".join(lines + ["M2"]) + "\n"


def _square(side: float = 20.0) -> np.ndarray:
    return np.array([[0, 0], [side, 0], [side, side], [0, side], [0, 0]], float)


def _star(r_out: float = 20.0, r_in: float = 8.0, points: int = 5) -> np.ndarray:
    phi = np.pi / 2 + np.arange(2 * points + 1) * np.pi / points
    r = np.where(np.arange(2 * points + 1) % 2 == 0, r_out, r_in)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi)])


@pytest.mark.parametrize("shape", ["square", "star"])
def test_g64_p_blends_corners_faster_within_p(shape):
    vertices = _square() if shape == "square" else _star()
    tol = 0.2
    plans = {}
    for blend in ("G61", f"G64 P{tol}"):
        prog = interpret_text(_polygon_program(vertices, blend))
        plans[blend] = (prog, plan_program(prog, MACHINE))
    prog_e, exact = plans["G61"]
    prog_b, blended = plans[f"G64 P{tol}"]
    corners = len(vertices) - 2
    blends = blended.pieces.kind_counts().get("ph", 0)
    # Every corner is blended where the blend is faster than a stop (issue 13): all of the
    # square's and the star's five inner corners; its four sharp tips stop, their P0.2
    # blends being slower (corner log: stop_faster).
    assert blends == (corners if shape == "square" else 5)
    assert "ph" not in exact.pieces.kind_counts()
    # Blending saves the stops' time in the kinematics (dynamics off). Under the contour
    # check a stop is now shaped to the servo (planner v2, issue 13) and costs little, while
    # a P0.2 blend must slow to its servo limit: whether a blend beats a stop there is the
    # blend decision's to make (corners/blend_pays), not this test's.
    off = LookaheadOptions(dynamics="off")
    assert (
        plan_program(prog_b, lookahead=off).cycle_time_s
        < plan_program(prog_e, lookahead=off).cycle_time_s
    )
    for prog, plan in ((prog_e, exact), (prog_b, blended)):
        assert_limits(plan)
        np.testing.assert_allclose(plan.samples.points_mm[-1], end_point(prog), atol=1e-12)
    # Corner deviation measured from the samples: every sample within P of the programmed
    # path (the rapid to the start, then the polygon), and the blends do cut the corners
    # (the exact-stop run stays on the path).
    d_b = distance_to_path(blended.samples.points_mm, programmed_path(prog_b), reach=1.0)
    d_e = distance_to_path(exact.samples.points_mm, programmed_path(prog_e))
    assert d_e.max() <= 1e-9
    assert d_b.max() <= tol
    corner_pts = np.column_stack([vertices[1:-1], np.zeros(corners)])
    dev_b = vertex_deviation(blended.samples.points_mm, corner_pts)
    dev_e = vertex_deviation(exact.samples.points_mm, corner_pts)
    assert dev_e.max() <= 1e-5  # exact stops: the samples straddle each vertex at ~0 feed
    assert dev_b.max() <= tol
    assert np.sum(dev_b > 0.5 * tol) == blends  # the blended corners use most of P


def test_g64_p_corner_deviation_matches_the_blend_closed_form():
    """A 90° corner at P = 0.2: the vertex's distance to the sampled path is the blend's
    deviation, tol (1 − ½·SEARCH_WINDOW) by construction (its closed form), to the chord
    error of the servo steps; the samples' farthest distance from the lines is at most that
    times sin 45° (the blend's midpoint lies on the bisector)."""
    from nurbscnc.geometry.blend import SEARCH_WINDOW, line_deviation_per_trim

    tol = 0.2
    prog = interpret_text(_polygon_program(np.array([[0, 0], [30, 0], [30, 30.0]]), f"G64 P{tol}"))
    plan = plan_program(prog, MACHINE, LookaheadOptions(dynamics="off"))
    smp = plan.samples.points_mm
    d = distance_to_path(smp, programmed_path(prog), reach=1.0)
    dev = vertex_deviation(smp, np.array([[30.0, 0.0, 0.0]]))[0]
    expected = tol * (1.0 - 0.5 * SEARCH_WINDOW)
    # The blend's peak curvature in closed form (θ = 90°, c = s = cos 45°, trim d from the
    # deviation per trim of the symmetric blend), and the sagitta κh²/8 of a servo step h.
    c = np.cos(np.pi / 4)
    trim = expected / line_deviation_per_trim(np.pi / 2)
    kappa = 64 * c / (30 * c * trim / (6 * c + 1) * (1 + c) ** 2)
    step = np.linalg.norm(np.diff(smp, axis=0), axis=1).max()
    sagitta = kappa * step**2 / 8
    assert expected <= dev <= expected + sagitta
    # (the distance to the nearer line peaks in a kink at the midpoint: a sample half a step
    # off it is up to a step closer)
    assert expected * np.sqrt(0.5) - step <= d.max() <= expected * np.sqrt(0.5) + 1e-12


# --- a 100,000-segment polyline circle -------------------------------------------------------


def test_hundred_thousand_segment_circle_keeps_the_feed():
    """A G1 polyline of 100,000 chords approximating R = 50 mm (coordinates to 1 nm, as a
    CAM system writes them) under G64 P0.005 at F3000: at most one blend and one line piece
    per segment, no exact stop anywhere on the circle, the feed within 2 % of F over its
    middle 80 %, every sample within P of the polygon, and the end point exact."""
    n, radius, feed = 100_000, 50.0, 50.0
    th = np.linspace(0.0, 2 * np.pi, n + 1)
    pts = np.column_stack([radius * np.cos(th), radius * np.sin(th)]).round(6)
    # Q0: LinuxCNC's naive CAM detector (Q defaults to P since issue 13) would merge the
    # chords into a few hundred lines; this test is about blending 100,000 of them.
    lines = ["G21 G90 G17 G64 P0.005 Q0", f"G0 X{pts[0, 0]:.6f} Y{pts[0, 1]:.6f}", "F3000"]
    lines += [f"G1 X{x:.6f} Y{y:.6f}" for x, y in pts[1:]]
    prog = interpret_text("\n".join(lines + ["M2"]) + "\n")
    # The chords as written (smoothing, the default, would fit them as splines instead).
    plan = plan_program(prog, MACHINE, LookaheadOptions(plan=PlanOptions(smooth=False)))
    counts = plan.pieces.kind_counts()
    assert counts["rapid"] == 1
    assert 0.5 * n < counts["ph"] < n and counts.get("line", 0) < n
    assert len(plan.pieces) < 2 * n
    smp = plan.samples
    on_circle = smp.piece > 0
    v = smp.v_mm_s[on_circle]
    mid = v[v.size // 10 : 9 * v.size // 10]
    assert np.all(np.abs(mid / feed - 1.0) <= 0.02)
    assert np.all(plan.profile.junction_speeds_mm_s[2:-1] > 0.0)  # no stop on the circle
    polygon = np.column_stack([pts, np.zeros(n + 1)])
    d = distance_to_path(smp.points_mm[on_circle], (np.zeros((0, 3)), np.zeros((0, 3)), [polygon]))
    assert d.max() <= 0.005
    np.testing.assert_allclose(smp.points_mm[-1], [pts[-1, 0], pts[-1, 1], 0.0], atol=1e-12)
    assert_limits(plan)
