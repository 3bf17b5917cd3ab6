"""Reference points as a LinuxCNC ``halstreamer`` file: one line per servo period.

LinuxCNC's ``streamer`` HAL component (loaded as ``loadrt streamer depth=D cfg=fff``) exports
one output pin per character of its cfg string and, every time its function runs (once per
period of the thread it is added to), takes one line of its FIFO and writes the values to the
pins; the user-space ``halstreamer`` program fills the FIFO from a text file. The file format,
from the halstreamer(1) and streamer(9) manual pages: one line per sample, values separated by
whitespace, in the order of the cfg string; floats as strtod(3) reads them; lines beginning with
``#`` are comments. When the FIFO runs empty the pins keep their last values.

This writer emits cfg ``fff``: x y z in mm (machine coordinates, the units of the profile), one
line per servo period T_s, six decimals (1 nm, below any step size). A program that uses rotary
axes adds one float pin per axis it uses, in the order a b c, after z (cfg ``ffff`` for A alone):
its position in degrees (machine coordinates, six decimals: 1e-6°, 17 nm at 1 m radius). The
first line is the start point, the last the end point at rest, exactly the points of
``run -o points.csv``. A comment header says the program, T_s, the columns, the line count, the
cfg string and the start point. The file is played at whatever rate the thread runs: the servo
thread's period must equal T_s (docs/linuxcnc.md).
"""

from __future__ import annotations

import numpy as np

from nurbscnc.output.files import (
    atomic_output,
    checked_rotary_axes,
    rotary_columns,
    windows_and_axes,
)

#: streamer cfg string of the columns this writer emits for a program without rotary axes
#: (three float pins: x, y, z); :func:`streamer_cfg` adds one per rotary axis.
STREAMER_CFG = "fff"
#: Decimals per value [mm, or deg for a rotary axis]: 1e-6 mm = 1 nm.
DECIMALS = 6


def streamer_cfg(rotary_axes=()) -> str:
    """The streamer cfg string: ``fff`` (x y z) and one ``f`` per rotary axis used."""
    return STREAMER_CFG + "f" * len(checked_rotary_axes(rotary_axes))


def _columns_text(rotary_axes: tuple) -> str:
    """The header's words for the columns: ``x y z [mm, machine coords]``, with rotary axes
    ``x y z a [mm; a in deg; machine coords]``."""
    if not rotary_axes:
        return "x y z [mm, machine coords]"
    names = " ".join(rotary_axes)
    return f"x y z {names} [mm; {names} in deg; machine coords]"


def halstreamer_header(
    points_mm: np.ndarray,
    period_s: float,
    program: str = "",
    count: int | None = None,
    rotary_axes=(),
) -> str:
    """The comment lines at the top of the file (each begins with ``#``): ``count`` lines
    (None: as many as ``points_mm`` has), starting at ``points_mm[0]`` (x y z [mm], then the
    ``rotary_axes`` [deg])."""
    axes = checked_rotary_axes(rotary_axes)
    start = " ".join(f"{v:.{DECIMALS}f}" for v in np.round(points_mm[0], DECIMALS) + 0.0)
    count = points_mm.shape[0] if count is None else int(count)
    return (
        f"# nurbscnc reference points for LinuxCNC halstreamer{': ' + program if program else ''}\n"
        f"# one line per servo period T_s = {period_s * 1e3:g} ms: {_columns_text(axes)}\n"
        f"# loadrt streamer depth=... cfg={streamer_cfg(axes)}; the servo thread period must be "
        f"{round(period_s * 1e9)} ns\n"
        f"# {count} lines; start point {start} (the machine must be there)\n"
    )


def halstreamer_lines(points_mm: np.ndarray) -> str:
    """The data lines ``x y z`` [mm] (and a rotary value [deg] per further column) for
    points (N, 3 + k), newline-terminated."""
    p = np.asarray(points_mm, dtype=float)
    # -0.000000 is harmless to strtod, but a clean file has no negative zeros: round first.
    p = np.round(p, DECIMALS) + 0.0
    # One %-format over the whole array (a line template repeated N times): the fastest way
    # Python has to print floats, no per-row loop.
    line = " ".join([f"%.{DECIMALS}f"] * p.shape[1]) + "\n"
    return (line * p.shape[0]) % tuple(p.ravel().tolist())


def halstreamer_values(samples) -> np.ndarray:
    """The values of one window of :class:`~nurbscnc.plan.timing.Samples` as the file's
    columns (N, 3 + k): x y z [mm], then the rotary axes the program uses [deg]."""
    rotary = rotary_columns(samples)
    if not rotary:
        return samples.points_mm
    return np.column_stack((samples.points_mm, *rotary))


#: Rows formatted per string (a window may be larger: the text of 64 Ki rows is ~2.5 MB).
LINES_BLOCK = 1 << 16


def write_halstreamer(
    path: str, points_mm, period_s: float, program: str = "", rotary_axes=()
) -> None:
    """Write points (N, 3 + k) — x y z [mm], then the k ``rotary_axes`` [deg] — one per
    period ``period_s`` [s], as a halstreamer file (atomically; ``-`` is stdout)."""
    p = np.asarray(points_mm, dtype=float)
    width = 3 + len(checked_rotary_axes(rotary_axes))
    if p.ndim != 2 or p.shape[1] != width or p.shape[0] == 0:
        raise ValueError(f"points must be (N, {width}) with N >= 1, got {p.shape}")
    write_halstreamer_windows(path, [p], p.shape[0], period_s, program, rotary_axes)


def write_halstreamer_windows(
    path: str, windows, count: int, period_s: float, program: str = "", rotary_axes=()
) -> None:
    """:func:`write_halstreamer` of points given window by window (arrays (m, 3 + k) in
    order, ``count`` rows in all): the header (which names the count and the first point)
    from the first window, then each window's lines as it comes — the same bytes as the
    whole-array writer, one window of memory. Fewer or more rows than ``count`` is a
    ValueError (and no file)."""
    width = 3 + len(checked_rotary_axes(rotary_axes))
    with atomic_output(path) as fh:
        rows = 0
        for w in windows:
            p = np.asarray(w, dtype=float)
            if p.ndim != 2 or p.shape[1] != width:
                raise ValueError(f"a window of points must be (m, {width}), got {p.shape}")
            if rows == 0 and p.shape[0]:
                fh.write(halstreamer_header(p, period_s, program, count, rotary_axes))
            for lo in range(0, p.shape[0], LINES_BLOCK):
                fh.write(halstreamer_lines(p[lo : lo + LINES_BLOCK]))
            rows += p.shape[0]
        if rows != count:
            raise ValueError(f"{rows} halstreamer lines written, {count} announced")


def write_halstreamer_samples(
    path: str, windows, count: int, period_s: float, program: str = ""
) -> None:
    """:func:`write_halstreamer_windows` of :class:`~nurbscnc.plan.timing.Samples` given
    window by window: x y z and the rotary axes the program uses (the first window's
    :attr:`~nurbscnc.plan.timing.Samples.rotary_axes`, every window checked to name the
    same)."""
    axes, windows = windows_and_axes(windows)
    write_halstreamer_windows(
        path, (halstreamer_values(w) for w in windows), count, period_s, program, axes
    )
