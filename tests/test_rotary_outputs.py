"""The rotary axes A B C in the outputs: points files (CSV, NPZ), halstreamer files, their
readers and the summaries.

The samples are built by hand (a :class:`~nurbscnc.plan.timing.Samples` with ``abc_deg`` and
``rotary_axes``, as the planner makes them), so these tests need neither the interpreter's
nor the planner's rotary support. Files are read back by numpy and zipfile (not by our
reader) where the format is checked; a program without rotary axes writes the bytes an
explicit POINT_COLUMNS table gives (and, checked once when this was written, main's bytes);
malformed rotary columns are refused with exit 2. The halstreamer file is played for real
under ``halrun`` when LinuxCNC is installed: four streamer pins, the fourth driving an A
step generator in steps per degree.
"""

from __future__ import annotations

import dataclasses
import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.errors import DataError
from nurbscnc.output.files import (
    POINT_COLUMNS,
    POINT_FORMATS,
    point_names,
    read_points,
    rotary_of_points,
    write_point_windows,
    write_points,
    write_table,
)
from nurbscnc.output.halstreamer import (
    streamer_cfg,
    write_halstreamer,
    write_halstreamer_samples,
)
from nurbscnc.plan.timing import Samples, rows_of
from tests.test_halstreamer import needs_halrun, play

PERIOD_S = 1e-3
N = 3000
#: A B C at the end of the hand-built samples [deg] (A turns forwards, C backwards).
ABC_END_DEG = (12.0, 0.0, -7.0)


def smoothstep(k: np.ndarray, n: int) -> np.ndarray:
    """3u² − 2u³ of u = k/(n − 1): at rest at both ends."""
    u = k / (n - 1)
    return u * u * (3.0 - 2.0 * u)


def samples(axes=("a",), n: int = N, abc: bool = True) -> Samples:
    """Reference points of a slow 3-D move (0.8 mm in X, a half sine in Y, −0.2 mm in Z)
    with A from 0 to 12° and C from 0 to −7° in step, one per millisecond, at rest at both
    ends; ``axes`` the rotary axes the program uses; ``abc`` False: no A B C columns."""
    k = np.arange(n)
    u = smoothstep(k, n)
    points = np.column_stack((0.8 * u, 0.3 * np.sin(np.pi * u), -0.2 * u))
    step = np.r_[0.0, np.linalg.norm(np.diff(points, axis=0), axis=1)]
    s = np.cumsum(step)
    t = k * PERIOD_S
    v = np.gradient(s, PERIOD_S)
    piece = k // 500
    abc_deg = np.column_stack([e * u for e in ABC_END_DEG]) if abc else None
    return Samples(
        t_s=t,
        tau_s=t,
        s_mm=s,
        v_mm_s=v,
        a_mm_s2=np.gradient(v, PERIOD_S),
        piece=piece,
        points_mm=points,
        param=s,
        line=piece + 10,
        abc_deg=abc_deg,
        rotary_axes=tuple(axes),
    )


def windows(smp: Samples, size: int):
    return [rows_of(smp, slice(i, i + size)) for i in range(0, smp.t_s.size, size)]


def run(args, **kwargs):
    return CliRunner().invoke(main, [str(a) for a in args], **kwargs)


def axes_set(axes: str = "abc", **limits: str) -> list[str]:
    """``--set`` options declaring the rotary ``axes`` on the bundled machine (``limits``:
    extra keys of their tables, e.g. ``max_deg="5"``)."""
    keys = {"v_max_deg_min": "600", "a_max_deg_s2": "100", "j_max_deg_s3": "1e4", **limits}
    return [f"--set=axis_limits.{a}.{k}={v}" for a in axes for k, v in keys.items()]


# ------------------------------------------------------------------ without rotary axes


