"""The fast lane: runs of plain straight-move lines interpreted in bulk, and the
continuation lines of G6.2 blocks read without the general parser (:func:`nurbs_words`).

CAM output is mostly lines such as ``N120 G1 X12.5 Y-3.25 Z-1 F600`` or ``X12.5 Y-3.25``:
straight moves under G0/G1 with constant words and nothing else. Interpreting them one at a
time costs a parse, a dictionary of words and a pass through the execution order per line;
here a run of them is recognised with ONE regular expression over a chunk of lines, the
numbers are converted once, and the modal values (position, motion, feed) are carried down
the run with numpy (a forward fill is a cumulative count into the given values).

The lane is exact: it does only what the interpreter's general path does on such a line
(interpret.py ``execute``: set F, set the motion mode, ``straight``), with the same float
operations in the same order, so the segments are the same to the bit (a test interprets
the corpus and the real programs both ways). It accepts a strict subset of the language:

``[N<int>[.<digits>]] [G0|G1] [X<num>] [Y<num>] [Z<num>] [F<num>] [(comment) | ;comment]``

in this order, any case, blanks between words (not inside numbers), a comment that is not a
``(MSG, …)``. Every other line (other words, expressions, block delete, ``%``, O-words, a
malformed line) ends the run and goes to the general path, which also reports every error:
the run stops BEFORE any line the general path would refuse (a G1 with no feed, a feed or a
coordinate out of range, an axis word under another motion mode). A run shorter than
:data:`MIN_RUN_LINES` goes to the general path too: there a line is cheaper, and is parsed
once (a loop's body runs from its blocks).
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import gc
import itertools
import re
from typing import NamedTuple

import numpy as np

from nurbscnc.geometry.segments import Line
from nurbscnc.program.codes import G_0, G_1
from nurbscnc.program.parse import MAX_LINE_CHARS

# Groups: 1 the motion digit of G0/G1 (G00, G01), 2-5 the X Y Z F numbers. A number here is
# any run of digits and points with a sign; the runs float() refuses ("1.2.3", ".") are not
# G-code numbers either, and make the line not plain (see _rows). The pattern does not
# match a line that is not plain, so findall over a chunk returns fewer rows than lines
# exactly when one is not.
_NUM = r"([+-]?[0-9.]+)"
_PLAIN = re.compile(
    r"^[ \t]*(?:[nN][0-9]+[ \t]*)?"
    r"(?:[gG]0?([01])(?![0-9.])[ \t]*)?"
    r"(?:[xX]" + _NUM + r"[ \t]*)?"
    r"(?:[yY]" + _NUM + r"[ \t]*)?"
    r"(?:[zZ]" + _NUM + r"[ \t]*)?"
    r"(?:[fF]" + _NUM + r"[ \t]*)?"
    r"(?:\((?!\s*[mM][sS][gG],)[^()\n]*\)[ \t]*|;.*)?$",
    re.M,
)

#: A run is read in chunks that start small (a run may be a few lines between two others)
#: and double while every line of the chunk is plain.
FIRST_CHUNK = 32
#: Shortest run the lane takes [lines]. Its whole-array work has a fixed cost per call of
#: about as many lines as this interpreted one by one; and a line the lane took is never
#: parsed, so a loop whose body holds a short plain run would pay that cost at every turn
#: (an endless two-line loop runs to its turn limit many times slower than line by line).
MIN_RUN_LINES = 8
MAX_CHUNK = 8192


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _plain_row(line: str):
    """The row (g, x, y, z, f) of one line, or None when it is not plain (or too long)."""
    if len(line) > MAX_LINE_CHARS:
        return None
    match = _PLAIN.match(line)
    if match is None:
        return None
    row = match.groups()
    if not all(_is_number(v) for v in row[1:] if v):
        return None
    return row


def _rows(lines, start: int, n: int) -> list:
    """Rows (g, x, y, z, f) of the plain lines from ``lines[start]`` on, at most ``n``,
    up to the first line that is not plain."""
    chunk = lines[start : start + n]
    text = "\n".join(chunk)
    # A line over the limit is not plain: the general path refuses it (parse.MAX_LINE_CHARS).
    # Only a chunk that long can hold one (a chunk of 8,192 plain lines is often longer):
    # the run ends before the first such line, and the lines before it are read as a chunk.
    if len(text) > MAX_LINE_CHARS and max(map(len, chunk)) > MAX_LINE_CHARS:
        chunk = chunk[: next(k for k, line in enumerate(chunk) if len(line) > MAX_LINE_CHARS)]
        if not chunk:
            return []
        text = "\n".join(chunk)
    rows = _PLAIN.findall(text)
    if len(rows) == len(chunk):
        return rows  # (numbers float() refuses: plain_run checks them, see _strict_rows)
    return rows[: _leading_plain(text, chunk)]


def _leading_plain(text: str, chunk) -> int:
    """How many lines of ``chunk`` (``text`` their join) are plain before the first that is
    not: each match of :data:`_PLAIN` is one whole line (it is anchored at both ends and takes
    no line break), so the k-th match starts at the k-th line's start exactly while the lines
    before are all plain. (The rows' numbers are checked as a whole chunk's are, by
    plain_run's fallback; a line at a time they cost 5 µs each, and a run's last chunk may
    hold 8,192 lines.)"""
    starts = itertools.accumulate(map(len, chunk), lambda at, n: at + n + 1, initial=0)
    count = 0
    for match, at in zip(_PLAIN.finditer(text), starts):
        if match.start() != at:
            break
        count += 1
    return count


def _strict_rows(lines, n: int) -> list:
    """Rows of the plain lines at the head of ``lines``, at most ``n``, each line checked
    alone (its numbers too)."""
    rows = []
    for line in lines[:n]:
        row = _plain_row(line)
        if row is None:
            break
        rows.append(row)
    return rows


_INF = float("inf")
# A G6.2 continuation line (a control point with its knot, or a knot alone): letters,
# then numbers, in groups (letter, number) for K, X, Y, Z, R in this order.
_G6_LINE = re.compile(
    r"[ \t]*(?:[nN][0-9]+[ \t]*)?"
    r"([kK])[ \t]*" + _NUM + r"[ \t]*"
    r"(?:([xX])[ \t]*" + _NUM + r"[ \t]*)?"
    r"(?:([yY])[ \t]*" + _NUM + r"[ \t]*)?"
    r"(?:([zZ])[ \t]*" + _NUM + r"[ \t]*)?"
    r"(?:([rR])[ \t]*" + _NUM + r"[ \t]*)?"
)


def nurbs_words(line: str) -> dict | None:
    """The words of a G6.2 continuation line, ``[N<int>] K<num> [X<num>] [Y<num>] [Z<num>]
    [R<num>]`` in this order (any case, blanks between words), as the general path reads
    them: ``{letter: (value, column)}``, the column 1-based at the letter; None for any
    other line (a comment, another word or order, a number ``float`` refuses or reads as
    infinite): those go to the general path, which also reports every error. The
    interpreter hands these words to the G6.2 block (nurbsblock.py ``g6``) as the general
    path would after parsing and the execution order, which do nothing else for them."""
    match = _G6_LINE.fullmatch(line) if len(line) <= MAX_LINE_CHARS else None
    if match is None:
        return None
    words = {}
    for g in range(1, 11, 2):
        letter = match.group(g)
        if letter is None:
            continue
        try:
            value = float(match.group(g + 1))
        except ValueError:
            return None
        if value == _INF or value == -_INF:
            return None
        words[letter.upper()] = (value, match.start(g) + 1)
    return words


class BulkState(NamedTuple):
    """The interpreter state a run needs and changes: ``motion`` code ×10 (None: none),
    ``feed`` (F as written), ``feed_mm`` [mm/min], ``prog_mm`` program position [mm],
    ``scale`` [mm per program unit]; limits as in interpret.py."""

    motion: int | None
    feed: float
    feed_mm: float
    prog_mm: tuple
    scale: float


class BulkRun(NamedTuple):
    """The result of :func:`plain_run`: ``count`` lines consumed; ``worded`` their indexes
    that carry words; per move (a line whose end differs from its start): ``starts_mm``,
    ``ends_mm`` (machine, lists of (x, y, z) tuples), ``feeds_mm_s``, ``rapid``, ``index`` (line
    index); and the state after the run."""

    count: int
    worded: np.ndarray
    starts_mm: list
    ends_mm: list
    feeds_mm_s: list
    rapid: list
    index: list
    state: BulkState


def _given(rows) -> tuple[np.ndarray, np.ndarray]:
    """The rows' words: a mask (n, 5) of the given ones (g, x, y, z, f) and their values
    (n, 5) (0 where not given): every string of the rows read in one pass, row by row, the
    numbers by ``float`` as the general path reads them."""
    n = len(rows)
    flat = list(itertools.chain.from_iterable(rows))
    given = np.fromiter(map(bool, flat), dtype=bool, count=5 * n).reshape(n, 5)
    values = np.zeros((n, 5))
    values[given] = np.fromiter(map(float, filter(None, flat)), dtype=float)
    return given, values


def _filled(
    given: np.ndarray, values: np.ndarray, initial: float, scale: float | None
) -> np.ndarray:
    """Forward fill of one column (``given`` mask, ``values`` (n,)): the k-th given value
    goes to every line from its own to the next given one; lines before the first keep
    ``initial``. ``scale`` multiplies the given values (units), as the general path does
    value by value."""
    picked = values[given]
    if scale is not None:
        picked = picked * scale
    return np.concatenate(([initial], picked))[np.cumsum(given)]


def plain_run(lines, start: int, state: BulkState, to_machine, limits) -> BulkRun | None:
    """Interpret the run of plain lines starting at ``lines[start]`` (see the module doc).

    ``to_machine(prog (n, 3)) -> (n, 3)``: the coordinate transform in force, array form;
    ``limits``: (MAX_COORD_MM, MIN_FEED_MM_MIN, MAX_FEED_MM_MIN). Returns None when the first
    line is not one the lane takes.
    """
    max_coord, min_feed, max_feed = limits
    first = _plain_row(lines[start])
    if first is None or (state.motion not in (G_0, G_1) and not first[0] and any(first[1:])):
        return None  # not plain, or a plain line for another motion mode (G81 X Y): cheap no
    rows: list = []
    size = FIRST_CHUNK
    pos = start
    while pos < len(lines):
        chunk = _rows(lines, pos, size)
        rows += chunk
        pos += len(chunk)
        if len(chunk) < size:
            break
        size = min(2 * size, MAX_CHUNK)
    if len(rows) < MIN_RUN_LINES:
        return None  # line by line: cheaper, and each line is then parsed once (a loop body)
    try:
        return _run(rows, start, state, to_machine, limits)
    except ValueError:  # a run of digits and points that is not a number ("1.2.3")
        rows = _strict_rows(lines[start:], len(rows))
        return _run(rows, start, state, to_machine, limits) if rows else None


def _triples(points: np.ndarray) -> list:
    """(n, 3) array → list of n (x, y, z) tuples of floats."""
    flat = iter(points.ravel().tolist())
    return list(zip(flat, flat, flat))


def _run(rows, start: int, state: BulkState, to_machine, limits) -> BulkRun | None:
    max_coord, min_feed, max_feed = limits
    n = len(rows)
    given, values = _given(rows)
    scale = state.scale
    # Motion: None is -1, G0 is 0, G1 is 10.
    motion0 = -1 if state.motion is None else state.motion
    has_g, has_f = given[:, 0], given[:, 4]
    motion = _filled(has_g, values[:, 0], motion0, 10.0)
    feed_mm = _filled(has_f, values[:, 4], state.feed_mm, scale)
    feed_raw = _filled(has_f, values[:, 4], state.feed, None)
    prog = [
        (_filled(given[:, i], values[:, i], state.prog_mm[i - 1], scale), given[:, i])
        for i in (1, 2, 3)
    ]
    has_axes = given[:, 1] | given[:, 2] | given[:, 3]
    worded = has_axes | has_g | has_f
    # Lines the general path refuses or treats otherwise end the run before them.
    bad = worded & (motion != G_0) & (motion != G_1)
    bad |= has_f & (
        (feed_raw < 0.0) | ((feed_mm != 0.0) & ((feed_mm < min_feed) | (feed_mm > max_feed)))
    )
    bad |= has_axes & (motion == G_1) & ~(feed_mm > 0.0)
    for values, given in prog:
        bad |= given & ~(np.abs(values) <= max_coord)
    first_bad = np.flatnonzero(bad)
    if first_bad.size:
        n = int(first_bad[0])
        if n == 0:
            return None
    ends_prog = np.column_stack([values[:n] for values, _ in prog])
    ends = to_machine(ends_prog)
    starts = np.empty_like(ends)
    starts[0] = to_machine(np.array([state.prog_mm], dtype=float))[0]
    starts[1:] = ends[:-1]
    moves = np.flatnonzero(has_axes[:n] & (ends != starts).any(axis=1))
    rapid = motion[moves] == G_0
    feeds = np.where(rapid, 0.0, feed_mm[moves] / 60.0)
    # A move starts where the line before it ended: when that line is a move too (nearly
    # always) its end tuple is shared (equal values; one object instead of two).
    ends_t = _triples(ends[moves])
    follows = np.zeros(moves.size, dtype=bool)
    follows[1:] = moves[1:] - 1 == moves[:-1]
    fresh = _triples(starts[moves[~follows]])
    pool = ends_t + fresh  # move k starts at pool[k − 1] if it follows, else at a fresh one
    at = np.arange(-1, moves.size - 1)
    at[~follows] = len(ends_t) + np.arange(len(fresh))
    starts_t = list(map(pool.__getitem__, at.tolist()))
    last = n - 1
    new_motion = int(motion[last])
    return BulkRun(
        count=n,
        worded=np.flatnonzero(worded[:n]) + start,
        starts_mm=starts_t,
        ends_mm=ends_t,
        feeds_mm_s=feeds.tolist(),
        rapid=rapid.tolist(),
        index=(moves + start).tolist(),
        state=BulkState(
            motion=None if new_motion < 0 else new_motion,
            feed=float(feed_raw[last]),
            feed_mm=float(feed_mm[last]),
            prog_mm=tuple(ends_prog[last].tolist()),
            scale=scale,
        ),
    )


def make_lines(columns: dict) -> list:
    """Line segments from columns: ``columns`` maps every field of
    :class:`~nurbscnc.geometry.segments.Line` to an iterable of its values, one per line.

    The same objects as ``Line(**fields)`` one by one (a test compares them field by field),
    made faster: a frozen dataclass's ``__init__`` sets each field through
    ``object.__setattr__`` (seven Python-level calls per Line), while here each field's
    slot descriptor is mapped over all the new objects in C.
    """
    names = [f.name for f in dataclasses.fields(Line)]
    if sorted(names) != sorted(columns):
        raise TypeError(f"Line fields {names}, given {sorted(columns)}")
    lines = None
    for name in names:
        values = columns[name]
        if lines is None:
            values = list(values)
            lines = list(map(object.__new__, itertools.repeat(Line, len(values))))
        collections.deque(map(getattr(Line, name).__set__, lines, values), maxlen=0)
    return lines or []


@contextlib.contextmanager
def pause_cyclic_gc():
    """Pause CPython's cycle collector while a run's segments are made (restored after).

    The segments hold no reference cycles, but the collector cannot know: building 200,000
    Line objects triggers a dozen full collections, each walking every object made so far
    (a cost that grows as the square of the run's length). Reference
    counting still frees everything; only the cycle search waits until the run is built.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()
