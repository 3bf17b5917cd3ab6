"""The dynamics check's true distance near each reference point (SPEC §8;
nurbscnc.geometry.distance.windowed_contour_mm).

- the polyline kept across re-plans (``PathIndex.dense_polyline``: filled once, partly when
  it does not all fit, with slabs of any size) gives the same bits as placing it afresh;
- against an independent reference, the exact distance (k-d tree, point to segment) to a
  much denser polyline of the path (``contour_error_true``): never below it and, but where
  the tool overshoots a corner, equal to it up to the check polyline's chord error, on a
  program of blended lines, arcs and a rapid.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.geometry import distance, polyline
from nurbscnc.geometry.distance import PathIndex, windowed_contour_mm
from nurbscnc.geometry.polyline import CHORD_MM, dense_path_mm
from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import run_program
from nurbscnc.plan.lookahead import plan_checked
from nurbscnc.program.interpret import interpret_text
from nurbscnc.servo.model import contour_error_true, simulate_axes
from tests.plan_helpers import assert_same_levers

MACHINE = load_machine()
CORPUS = Path(
    os.environ.get("NURBSCNC_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus")
)

# Blended lines (PH corners), arcs and a rapid: ~3 s of motion.
PROGRAM = """G21 G17 G90 G94
G64 P0.01
G0 X0 Y0
G1 X10 Y0 F3000
G1 X15 Y4
G1 X15 Y10
G3 X5 Y10 I-5 J0
G1 X2 Y3
G1 X0 Y0
G0 X30 Y0
G1 X40 Y0 F2400
G3 X40 Y10 I0 J5
G1 X30 Y10
M2
"""


@pytest.fixture(scope="module")
def case():
    """Pieces, profile and the servo's response (settle tail included) of PROGRAM."""
    run = run_program(interpret_text(PROGRAM), MACHINE)
    pieces, profile, ref = run.plan.pieces, run.plan.profile, run.samples
    servo = MACHINE.servo
    actual = simulate_axes([servo.x, servo.y, servo.z], ref.points_mm, servo.period_s, settle=True)
    n = ref.t_s.size
    held = np.vstack((ref.points_mm, np.repeat(ref.points_mm[-1:], actual.shape[0] - n, 0)))
    lag = np.sqrt(np.sum((held - actual) ** 2, axis=1))
    s = np.concatenate((ref.s_mm, np.full(actual.shape[0] - n, ref.s_mm[-1])))
    return pieces, profile, actual, lag, s


@pytest.mark.parametrize("fill_block", [PathIndex.FILL_BLOCK, 777])
@pytest.mark.parametrize("slab", [distance.SLAB, 997])
@pytest.mark.parametrize("room", [PathIndex.DENSE_POINTS, 5000])
def test_the_kept_polyline_gives_the_same_bits(case, monkeypatch, slab, room, fill_block):
    pieces, profile, actual, lag, s = case
    monkeypatch.setattr(distance, "SLAB", slab)
    monkeypatch.setattr(PathIndex, "FILL_BLOCK", fill_block)
    fresh = windowed_contour_mm(actual, lag, s, pieces, profile)
    index = PathIndex(pieces)
    index.DENSE_POINTS = room  # all of the polyline fits, or only its first pieces
    for _ in range(2):  # filled, then read back (a re-plan)
        np.testing.assert_array_equal(
            windowed_contour_mm(actual, lag, s, pieces, profile, index), fresh
        )
    total = int(polyline.path_counts(pieces).sum())
    assert (index._dense["filled"] == len(pieces)) == (total <= room)
    # Other windows of samples (a re-plan's windows fall elsewhere): the same numbers.
    for lo, hi in ((0, 500), (313, 2900), (1800, actual.shape[0])):
        sl = slice(lo, hi)
        np.testing.assert_array_equal(
            windowed_contour_mm(actual[sl], lag[sl], s[sl], pieces, profile, index), fresh[sl]
        )