@pytest.mark.parametrize("abc", [False, True])
def test_without_rotary_axes_the_files_are_the_xyz_tables_bytes(tmp_path, abc):
    """No rotary axes used (with or without A B C in the samples): the CSV is the header and
    numpy's savetxt of t x y z feed piece line, the NPZ the same bytes as the table of those
    seven named columns, the halstreamer file that of the x y z points."""
    smp = samples(axes=(), abc=abc)
    cols = (
        smp.t_s,
        smp.points_mm[:, 0],
        smp.points_mm[:, 1],
        smp.points_mm[:, 2],
        smp.v_mm_s,
        smp.piece,
        smp.line,
    )
    csv = tmp_path / "p.csv"
    write_points(str(csv), smp)
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack(cols).astype(float), fmt=POINT_FORMATS, delimiter=",")
    assert csv.read_bytes() == ("t,x,y,z,feed,piece,line\n" + buf.getvalue()).encode()

    npz, table = tmp_path / "p.npz", tmp_path / "table.npz"
    write_points(str(npz), smp)
    write_table(str(table), POINT_COLUMNS, cols, POINT_FORMATS, npz=True)
    assert npz.read_bytes() == table.read_bytes()
    with zipfile.ZipFile(npz) as z:
        assert z.namelist() == [f"{c}.npy" for c in POINT_COLUMNS]

    hs, plain = tmp_path / "p.hs", tmp_path / "plain.hs"
    write_halstreamer_samples(str(hs), windows(smp, 700), N, PERIOD_S, "part.nc")
    write_halstreamer(str(plain), smp.points_mm, PERIOD_S, "part.nc")
    assert hs.read_bytes() == plain.read_bytes()
    assert "cfg=fff;" in hs.read_text() and streamer_cfg(()) == "fff"


# --------------------------------------------------------------------- CSV and NPZ round trips

AXES = [("a",), ("c",), ("a", "c"), ("a", "b", "c")]


@pytest.mark.parametrize("axes", AXES)
def test_csv_has_the_used_axes_after_z_and_reads_back(tmp_path, axes):
    smp = samples(axes)
    out = tmp_path / "p.csv"
    write_points(str(out), smp)
    header = out.read_text().split("\n", 1)[0]
    assert header == "t,x,y,z," + ",".join(axes) + ",feed,piece,line"
    table = np.loadtxt(out, delimiter=",", skiprows=1)  # numpy, not our reader
    assert table.shape == (N, 7 + len(axes))
    for j, name in enumerate(axes):
        want = smp.abc_deg[:, "abc".index(name)]
        assert np.max(np.abs(table[:, 4 + j] - want)) <= 5e-10  # nine decimals
    assert np.max(np.abs(table[:, 1:4] - smp.points_mm)) <= 5e-10
    np.testing.assert_array_equal(table[:, -1], smp.line)

    data = read_points(str(out))
    got_axes, abc = rotary_of_points(data)
    assert got_axes == axes and abc.shape == (N, 3)
    for j, name in enumerate("abc"):
        want = smp.abc_deg[:, j] if name in axes else np.zeros(N)
        assert np.max(np.abs(abc[:, j] - want)) <= 5e-10
    # window by window: the same bytes
    again = tmp_path / "w.csv"
    write_point_windows(str(again), windows(smp, 777), N)
    assert again.read_bytes() == out.read_bytes()


@pytest.mark.parametrize("axes", AXES)
def test_npz_has_the_used_axes_and_reads_back_bit_for_bit(tmp_path, axes):
    smp = samples(axes)
    out = tmp_path / "p.npz"
    write_points(str(out), smp)
    with zipfile.ZipFile(out) as z:
        assert z.testzip() is None
        assert z.namelist() == [f"{c}.npy" for c in point_names(axes)]
    with np.load(out, allow_pickle=False) as back:
        for name in axes:
            np.testing.assert_array_equal(back[name], smp.abc_deg[:, "abc".index(name)])
        np.testing.assert_array_equal(back["x"], smp.points_mm[:, 0])
    data = read_points(str(out))
    got_axes, abc = rotary_of_points(data)
    assert got_axes == axes
    for name in axes:
        j = "abc".index(name)
        np.testing.assert_array_equal(abc[:, j], smp.abc_deg[:, j])
    again = tmp_path / "w.npz"
    write_point_windows(str(again), windows(smp, 1024), N)
    assert again.read_bytes() == out.read_bytes()


