"""The paper's figures as PNG files (SPEC §9, issue 5; the ``plot`` extra, matplotlib).

Pure functions: arrays in, one PNG out. Each builds its own ``matplotlib.figure.Figure`` on an
Agg canvas (no pyplot, no global state, no display needed) and writes through
:func:`nurbscnc.output.files.atomic_output`, so a failed plot never leaves half a file.
matplotlib is imported only when a plot is made; without it a :class:`ConfigError` says how to
install the extra.

- :func:`plot_path`: the tool path in XY with the corner regions / PH pieces marked (Fig. 1).
- :func:`plot_feed_profiles`: feed over time per algorithm (Fig. 2, 4, 6).
- :func:`plot_contour_error`: contour error over time per algorithm (Fig. 7).
- :func:`plot_axis_errors`: x and y axis errors over time per algorithm.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from nurbscnc.errors import ConfigError, OutputError
from nurbscnc.output.files import atomic_output

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


def plot_path(
    path_mm,
    corner_pieces: Sequence,
    out_png: str,
    title: str = "Tool path and corner regions",
    figsize_in=FIGSIZE_IN,
) -> str:
    """Fig. 1: the path (N, 2|3) [mm] in XY, with each corner piece (m, 2|3) highlighted.

    Corner pieces (the PH quintics replacing the sharp-corner regions, SPEC §5-§6) are drawn
    over the path in a second colour with their end points marked. Returns ``out_png``.
    """
    path = _xy(path_mm, "path_mm")
    pieces = [_xy(p, "corner piece") for p in corner_pieces]
    fig, (ax,) = _figure(figsize_in)
    ax.plot(path[:, 0], path[:, 1], color="0.45", lw=1.0, label="path")
    for i, piece in enumerate(pieces):
        ax.plot(piece[:, 0], piece[:, 1], color="tab:red", lw=2.2,
                label="corner region (PH piece)" if i == 0 else None)  # fmt: skip
        ends = piece[[0, -1]]
        ax.plot(ends[:, 0], ends[:, 1], "o", color="tab:red", ms=3.5, mfc="white")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    count = f"{len(pieces)} corner piece" + ("" if len(pieces) == 1 else "s")
    ax.set_title(f"{title} ({count})")
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.legend(loc="best")
    return _save(fig, out_png)


def _time_series_plot(series: Mapping, out_png: str, title: str, ylabel: str, what: str,
                      lw: float, figsize_in, zero_line: bool, y_from_zero: bool) -> str:
    """One axes of ``{name: (t_s, y)}`` lines against time [s], saved to ``out_png``."""
    fig, (ax,) = _figure(figsize_in)
    for name, (t, y) in _series(series, 2, what):
        ax.plot(t, y, lw=lw, label=name)
    if zero_line:
        ax.axhline(0.0, color="0.3", lw=0.5)
    if y_from_zero:
        ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.legend(loc="best")
    return _save(fig, out_png)


def plot_feed_profiles(
    profiles: Mapping,
    out_png: str,
    title: str = "Feed profiles",
    figsize_in=FIGSIZE_IN,
) -> str:
    """Fig. 2/4/6: feed v [mm/s] over time t [s], one line per ``{name: (t_s, v_mm_s)}``."""
    return _time_series_plot(profiles, out_png, title, "feed [mm/s]", "feed profiles", 1.0,
                             figsize_in, zero_line=False, y_from_zero=True)


def plot_contour_error(
    errors: Mapping,
    out_png: str,
    title: str = "Contour error",
    figsize_in=FIGSIZE_IN,
) -> str:
    """Fig. 7: contour error [µm] over time [s], one line per ``{name: (t_s, err_um)}``."""
    return _time_series_plot(errors, out_png, title, "contour error [µm]", "contour errors",
                             0.8, figsize_in, zero_line=True, y_from_zero=False)


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
