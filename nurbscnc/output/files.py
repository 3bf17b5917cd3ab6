"""Writing results: reference points and profile dumps as CSV or NPZ, atomically.

Every writer goes through :func:`atomic_output`, which decides what ``-o PATH`` means:

- ``-``: standard output.
- a symbolic link is followed (as ``cp`` or a shell redirection do): the link stays, its final
  target is what gets written (a dangling link creates its target);
- a regular file (or a new name): the data goes to a temporary ``.nurbscnc-*.tmp`` in the
  target's folder and is renamed over the target only when complete, so a failure never leaves
  half a file nor clobbers a good one. An existing file keeps its permission bits (and, when
  the process may, its owner); a new file gets ``0666`` minus the umask, as any Unix tool;
- a character device or a FIFO (``/dev/null``, ``/dev/stdout``, a named pipe) is opened and
  written directly: it is never replaced by a rename;
- a directory, a block device or a socket is refused (:class:`OutputError`, exit 3).

Nothing but the target (and, for a moment, the temporary file beside it) is ever touched.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import secrets
import stat
import sys
import warnings
import zipfile
import zlib
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from nurbscnc.errors import DataError, OutputError, SourcePos
from nurbscnc.output import inputs
from nurbscnc.output.inputs import read_input_bytes
from nurbscnc.output.npz import write_npz

if TYPE_CHECKING:  # the annotations only: no import at start-up
    from nurbscnc.plan.timing import Samples

#: Column order of a reference-point file (units: s, mm, mm, mm, mm/s, index, source line).
POINT_COLUMNS = ("t", "x", "y", "z", "feed", "piece", "line")
#: The rotary axes' columns [deg, machine coordinates]: each one written only when the
#: program uses that axis (:attr:`~nurbscnc.plan.timing.Samples.rotary_axes`), in this order,
#: between ``z`` and ``feed`` (:func:`point_names`). A program without rotary axes writes
#: exactly POINT_COLUMNS.
ROTARY_COLUMNS = ("a", "b", "c")
#: Column order of a profile dump (s, mm, mm/s, mm/s², mm/s³, index).
PROFILE_COLUMNS = ("t", "s", "v", "a", "j", "piece")
#: Largest magnitude accepted in a reference-point file (1e9 mm = 1000 km for a coordinate,
#: 1e9 s, 1e9 mm/s). Far beyond any machine, yet its square and sums of squares stay finite,
#: so the servo simulation can never overflow on a point file it accepted.
POINT_VALUE_LIMIT = 1e9
#: Prefix and suffix of the temporary file beside a regular-file output.
TEMP_PREFIX, TEMP_SUFFIX = ".nurbscnc-", ".tmp"


def output_target(path: str) -> tuple[str, os.stat_result | None]:
    """Where ``-o path`` writes: the path with every symbolic link resolved, and its ``stat``
    (None when it does not exist yet). Raises OutputError for what cannot be written.

    The type comes from ``stat(path)`` itself, so ``/dev/stdout`` or ``/dev/fd/N`` (links
    into /proc that name an open file, not a path) are judged by what they reach: a pipe or a
    terminal is written in place; such a link is also written in place when it reaches a
    regular file (the shell's ``> file``), never replaced by a rename.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    target = os.path.realpath(path)
    if st is None:
        folder = os.path.dirname(target)
        if not os.path.isdir(folder):
            raise OutputError(f"cannot write {path}: folder {folder} does not exist")
        return target, None
    if stat.S_ISDIR(st.st_mode):
        raise OutputError(f"cannot write {path}: it is a directory")
    if not (stat.S_ISREG(st.st_mode) or stat.S_ISCHR(st.st_mode) or stat.S_ISFIFO(st.st_mode)):
        raise OutputError(f"cannot write {path}: not a regular file, character device or FIFO")
    return target, st


def _in_place(path: str, st: os.stat_result | None) -> bool:
    """Write by opening the path (not by rename): devices, FIFOs, open files via /proc."""
    if st is None:
        return False
    return not stat.S_ISREG(st.st_mode) or _through_proc(path)


def _through_proc(path: str) -> bool:
    """Whether resolving ``path`` passes through /proc (``/dev/stdout``, ``/dev/fd/1``)."""
    current = os.path.abspath(path)
    for _ in range(40):  # the kernel's own limit on a chain of links
        folder, name = os.path.split(current)
        folder = os.path.realpath(folder)
        if folder == "/proc" or folder.startswith("/proc/"):
            return True
        current = os.path.join(folder, name)
        if not os.path.islink(current):
            return False
        current = os.path.join(folder, os.readlink(current))
    return False


def _create_temp(folder: str, mode: int, named: list) -> tuple[int, str]:
    """A new, exclusive temporary file in ``folder`` created with ``mode`` (the kernel applies
    the umask); returns (fd, path). Its name is in ``named`` from just before it is created
    (a signal can land between the file's creation and this function's return: the caller
    removes it by that name)."""
    for _ in range(100):
        tmp = os.path.join(folder, f"{TEMP_PREFIX}{secrets.token_hex(6)}{TEMP_SUFFIX}")
        named[:] = [tmp]
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, mode), tmp
        except FileExistsError:  # not ours
            named.clear()
            continue
    raise FileExistsError(f"no free temporary name in {folder}")


