"""Plots of issue 16: rapids dashed, cuts coloured by feed, ε_max on the contour plot, the
path coloured by the limiting factor, the feed along the program with the programmed F, and
the program's name in every title. The matplotlib objects are inspected (artists, their data,
styles and titles), not the pixels.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.output import plots

pytest.importorskip("matplotlib", reason="matplotlib (the 'plot' extra) is not installed")
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
NACA = ROOT / "programs" / "naca2415.nc"


def titles(fig) -> list[str]:
    return [ax.get_title() for ax in fig.axes if ax.get_title()]


def test_path_rapids_dashed_and_cuts_coloured_by_feed():
    # A rapid to (10, 0), then a cut back at a rising feed.
    x = np.array([0.0, 5.0, 10.0, 7.5, 5.0, 2.5, 0.0])
    pts = np.column_stack([x, np.zeros(7), np.zeros(7)])
    rapid = np.array([False, True, True, False, False, False, False])
    feed = np.array([0.0, 50.0, 50.0, 10.0, 20.0, 30.0, 40.0])
    fig = plots.path_figure(pts, [], "part.nc: tool path", rapid=rapid, feed_mm_s=feed)
    (ax,) = [a for a in fig.axes if a.get_title()]
    cols = [c for c in ax.collections if isinstance(c, LineCollection)]
    dashed = [c for c in cols if c.get_label() == "rapid (G0)"]
    (rap,) = dashed
    assert len(rap.get_segments()) == 2  # the two moves reaching rapid points
    offset, pattern = rap.get_linestyle()[0]
    assert pattern is not None and len(pattern) >= 2  # a dash pattern, not a solid line
    (cuts,) = [c for c in cols if c.get_array() is not None]
    # Each cut segment carries the feed of the point it reaches, in mm/min.
    assert np.array_equal(np.asarray(cuts.get_array()), feed[3:] * 60.0)
    assert len(cuts.get_segments()) == 4
    assert "part.nc" in ax.get_title()


def test_contour_plot_draws_eps_max():
    t = np.linspace(0.0, 1.0, 101)
    fig = plots._time_series_figure(
        {"true": (t, 10 * t)},
        "part.nc: contour error",
        "contour error [µm]",
        "contour",
        0.8,
        plots.FIGSIZE_IN,
        True,
        False,
        (15.0, "ε_max = 15 µm"),
    )
    ax = fig.axes[0]
    (line,) = [ln for ln in ax.get_lines() if ln.get_label() == "ε_max = 15 µm"]
    assert np.all(np.asarray(line.get_ydata()) == 15.0)
    assert line.get_linestyle() == "--"
    assert to_rgba(line.get_color()) == to_rgba("tab:red")


def test_feed_along_draws_the_programmed_feed_per_piece():
    s = np.linspace(0.0, 30.0, 301)
    v = np.minimum(20.0, s)
    fig = plots.feed_along_figure(
        s,
        v,
        [0.0, 10.0],
        [10.0, 30.0],
        [20.0, 25.0],
        cap_mm_s=[20.0, 22.0],
        title="p.nc: feed along",
    )
    ax = fig.axes[0]
    (prog,) = [ln for ln in ax.get_lines() if ln.get_label() == "programmed F"]
    x, y = np.asarray(prog.get_xdata()), np.asarray(prog.get_ydata())
    keep = ~np.isnan(y)
    assert np.array_equal(x[keep], [0.0, 10.0, 10.0, 30.0])
    assert np.array_equal(y[keep], [1200.0, 1200.0, 1500.0, 1500.0])  # mm/min
    (planned,) = [ln for ln in ax.get_lines() if ln.get_label() == "planned feed"]
    assert np.array_equal(np.asarray(planned.get_ydata()), v * 60.0)


def test_limits_path_has_one_coloured_collection_per_limit():
    pts = np.column_stack([np.arange(6.0), np.zeros(6), np.zeros(6)])
    code = np.array([0, 0, 0, 3, 3, 8])
    names = [f"limit {i}" for i in range(14)]
    fig = plots.limits_figure(pts, code, names, "p.nc: limits")
    cols = {c.get_label(): c for c in fig.axes[0].collections}
    assert set(cols) == {"limit 0", "limit 3", "limit 8"}
    assert len(cols["limit 0"].get_segments()) == 2  # moves reaching points 1, 2
    assert len(cols["limit 3"].get_segments()) == 2
    assert to_rgba(cols["limit 8"].get_colors()[0]) == to_rgba(plots.LIMIT_COLOURS[8])


@pytest.fixture()
def captured(monkeypatch):
    """Every figure the CLI saves, with the file it went to."""
    saved = []
    real = plots._save

    def save(fig, out_png):
        saved.append((fig, out_png))
        return real(fig, out_png)

    monkeypatch.setattr(plots, "_save", save)
    return saved


@pytest.mark.parametrize(
    "command",
    [
        ["plan", "{prog}", "--plot", "{dir}"],
        ["run", "{prog}", "-o", "{prog}.csv", "--plot", "{dir}"],
        ["simulate", "{prog}", "--plot", "{dir}"],
        ["compare", "{prog}", "--algorithm", "ours", "--plot", "{dir}"],
    ],
)
def test_every_figure_is_titled_with_the_program(tmp_path, captured, command):
    prog = tmp_path / "wing.nc"
    prog.write_text("G0 X-5 Y0\n" + NACA.read_text())
    args = [a.format(prog=prog, dir=tmp_path / "figs") for a in command]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert len(captured) >= 2
    for fig, path in captured:
        assert Path(path).is_file() and Path(path).stat().st_size > 0
        assert titles(fig) and all(str(prog) in t for t in titles(fig)), (path, titles(fig))


def test_plan_plots_show_rapids_limits_and_eps(tmp_path, captured):
    prog = tmp_path / "wing.nc"
    prog.write_text("G0 X-5 Y0\n" + NACA.read_text())
    res = CliRunner().invoke(main, ["plan", str(prog), "--plot", str(tmp_path / "figs")])
    assert res.exit_code == 0, res.output
    figs = {Path(p).name: f for f, p in captured}
    assert set(figs) == {
        "feed.png",
        "path.png",
        "path_side.png",
        "feed_along.png",
        "limits.png",
        "contour_error.png",
    }
    path_ax = figs["path.png"].axes[0]
    assert any(c.get_label() == "rapid (G0)" for c in path_ax.collections)
    eps = [
        ln
        for ln in figs["contour_error.png"].axes[0].get_lines()
        if ln.get_label().startswith("ε_max")
    ]
    assert len(eps) == 1 and np.all(np.asarray(eps[0].get_ydata()) == 15.0)
    labels = {c.get_label() for c in figs["limits.png"].axes[0].collections}
    assert "rapid rate" in labels and len(labels) >= 2