def test_windowed_distance_is_the_true_distance_to_the_path(case):
    pieces, profile, actual, lag, s = case
    got = windowed_contour_mm(actual, lag, s, pieces, profile)
    h = 1e-4
    fine = dense_path_mm(pieces, profile, spacing_mm=h)
    true = contour_error_true(actual, fine)
    # The fine polyline's chords are off the curve by κh²/8 at most (doubled: κ of a PH
    # corner is its sampled peak).
    off = 2.0 * float(np.max(pieces.kappa_max_per_mm)) * h * h / 8.0 + 1e-12
    # The check's polyline is off the curve by its chord error CHORD_MM at most (either way:
    # a point inside a curve may be nearer its chord). Near the reference only, it is never
    # below the distance to the whole path, and equal to it wherever the nearest point is
    # in the window: all but the few samples where the tool overshoots a sharp corner
    # towards the next piece (the check measures those against the whole path,
    # PathIndex.distance_mm).
    assert np.all(got >= true - CHORD_MM - off)
    same = np.abs(got - true) <= CHORD_MM + off
    assert np.mean(same) > 0.99
    assert got.max() > 1e-3  # the servo does lag: the check measures something


@pytest.mark.parametrize(
    ("way", "direct_pairs", "band_after", "block_pieces"),
    [
        ("trees", -1, PathIndex.BAND_AFTER, 0),
        ("bands", PathIndex.DIRECT_PAIRS, 0, 0),
        ("direct", PathIndex.DIRECT_PAIRS, 10**9, PathIndex.DIRECT_BLOCK_PIECES),
        ("direct", PathIndex.DIRECT_PAIRS, 10**9, 0),
    ],
)
def test_the_global_distance_is_the_true_distance(
    case, way, direct_pairs, band_after, block_pieces, monkeypatch
):
    """PathIndex.distance_mm, candidates by the k-d trees, through the bands of centres
    sorted along an axis, or by testing every piece's ball (a program's first queries: all
    pairs of a block at once, or a point at a time through its x band, as for programs of
    more than DIRECT_BLOCK_PIECES): against the exact distance to a much denser polyline of
    the path, for tool samples and for points up to 2 mm off the path (upper bounds from
    the windowed distance, or 3 mm)."""
    pieces, profile, actual, lag, s = case
    monkeypatch.setattr(PathIndex, "DIRECT_PAIRS", direct_pairs)
    monkeypatch.setattr(PathIndex, "BAND_AFTER", band_after)
    monkeypatch.setattr(PathIndex, "DIRECT_BLOCK_PIECES", block_pieces)
    rng = np.random.default_rng(7)
    pick = rng.choice(actual.shape[0], 300, replace=False)
    q = np.vstack((actual[pick], actual[pick[:100]] + rng.uniform(-2.0, 2.0, (100, 3))))
    upper = np.concatenate(
        (windowed_contour_mm(actual, lag, s, pieces, profile)[pick], np.full(100, 3.0))
    )
    index = PathIndex(pieces)
    got = index.distance_mm(q, upper)
    taken = "trees" if index._built else "bands" if index._bands else "direct"
    assert taken == way  # the way asked for was taken
    h = 1e-4
    true = contour_error_true(q, dense_path_mm(pieces, profile, spacing_mm=h))
    off = 2.0 * float(np.max(pieces.kappa_max_per_mm)) * h * h / 8.0 + 1e-12
    # The polyline of the check is within CHORD_MM of the curve; never above the bound.
    want = np.minimum(true, upper)
    assert np.all(np.abs(got - want) <= CHORD_MM + off)
    assert np.all(got <= upper)


def _column_of_cuts(count: int) -> str:
    """``count`` 2 mm squares and quarter arcs stacked along Y (one X for all: the bands
    must be made along Y), rapids between them."""
    lines = ["G21 G17 G90 G94", "G64 P0.01", "F1200"]
    for k in range(count):
        y = 3.0 * k
        lines += [
            f"G0 X0 Y{y:.3f}",
            "G0 Z0",
            f"G1 X2 Y{y:.3f}",
            f"G1 X2 Y{y + 2:.3f}",
            f"G3 X0 Y{y + 2:.3f} I-1 J0",
            f"G1 X0 Y{y:.3f}",
            "G0 Z2",
        ]
    return "\n".join(lines + ["M2"])