def test_rotary_columns_without_positions_or_changing_are_refused(tmp_path):
    """Samples naming an axis without A B C, or windows that change their axes, are a
    programming error (ValueError), never a file of zeros; nothing is left behind."""
    out = tmp_path / "out" / "p.csv"
    out.parent.mkdir()
    with pytest.raises(ValueError, match="need abc_deg"):
        write_points(str(out), samples(("a",), abc=False))
    parts = windows(samples(("a",)), 1000)
    parts[1] = dataclasses.replace(parts[1], rotary_axes=("a", "b"))
    with pytest.raises(ValueError, match="differ"):
        write_point_windows(str(out), parts, N)
    with pytest.raises(ValueError, match="distinct names"):
        write_points(str(out), samples(("c", "a")))
    assert list(out.parent.iterdir()) == []


# ------------------------------------------------------------------------------ readers


def _xyz_only(path: Path, data: dict) -> Path:
    """The points file ``path`` again, in its format, without its rotary columns."""
    out = path.with_name("xyz" + path.suffix)
    write_table(str(out), POINT_COLUMNS, [data[c] for c in POINT_COLUMNS], POINT_FORMATS)
    return out


@pytest.mark.parametrize("suffix", ["csv", "npz"])
def test_simulate_reads_a_rotary_points_file(tmp_path, suffix):
    """``simulate`` takes the rotary columns: the X Y Z simulation is that of the same file
    without them, and it reports the axes, where they end and that it checks X Y Z only."""
    smp = samples(("a", "c"))
    out = tmp_path / f"p.{suffix}"
    write_points(str(out), smp)
    with_rotary = run(["simulate", out, "--json", *axes_set("ac")])
    assert with_rotary.exit_code == 0, with_rotary.output
    got = json.loads(with_rotary.stdout)
    plain = run(["simulate", _xyz_only(out, read_points(str(out))), "--json"])
    want = json.loads(plain.stdout)
    rotary = got.pop("rotary")
    assert rotary["axes"] == ["a", "c"] and rotary["contour_check"] == "xyz"
    assert rotary["final_abc_deg"] == pytest.approx({"a": 12.0, "c": -7.0}, abs=5e-10)
    assert "X Y Z only" in rotary["note"]
    for key in ("program", "machine_profile"):
        got.pop(key), want.pop(key)
    assert got == want
    text = run(["simulate", out, *axes_set("ac")])
    assert text.exit_code == 0
    assert "rotary axes A C (end at A12° C-7°): the contour check" in text.stdout
    assert "X Y Z only" in text.stdout and "r·δ·π/180 mm" in text.stdout
    if suffix == "csv":  # from standard input, recognised by its header
        piped = run(["simulate", "-", "--json", *axes_set("ac")], input=out.read_text())
        assert piped.exit_code == 0, piped.output
        assert json.loads(piped.stdout)["rotary"]["axes"] == ["a", "c"]


@pytest.mark.parametrize("command", ["simulate", "stream"])
def test_simulate_checks_the_rotary_columns_as_stream_does(tmp_path, command):
    """A column of an axis the machine lacks, or beyond its soft limits, is refused by both
    commands with the same words, before anything runs (``stream`` before any port)."""
    out = tmp_path / "p.csv"
    write_points(str(out), samples(("a", "c")))  # A ends at 12°, C at −7°
    port = ["--port", str(tmp_path / "no-card")] if command == "stream" else []
    lacking = run([command, out, *port, *axes_set("a")])
    assert lacking.exit_code == 2, lacking.output
    assert f"{out}: a column c but the machine has no C axis" in lacking.stderr
    beyond = run([command, out, *port, *axes_set("a", max_deg="5"), *axes_set("c")])
    assert beyond.exit_code == 2, beyond.output
    assert "is outside its soft limits [-inf, 5] deg" in beyond.stderr
    assert "Traceback" not in beyond.output


def _csv(path: Path, header: str, rows: list[str]) -> Path:
    path.write_text(header + "\n" + "".join(r + "\n" for r in rows))
    return path