@contextlib.contextmanager
def atomic_output(path: str, binary: bool = False):
    """Yield a file object for ``path`` (module docstring: ``-``, links, regular files by
    rename, devices and FIFOs directly). OSError passes through (callers name the file)."""
    if path == "-":
        yield sys.stdout.buffer if binary else sys.stdout
        return
    target, st = output_target(path)
    if st is not None and not os.access(path, os.W_OK):  # as a shell redirection would
        raise OutputError(f"cannot write {path}: Permission denied")
    mode, newline = ("wb", None) if binary else ("w", "")
    if _in_place(path, st):  # a device, a FIFO, /dev/stdout: write in place
        with open(path, mode, newline=newline) as fh:
            yield fh
        return
    fd, named = -1, []
    try:
        fd, tmp = _create_temp(os.path.dirname(target), 0o666, named)
        if st is not None:  # keep the existing file's permissions (and owner if we may)
            os.fchmod(fd, stat.S_IMODE(st.st_mode))
            if (st.st_uid, st.st_gid) != (os.geteuid(), os.getegid()):
                with contextlib.suppress(OSError):
                    os.fchown(fd, st.st_uid, st.st_gid)
        # The descriptor stays ours (closefd=False), closed once below: were the file
        # object its owner, a signal between its creation and the line marking that would
        # have it closed twice (by the object, then here), the second time perhaps another
        # file's by then.
        with os.fdopen(fd, mode, newline=newline, closefd=False) as fh:
            yield fh
        closing, fd = fd, -1  # marked first: a signal in between leaks it, never closes twice
        os.close(closing)
        os.replace(tmp, target)
    except BaseException:
        if fd >= 0:
            with contextlib.suppress(OSError):
                os.close(fd)
        for tmp in named:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise


def _csv_rows(fh, columns, formats) -> None:
    """Rows of one window of columns as CSV text (no header): np.savetxt formats each row on
    its own, so the windows' text joined is the whole table's, byte for byte."""
    n = len(columns[0])
    block = 65536
    for start in range(0, n, block):
        chunk = np.column_stack(
            [np.asarray(c[start : start + block], dtype=float) for c in columns]
        )
        buf = io.StringIO()
        np.savetxt(buf, chunk, fmt=formats, delimiter=",")
        fh.write(buf.getvalue())


def write_table_windows(
    path: str, names, windows, count: int, formats, npz: bool | None = None
) -> None:
    """Write named columns given window by window (an iterable of column tuples, rows in
    order, ``count`` rows in all) to ``path`` (``-``: stdout), atomically: NPZ when ``npz``
    (None: when the path ends in .npz), else CSV. Memory: one window (the NPZ's columns are
    deflated as they come and spooled to disk, :func:`~nurbscnc.output.npz.write_npz`). An
    exception from ``windows`` (a point outside the soft limits, found as it is made)
    leaves no file."""
    if npz is None:
        npz = path.endswith(".npz")
    try:
        if npz:
            spool_dir = None  # stdout, a device, a FIFO: the system's temporary folder
            if path != "-":
                target, st = output_target(path)
                spool_dir = None if _in_place(path, st) else os.path.dirname(target)
            with atomic_output(path, binary=True) as fh:
                write_npz(fh, spool_dir, names, windows, count)
        else:
            with atomic_output(path) as fh:
                fh.write(",".join(names) + "\n")
                for columns in windows:
                    _csv_rows(fh, columns, formats)
    except BrokenPipeError:
        raise  # a reader that went away (``| head``): the CLI ends quietly
    except OSError as exc:
        name = "standard output" if path == "-" else path
        raise OutputError(f"cannot write {name}: {exc.strerror or exc}") from None


