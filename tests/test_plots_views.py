"""The plan's figures show what a user needs and stay quick on long programs: side views
(XZ, YZ) with plunges and Z rapids, the feed over time in mm/min with the programmed F dashed
above it, the slowest corners circled (a capped number, said in the legend), one collection
for all corner pieces, and dense series thinned to the figure's pixels without losing a
peak. The matplotlib objects are inspected, not the pixels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.output import plots

pytest.importorskip("matplotlib", reason="matplotlib (the 'plot' extra) is not installed")
from matplotlib.collections import LineCollection  # noqa: E402

POCKET = """G21 G90 G64 P0.01 F1200
G0 Z5
G0 X0 Y0
G1 Z-1 F300
G1 X20 F1200
G1 Y10
G1 X0
G1 Y0
G0 Z5
G0 X30 Y0
G1 Z-2 F300
G1 X50 Y0 F1500
G1 Y10
G1 X30
G1 Y0
G0 Z5
M2
"""


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    """The figures ``plan --plot`` saves for a two-pocket part, by file name."""
    tmp = tmp_path_factory.mktemp("views")
    prog = tmp / "pockets.nc"
    prog.write_text(POCKET)
    saved = {}
    real = plots._save

    def save(fig, out_png):
        saved[Path(out_png).name] = fig
        return real(fig, out_png)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plots, "_save", save)
        res = CliRunner().invoke(main, ["plan", str(prog), "--plot", str(tmp / "figs")])
    assert res.exit_code == 0, res.output
    return saved


def test_side_views_show_the_plunges_and_z_rapids(figures):
    fig = figures["path_side.png"]
    xz, yz = [a for a in fig.axes if a.get_title()]
    assert xz.get_xlabel() == "x [mm]" and yz.get_xlabel() == "y [mm]"
    assert xz.get_ylabel() == "z [mm]"
    for ax in (xz, yz):
        cols = {c.get_label(): c for c in ax.collections if isinstance(c, LineCollection)}
        cut_z = np.concatenate([s[:, 1] for s in cols["cut"].get_segments()])
        rapid_z = np.concatenate([s[:, 1] for s in cols["rapid (G0)"].get_segments()])
        # The two depths are cut, the plunges go down to them, the rapids reach Z5.
        assert cut_z.min() == pytest.approx(-2.0, abs=1e-9)
        assert np.any(np.abs(cut_z + 1.0) < 1e-9)
        assert rapid_z.max() == pytest.approx(5.0, abs=1e-9)
    # The XZ view spans the parts in x: 0 … 50 mm, to the thinning's grid cell (the
    # path's extent, 55 mm with Z, over PATH_GRID_PX cells).
    x = np.concatenate([s[:, 0] for c in xz.collections for s in c.get_segments()])
    cell = 55.0 / plots.PATH_GRID_PX
    assert x.min() == pytest.approx(0.0, abs=1e-9) and x.max() == pytest.approx(50.0, abs=cell)


def test_feed_over_time_in_mm_min_with_the_programmed_f_dashed_above(figures):
    ax = figures["feed.png"].axes[0]
    assert ax.get_ylabel() == "feed [mm/min]"
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    planned, programmed = lines["planned feed"], lines[plots.PROGRAMMED_LABEL]
    assert programmed.get_linestyle() == "--"
    assert programmed.get_zorder() > planned.get_zorder()
    # The programmed F of the moves, in mm/min: the plunges' 300, the cuts' 1200 and 1500,
    # the rapid rate (the default machine's V_max, 3500 mm/min).
    assert set(np.unique(np.round(programmed.get_ydata(), 6))) == {300.0, 1200.0, 1500.0, 3500.0}
    assert np.max(planned.get_ydata()) <= 3500.0 + 1e-6


def test_corner_markers_are_capped_and_the_corner_pieces_one_collection(figures):
    ax = figures["path.png"].axes[0]
    pieces = [c for c in ax.collections if c.get_label().startswith("corner pieces")]
    assert len(pieces) == 1
    count = int(pieces[0].get_label().rsplit(" ", 1)[1])
    assert count == len(pieces[0].get_segments()) >= 6
    (marks,) = [ln for ln in ax.get_lines() if ln.get_marker() == "o"]
    assert len(marks.get_xdata()) == min(count, 10)


def test_slowest_corners_picks_the_slowest_pieces():
    from types import SimpleNamespace

    from nurbscnc.app.plots import slowest_corners
    from nurbscnc.geometry.path import Kind

    kind = np.array([Kind.LINE, Kind.PH, Kind.LINE, Kind.PH, Kind.LINE, Kind.PH])
    plan = SimpleNamespace(pieces=SimpleNamespace(kind=kind))
    piece = np.array([0, 1, 1, 2, 3, 3, 4, 5, 5])
    v = np.array([9.0, 5.0, 4.0, 9.0, 1.0, 2.0, 9.0, 7.0, 3.0])
    pts = np.column_stack([np.arange(9.0), np.zeros(9), np.zeros(9)])
    smp = SimpleNamespace(piece=piece, v_mm_s=v, points_mm=pts)
    marks, label = slowest_corners(plan, smp, count=2)
    assert marks[:, 0].tolist() == [4.0, 8.0]  # piece 3 at 1 mm/s, piece 5 at 3 mm/s
    assert label == "the 2 slowest corners (of 3)"
    marks, label = slowest_corners(plan, smp, count=5)
    assert marks[:, 0].tolist() == [4.0, 8.0, 2.0] and label == "corners (3)"


def test_decimate_series_keeps_every_column_extreme():
    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0.0, 100.0, 200_000))
    y = rng.normal(size=t.size)
    y[5000:9000] = np.nan
    k = plots.decimate_series(t, [y], 800)
    assert k.size < 8 * 800 and np.all(np.diff(k) > 0)
    col = np.minimum(((t - t[0]) * (800 / (t[-1] - t[0]))).astype(int), 799)
    for c in np.unique(col):
        whole, kept = y[col == c], y[k][col[k] == c]
        if np.all(np.isnan(whole)):
            continue
        assert np.nanmax(kept) == np.nanmax(whole) and np.nanmin(kept) == np.nanmin(whole)
    # The gap stays a gap: its first sample is kept, NaN.
    assert np.isnan(y[k]).any()
    short = np.arange(100.0)
    assert np.array_equal(plots.decimate_series(short, [short], 800), np.arange(100))


def test_thin_path_keeps_the_shape_to_a_grid_cell():
    s = np.linspace(0.0, 2 * np.pi, 1_000_000)
    xy = np.column_stack([50 * np.cos(s), 50 * np.sin(s)])
    flags = s > np.pi
    k = plots.thin_path(xy, plots._changes(flags))
    assert 1000 < k.size < 20_000 and k[0] == 0 and k[-1] == s.size - 1
    # Each dropped point lies within one grid cell of the kept polyline's vertices.
    cell = 100.0 / plots.PATH_GRID_PX
    gap = np.max(np.hypot(*np.diff(xy[k], axis=0).T))
    assert gap <= 2 * np.sqrt(2) * cell
    i = int(np.argmax(flags))
    assert {i - 1, i} <= set(k.tolist())  # the change of flag is a vertex