GOOD_ROW = "0.000000,0.0,0.0,0.0,{a},0.0,0,1"
BAD_CSV = {
    "out_of_order": ("t,x,y,z,c,a,feed,piece,line", ["0,0,0,0,0,0,0,0,1"], "expected the header"),
    "without_z": ("t,x,y,a,feed,piece,line", ["0,0,0,0,0,0,1"], "expected the header"),
    "twice": ("t,x,y,z,a,a,feed,piece,line", ["0,0,0,0,0,0,0,0,1"], "expected the header"),
    "after_line": ("t,x,y,z,feed,piece,line,a", ["0,0,0,0,0,0,1,0"], "expected the header"),
    "upper_case": ("t,x,y,z,A,feed,piece,line", ["0,0,0,0,0,0,0,1"], "expected the header"),
    "missing_value": ("t,x,y,z,a,feed,piece,line", ["0,0,0,0,0,0,1"], "expected 8 columns"),
    "nan": (
        "t,x,y,z,a,feed,piece,line",
        [GOOD_ROW.format(a="1.5"), "0.001000,0.0,0.0,0.0,nan,0.0,0,1"],
        "3:22: error: a = nan is not finite",
    ),
    "huge": (
        "t,x,y,z,a,feed,piece,line",
        [GOOD_ROW.format(a="1e10")],
        "a = 10000000000.0 is beyond ±1e+09",
    ),
    "text": ("t,x,y,z,a,feed,piece,line", [GOOD_ROW.format(a="ten")], "not a table of numbers"),
}


@pytest.mark.parametrize("case", sorted(BAD_CSV))
def test_malformed_rotary_csv_exits_2(tmp_path, case):
    header, rows, words = BAD_CSV[case]
    path = _csv(tmp_path / "points.csv", header, rows)
    result = run(["simulate", path])
    assert result.exit_code == 2, result.output
    assert "error: " in result.stderr and words in result.stderr
    assert "Traceback" not in result.output


def _npz_with(path: Path, **rotary) -> Path:
    """A reference-point NPZ of 6 rows (numpy's own writer) with the given rotary arrays."""
    n = 6
    cols = {c: np.zeros(n) for c in POINT_COLUMNS}
    cols["t"] = np.arange(n) * PERIOD_S
    np.savez(path, **cols, **rotary)
    return path


BAD_NPZ = {
    "two_d": ({"a": np.zeros((6, 1))}, "must be numeric, 1-D"),
    "short": ({"b": np.zeros(5)}, "of one length"),
    "strings": ({"a": np.array(["x"] * 6)}, "must be numeric"),
    "bools": ({"c": np.zeros(6, dtype=bool)}, "must be numeric"),
    "objects": ({"a": np.array([None] * 6, dtype=object)}, "holds Python objects"),
    "nan": ({"c": np.where(np.arange(6) == 4, np.nan, 0.0)}, "c = nan is not finite (row 5)"),
    "inf": ({"a": np.full(6, -np.inf)}, "a = -inf is not finite (row 1)"),
}


@pytest.mark.parametrize("case", sorted(BAD_NPZ))
def test_malformed_rotary_npz_exits_2(tmp_path, case):
    rotary, words = BAD_NPZ[case]
    path = _npz_with(tmp_path / "points.npz", **rotary)
    with pytest.raises(DataError) as info:
        read_points(str(path))
    assert words in info.value.message
    result = run(["simulate", path])
    assert result.exit_code == 2, result.output
    assert f"{path}: error: " in result.stderr and words in result.stderr


def test_a_written_header_is_a_header_and_other_text_is_not():
    from nurbscnc.output.files import point_header

    for axes in AXES:
        names = point_names(axes)
        for k in range(3, len(names) + 1):
            cut = names[:k]
            accepted = point_header(",".join(cut) + "\n1,2,3\n")
            # a prefix that ends inside the rotary columns still names each column it has
            assert accepted == cut
    assert point_header("G1 X1 A90\n") is None
    assert point_header("t,x,y,b,c\n") is None


# -------------------------------------------------------------------------------- halstreamer