def write_table(path: str, names, columns, formats, npz: bool | None = None) -> None:
    """Write named columns to ``path`` (``-``: stdout): NPZ when ``npz`` (None: when the path
    ends in .npz), else CSV."""
    write_table_windows(path, names, [columns], len(columns[0]), formats, npz)


#: printf formats of the reference-point columns (POINT_COLUMNS).
POINT_FORMATS = ["%.6f", "%.9f", "%.9f", "%.9f", "%.6f", "%d", "%d"]
#: printf format of a rotary column [deg]: nine decimals, as x y z [mm].
ROTARY_FORMAT = "%.9f"


def checked_rotary_axes(axes) -> tuple:
    """``axes`` as a tuple of distinct names of ROTARY_COLUMNS in their order (``("a",
    "c")``); anything else is a ValueError (the writers' input is the program's
    :attr:`~nurbscnc.geometry.segments.Program.rotary_axes`, never the user's)."""
    axes = tuple(axes)
    if axes != tuple(c for c in ROTARY_COLUMNS if c in axes):
        raise ValueError(f"rotary axes must be distinct names of a, b, c in order, got {axes}")
    return axes


def point_names(rotary_axes=()) -> tuple:
    """The column names of a reference-point file: ``t,x,y,z``, the rotary axes the program
    uses (``a``, ``b``, ``c`` [deg], in that order), then ``feed,piece,line``."""
    return POINT_COLUMNS[:4] + checked_rotary_axes(rotary_axes) + POINT_COLUMNS[4:]


def point_formats(rotary_axes=()) -> list:
    """The printf formats of :func:`point_names`'s columns."""
    return POINT_FORMATS[:4] + [ROTARY_FORMAT] * len(rotary_axes) + POINT_FORMATS[4:]


def rotary_columns(samples: Samples) -> tuple:
    """The columns (N,) [deg] of the rotary axes ``samples`` uses
    (:attr:`~nurbscnc.plan.timing.Samples.rotary_axes`), picked from its ``abc_deg`` (N, 3);
    ``()`` for a program without rotary axes. Samples that name axes but carry no A B C
    are a ValueError (a stage dropped them: writing zeros would move the part wrongly)."""
    axes = checked_rotary_axes(samples.rotary_axes)
    if not axes:
        return ()
    abc = samples.abc_deg
    if abc is None or abc.ndim != 2 or abc.shape != (samples.t_s.size, 3):
        got = None if abc is None else abc.shape
        raise ValueError(f"samples of rotary axes {axes} need abc_deg (N, 3), got {got}")
    return tuple(abc[:, ROTARY_COLUMNS.index(name)] for name in axes)


def point_columns(samples: Samples) -> tuple:
    """The columns of reference points (whole or one window), in :func:`point_names`'s
    order: t, x, y, z, the rotary axes the program uses, feed, piece, line."""
    p = samples.points_mm
    return (
        samples.t_s,
        p[:, 0],
        p[:, 1],
        p[:, 2],
        *rotary_columns(samples),
        samples.v_mm_s,
        samples.piece,
        samples.line,
    )


def windows_and_axes(windows: Iterable[Samples]) -> tuple[tuple, Iterable[Samples]]:
    """The rotary axes of samples given window by window (the first window's; ``()`` when
    there is none) and the same windows, each checked to name the same axes (ValueError:
    one file has one set of columns)."""
    windows = iter(windows)
    first = next(windows, None)
    if first is None:
        return (), iter(())
    axes = checked_rotary_axes(first.rotary_axes)

    def all_windows():
        yield first
        for w in windows:
            if tuple(w.rotary_axes) != axes:
                raise ValueError(f"a window's rotary axes {w.rotary_axes} differ from {axes}")
            yield w

    return axes, all_windows()


def write_points(path: str, samples: Samples, npz: bool | None = None) -> None:
    """Reference points: ``t,x,y,z,feed,piece,line`` (s, mm, mm, mm, mm/s, index, line),
    with the program's rotary axes (``a``, ``b``, ``c`` [deg]) after ``z``; NPZ when ``npz``
    (None: by the path's suffix)."""
    write_point_windows(path, [samples], int(samples.t_s.size), npz)


def write_point_windows(
    path: str, windows: Iterable[Samples], count: int, npz: bool | None = None
) -> None:
    """:func:`write_points` of reference points given window by window (``count`` rows in
    all, e.g. :meth:`nurbscnc.pipeline.Run.chunks`): the same bytes, one window of memory.
    The columns are the first window's (:func:`windows_and_axes`)."""
    axes, windows = windows_and_axes(windows)
    write_table_windows(
        path,
        point_names(axes),
        (point_columns(w) for w in windows),
        count,
        point_formats(axes),
        npz,
    )


