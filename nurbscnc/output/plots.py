"""The paper's figures as PNG files (SPEC §9; the ``plot`` extra, matplotlib).

Pure functions: arrays in, one PNG out. Each builds its own ``matplotlib.figure.Figure`` on an
Agg canvas (no pyplot, no global state, no display needed) and writes through
:func:`nurbscnc.output.files.atomic_output`, so a failed plot never leaves half a file.
matplotlib is imported only when a plot is made; without it a :class:`ConfigError` says how to
install the extra.

- :func:`plot_path`: the tool path in XY with the corner regions / PH pieces marked (Fig. 1),
  rapids dashed, cuts coloured by feed;
- :func:`plot_path_limits`: the tool path coloured by the limit that set the feed
  (``plan --explain``);
- :func:`plot_feed_along`: the feed along the path length with the programmed F drawn in;
- :func:`plot_feed_profiles`: feed over time per algorithm (Fig. 2, 4, 6).
- :func:`plot_contour_error`: contour error over time per algorithm (Fig. 7), ε_max drawn.

Every ``plot_*`` has a ``*_figure`` twin or builder returning the unsaved Figure (tests
inspect titles and artists there). The CLI puts the program's name in every title.
- :func:`plot_axis_errors`: x and y axis errors over time per algorithm.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from nurbscnc.errors import ConfigError, OutputError
from nurbscnc.output.files import atomic_output

#: The legend name of a time series of samples on rapids (drawn grey, under the others): the
#: contour error the guarantee does not cover (:mod:`nurbscnc.plan.scope`).
RAPIDS_LABEL = "on rapids (not guaranteed)"

#: The legend name of the programmed feed F over time (drawn dashed, above the planned feed).
PROGRAMMED_LABEL = "programmed F"

#: Default figure size [inches] and resolution [dots per inch]: 800 x 500 pixels.
FIGSIZE_IN = (8.0, 5.0)
DPI = 100
_INSTALL_HINT = "plots need matplotlib: pip install 'nurbscnc[plot]'"


def _figure(figsize_in, nrows: int = 1):
    """A new Figure on an Agg canvas and its axes (lazy matplotlib import)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise ConfigError(_INSTALL_HINT) from exc
    fig = Figure(figsize=figsize_in, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, 1, sharex=True, squeeze=False)[:, 0]
    return fig, axes


def _save(fig, out_png: str) -> str:
    try:
        with atomic_output(out_png, binary=True) as fh:
            fig.savefig(fh, format="png", dpi=DPI)
    except OSError as exc:
        raise OutputError(f"cannot write {out_png}: {exc.strerror or exc}") from None
    return out_png


def _xy(points, what: str) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] < 2:
        raise ConfigError(f"{what} must be an (N, 2) or (N, 3) array of points, got {p.shape}")
    return p[:, :2]


def _series(series: Mapping, width: int, what: str) -> list[tuple[str, list[np.ndarray]]]:
    """Validate {name: (t, y1, ...)} with ``width`` equally long 1-D arrays per entry."""
    if not series:
        raise ConfigError(f"{what}: nothing to plot")
    out = []
    for name, arrays in series.items():
        arrs = [np.asarray(a, dtype=float) for a in arrays]
        if len(arrs) != width or any(a.ndim != 1 or a.shape != arrs[0].shape for a in arrs):
            raise ConfigError(f"{what}: {name!r} must be {width} equally long 1-D arrays")
        out.append((str(name), arrs))
    return out


