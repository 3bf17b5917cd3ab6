"""The ``check`` summary over the segments' columns equals the per-segment definition.

:func:`nurbscnc.plan.report.program_summary` works on whole arrays (issue 14). The reference
here is the straightforward definition, one segment at a time (the code it replaced): every
number must be the same float — lengths, running totals, the bounding box (down to −0.0
against 0.0), the feed range — and the JSON the same text, key order included.
"""

from __future__ import annotations

import json
import math
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbscnc.geometry.nurbs import NurbsCurve
from nurbscnc.geometry.paths import geometry_of
from nurbscnc.geometry.segments import Line, Program, Rotate
from nurbscnc.plan.report import program_summary
from nurbscnc.program.columns import KINDS, segment_columns
from nurbscnc.program.interpret import interpret_text


def reference_summary(prog) -> dict:
    """The summary, one segment at a time."""
    segments, points, feeds = [], [np.asarray(prog.start_mm, dtype=float)], []
    feed_len = rapid_len = 0.0
    for seg in prog.segments:
        moving = seg.kind not in ("dwell", "pause")
        length = 0.0
        if moving:
            nurbs = seg.kind == "nurbs"
            length = float(NurbsCurve.from_segment(seg).length_mm if nurbs else seg.length_mm)
        entry = {"kind": seg.kind, "line": seg.line, "length_mm": length}
        if seg.kind == "nurbs":
            entry.update(
                degree=seg.degree,
                control_points=len(seg.control_points_mm),
                knots=len(seg.knots),
                plane=seg.plane,
            )
            points.append(np.asarray(seg.control_points_mm))
        elif moving:
            points.append(np.asarray([seg.start_mm, seg.end_mm], dtype=float))
        if seg.kind == "arc":
            geom = geometry_of(seg)
            points.append(geom.point(np.linspace(geom.u_start, geom.u_end, 65)))
        if seg.kind == "rapid":
            rapid_len += length
        elif moving and seg.kind != "rotate":  # a rotary-only move: X Y Z at rest
            feed_len += length
            feeds.append(seg.feed_mm_s)
        segments.append(entry)
    allpts = np.vstack([np.reshape(p, (-1, 3)) for p in points])
    return {
        "ok": True,
        "program": prog.name,
        "blocks": prog.blocks,
        "segments": segments,
        "counts": dict(Counter(s["kind"] for s in segments)),
        "length_mm": feed_len,
        "rapid_length_mm": rapid_len,
        "bounding_box_mm": {"min": allpts.min(axis=0).tolist(), "max": allpts.max(axis=0).tolist()},
        "feed_range_mm_s": {
            "min": min(feeds) if feeds else None,
            "max": max(feeds) if feeds else None,
        },
        "notes": [{"line": n.line, "message": n.message} for n in prog.notes],
        "errors": [],
    }


# Every kind of segment: rapids, lines through −0 and 0, circular arcs in the three planes,
# a helix, a full turn, a spiral (end radius off by 0.5 µm), a dwell, pauses, NURBS (G5.2)
# and a cubic spline (G5).
POOL_PROGRAM = """G21 G90 G94 G17
G0 X-0 Y0 Z5
G1 Z-0 F300
G1 X10 Y-0 F1200
G2 X20 Y0 I5 J0
G3 X20 Y10 Z-2 I0 J5 F900
G2 X20 Y10 I-3 J0 P2
G4 P0.5
M0
G18 G2 X30 I5 K0
G19 G3 Y20 J5 K0
G17 G3 X40.0000005 Y20 I5 J0
G5.2 X40 Y20 P1 L3
X45 Y30 P2
X50 Y20 P1
X55 Y25 P1
G5.3
G5 X60 Y30 I2 J2 P3 Q-1
M1
G0 X0 Y0 Z10
M2
"""


@pytest.fixture(scope="module")
def pool():
    # A rotary-only move as the interpreter makes it for "G1 A90 F600" at X0 Y0 Z10.
    rotate = Rotate((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), (90.0, 0.0, 0.0), 10.0, 99)
    segments = (*interpret_text(POOL_PROGRAM).segments, rotate)
    assert {s.kind for s in segments} == set(KINDS)
    return segments