def write_profile(path: str, t_s, s_mm, v, a, j, piece) -> None:
    """A feed-profile dump: ``t,s,v,a,j,piece`` (s, mm, mm/s, mm/s², mm/s³, index)."""
    write_table(
        path,
        PROFILE_COLUMNS,
        (t_s, s_mm, v, a, j, piece),
        ["%.6f", "%.9f", "%.6f", "%.4f", "%.2f", "%d"],
    )


def point_header(text: str) -> tuple[str, ...] | None:
    """The columns of a reference-point CSV whose first line is ``text``'s: ``t,x,y``,
    ``t,x,y,z`` or the full ``t,x,y,z,feed,piece,line`` (any leading prefix of POINT_COLUMNS
    from ``t,x,y`` on), with after ``z`` any of the rotary columns ``a``, ``b``, ``c`` in
    that order (:func:`point_names`); None when the first line is not such a header (a
    program, say)."""
    first = text.lstrip("\ufeff").split("\n", 1)[0].rstrip("\r")
    names = tuple(f.strip() for f in first.split(","))
    try:  # the rotary columns named after z, out of order or twice: not a header
        full = point_names(c for c in names[4:] if c in ROTARY_COLUMNS)
    except ValueError:
        return None
    if len(names) >= 3 and names == full[: len(names)]:
        return names
    return None


def rotary_of_points(data: dict) -> tuple[tuple, np.ndarray | None]:
    """The rotary axes of a points file read by :func:`read_points` (its ``a``, ``b``, ``c``
    columns, in that order) and their positions ``abc_deg`` (N, 3) [deg] with every column
    of A B C (0 for an axis the file does not have: a program leaves an unused axis at 0),
    as :attr:`~nurbscnc.plan.timing.Reference.abc_deg`; ``((), None)`` without rotary
    columns."""
    axes = tuple(c for c in ROTARY_COLUMNS if c in data)
    if not axes:
        return (), None
    n = data["x"].shape[0]
    abc = np.zeros((n, 3))
    for name in axes:
        abc[:, ROTARY_COLUMNS.index(name)] = data[name]
    return axes, abc


def read_points(path: str) -> dict:
    """Read a reference-point file (CSV with a header as :func:`point_header` accepts, or NPZ;
    ``-``: CSV from stdin) into arrays, by column name. A missing ``z`` column is 0 mm;
    missing ``feed``, ``piece``, ``line`` and rotary ``a``, ``b``, ``c`` [deg] are absent
    from the result (:func:`rotary_of_points` gathers the rotary ones).

    OSError → OutputError (exit 3). Bad content → DataError (exit 2) at its line and column
    where a CSV has them: the header, the column count, text that is not a number, a value
    that is not finite or beyond ``POINT_VALUE_LIMIT`` (named).
    """
    if path != "-" and path.endswith(".npz"):
        try:
            return _read_points_npz(path)
        except OSError as exc:
            raise OutputError(f"cannot read {path}: {exc.strerror or exc}") from None
    text = read_input_bytes(path, "the point file").decode("utf-8", errors="replace")
    return read_points_text(text.replace("\r\n", "\n").replace("\r", "\n"))


def read_points_text(text: str) -> dict:
    """:func:`read_points` of a CSV already read into ``text``."""
    names = point_header(text)
    lines = text.lstrip("\ufeff").splitlines()
    if names is None:
        header = lines[0] if lines else ""
        raise DataError(
            f"expected the header {','.join(POINT_COLUMNS)} (or t,x,y / t,x,y,z; rotary "
            "columns a, b, c [deg] after z, in that order)",
            SourcePos(1, 1, header),
        )
    try:
        with warnings.catch_warnings():  # "input contained no data": reported below
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(lines[1:], delimiter=",", ndmin=2, comments=None)
    except ValueError as exc:  # numpy names the row (0-based after the header)
        raise DataError(f"not a table of numbers: {str(exc)[:200]}") from None
    if data.size == 0:
        raise DataError("no reference points after the header")
    if data.shape[1] != len(names):
        raise DataError(f"expected {len(names)} columns, got {data.shape[1]}")
    _check_values(data, names, lambda row, col: _csv_position(lines, row, col))
    result = {c: data[:, i] for i, c in enumerate(names)}
    result.setdefault("z", np.zeros(data.shape[0]))  # a planar file: z = 0 mm
    return result