@pytest.mark.parametrize("band_after", [0, 10**9])
def test_the_bands_find_every_piece_whose_ball_is_near(monkeypatch, band_after):
    """PathIndex.candidates through the bands (or every ball, the reference way) includes
    every piece whose ball (centre (A + B)/2, radius L/2) comes within u of a query point,
    brute force over all pairs, for blocks of points about the path and off it."""
    monkeypatch.setattr(PathIndex, "BAND_AFTER", band_after)
    run = run_program(interpret_text(_column_of_cuts(40)), MACHINE)
    pieces = run.plan.pieces
    centre = 0.5 * (pieces.start_mm + pieces.end_mm).T
    radius = 0.5 * pieces.length_mm
    rng = np.random.default_rng(3)
    index = PathIndex(pieces)
    for _ in range(60):
        base = np.array([rng.uniform(-1.0, 3.0), rng.uniform(-1.0, 120.0), rng.uniform(-1, 3)])
        q = base + rng.uniform(-0.5, 0.5, (int(rng.integers(1, 9)), 3))
        u = rng.uniform(0.0, 1.5, q.shape[0])
        gap = np.linalg.norm(q[:, None, :] - centre[None, :, :], axis=2) - radius[None, :]
        want = np.flatnonzero(np.any(gap <= u[:, None], axis=0))
        got = index.candidates(q, u)
        assert np.all(np.isin(want, got))
        assert np.all(np.diff(got) > 0)  # sorted, once each
    assert (index._bands is not None) == (band_after == 0)
    assert index._built is None


@pytest.mark.parametrize("tree_min", [1, PathIndex.TREE_MIN])
def test_the_trees_find_exactly_the_pieces_whose_ball_is_near(monkeypatch, tree_min):
    """PathIndex.candidates through the k-d trees (one query about each block of points,
    then every ball tested against every point) is exactly the set of pieces whose ball
    (centre (A + B)/2, radius L/2) comes within u of some query point, brute force over all
    pairs, sorted and once each, for blocks about the path and off it; and the distances
    it gives are those of the direct way (every ball tested), bit for bit."""
    monkeypatch.setattr(PathIndex, "TREE_MIN", tree_min)
    run = run_program(interpret_text(_column_of_cuts(40)), MACHINE)
    pieces = run.plan.pieces
    centre = 0.5 * (pieces.start_mm + pieces.end_mm).T
    radius = 0.5 * pieces.length_mm
    rng = np.random.default_rng(5)
    monkeypatch.setattr(PathIndex, "DIRECT_PAIRS", -1)  # the trees from the first query
    trees = PathIndex(pieces)
    blocks = []
    for _ in range(80):
        base = np.array([rng.uniform(-1.0, 3.0), rng.uniform(-1.0, 120.0), rng.uniform(-1, 3)])
        q = base + rng.uniform(-0.5, 0.5, (int(rng.integers(1, 40)), 3))
        u = rng.uniform(0.0, 1.5, q.shape[0])
        gap = np.linalg.norm(q[:, None, :] - centre[None, :, :], axis=2) - radius[None, :]
        want = np.flatnonzero(np.any(gap <= u[:, None], axis=0))
        assert np.array_equal(trees.candidates(q, u), want)
        blocks.append((q, u))
    assert trees._built is not None
    monkeypatch.setattr(PathIndex, "DIRECT_PAIRS", 10**12)
    monkeypatch.setattr(PathIndex, "BAND_AFTER", 10**12)
    direct = PathIndex(pieces)
    for q, u in blocks:
        assert np.array_equal(trees.distance_mm(q, u), direct.distance_mm(q, u))
    assert direct._built is None and direct._bands is None
    # Lines' ends kept once (PathIndex._line_ends) or placed for each block: the same bits.
    monkeypatch.setattr(PathIndex, "LINE_ENDS_PIECES", 0)
    placed = PathIndex(pieces)
    for q, u in blocks:
        assert np.array_equal(placed.distance_mm(q, u), direct.distance_mm(q, u))
    assert placed._lines is None and direct._lines is not None


def _plans_by(text: str, way: str, monkeypatch):
    """(plan, check) of ``text`` with the check's refinement finding its candidates by the
    k-d trees from the first query (every radius group a tree), or by testing every ball."""
    huge = 10**15
    trees = way == "trees"
    monkeypatch.setattr(PathIndex, "DIRECT_PAIRS", -1 if trees else huge)
    monkeypatch.setattr(PathIndex, "BAND_AFTER", PathIndex.BAND_AFTER if trees else huge)
    monkeypatch.setattr(PathIndex, "DIRECT_BLOCK_PIECES", huge)
    monkeypatch.setattr(PathIndex, "TREE_MIN", 1 if trees else PathIndex.TREE_MIN)
    asked = []  # per candidates query: whether the trees answered it
    real = PathIndex.candidates

    def counting(self, q, upper_mm):
        found = real(self, q, upper_mm)
        asked.append(self._built is not None)
        return found

    monkeypatch.setattr(PathIndex, "candidates", counting)
    plan, chk = plan_checked(interpret_text(text), MACHINE, keep_reference=False)
    assert all(asked) if trees else not any(asked)
    return plan, chk, len(asked)


