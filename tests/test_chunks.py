"""Output in chunks (issue 14): the plan's samples window by window, equal to the whole arrays.

References: the whole-array sampler of the same plan (:func:`sample_plan`, one call over all
rows, as every command used before), and the writers' whole-array output (the files must be
byte-identical). Window sizes 1 (every join), 7 (joins inside runs of NURBS samples, inside
PH corners and dwells) and 4096 (a window holds several pieces).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.interpolate.sample import sample_chunks, sample_plan
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan.lookahead import plan_program
from nurbscnc.plan.timing import sample_count
from nurbscnc.program.interpret import interpret_text

ROOT = Path(__file__).resolve().parents[1]
MACHINE = load_machine()
PERIOD = MACHINE.servo.period_s
WINDOWS = (1, 7, 4096)
FIELDS = ("t_s", "points_mm", "s_mm", "v_mm_s", "a_mm_s2", "piece", "line", "param")

#: Lines, an arc, a helix, a dwell inside the motion and one after the end, a rapid.
MIXED = """G21 G17 G90 G94
G0 X0 Y0 Z0
G1 X4 F1200
G2 X8 Y0 I2 J0
G4 P0.05
G3 X8 Y4 Z1 I0 J2
G1 X0 Y4 F600
G4 P0.02
M2
"""


def _plan(name: str):
    text = (ROOT / "programs" / name).read_text() if name.endswith(".nc") else name
    return plan_program(interpret_text(text), MACHINE)


@pytest.fixture(scope="module")
def plans():
    return {"naca2415": _plan("naca2415.nc"), "mixed": _plan(MIXED)}


def _joined(chunks, field):
    return np.concatenate([getattr(c, field) for c in chunks])


@pytest.mark.parametrize("interpolator", ["exact", "taylor"])
@pytest.mark.parametrize("window", WINDOWS)
@pytest.mark.parametrize("name", ["naca2415", "mixed"])
def test_chunks_are_the_rows_of_the_whole_samples(plans, name, window, interpolator):
    """Every field of the windows, joined, is bit-identical to the whole samples: the exact
    placement per row, and the Taylor recurrence carried across joins (its runs of NURBS
    samples cross windows of 1 and 7 rows)."""
    plan = plans[name]
    whole = sample_plan(plan.pieces, plan.profile, PERIOD, interpolator)
    chunks = list(sample_chunks(plan.pieces, plan.profile, PERIOD, interpolator, window))
    n = sample_count(plan.pieces, plan.profile, PERIOD)
    assert [c.t_s.size for c in chunks] == [min(window, n - k) for k in range(0, n, window)]
    assert all(c.interpolator == interpolator for c in chunks)
    for field in FIELDS:
        np.testing.assert_array_equal(_joined(chunks, field), getattr(whole, field), err_msg=field)


def test_taylor_windows_continue_the_recurrence(plans):
    """The Taylor points differ from the exact ones inside a run (so a window restarting its
    run at the exact u would show): at window 7 the joins fall inside runs, and the rows
    right after each join still equal the whole recurrence, not the exact placement."""
    plan = plans["naca2415"]
    taylor = sample_plan(plan.pieces, plan.profile, PERIOD, "taylor")
    exact = sample_plan(plan.pieces, plan.profile, PERIOD, "exact")
    firsts = np.arange(7, taylor.t_s.size, 7)
    moved = firsts[np.any(taylor.points_mm[firsts] != exact.points_mm[firsts], axis=1)]
    assert moved.size > 20  # many joins land where Taylor and exact differ
    chunks = list(sample_chunks(plan.pieces, plan.profile, PERIOD, "taylor", 7))
    np.testing.assert_array_equal(_joined(chunks, "points_mm")[moved], taylor.points_mm[moved])


def test_window_must_be_positive(plans):
    plan = plans["mixed"]
    with pytest.raises(ValueError, match="chunk"):
        next(sample_chunks(plan.pieces, plan.profile, PERIOD, "exact", 0))


# ------------------------------------------------------------------------------- writers


@pytest.fixture()
def frozen_clock(monkeypatch):
    """zipfile stamps each member with the current time: one fixed second for both writes."""
    import time

    monkeypatch.setattr(time, "time", lambda: 1_700_000_000.0)


def _today_csv(samples) -> bytes:
    """The CSV as the whole-array writer made it: the header, then np.savetxt of all rows."""
    import io

    from nurbscnc.output.files import POINT_COLUMNS, POINT_FORMATS, point_columns

    buf = io.StringIO()
    table = np.column_stack([np.asarray(c, dtype=float) for c in point_columns(samples)])
    np.savetxt(buf, table, fmt=POINT_FORMATS, delimiter=",")
    return (",".join(POINT_COLUMNS) + "\n" + buf.getvalue()).encode()


def _today_npz(path, samples) -> bytes:
    """The NPZ as numpy's np.savez_compressed makes it (a zip of ``<name>.npy`` members,
    zip64 forced), at the writers' deflate level (NPZ_DEFLATE_LEVEL, 1) instead of zlib's
    default, a member stored where its first NPZ_PROBE_ROWS rows deflate to more than
    NPZ_STORE_RATIO of their size; numpy.load reads it back to the same columns."""
    import zipfile
    import zlib

    from nurbscnc.output.files import POINT_COLUMNS, point_columns
    from nurbscnc.output.npz import NPZ_DEFLATE_LEVEL, NPZ_PROBE_ROWS, NPZ_STORE_RATIO

    columns = dict(zip(POINT_COLUMNS, point_columns(samples)))
    with zipfile.ZipFile(path, mode="w", compresslevel=NPZ_DEFLATE_LEVEL) as zipf:
        for name, col in columns.items():
            head = np.ascontiguousarray(np.asanyarray(col)[:NPZ_PROBE_ROWS]).tobytes()
            packs = len(zlib.compress(head, NPZ_DEFLATE_LEVEL)) <= NPZ_STORE_RATIO * len(head)
            zipf.compression = zipfile.ZIP_DEFLATED if packs else zipfile.ZIP_STORED
            with zipf.open(f"{name}.npy", "w", force_zip64=True) as fid:
                np.lib.format.write_array(fid, np.asanyarray(col), allow_pickle=False)
    with np.load(path) as back:
        assert list(back.files) == list(columns)
        for name, col in columns.items():
            np.testing.assert_array_equal(back[name], col)
    return Path(path).read_bytes()


def _assert_same_npz(ours: Path, reference: Path) -> None:
    """``ours`` holds what zipfile wrote in ``reference`` (:func:`_today_npz`): the same
    members in order, each stored or deflated alike, with the CRC-32 and size zipfile
    computed from the data; zipfile's own check (every member inflated and its CRC
    compared) passes; numpy.load reads the same columns. (The deflate streams differ: ours
    deflates the .npy header apart from the data, so the bytes do.)"""
    import zipfile

    with zipfile.ZipFile(ours) as a, zipfile.ZipFile(reference) as b:
        assert a.testzip() is None
        got, want = a.infolist(), b.infolist()
        assert [i.filename for i in got] == [i.filename for i in want]
        for x, y in zip(got, want):
            assert (
                x.compress_type,
                x.CRC,
                x.file_size,
                x.date_time,
                x.external_attr,
                x.extract_version,
            ) == (
                y.compress_type,
                y.CRC,
                y.file_size,
                y.date_time,
                y.external_attr,
                y.extract_version,
            )
    with np.load(ours) as p, np.load(reference) as q:
        assert list(p.files) == list(q.files)
        for name in q.files:
            assert np.array_equal(p[name], q[name]) and p[name].dtype == q[name].dtype


def test_npz_stores_what_does_not_deflate(tmp_path):
    """Random doubles (no redundancy: deflate cannot shrink them) are stored, a piece index
    column (runs of equal integers) is deflated, and the file reads back."""
    import zipfile

    from nurbscnc.output.npz import write_npz

    rng = np.random.default_rng(0)
    cols = {"x": rng.normal(size=100_000), "piece": np.repeat(np.arange(1000), 100)}
    out = tmp_path / "two.npz"
    with open(out, "wb") as fh:
        write_npz(fh, str(tmp_path), list(cols), [tuple(cols.values())], 100_000)
    with zipfile.ZipFile(out) as z:
        kind = {i.filename: i.compress_type for i in z.infolist()}
    assert kind == {"x.npy": zipfile.ZIP_STORED, "piece.npy": zipfile.ZIP_DEFLATED}
    with np.load(out) as back:
        for name, col in cols.items():
            np.testing.assert_array_equal(back[name], col)


@pytest.mark.parametrize("window", WINDOWS)
@pytest.mark.parametrize("fmt", ["csv", "npz", "halstreamer"])
def test_windowed_writers_write_todays_bytes(plans, tmp_path, frozen_clock, fmt, window):
    """CSV, NPZ (columns deflated as they come and spooled to disk) and halstreamer files
    written window by window are byte-identical to the whole-array files, the NPZ holding
    what zipfile writes of the same columns; the spool leaves nothing behind."""
    from nurbscnc.output.files import write_point_windows, write_points
    from nurbscnc.output.halstreamer import (
        halstreamer_header,
        halstreamer_lines,
        write_halstreamer_windows,
    )

    plan = plans["naca2415"]
    whole = sample_plan(plan.pieces, plan.profile, PERIOD)
    n = whole.t_s.size
    windows = sample_chunks(plan.pieces, plan.profile, PERIOD, "exact", window)
    out = tmp_path / "out" / f"points.{ {'halstreamer': 'hs'}.get(fmt, fmt) }"
    out.parent.mkdir()
    if fmt == "csv":
        write_point_windows(str(out), windows, n)
        expected = _today_csv(whole)
    elif fmt == "npz":
        write_point_windows(str(out), windows, n)
        single = tmp_path / "single.npz"  # the whole arrays: the same bytes
        write_points(str(single), whole)
        expected = single.read_bytes()
        _today_npz(tmp_path / "today.npz", whole)  # zipfile's NPZ of the same columns
        _assert_same_npz(single, tmp_path / "today.npz")
    else:
        write_halstreamer_windows(str(out), (w.points_mm for w in windows), n, PERIOD, "naca")
        expected = (
            halstreamer_header(whole.points_mm, PERIOD, "naca") + halstreamer_lines(whole.points_mm)
        ).encode()
    assert out.read_bytes() == expected
    assert sorted(p.name for p in out.parent.iterdir()) == [out.name]


def test_npz_with_a_short_count_is_refused_and_leaves_no_file(plans, tmp_path):
    """The .npy headers are written from the announced row count: windows that do not add up
    to it are an error, and the half-written file is removed (the old one stays)."""
    from nurbscnc.output.files import write_point_windows

    plan = plans["mixed"]
    n = sample_count(plan.pieces, plan.profile, PERIOD)
    out = tmp_path / "points.npz"
    out.write_bytes(b"old")
    for count in (n - 1, n + 1):
        with pytest.raises(ValueError, match="announced"):
            write_point_windows(
                str(out), sample_chunks(plan.pieces, plan.profile, PERIOD, "exact", 100), count
            )
    assert out.read_bytes() == b"old" and list(tmp_path.iterdir()) == [out]


@pytest.mark.parametrize("fmt", ["csv", "npz", "halstreamer"])
def test_an_error_in_a_later_window_leaves_no_file(plans, tmp_path, fmt):
    """A window that raises mid-write (a point outside the soft limits is found as it is
    made) leaves the old file untouched and no temporary file."""
    from nurbscnc.errors import PlanningError
    from nurbscnc.output.files import write_point_windows
    from nurbscnc.output.halstreamer import write_halstreamer_windows

    plan = plans["mixed"]
    n = sample_count(plan.pieces, plan.profile, PERIOD)

    def failing():
        for k, w in enumerate(sample_chunks(plan.pieces, plan.profile, PERIOD, "exact", 50)):
            if k == 3:
                raise PlanningError("outside")
            yield w

    out = tmp_path / f"points.{fmt}"
    out.write_bytes(b"old")
    with pytest.raises(PlanningError):
        if fmt == "halstreamer":
            write_halstreamer_windows(str(out), (w.points_mm for w in failing()), n, PERIOD)
        else:
            write_point_windows(str(out), failing(), n, npz=fmt == "npz")
    assert out.read_bytes() == b"old" and list(tmp_path.iterdir()) == [out]


# ------------------------------------------------------------------------------ summaries


@pytest.mark.parametrize("interpolator", ["exact", "taylor"])
@pytest.mark.parametrize("window", WINDOWS)
def test_summary_numbers_from_windows_equal_the_whole_arrays(plans, window, interpolator):
    """Sample count, highest feed and the feed fluctuation on NURBS (SPEC §3: true arc length
    of every step on one curve, the steps across window joins included) gathered window by
    window equal the whole-array formulas (count, max, max |Δs_true/Δs_planned − 1| over
    the steps at ≥ 10 % of the highest cap) exactly."""
    from nurbscnc.plan.report import SampleStats, nurbs_step_lengths

    plan = plans["naca2415"]
    whole = sample_plan(plan.pieces, plan.profile, PERIOD, interpolator)
    k, ds_true = nurbs_step_lengths(plan.pieces, whole)
    fast = whole.v_mm_s[k] >= 0.1 * float(np.max(plan.caps_mm_s))
    planned = whole.s_mm[k + 1] - whole.s_mm[k]
    expected = float(np.max(np.abs(ds_true[fast] / planned[fast] - 1.0)))
    stats = SampleStats(plan)
    for w in sample_chunks(plan.pieces, plan.profile, PERIOD, interpolator, window):
        stats.add(w)
    assert stats.count == whole.t_s.size
    assert stats.feed_max_mm_s == float(whole.v_mm_s.max())
    assert stats.feed_fluctuation_max == expected
    assert stats.interpolator == interpolator
    if window == 7:  # the step across a join can be the worst: it is not skipped
        joins = np.arange(6, whole.t_s.size - 1, 7)
        assert np.isin(k, joins).sum() > 20


def test_a_window_outside_the_soft_limits_names_the_first_line(plans):
    """A lazy run checks each window as it is made: the error is the whole-array check's
    (the first offending point, its line and axis), and it comes before that window is
    handed out."""
    from nurbscnc.errors import PlanningError
    from nurbscnc.machine.profile import SoftLimits
    from nurbscnc.pipeline import Run
    from nurbscnc.plan.options import Algorithm
    from nurbscnc.plan.report import check_soft_limits

    plan = plans["mixed"]
    whole = sample_plan(plan.pieces, plan.profile, PERIOD)
    box = SoftLimits((-1.0, -1.0, -1.0), (6.0, 10.0, 10.0))  # X beyond 6 mm: the arc's end
    with pytest.raises(PlanningError) as expected:
        check_soft_limits(whole.points_mm, whole.line, box)
    first_bad = int(np.flatnonzero(whole.points_mm[:, 0] > 6.0)[0])
    run = Run(Algorithm.PH_LOOKAHEAD, None, plan, None, None, "exact", PERIOD, box)
    handed = 0
    with pytest.raises(PlanningError) as got:
        for w in run.chunks(7):
            handed += w.t_s.size
    assert str(got.value) == str(expected.value)
    assert got.value.pos.line == expected.value.pos.line == int(whole.line[first_bad])
    assert handed == first_bad - first_bad % 7  # the offending window was not handed out


# ----------------------------------------------------------------------------------- CLI


@pytest.mark.parametrize("window", [7, 4096])
@pytest.mark.parametrize("dynamics", ["off", "local"])
@pytest.mark.parametrize("suffix", ["csv", "npz", "hs"])
def test_run_writes_the_whole_runs_bytes_and_summary(
    tmp_path, monkeypatch, frozen_clock, suffix, dynamics, window
):
    """``run -o`` writes, window by window, the file the whole-array writers make of the
    run's whole samples, and prints the summary of the whole samples — with the check off
    (the points re-sampled as they are written) and on (its kept reference, sliced)."""
    from click.testing import CliRunner

    import nurbscnc.pipeline as pipeline
    from nurbscnc.app.planning import make_plan
    from nurbscnc.app.summary import summary_of
    from nurbscnc.cli.main import main
    from nurbscnc.output.files import write_points
    from nurbscnc.output.halstreamer import write_halstreamer
    from nurbscnc.plan.report import plan_summary

    monkeypatch.setattr(pipeline, "CHUNK", window)
    src = str(ROOT / "programs" / "naca2415.nc")
    out = tmp_path / f"points.{suffix}"
    res = CliRunner().invoke(
        main,
        ["run", src, "-o", str(out), "--json", "--dynamics", dynamics, "--interpolator", "taylor"],
    )
    assert res.exit_code == 0, res.output
    prog, mach, run = make_plan(src, dynamics=dynamics, interpolator="taylor")
    whole = run.samples
    expected = tmp_path / f"whole.{suffix}"
    if suffix == "hs":
        write_halstreamer(str(expected), whole.points_mm, mach.servo.period_s, prog.name)
    else:
        write_points(str(expected), whole)
    assert out.read_bytes() == expected.read_bytes()
    summary = json.loads(res.stdout)
    reference = plan_summary(
        prog, mach, whole, run.plan, run.check, run.algorithm, run.cycle_time_s
    )
    assert {k: summary[k] for k in reference} == json.loads(json.dumps(reference))
    assert summary == json.loads(json.dumps(summary_of(prog, mach, run)))
    assert "feed_fluctuation_max" in summary and summary["samples"] == whole.t_s.size
