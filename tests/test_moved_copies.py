"""A NURBS block that repeats an earlier one at another place (a part cut again elsewhere)
is planned from that one's pieces moved (plan/moved_copies.py ``Repeats``), and the kinematic
lower bound grids it once (plan/lowerbound.py ``_moved_copies``): the same pieces and bound
as planning the copy on its own, to rounding; a curve that differs is planned afresh."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan import lowerbound
from nurbscnc.plan.lowerbound import program_lower_bound_s
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.program.interpret import interpret_text

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from scale_bench import airfoils_program  # noqa: E402

COLUMNS = (
    "length_mm",
    "v_cap_mm_s",
    "kappa_max_per_mm",
    "kind",
    "rapid",
    "stop_after",
    "pass_after",
    "blend_mm",
)


def _nurbs_rows(pieces, segment: int) -> np.ndarray:
    return np.flatnonzero(np.asarray(pieces.segment) == segment)


def _copy_alone(text: str, which: int) -> str:
    """The program ``text`` (airfoils_program) with only its airfoil ``which`` (0-based)."""
    lines = text.splitlines()
    starts = [i for i, ln in enumerate(lines) if ln.startswith("G0")] + [len(lines) - 1]
    return "\n".join(lines[:3] + lines[starts[which] : starts[which + 1]] + ["M2", ""])


def _sample_points(pieces, rows: np.ndarray) -> np.ndarray:
    frac = np.linspace(0.0, 1.0, 9)
    idx = np.repeat(rows, frac.size)
    return pieces.path.points(idx, np.tile(frac, rows.size) * pieces.length_mm[idx])[0]


def _assert_same_pieces(ours, mine: np.ndarray, theirs_list, theirs: np.ndarray) -> None:
    """Rows ``mine`` of PieceList ``ours`` and rows ``theirs`` of ``theirs_list`` hold the
    same cells, corners, caps and lengths (to 1e-10 relative: a curve's derivatives far from
    the origin carry 1e-11 relative rounding, so do the caps they set) and the same points
    along every piece (to 1e-11 mm)."""
    for name in COLUMNS:
        np.testing.assert_allclose(
            np.asarray(getattr(ours, name))[mine].astype(float),
            np.asarray(getattr(theirs_list, name))[theirs].astype(float),
            rtol=1e-10,
            atol=1e-12,
            err_msg=name,
        )
    np.testing.assert_allclose(
        _sample_points(ours, mine), _sample_points(theirs_list, theirs), rtol=0, atol=1e-11
    )


def test_a_moved_airfoil_gets_the_pieces_it_would_get_alone():
    machine = load_machine()
    text = airfoils_program(count=3, chord_mm=20.0, pitch_mm=35.0)
    whole = segment_pieces(interpret_text(text).segments, machine)
    nurbs_segments = sorted({int(s) for s, k in zip(whole.segment, whole.kind) if k == 4})
    assert len(nurbs_segments) == 3
    for which in (1, 2):
        alone = segment_pieces(interpret_text(_copy_alone(text, which)).segments, machine)
        mine = _nurbs_rows(whole, nurbs_segments[which])
        theirs = _nurbs_rows(alone, int(alone.segment[np.asarray(alone.kind) == 4][0]))
        assert mine.size == theirs.size > 100
        # (NURBS cells on the copy's own curve, PH corners moved)
        _assert_same_pieces(whole, mine, alone, theirs)
        for name in ("start_mm", "end_mm", "tangent_start", "tangent_end"):
            np.testing.assert_allclose(
                getattr(whole, name)[:, mine], getattr(alone, name)[:, theirs], rtol=0, atol=1e-11
            )
        assert np.array_equal(
            whole.line[mine], alone.line[theirs] - alone.line[theirs][0] + whole.line[mine][0]
        )


def test_translation_is_found_to_rounding_only():
    rng = np.random.default_rng(5)
    ctrl = rng.uniform(-50.0, 50.0, (12, 3))
    knots = np.r_[[0.0] * 4, np.linspace(0.1, 0.9, 8), [1.0] * 4]
    weights = rng.uniform(0.5, 2.0, 12)
    base = NurbsCurve(3, knots, ctrl, weights)
    delta = np.array([70.0, -3.25, 0.5])
    moved = NurbsCurve(3, knots, ctrl + delta, weights)
    np.testing.assert_allclose(moved.translation_from(base), delta, rtol=0, atol=1e-12)
    assert moved.shape_key() == base.shape_key()
    # One control point 1e-9 mm off, a weight or a knot changed: not a copy.
    bent = ctrl + delta
    bent[5, 1] += 1e-9
    assert NurbsCurve(3, knots, bent, weights).translation_from(base) is None
    w2 = weights.copy()
    w2[3] *= 1.0 + 1e-15
    assert NurbsCurve(3, knots, ctrl + delta, w2).translation_from(base) is None
    k2 = knots.copy()
    k2[6] += 1e-12
    assert NurbsCurve(3, k2, ctrl + delta, weights).translation_from(base) is None
    # A copy shares its tables: the same arc lengths, its own points.
    moved.sharing_tables(base)
    u = np.linspace(0.0, 1.0, 41)
    np.testing.assert_allclose(moved.arc_length(u), base.arc_length(u), rtol=0, atol=1e-12)
    fresh = NurbsCurve(3, knots, ctrl + delta, weights)
    s = np.linspace(0.0, base.length_mm, 101)
    np.testing.assert_allclose(
        moved.points_at_length(s)[0], fresh.points_at_length(s)[0], rtol=0, atol=1e-9
    )


def test_a_bent_copy_is_planned_afresh():
    """The third airfoil with one control point 1 µm off: planned on its own (its cells
    differ from the first's where the curvature does)."""
    machine = load_machine()
    text = airfoils_program(count=3, chord_mm=20.0, pitch_mm=35.0)
    lines = text.splitlines()
    third = [i for i, ln in enumerate(lines) if ln.startswith("G0")][2]
    words = lines[third + 5].split()
    words = [f"Y{float(w[1:]) + 1e-3:.6f}" if w.startswith("Y") else w for w in words]
    lines[third + 5] = " ".join(words)
    whole = segment_pieces(interpret_text("\n".join(lines) + "\n").segments, machine)
    alone = segment_pieces(
        interpret_text(_copy_alone("\n".join(lines) + "\n", 2)).segments, machine
    )
    segs = sorted({int(s) for s, k in zip(whole.segment, whole.kind) if k == 4})
    mine = _nurbs_rows(whole, segs[2])
    theirs = _nurbs_rows(alone, int(alone.segment[np.asarray(alone.kind) == 4][0]))
    np.testing.assert_allclose(whole.v_cap_mm_s[mine], alone.v_cap_mm_s[theirs], rtol=1e-12)
    first = _nurbs_rows(whole, segs[0])
    assert not np.allclose(
        whole.kappa_max_per_mm[mine], whole.kappa_max_per_mm[first], rtol=1e-6, atol=0
    )


def test_the_lower_bound_grids_a_copy_once_with_the_same_bound(monkeypatch):
    machine = load_machine()
    prog = interpret_text(airfoils_program(count=4, chord_mm=20.0, pitch_mm=35.0))
    calls = []
    real = lowerbound._sample_rows

    def counting(path, rows, *args):
        calls.append(int(np.count_nonzero(np.take(path.kind, rows) == 4)))
        return real(path, rows, *args)

    monkeypatch.setattr(lowerbound, "_sample_rows", counting)
    bound = program_lower_bound_s(prog.segments, machine)
    assert calls == [1]  # four airfoils, one grid
    # Each curve gridded on its own (no copies found): the same bound to rounding.
    monkeypatch.setattr(
        lowerbound,
        "_moved_copies",
        lambda path, rows, top: (np.arange(rows.size), np.arange(rows.size)),
    )
    calls.clear()
    alone = program_lower_bound_s(prog.segments, machine)
    assert calls == [4]
    assert bound == pytest.approx(alone, rel=1e-12)


def _with_before_copy(text: str, which: int, inserted: str) -> str:
    """``text`` (airfoils_program) with the line ``inserted`` before airfoil ``which``."""
    lines = text.splitlines()
    at = [i for i, ln in enumerate(lines) if ln.startswith("G0")][which]
    return "\n".join(lines[:at] + [inserted] + lines[at:]) + "\n"


@pytest.mark.parametrize("inserted", ["F1200", "G64 P0.05"])
def test_a_copy_at_another_feed_or_blend_is_its_own(inserted):
    """The second airfoil at another F (or G64 P) gets its own caps: those it gets alone."""
    machine = load_machine()
    text = _with_before_copy(airfoils_program(count=2, chord_mm=20.0, pitch_mm=35.0), 1, inserted)
    whole = segment_pieces(interpret_text(text).segments, machine)
    segs = sorted({int(s) for s, k in zip(whole.segment, whole.kind) if k == 4})
    lines = text.splitlines()
    at = [i for i, ln in enumerate(lines) if ln.startswith("G0")][1]
    alone_text = "\n".join(lines[:3] + [inserted] + lines[at:]) + "\n"
    alone = segment_pieces(interpret_text(alone_text).segments, machine)
    mine = _nurbs_rows(whole, segs[1])
    theirs = _nurbs_rows(alone, int(alone.segment[np.asarray(alone.kind) == 4][0]))
    np.testing.assert_allclose(whole.v_cap_mm_s[mine], alone.v_cap_mm_s[theirs], rtol=1e-10)
    np.testing.assert_allclose(whole.blend_mm[mine], alone.blend_mm[theirs], rtol=0, atol=0)
    first = _nurbs_rows(whole, segs[0])
    if inserted.startswith("F"):  # the feed changed the cells or caps a copy would have kept
        assert mine.size != first.size or not np.allclose(
            whole.v_cap_mm_s[mine], whole.v_cap_mm_s[first]
        )
    else:  # the blend tolerance is the copy's own
        assert whole.blend_mm[mine][0] == 0.05 != whole.blend_mm[first][0]


def _curve_of(pieces, segment: int):
    row = int(_nurbs_rows(pieces, segment)[0])
    return pieces.objects[row][0]


def test_a_copy_one_tenth_of_a_nanometre_off_is_planned_afresh():
    """Control points 1e-10 mm off (the same shape key, beyond 8 ulps): not a copy. A
    true copy shares its original's arc-length tables; this one builds its own."""
    machine = load_machine()
    text = airfoils_program(count=3, chord_mm=20.0, pitch_mm=35.0)
    segments = list(interpret_text(text).segments)
    nurbs = [i for i, s in enumerate(segments) if s.kind == "nurbs"]
    bent = np.array(segments[nurbs[2]].control_points_mm)
    bent[4, 1] += 1e-10
    segments[nurbs[2]] = dataclasses.replace(segments[nurbs[2]], control_points_mm=bent)
    pieces = segment_pieces(segments, machine)
    first, copy, other = (_curve_of(pieces, i) for i in nurbs)
    assert copy.translation_from(first) is not None and other.translation_from(first) is None
    assert copy.shape_key() == other.shape_key() == first.shape_key()
    assert copy.__dict__.get("arc_table") is first.arc_table  # taken
    assert other.arc_table is not first.arc_table  # built for itself


def _pocket_passes(depths_mm) -> str:
    """A circle of 64 chords (r = 4 mm) cut at each depth of ``depths_mm``: plunge, the
    chords, lift (a pocket's passes, as PyCut writes them)."""
    angle = np.linspace(0.0, 2.0 * np.pi, 65)
    ring = [f"G1 X{4.0 * np.cos(a):.4f} Y{4.0 * np.sin(a):.4f}" for a in angle[1:]]
    out = ["G21 G17 G90 G64 P0.02", "G0 Z2", "G0 X4 Y0"]
    for z in depths_mm:
        out += [f"G1 Z{z:.3f} F300", "F1200", *ring, "G0 Z2", "G0 X4 Y0"]
    return "\n".join([*out, "M2", ""])


def test_a_pocket_pass_one_depth_lower_gets_the_smoothed_pieces_it_would_get_alone():
    """Each pass's chords become one smoothed spline; the passes below the first are moved
    copies of it: planned from its pieces (sharing its arc-length tables), with the cells,
    caps and lengths of the pass planned alone and each piece's own source line."""
    machine = load_machine()
    depths = (-0.1, -0.2, -0.3)
    whole = segment_pieces(interpret_text(_pocket_passes(depths)).segments, machine)
    nurbs = sorted({int(s) for s, k in zip(whole.segment, whole.kind) if k == 4})
    assert len(nurbs) == len(depths)  # one spline a pass
    cells = np.flatnonzero(np.asarray(whole.kind) == 4)
    curves = {id(g): g for g in (whole.objects[int(r)][0] for r in cells) if g.degree == 3}
    assert len(curves) == len(depths)  # the splines (the plunges' space blends: quintics)
    tables = {id(c.__dict__.get("arc_table")) for c in curves.values()}
    assert len(tables) == 1  # built once, for the first pass
    for which, depth in enumerate(depths):
        alone = segment_pieces(interpret_text(_pocket_passes([depth])).segments, machine)
        mine = _nurbs_rows(whole, nurbs[which])
        theirs = _nurbs_rows(alone, int(alone.segment[np.asarray(alone.kind) == 4][0]))
        assert mine.size == theirs.size > 20
        _assert_same_pieces(whole, mine, alone, theirs)
        # The pass alone starts at line 4 (plunge), the whole program's pass k 68 lines later.
        assert np.array_equal(whole.line[mine], alone.line[theirs] + 68 * which)


def test_the_plunges_space_blends_one_depth_lower_share_the_first_ones_tables(monkeypatch):
    """The 3-D blend from each pass's plunge into its ring is the first pass's moved down:
    they share one arc-length table (built once), and the pieces and points along them are
    those of every blend with its own tables (to rounding: a table of the copy's own would
    be built on control points moved by 0.1 mm, equal to 1e-12 relative)."""
    from nurbscnc.plan import blends as blends_module

    machine = load_machine()
    segments = interpret_text(_pocket_passes((-0.1, -0.2, -0.3))).segments
    shared = segment_pieces(segments, machine)
    quintics = {
        id(g): g for g, *_ in shared.objects.values() if isinstance(g, NurbsCurve) and g.degree == 5
    }
    assert len(quintics) == 3  # one space blend a plunge
    assert len({id(g.__dict__.get("arc_table")) for g in quintics.values()}) == 1
    monkeypatch.setattr(blends_module, "_share_moved_tables", lambda blends: None)
    own = segment_pieces(segments, machine)
    theirs = {id(g): g for g, *_ in own.objects.values() if getattr(g, "degree", 0) == 5}
    assert len({id(g.arc_table) for g in theirs.values()}) == 3  # each its own without
    rows = np.arange(len(shared))
    _assert_same_pieces(shared, rows, own, rows)