def _cam_heads() -> list:
    cam = CORPUS / "cam"
    return sorted(cam.glob("*.nc")) if cam.is_dir() else []


def _assert_same_plans(text: str, monkeypatch) -> int:
    (plan, chk, n), (ref, ref_chk, _) = (
        _plans_by(text, w, monkeypatch) for w in ("trees", "direct")
    )
    assert plan.iterations == ref.iterations and plan.cycle_time_s == ref.cycle_time_s
    assert_same_levers(plan, ref)
    np.testing.assert_array_equal(plan.profile.phase_start_time_s, ref.profile.phase_start_time_s)
    for f in ("count", "index", "err_mm", "tau_s", "run_piece", "run_start", "restart_count"):
        np.testing.assert_array_equal(getattr(chk.overs, f), getattr(ref_chk.overs, f), f)
    assert chk.contour_stats() == ref_chk.contour_stats()  # the rms too: the same distances
    return n


def test_plans_alike_with_the_trees_and_every_ball(monkeypatch):
    """Forty stacked cuts 1 mm apart (the refinement finds the neighbouring cut): the plan
    and its check with the trees' candidates equal those of testing every ball."""
    assert _assert_same_plans(_column_of_cuts(40), monkeypatch) > 0  # the refinement ran


@pytest.mark.skipif(not _cam_heads(), reason=f"no corpus CAM programs under {CORPUS}/cam")
@pytest.mark.parametrize("path", _cam_heads(), ids=lambda p: p.name)
def test_corpus_cam_plans_alike_with_the_trees_and_every_ball(path, monkeypatch):
    """The first 400 lines of each corpus CAM program (then M2), as above."""
    _assert_same_plans("\n".join(path.read_text().splitlines()[:400]) + "\nM2\n", monkeypatch)