def test_halstreamer_has_a_pin_per_used_axis(tmp_path):
    smp = samples(("a", "c"))
    out = tmp_path / "p.hs"
    write_halstreamer_samples(str(out), windows(smp, 999), N, PERIOD_S, "engrave.nc")
    lines = out.read_text().splitlines()
    header = [ln for ln in lines if ln.startswith("#")]
    assert header == [
        "# nurbscnc reference points for LinuxCNC halstreamer: engrave.nc",
        "# one line per servo period T_s = 1 ms: x y z a c [mm; a c in deg; machine coords]",
        "# loadrt streamer depth=... cfg=fffff; the servo thread period must be 1000000 ns",
        f"# {N} lines; start point 0.000000 0.000000 0.000000 0.000000 0.000000 "
        "(the machine must be there)",
    ]
    values = np.array([[float(v) for v in ln.split()] for ln in lines[len(header) :]])
    want = np.column_stack((smp.points_mm, smp.abc_deg[:, 0], smp.abc_deg[:, 2]))
    assert values.shape == want.shape
    assert np.max(np.abs(values - want)) <= 5e-7 + 1e-12
    whole = tmp_path / "whole.hs"
    write_halstreamer(str(whole), want, PERIOD_S, "engrave.nc", ("a", "c"))
    assert whole.read_bytes() == out.read_bytes()
    assert streamer_cfg(("a", "b", "c")) == "ffffff"
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        write_halstreamer(str(whole), smp.points_mm, PERIOD_S, "", ("a",))


#: Steps per degree of the A joint in the played graph (not the X Y Z's 1000 per mm, so
#: a mixed-up pin would show).
A_STEPS_PER_DEG = 50.0


@needs_halrun
def test_linuxcnc_streamer_plays_an_a_joint(tmp_path):
    """Under halrun: a ``cfg=ffff`` streamer drives X Y Z and an A step generator; the
    streamed values are the file's, period by period, and the A joint's step count follows
    A [deg] × steps per degree within one step, ending on the end's step."""
    smp = samples(("a",))
    out = tmp_path / "p.hs"
    write_halstreamer_samples(str(out), [smp], N, PERIOD_S, "a.nc")
    scale = (1000.0, 1000.0, 1000.0, A_STEPS_PER_DEG)
    rec = play(out.read_text(), N, scale, cfg=streamer_cfg(("a",)))
    want = np.column_stack((smp.points_mm, smp.abc_deg[:, 0]))
    assert np.max(np.abs(rec[:N, :4] - want)) <= 5e-7 + 1e-12
    counts = rec[:, 4:8]
    err_steps = np.abs(counts[1 : N + 1] - want * np.asarray(scale))
    assert err_steps.max() <= 1.0
    assert np.array_equal(counts[-1], np.round(want[-1] * np.asarray(scale)))
    assert counts[-1, 3] == ABC_END_DEG[0] * A_STEPS_PER_DEG  # 600 steps: it did turn


# --------------------------------------------------------------------------------- summaries


def _program(segments, start_abc=(0.0, 0.0, 0.0), axes=("a",)):
    from nurbscnc.geometry.segments import Program

    return Program(
        segments=tuple(segments),
        start_mm=np.zeros(3),
        rotary_axes=axes,
        start_abc_deg=start_abc,
    )


def test_final_abc_is_the_last_rotary_position_of_the_program():
    """The one rule (program/columns.py) read two ways: :func:`end_abc_deg` from the end
    back, :func:`segment_abc_deg`'s last end row (whole-array), on the same programs."""
    from nurbscnc.geometry.segments import Dwell, Line, Pause, Rotate
    from nurbscnc.program.columns import end_abc_deg, segment_abc_deg

    def final_abc_deg(prog):
        walked = end_abc_deg(prog.segments, prog.start_abc_deg)
        columns = segment_abc_deg(prog.segments, prog.start_abc_deg)[1]
        assert tuple(columns[-1]) == walked
        return walked

    o, x = (0.0, 0.0, 0.0), (10.0, 0.0, 0.0)
    line = Line(o, x, 10.0, 1, abc_deg=(0.0, 0.0, 0.0, 30.0, 0.0, -5.0))
    turn = Rotate(x, (30.0, 0.0, -5.0), (95.5, 0.0, -5.0), 2.0, 2)
    back = Line(x, o, 10.0, 3)  # no abc_deg: A B C are 0 all along
    rest = Dwell(0.5, o, 4)
    stop = Pause(x, 5)
    assert final_abc_deg(_program([line, rest])) == (30.0, 0.0, -5.0)
    assert final_abc_deg(_program([line, turn, rest, stop])) == (95.5, 0.0, -5.0)
    assert final_abc_deg(_program([line, turn, back, rest])) == (0.0, 0.0, 0.0)
    assert final_abc_deg(_program([rest], start_abc=(45.0, 0.0, 0.0))) == (45.0, 0.0, 0.0)
    # Every row: a stop holds the end before it (the start before the first move); a Line
    # without abc_deg is at 0.
    prog = _program([rest, line, rest, turn, stop, back, rest], start_abc=(7.0, 1.0, 2.0))
    abc0, abc1 = segment_abc_deg(prog.segments, prog.start_abc_deg)
    np.testing.assert_array_equal(
        abc0,
        [[7, 1, 2], [0, 0, 0], [30, 0, -5], [30, 0, -5], [95.5, 0, -5], [0, 0, 0], [0, 0, 0]],
    )
    np.testing.assert_array_equal(
        abc1,
        [[7, 1, 2], [30, 0, -5], [30, 0, -5], [95.5, 0, -5], [95.5, 0, -5], [0, 0, 0], [0, 0, 0]],
    )