#: An NPZ is a zip archive: its first bytes are a local file header (or, empty, the end of
#: its central directory); a .npy array starts with b"\x93NUMPY".
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")
_NPY_MAGIC = b"\x93NUMPY"


def _read_points_npz(path: str) -> dict:
    """The arrays of a reference-point NPZ (``write_npz``'s layout: POINT_COLUMNS, and the
    rotary columns ``a``, ``b``, ``c`` it has), every malformed file a DataError: not a zip
    (a .npy renamed), a damaged archive or member, a missing array, a header declaring more
    data than the member holds (checked before numpy allocates it), pickled objects, wrong
    shapes or types (a rotary column's too), values that are not finite."""
    with open(path, "rb") as fh:
        head = fh.read(len(_NPY_MAGIC))
    if head[:4] not in _ZIP_MAGIC:
        what = "a single .npy array" if head == _NPY_MAGIC else "not a zip archive"
        raise DataError(f"not a reference-point NPZ file: {what} (expected a zip of .npy arrays)")
    try:
        with zipfile.ZipFile(path) as archive:
            members = set(archive.namelist())
            missing = [c for c in POINT_COLUMNS if f"{c}.npy" not in members]
            if missing:
                raise DataError(f"missing arrays {', '.join(missing)}")
            names = point_names(c for c in ROTARY_COLUMNS if f"{c}.npy" in members)
            for c in names:
                _check_npy_member(archive, f"{c}.npy")
        with np.load(path, allow_pickle=False) as npz:
            arrays = [np.asarray(npz[c]) for c in names]
    except (ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        # ValueError: a bad .npy header, pickled objects (refused); the others: a damaged zip
        raise DataError(f"not a reference-point NPZ file: {str(exc)[:200]}") from None
    if (
        any(a.ndim != 1 or a.shape != arrays[0].shape or a.dtype.kind not in "iuf" for a in arrays)
        or arrays[0].size == 0
    ):
        raise DataError(
            f"the arrays {', '.join(names)} must be numeric, 1-D, non-empty and of one length"
        )
    data = np.column_stack([a.astype(float) for a in arrays])
    _check_values(data, names, lambda row, col: None, lambda row: f" (row {row + 1})")
    return {c: data[:, i] for i, c in enumerate(names)}


def _check_npy_member(archive: zipfile.ZipFile, name: str) -> None:
    """Refuse a member whose .npy header declares more bytes than the member holds (numpy
    would allocate the declared array before reading: a 200-byte file could ask for
    terabytes), or more than :data:`~nurbscnc.output.inputs.MAX_INPUT_BYTES`."""
    size = archive.getinfo(name).file_size
    with archive.open(name) as member:
        version = np.lib.format.read_magic(member)
        read_header = (
            np.lib.format.read_array_header_1_0
            if version == (1, 0)
            else np.lib.format.read_array_header_2_0
        )
        shape, _fortran, dtype = read_header(member)
    if dtype.hasobject:
        raise DataError(f"array {name} holds Python objects (pickled data is refused)")
    declared = math.prod(shape) * dtype.itemsize
    if declared > min(size, inputs.MAX_INPUT_BYTES):
        raise DataError(
            f"array {name} declares {declared:,} bytes of data; the member holds {size:,}"
        )


def _check_values(data: np.ndarray, names, position, where=lambda row: "") -> None:
    """Refuse NaN, ±inf and magnitudes beyond POINT_VALUE_LIMIT, naming the first one (its
    column's name from ``names``); ``position(row, col)`` gives its SourcePos (or None),
    ``where(row)`` a suffix."""
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(data) <= POINT_VALUE_LIMIT)  # NaN compares False: caught too
    if bad.any():
        row, col = (int(k) for k in np.argwhere(bad)[0])
        value = float(data[row, col])
        what = (
            "is not finite" if not math.isfinite(value) else (f"is beyond ±{POINT_VALUE_LIMIT:g}")
        )
        raise DataError(f"{names[col]} = {value!r} {what}{where(row)}", position(row, col))


def _csv_position(lines: list[str], row: int, col: int) -> SourcePos | None:
    """Line, column and text of field ``col`` of data row ``row`` (np.loadtxt skips blank
    lines, so the lines are scanned again; only on an error)."""
    seen = -1
    for number, text in enumerate(lines[1:], 2):
        if text.strip():
            seen += 1
            if seen == row:
                fields = text.split(",")
                column = 1 + sum(len(f) + 1 for f in fields[:col])
                if col < len(fields):  # under the value, not its leading spaces
                    column += len(fields[col]) - len(fields[col].lstrip())
                return SourcePos(number, column, text)
    return None
