"""Writing results: reference points and profile dumps as CSV or NPZ, atomically.

Every writer goes through :func:`atomic_output`: the data is written to a temporary file in
the destination's folder and renamed over the destination only when complete, so a failure
never leaves a half-written file (and never clobbers a good one).
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile

import numpy as np

from nurbscnc.errors import OutputError

#: Column order of a reference-point file (units: s, mm, mm, mm, mm/s, index, source line).
POINT_COLUMNS = ("t", "x", "y", "z", "feed", "piece", "line")
#: Column order of a profile dump (s, mm, mm/s, mm/s², mm/s³, index).
PROFILE_COLUMNS = ("t", "s", "v", "a", "j", "piece")


@contextlib.contextmanager
def atomic_output(path: str, binary: bool = False):
    """Yield a file object; on success it replaces ``path`` atomically (``-``: stdout)."""
    if path == "-":
        if binary:
            yield sys.stdout.buffer
        else:
            yield sys.stdout
        return
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise OutputError(f"cannot write {path}: folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=".nurbscnc-", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb" if binary else "w", newline="" if not binary else None) as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _columns_csv(fh, names, columns, formats) -> None:
    fh.write(",".join(names) + "\n")
    n = len(columns[0])
    block = 65536
    for start in range(0, n, block):
        chunk = np.column_stack([np.asarray(c[start : start + block], dtype=float)
                                 for c in columns])  # fmt: skip
        buf = io.StringIO()
        np.savetxt(buf, chunk, fmt=formats, delimiter=",")
        fh.write(buf.getvalue())


def write_table(path: str, names, columns, formats) -> None:
    """Write named columns to ``path``: NPZ when it ends in .npz, else CSV (``-``: stdout)."""
    try:
        if path.endswith(".npz"):
            with atomic_output(path, binary=True) as fh:
                np.savez_compressed(fh, **{n: np.asarray(c) for n, c in zip(names, columns)})
        else:
            with atomic_output(path) as fh:
                _columns_csv(fh, names, columns, formats)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None


def write_points(path: str, samples) -> None:
    """Reference points: ``t,x,y,z,feed,piece,line`` (s, mm, mm, mm, mm/s, index, line)."""
    p = samples.points_mm
    cols = (samples.t_s, p[:, 0], p[:, 1], p[:, 2], samples.v_mm_s, samples.piece, samples.line)
    write_table(path, POINT_COLUMNS, cols, ["%.6f", "%.9f", "%.9f", "%.9f", "%.6f", "%d", "%d"])


def write_profile(path: str, t_s, s_mm, v, a, j, piece) -> None:
    """A feed-profile dump: ``t,s,v,a,j,piece`` (s, mm, mm/s, mm/s², mm/s³, index)."""
    write_table(path, PROFILE_COLUMNS, (t_s, s_mm, v, a, j, piece),
                ["%.6f", "%.9f", "%.6f", "%.4f", "%.2f", "%d"])  # fmt: skip


def read_points(path: str) -> dict:
    """Read a reference-point file (CSV with the header above, or NPZ) into arrays."""
    try:
        if path.endswith(".npz"):
            with np.load(path) as data:
                missing = [c for c in POINT_COLUMNS if c not in data]
                if missing:
                    raise OutputError(f"{path}: missing arrays {', '.join(missing)}")
                return {c: np.asarray(data[c]) for c in POINT_COLUMNS}
        with open(path, encoding="utf-8") as fh:
            header = fh.readline().strip()
            if tuple(header.split(",")) != POINT_COLUMNS:
                raise OutputError(
                    f"{path}:1: expected the header {','.join(POINT_COLUMNS)}, got {header[:60]!r}"
                )
            data = np.loadtxt(fh, delimiter=",", ndmin=2)
    except (OSError, ValueError) as exc:
        raise OutputError(f"cannot read {path}: {exc}") from None
    if data.shape[1] != len(POINT_COLUMNS):
        raise OutputError(f"{path}: expected {len(POINT_COLUMNS)} columns, got {data.shape[1]}")
    return {c: data[:, i] for i, c in enumerate(POINT_COLUMNS)}