def test_summary_names_the_axes_and_what_the_contour_check_does_not_see():
    """The plan summary of a real run, its program given rotary axes: the summary gains
    the ``rotary`` object (axes, where they end, what the contour check covers) and nothing
    else changes; the text says the contour check covers X Y Z only. Without rotary axes
    the summary is as before."""
    from rich.console import Console

    from nurbscnc.app.planning import make_plan
    from nurbscnc.app.summary import rotary_text, summary_of
    from nurbscnc.cli.plan import print_plan_summary

    root = Path(__file__).resolve().parents[1]
    prog, mach, run_ = make_plan(str(root / "programs" / "naca2415.nc"), dynamics="off")
    plain = summary_of(prog, mach, run_)
    assert "rotary" not in plain and rotary_text(plain) is None
    held = (0.0, 22.5, 0.0, 0.0, 22.5, 0.0)  # B held at 22.5° all along
    turned = dataclasses.replace(
        prog,
        segments=tuple(
            dataclasses.replace(seg, abc_deg=held) if seg.kind in ("line", "rapid", "arc") else seg
            for seg in prog.segments
        ),
        rotary_axes=("b",),
        start_abc_deg=(0.0, 22.5, 0.0),
    )
    summary = summary_of(turned, mach, run_)
    rotary = summary.pop("rotary")
    note_b = XYZ_ONLY["note"].replace("on A", "on B")
    assert rotary == {"axes": ["b"], "final_abc_deg": {"b": 22.5}, **XYZ_ONLY, "note": note_b}
    assert json.dumps(summary) == json.dumps(plain)
    buf = io.StringIO()
    print_plan_summary(turned, mach, summary_of(turned, mach, run_), Console(file=buf, width=200))
    text = buf.getvalue()
    assert "rotary axes B (end at B22.5°): the contour check covers X Y Z only" in text
    assert "an error of δ° on B is r·δ·π/180 mm at radius r" in text


#: The ``rotary`` object's words on the contour check.
XYZ_ONLY = {
    "contour_check": "xyz",
    "note": "the contour check covers X Y Z only: it does not see the tool's position on a "
    "rotated part (an error of δ° on A is r·δ·π/180 mm at radius r)",
}


def test_the_planners_rotary_object_is_kept_and_completed():
    """A summary whose planner made a ``rotary`` object (its rotary-only moves) keeps those
    entries and gains the end position; the text names both."""
    from nurbscnc.app.summary import rotary_text, with_rotary

    planned = {"rotary": {"axes": ["a"], "rotate_moves": 2, "rotate_time_s": 1.25, **XYZ_ONLY}}
    summary = with_rotary(planned, ("a",), (270.0, 0.0, 0.0))
    assert summary["rotary"] == {**planned["rotary"], "final_abc_deg": {"a": 270.0}}
    assert rotary_text(summary) == (
        "  rotary axes A (end at A270°): 2 rotary-only moves, 1.2500 s; " + XYZ_ONLY["note"]
    )
    assert with_rotary({"ok": True}, (), (0.0, 0.0, 0.0)) == {"ok": True}