def _segments_xy(xy: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Line segments (m, 2, 2) between consecutive points where both ends are in ``mask``."""
    keep = mask[:-1] & mask[1:]
    return np.stack([xy[:-1][keep], xy[1:][keep]], axis=1)


#: Samples kept per pixel column of a time series (its minimum and maximum in each column, so
#: every peak stays visible) and the grid [px] a path's points are thinned to.
PER_PIXEL = 2
PATH_GRID_PX = 800


def decimate_series(t, ys: Sequence[np.ndarray], width_px: int) -> np.ndarray:
    """Indices of the samples of a time series ``t`` (N,) (with its value series ``ys``) to
    draw at ``width_px`` pixels: all of them when there are at most :data:`PER_PIXEL` · 2
    per pixel, else in each of ``width_px`` equal time columns the first, last, smallest and
    largest sample of every series, in order (the pixels show the same: each column's line
    spans its extremes), and both ends of every NaN gap (gaps stay gaps)."""
    t = np.asarray(t, dtype=float)
    n = t.size
    if n <= 2 * PER_PIXEL * width_px:
        return np.arange(n)
    span = max(float(t[-1] - t[0]), 1e-300)
    col = np.minimum(((t - t[0]) * (width_px / span)).astype(np.int64), width_px - 1)
    new = np.r_[True, col[1:] != col[:-1]]
    starts = np.flatnonzero(new)
    seg = np.cumsum(new) - 1  # each sample's column, numbered among the non-empty ones
    keep = [starts, np.append(starts[1:], n) - 1]
    rows = np.arange(n)
    for y in ys:
        y = np.asarray(y, dtype=float)
        nan = np.isnan(y)
        for fill, reduce in ((np.inf, np.minimum), (-np.inf, np.maximum)):
            v = np.where(nan, fill, y)
            hit = v == reduce.reduceat(v, starts)[seg]
            keep.append(np.minimum.reduceat(np.where(hit, rows, n - 1), starts))
        keep.append(np.flatnonzero(nan != np.r_[False, nan[:-1]]))
    return np.unique(np.concatenate(keep))


def thin_path(xy: np.ndarray, keep_too: np.ndarray | None = None) -> np.ndarray:
    """Indices of the points of a path ``xy`` (N, 2) to draw: the first and last, each point
    that leaves the grid cell (:data:`PATH_GRID_PX` cells across the path's extent) of the
    point before it, and every point where ``keep_too`` (N,) is set (a change of rapid or
    feed colour). A 1 ms reference has ~10⁶ points where the figure has ~10³ pixels."""
    n = xy.shape[0]
    if n <= 2 * PATH_GRID_PX:
        return np.arange(n)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    cell_mm = max(float(np.max(hi - lo)), 1e-9) / PATH_GRID_PX
    cell = np.floor((xy - lo) / cell_mm).astype(np.int64)
    moved = np.r_[True, np.any(cell[1:] != cell[:-1], axis=1)]
    moved[-1] = True
    if keep_too is not None:
        moved |= keep_too
    return np.flatnonzero(moved)


def _changes(flags) -> np.ndarray:
    """(N,) bool: where ``flags`` differs from the sample before or after it."""
    f = np.asarray(flags)
    d = np.r_[False, f[1:] != f[:-1]]
    return d | np.r_[d[1:], False]


def path_figure(
    path_mm,
    corner_pieces: Sequence,
    title: str = "Tool path and corner regions",
    figsize_in=FIGSIZE_IN,
    rapid=None,
    feed_mm_s=None,
    marks_mm=None,
    marks_label: str | None = None,
):
    """The Figure of :func:`plot_path` (not saved)."""
    from matplotlib.collections import LineCollection

    path = _xy(path_mm, "path_mm")
    pieces = [_xy(p, "corner piece") for p in corner_pieces]
    fig, (ax,) = _figure(figsize_in)
    n = path.shape[0]
    rapid = np.zeros(n, dtype=bool) if rapid is None else np.asarray(rapid, dtype=bool)
    if rapid.shape != (n,):
        raise ConfigError(f"rapid must have one flag per point ({n}), got {rapid.shape}")
    feed = None
    if feed_mm_s is not None:
        feed = np.asarray(feed_mm_s, dtype=float)
        if feed.shape != (n,):
            raise ConfigError(f"feed_mm_s must have one value per point ({n}), got {feed.shape}")
    keep = thin_path(path, _changes(rapid))
    path, rapid = path[keep], rapid[keep]
    if rapid.any():
        # A point is on a rapid when the move that reaches it is one: the segment between two
        # points is drawn as the later point's move.
        segs = np.stack([path[:-1], path[1:]], axis=1)[rapid[1:]]
        ax.add_collection(
            LineCollection(segs, colors="0.55", linestyles="dashed", lw=0.9, label="rapid (G0)")
        )
    cut = np.concatenate(([True], ~rapid[1:]))
    if feed is not None:
        feed = feed[keep]
        cutting = ~rapid[1:]
        segs = np.stack([path[:-1], path[1:]], axis=1)[cutting]
        lc = LineCollection(segs, cmap="viridis", lw=1.4)
        lc.set_array(feed[1:][cutting] * 60.0)
        ax.add_collection(lc)
        fig.colorbar(lc, ax=ax, label="feed [mm/min]")
    else:
        ax.add_collection(
            LineCollection(_segments_xy(path, cut), colors="0.45", lw=1.0, label="path")
        )
    ax.autoscale_view()
    if pieces:
        # One collection for every corner piece (a 2.5-D part has hundreds).
        ax.add_collection(
            LineCollection(
                [p for p in pieces if p.shape[0] > 1],
                colors="tab:red",
                lw=2.2,
                label=f"corner pieces (PH): {len(pieces)}",
            )
        )
    if marks_mm is not None and len(marks_mm):
        marks = _xy(marks_mm, "marks_mm")
        ax.plot(
            marks[:, 0], marks[:, 1], "o", color="tab:red", ms=5, mfc="white", label=marks_label
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    count = f"{len(pieces)} corner piece" + ("" if len(pieces) == 1 else "s")
    ax.set_title(f"{title} ({count})")
    ax.grid(True, lw=0.4, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize="small")
    return fig


def side_figure(path_mm, title: str, figsize_in=FIGSIZE_IN, rapid=None):
    """The Figure of :func:`plot_path_sides` (not saved): the path seen from the front (XZ)
    and from the side (YZ), cuts solid, rapids dashed grey."""
    from matplotlib.collections import LineCollection

    p = np.asarray(path_mm, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ConfigError(f"path_mm must be an (N, 3) array of points, got {p.shape}")
    n = p.shape[0]
    rapid = np.zeros(n, dtype=bool) if rapid is None else np.asarray(rapid, dtype=bool)
    if rapid.shape != (n,):
        raise ConfigError(f"rapid must have one flag per point ({n}), got {rapid.shape}")
    fig, _ = _figure(figsize_in)
    fig.clear()
    axes = fig.subplots(1, 2, sharey=True)
    for ax, (a, name) in zip(axes, ((0, "x"), (1, "y"))):
        xz = p[:, [a, 2]]
        keep = thin_path(xz, _changes(rapid))
        xz, r = xz[keep], rapid[keep]
        segs = np.stack([xz[:-1], xz[1:]], axis=1)
        if (~r[1:]).any():
            ax.add_collection(LineCollection(segs[~r[1:]], colors="tab:blue", lw=1.0, label="cut"))
        if r[1:].any():
            ax.add_collection(
                LineCollection(
                    segs[r[1:]], colors="0.55", linestyles="dashed", lw=0.9, label="rapid (G0)"
                )
            )
        ax.autoscale_view()
        ax.set_xlabel(f"{name} [mm]")
        side = "from the front" if a == 0 else "from the side"
        ax.set_title(f"{title}, {name.upper()}Z {side}", fontsize="medium")
        ax.grid(True, lw=0.4, alpha=0.5)
    axes[0].set_ylabel("z [mm]")
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(loc="best", fontsize="small")
    return fig


def plot_path_sides(path_mm, out_png: str, title: str, figsize_in=FIGSIZE_IN, rapid=None) -> str:
    """The path (N, 3) [mm] from the front (XZ) and the side (YZ): plunges, depths and Z
    rapids, which the XY view hides. ``rapid`` (N,): the points reached by a rapid."""
    return _save(side_figure(path_mm, title, figsize_in, rapid), out_png)


def plot_path(
    path_mm,
    corner_pieces: Sequence,
    out_png: str,
    title: str = "Tool path and corner regions",
    figsize_in=FIGSIZE_IN,
    rapid=None,
    feed_mm_s=None,
    marks_mm=None,
    marks_label: str | None = None,
) -> str:
    """Fig. 1: the path (N, 2|3) [mm] in XY, with each corner piece (m, 2|3) highlighted.

    Corner pieces (the PH quintics replacing the sharp-corner regions, SPEC §5-§6) are drawn
    over the path in a second colour with their end points marked. ``rapid`` (N,) marks the
    points reached by a rapid move: those moves are drawn dashed; ``feed_mm_s`` (N,), when
    given, colours the cutting moves by their feed (a colour bar in mm/min); ``marks_mm``
    (k, 2|3) circles a few points (the slowest corners) under ``marks_label``. The path is
    thinned to the figure's resolution (:func:`thin_path`). Returns ``out_png``.
    """
    fig = path_figure(
        path_mm, corner_pieces, title, figsize_in, rapid, feed_mm_s, marks_mm, marks_label
    )
    return _save(fig, out_png)


#: Colours of the limiting factors (tab10 and tab20 entries; index = Limit code).
LIMIT_COLOURS = (
    "tab:green",
    "tab:olive",
    "0.6",
    "tab:purple",
    "tab:blue",
    "tab:brown",
    "tab:pink",
    "tab:cyan",
    "tab:red",
    "black",
    "tab:orange",
    "gold",
    "0.3",
    "0.3",
)


def limits_figure(path_mm, limit_code, names: Sequence[str], title: str, figsize_in=FIGSIZE_IN):
    """The Figure of :func:`plot_path_limits` (not saved)."""
    from matplotlib.collections import LineCollection

    path = _xy(path_mm, "path_mm")
    code = np.asarray(limit_code, dtype=np.int64)
    if code.shape != (path.shape[0],):
        raise ConfigError(f"limit_code must have one code per point ({path.shape[0]})")
    fig, (ax,) = _figure(figsize_in)
    keep = thin_path(path, _changes(code))
    path, code = path[keep], code[keep]
    segs = np.stack([path[:-1], path[1:]], axis=1)
    seg_code = code[1:]
    for c in np.unique(seg_code).tolist():
        ax.add_collection(
            LineCollection(
                segs[seg_code == c],
                lw=1.6,
                label=names[c],
                colors=LIMIT_COLOURS[c % len(LIMIT_COLOURS)],
            )
        )
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(title)
    ax.grid(True, lw=0.4, alpha=0.5)
    if seg_code.size:
        ax.legend(loc="best", fontsize="small")
    return fig


def plot_path_limits(
    path_mm,
    limit_code,
    names: Sequence[str],
    out_png: str,
    title: str = "Tool path by limiting factor",
    figsize_in=FIGSIZE_IN,
) -> str:
    """The path (N, 2|3) [mm] in XY, each move coloured by the limit that set its feed:
    ``limit_code`` (N,) the code of the move reaching each point, ``names`` the legend
    names by code (:class:`nurbscnc.plan.explain.Limit`)."""
    return _save(limits_figure(path_mm, limit_code, names, title, figsize_in), out_png)


def feed_along_figure(
    s_mm,
    v_mm_s,
    piece_start_mm,
    piece_end_mm,
    programmed_mm_s,
    cap_mm_s=None,
    title: str = "Feed along the program",
    figsize_in=FIGSIZE_IN,
):
    """The Figure of :func:`plot_feed_along` (not saved)."""
    s, v = (np.asarray(a, dtype=float) for a in (s_mm, v_mm_s))
    if s.ndim != 1 or s.shape != v.shape:
        raise ConfigError("feed along: s_mm and v_mm_s must be equally long 1-D arrays")
    a, b, f = (np.asarray(x, dtype=float) for x in (piece_start_mm, piece_end_mm, programmed_mm_s))
    fig, (ax,) = _figure(figsize_in)

    def steps(y):
        # Horizontal steps: each piece's value over [start, end], gaps (NaN) between pieces.
        xs = np.column_stack([a, b, np.full(a.size, np.nan)]).ravel()
        ys = np.column_stack([y, y, np.full(a.size, np.nan)]).ravel()
        return xs, ys * 60.0

    ax.plot(*steps(f), color="black", lw=1.3, ls="--", label="programmed F", zorder=3)
    if cap_mm_s is not None:
        ax.plot(
            *steps(np.asarray(cap_mm_s, dtype=float)),
            color="tab:orange",
            lw=0.8,
            ls=":",
            label="cap",
        )
    k = decimate_series(s, [v], round(figsize_in[0] * DPI))
    ax.plot(s[k], v[k] * 60.0, color="tab:blue", lw=1.0, label="planned feed", zorder=2)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("path length [mm]")
    ax.set_ylabel("feed [mm/min]")
    ax.set_title(title)
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.legend(loc="best")
    return fig


def plot_feed_along(
    s_mm,
    v_mm_s,
    piece_start_mm,
    piece_end_mm,
    programmed_mm_s,
    out_png: str,
    cap_mm_s=None,
    title: str = "Feed along the program",
    figsize_in=FIGSIZE_IN,
) -> str:
    """The planned feed v [mm/s] over the path length s [mm] (drawn in mm/min), with each
    piece's programmed F (``piece_start_mm``..``piece_end_mm``, ``programmed_mm_s``) as a
    dashed step and, optionally, its final cap ``cap_mm_s`` dotted."""
    return _save(
        feed_along_figure(
            s_mm, v_mm_s, piece_start_mm, piece_end_mm, programmed_mm_s, cap_mm_s, title, figsize_in
        ),
        out_png,
    )


def _time_series_plot(
    series: Mapping,
    out_png: str,
    title: str,
    ylabel: str,
    what: str,
    lw: float,
    figsize_in,
    zero_line: bool,
    y_from_zero: bool,
    limit: tuple | None = None,
) -> str:
    """One axes of ``{name: (t_s, y)}`` lines against time [s], saved to ``out_png``."""
    return _save(
        _time_series_figure(
            series, title, ylabel, what, lw, figsize_in, zero_line, y_from_zero, limit
        ),
        out_png,
    )


def _time_series_figure(
    series: Mapping,
    title: str,
    ylabel: str,
    what: str,
    lw: float,
    figsize_in,
    zero_line: bool,
    y_from_zero: bool,
    limit: tuple | None = None,
):
    """The Figure of :func:`_time_series_plot`; ``limit`` (value, label): a red dashed
    horizontal line (ε_max on the contour plot)."""
    fig, (ax,) = _figure(figsize_in)
    width_px = round(figsize_in[0] * DPI)
    for name, (t, y) in _series(series, 2, what):
        k = decimate_series(t, [y], width_px)
        if name == RAPIDS_LABEL:
            ax.plot(t[k], y[k], lw=lw, label=name, color="0.65", zorder=1)
        elif name == PROGRAMMED_LABEL:  # above the planned feed, dashed
            ax.plot(t[k], y[k], lw=1.3, ls="--", color="black", label=name, zorder=3)
        else:
            ax.plot(t[k], y[k], lw=lw, label=name, zorder=2)
    if zero_line:
        ax.axhline(0.0, color="0.3", lw=0.5)
    if limit is not None:
        ax.axhline(limit[0], color="tab:red", lw=0.9, ls="--", label=limit[1])
    if y_from_zero:
        ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.legend(loc="best")
    return fig


def plot_feed_profiles(
    profiles: Mapping,
    out_png: str,
    title: str = "Feed profiles",
    figsize_in=FIGSIZE_IN,
    programmed=None,
) -> str:
    """Fig. 2/4/6: feed over time t [s], one line per ``{name: (t_s, v_mm_s)}``, drawn in
    mm/min (the unit of the program's F and of every other feed figure); ``programmed``
    ``(t_s, F_mm_s)``: the programmed feed of each sample's move, dashed above them."""
    series = {name: (t, np.asarray(v, dtype=float) * 60.0) for name, (t, v) in profiles.items()}
    if programmed is not None:
        series[PROGRAMMED_LABEL] = (programmed[0], np.asarray(programmed[1], dtype=float) * 60.0)
    return _time_series_plot(
        series,
        out_png,
        title,
        "feed [mm/min]",
        "feed profiles",
        1.0,
        figsize_in,
        zero_line=False,
        y_from_zero=True,
    )


def plot_contour_error(
    errors: Mapping,
    out_png: str,
    title: str = "Contour error",
    figsize_in=FIGSIZE_IN,
    eps_max_um: float | None = None,
) -> str:
    """Fig. 7: contour error [µm] over time [s], one line per ``{name: (t_s, err_um)}``;
    ``eps_max_um``, when given, the limit ε_max [µm] as a red dashed line."""
    limit = None if eps_max_um is None else (float(eps_max_um), f"ε_max = {eps_max_um:g} µm")
    return _time_series_plot(
        errors,
        out_png,
        title,
        "contour error [µm]",
        "contour errors",
        0.8,
        figsize_in,
        zero_line=True,
        y_from_zero=False,
        limit=limit,
    )


def plot_axis_errors(
    errors: Mapping,
    out_png: str,
    title: str = "Axis tracking errors",
    figsize_in=FIGSIZE_IN,
) -> str:
    """x and y axis errors [µm] over time [s] (two panels), ``{name: (t_s, ex_um, ey_um)}``."""
    series = _series(errors, 3, "axis errors")
    fig, (ax_x, ax_y) = _figure(figsize_in, nrows=2)
    for name, (t, ex, ey) in series:
        ax_x.plot(t, ex, lw=0.8, label=name)
        ax_y.plot(t, ey, lw=0.8, label=name)
    ax_x.set_ylabel("x error [µm]")
    ax_y.set_ylabel("y error [µm]")
    ax_y.set_xlabel("time [s]")
    ax_x.set_title(title)
    for ax in (ax_x, ax_y):
        ax.grid(True, lw=0.4, alpha=0.5)
    ax_x.legend(loc="best")
    return _save(fig, out_png)