def _chord_errors_mm(pieces) -> np.ndarray:
    """Distance [mm] from the true path to the check's dense polyline: at 1/4, 1/2 and 3/4
    of every chord's arc length, the exact point of its piece to the chord (the polyline's
    points are exact, so the error is inside the chords)."""
    counts = polyline.path_counts(pieces)
    piece = np.repeat(np.arange(len(pieces)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    local = (np.arange(piece.size) - first) / np.repeat(counts - 1, counts)
    local = local * pieces.length_mm[piece]
    ends = pieces.path.points(piece, local)[0]
    same = np.flatnonzero(piece[1:] == piece[:-1])
    a, b = ends[same], ends[same + 1]
    worst = np.zeros(same.size)
    for f in (0.25, 0.5, 0.75):
        q = pieces.path.points(piece[same], (1 - f) * local[same] + f * local[same + 1])[0]
        d = b - a
        t = np.clip(np.einsum("ij,ij->i", q - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
        worst = np.maximum(worst, np.linalg.norm(q - (a + t[:, None] * d), axis=1))
    return worst


@pytest.mark.parametrize("name", ["naca2415.nc", "butterfly.nc", "corners.nc", "naca2415_c40.nc"])
def test_the_dense_polyline_is_within_its_chord_error(name):
    """CHORD_MM (0.01 µm) holds on NURBS cells, PH corners and arcs of the repository's
    programs (the chords follow the curvature; MAX_SPACING_MM only caps them)."""
    from pathlib import Path

    from nurbscnc.plan.program_pieces import segment_pieces

    text = (Path(__file__).resolve().parents[1] / "programs" / name).read_text()
    pieces = segment_pieces(interpret_text(text).segments, MACHINE)
    err = _chord_errors_mm(pieces)
    assert err.size > 500
    assert err.max() <= CHORD_MM * (1.0 + 1e-6)


def test_a_near_cusp_piece_has_a_bounded_polyline():
    """The fuzzer's control polygon folding back by 1e-10 mm: κ 3e10 /mm on a NURBS cell
    asked the chord rule for 2e8 points (1.6 GB, exit 1); a piece gets at most
    MAX_PIECE_POINTS, and the rest of the polyline is as the rule asks."""
    from nurbscnc.plan.program_pieces import segment_pieces

    text = (
        "G21 G17 F1000\nG6.2 P4 K0 X0 Y0 R1\nK0 X1 Y1 R1\nK0 X0 Y1 R1\n"
        "K0 X1 Y0.0000000001 R1\nK1\nK1\nK1\nK1\nM2\n"
    )
    pieces = segment_pieces(interpret_text(text).segments, MACHINE)
    counts = polyline.path_counts(pieces)
    assert pieces.kappa_max_per_mm.max() > 1e9
    assert counts.max() == polyline.MAX_PIECE_POINTS
    kappa = 2.0 * pieces.kappa_max_per_mm  # NURBS cells
    h = np.minimum(polyline.MAX_SPACING_MM, np.sqrt(8.0 * CHORD_MM / kappa))
    free = counts < polyline.MAX_PIECE_POINTS
    assert np.all(counts[free] == np.maximum(np.ceil(pieces.length_mm[free] / h[free]) + 1, 3))


def test_passes_at_the_same_place_are_measured_once_with_the_same_result(monkeypatch):
    """programs/naca2415.nc's airfoil cut five times at the same place (multi-pass
    engraving, spring passes): the check measures a point's distance to the coincident
    passes once (PathIndex._distinct: the polylines are the same numbers), and the plan,
    its re-plans and its contour statistics are the very ones of measuring every pass."""
    from pathlib import Path

    from nurbscnc.machine.profile import load_machine
    from nurbscnc.pipeline import run_program
    from nurbscnc.program.interpret import interpret_text

    lines = (Path(__file__).resolve().parents[1] / "programs" / "naca2415.nc").read_text()
    body = [ln for ln in lines.splitlines()[2:] if ln.strip() and not ln.startswith("M2")]
    prog = interpret_text("G21 G17 G90 G94\n" + "\n".join(body * 5) + "\nM2\n")
    machine = load_machine()
    calls = []
    real = distance.PathIndex._distinct

    def counting(self, cand):
        out = real(self, cand)
        calls.append((cand.size, out.size))
        return out

    monkeypatch.setattr(distance.PathIndex, "_distinct", counting)
    monkeypatch.setattr(distance.PathIndex, "DISTINCT_MIN", 8)  # every block of 8 or more
    once = run_program(prog, machine)
    assert any(after * 4 < before for before, after in calls)  # passes were merged
    monkeypatch.setattr(distance.PathIndex, "DISTINCT_MIN", 1 << 60)
    every = run_program(prog, machine)
    assert once.cycle_time_s == every.cycle_time_s
    assert once.plan.iterations == every.plan.iterations
    assert once.check.contour_stats() == every.check.contour_stats()
    assert once.check.overs.worst_mm == every.check.overs.worst_mm


@pytest.mark.parametrize("name", ["naca2415.nc", "corners.nc"])
def test_chord_counts_without_a_cap_are_the_refinement_rule(name):
    """``chord_counts`` without ``max_points`` (the pre-compensation's polylines: chords of
    sagitta ≤ 1e-7 mm, at most 0.01 mm) is the rule ⌈L/h⌉ + 1 ≥ 3 on every piece, 2 on lines,
    the same integers; with the cap it is :func:`path_counts`."""
    from pathlib import Path

    from nurbscnc.geometry.path import Kind
    from nurbscnc.plan.program_pieces import segment_pieces

    text = (Path(__file__).resolve().parents[1] / "programs" / name).read_text()
    pieces = segment_pieces(interpret_text(text).segments, MACHINE)
    kind, length = pieces.kind, pieces.length_mm
    kappa = np.where(kind == Kind.NURBS, 2.0, 1.0) * np.abs(pieces.kappa_max_per_mm)
    with np.errstate(divide="ignore"):
        h = np.minimum(0.01, np.sqrt(8.0 * 1e-7 / kappa))
    want = np.maximum(np.ceil(length / h).astype(np.int64) + 1, 3)
    want = np.where((kind == Kind.LINE) | (length == 0.0), 2, want)
    got = polyline.chord_counts(kind, length, pieces.kappa_max_per_mm, 1e-7, 0.01)
    assert got.dtype == want.dtype and np.array_equal(got, want)
    capped = polyline.chord_counts(
        kind,
        length,
        pieces.kappa_max_per_mm,
        CHORD_MM,
        polyline.MAX_SPACING_MM,
        polyline.MAX_PIECE_POINTS,
    )
    assert np.array_equal(capped, polyline.path_counts(pieces))