COORD = st.one_of(st.sampled_from([0.0, -0.0, 1.5, -2.25, 1e-9, -1e-9]), st.floats(-1000.0, 1000.0))


def _lines():
    point = st.tuples(COORD, COORD, COORD)
    return st.builds(
        Line,
        point,
        point,
        st.sampled_from([0.0, 5.0, 20.0, 0.123]),
        st.integers(1, 1000),
        st.booleans(),
    )


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.one_of(st.integers(0, 40), _lines()), max_size=120), st.tuples(COORD, COORD, COORD)
)
def test_summary_equals_the_per_segment_definition(pool, picks, start):
    segments = tuple(pool[p % len(pool)] if isinstance(p, int) else p for p in picks)
    prog = Program(segments=segments, start_mm=np.array(start), blocks=len(segments))
    got, want = program_summary(prog), reference_summary(prog)
    assert json.dumps(got) == json.dumps(want)
    short = program_summary(prog, per_segment=False)  # the text report's: NURBS entries only
    assert short == {**want, "segments": [e for e in want["segments"] if e["kind"] == "nurbs"]}
    for box in ("min", "max"):  # −0.0 and 0.0 print differently, but check the sign bits too
        assert [math.copysign(1, v) for v in got["bounding_box_mm"][box]] == [
            math.copysign(1, v) for v in want["bounding_box_mm"][box]
        ]


def test_summary_of_a_long_program_equals_the_definition(pool):
    """Thousands of segments: running totals that a pairwise sum would round otherwise."""
    rng = np.random.default_rng(14)
    ends = [tuple(p) for p in rng.uniform(-500.0, 500.0, (3000, 3)).tolist()]
    lines = [
        Line(a, b, 10.0 + k % 7, k + 1, k % 5 == 0)
        for k, (a, b) in enumerate(zip(ends[:-1], ends[1:]))
    ]
    segments = tuple(lines[:1000]) + tuple(pool) + tuple(lines[1000:])
    prog = Program(segments=segments, start_mm=np.zeros(3), blocks=len(segments))
    assert json.dumps(program_summary(prog)) == json.dumps(reference_summary(prog))


def test_columns_are_the_segments_attributes(pool):
    cols = segment_columns(pool)
    assert cols.names.tolist() == [s.kind for s in pool]
    assert cols.lines.tolist() == [s.line for s in pool]
    assert cols.feeds_mm_s.tolist() == [s.feed_mm_s for s in pool]
    for got, name in ((cols.starts_mm, "start_mm"), (cols.ends_mm, "end_mm")):
        want = np.array([np.asarray(getattr(s, name), dtype=float) for s in pool])
        assert got.tobytes() == want.tobytes()


def test_columns_of_no_segments():
    cols = segment_columns(())
    assert cols.starts_mm.shape == (0, 3) and cols.kind.size == 0


def test_summary_json_in_pieces_is_json_dumps_text():
    """The summary's JSON, its large mappings encoded in pieces (cli ``_json_in_pieces``),
    is json.dumps's text, byte for byte."""
    from nurbscnc.app.summary import JSON_PIECE, summary_json

    rng = np.random.default_rng(7)
    times = {str(i): float(x) for i, x in enumerate(rng.exponential(0.01, 3 * JSON_PIECE + 5))}
    summary = {
        "ok": True,
        "program": '@@segment_times_s@@ "quoted" \\ é',
        "segment_times_s": times,
        "small": {"a": 1.5, "b": [1, None]},
        "inf": float("inf"),
        "exact": {str(i): 0.1 for i in range(JSON_PIECE)},
        "list": list(range(10)),
        "empty": {},
    }
    assert summary_json(summary) == json.dumps(summary)
    assert summary_json({}) == json.dumps({})
    odd = {1: "int key", None: times, "x": {str(i): i for i in range(JSON_PIECE + 1)}}
    assert summary_json(odd) == json.dumps(odd)
