"""The CLI's consoles and what it shows on them besides the commands' output: the progress
display, and an error as ``file:line:col: error: message`` with the source line and a caret.

The consoles are rich Consoles made on first use (``--help`` and shell completion do not
import rich): :data:`out` for the commands' output, :data:`err` for messages.
"""

from __future__ import annotations

import contextlib
import errno
import sys

from nurbscnc.errors import NurbsCncError, printable


def _rich_console_class():
    """The rich Console that leaves a failed write to the caller: on stdout a closed pipe or a
    full disk raises (handle_errors ends quietly with 141, or says so with 3; rich's default
    would exit 1), on stderr it is ignored. The unwritten text is dropped either way. (Built on
    first use: rich is imported when a command prints, not by ``--help``.)"""
    from rich.console import Console
    from rich.segment import Segment

    class _Console(Console):
        def _render_buffer(self, buffer) -> str:
            # Every text printed is escaped (errors.printable): a control character from a
            # program or a file never reaches the terminal raw, whichever path printed it
            # (notes, messages, tables, the progress line). rich's own control segments
            # (cursor moves of the progress display) and its styles pass untouched.
            return super()._render_buffer(
                seg if seg.control else Segment(printable(seg.text, True), seg.style)
                for seg in buffer
            )

        def render_str(self, text: str, **kwargs):
            # Before rich makes a Text of it (which would drop BEL, BS, CR silently).
            return super().render_str(printable(text, True), **kwargs)

        def on_broken_pipe(self) -> None:
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")

        def _check_buffer(self) -> None:
            try:
                super()._check_buffer()
            except OSError:
                del self._buffer[:]
                if not self.stderr:
                    raise

    return _Console


class _LazyConsole:
    """Stands for the module's rich Console ``name`` (``out`` or ``err``) until its first use,
    so that importing this module does not import rich: the first use (an attribute:
    ``print``, ``is_terminal``, ...) makes the Console from ``settings`` and puts it in the
    module in the stand-in's place. A stand-in a caller kept (``from ... import err`` before
    any use) forwards every use to that Console: attributes read and set, ``with``."""

    def __init__(self, name: str, **settings):
        object.__setattr__(self, "_name", name)
        object.__setattr__(self, "_settings", settings)
        object.__setattr__(self, "_console", None)

    def _real(self):
        if self._console is None:
            object.__setattr__(self, "_console", _rich_console_class()(**self._settings))
            if globals().get(self._name) is self:
                globals()[self._name] = self._console
        return self._console

    def __getattr__(self, attr: str):
        return getattr(self._real(), attr)

    def __setattr__(self, attr: str, value) -> None:
        setattr(self._real(), attr, value)

    def __enter__(self):
        return self._real().__enter__()

    def __exit__(self, *exc_info):
        return self._real().__exit__(*exc_info)


# Tables keep their width when piped (rich would assume 80 columns and truncate numbers).
# Markup and emoji codes are off: file names, source lines, messages and JSON are user text and
# must print literally (a file "[/].nc", "(:thumbs_up:)" in a comment, "part.nc:100:" would be
# markup or emoji otherwise). Styling goes through rich.text.Text objects only.
out = _LazyConsole(
    "out",
    highlight=False,
    markup=False,
    emoji=False,
    soft_wrap=True,
    width=None if sys.stdout.isatty() else 200,
)
err = _LazyConsole("err", stderr=True, highlight=False, markup=False, emoji=False, soft_wrap=True)


# -- progress ----------------------------------------------------------------------------------
def show_progress(as_json: bool = False, quiet: bool = False) -> bool:
    """Progress is shown on a terminal only: not when stderr is piped or redirected, not with
    --json or --quiet."""
    return not (as_json or quiet) and err.is_terminal


@contextlib.contextmanager
def progress_display(show: bool, title: str):
    """A one-line rich progress display on stderr (spinner, stage, elapsed time) while the
    block runs, gone afterwards; yields the function that names the current stage (the
    ``progress`` callback the stages are given; one that does nothing when not ``show``).
    The stage and title are user text: printed literally, never as markup."""
    if not show:
        yield lambda _stage: None
        return
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}", markup=False),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    ) as bar:
        # The stage first: a narrow terminal cuts the end of the line (a long file name).
        task = bar.add_task(f"starting · {title}", total=None)

        def say(stage: str) -> None:
            bar.update(task, description=f"{stage} · {title}", refresh=True)

        yield say


# -- error reporting ---------------------------------------------------------------------------
#: An echoed source line is cut to about this many characters around the error's column.
SOURCE_ECHO_CHARS = 120
#: A message longer than this is cut (a message quoting a 10 MB word stays readable).
MESSAGE_CHARS = 1000


def echo_source_line(text: str, column: int, width: int = SOURCE_ECHO_CHARS) -> tuple[str, int]:
    """The part of a source line shown under an error, and the 0-based caret offset in it.

    Lines up to ``width`` characters are shown whole; longer ones as a ``width``-character
    window around the column with ``…`` where text was cut. Tabs become spaces and control
    characters their escapes (:func:`~nurbscnc.errors.printable`: ESC shows as ``\x1b``); the
    caret stays under the column's character.
    """
    text = text.replace("\t", " ")
    col = min(max(column, 1) - 1, len(text))
    start = 0
    if len(text) > width:
        start = max(0, min(col - width // 2, len(text) - width))
    end = start + width
    prefix = "…" if start > 0 else ""
    suffix = "…" if end < len(text) else ""
    shown = prefix + printable(text[start:end]) + suffix
    return shown, len(prefix) + len(printable(text[start:col]))


def format_error(exc: NurbsCncError, filename: str) -> str:
    """``file:line:col: error: message``, then the source line (cut around the column) and a
    caret under the column."""
    message = exc.message
    if len(message) > MESSAGE_CHARS:
        message = message[:MESSAGE_CHARS] + f"… ({len(exc.message)} characters)"
    message, filename = printable(message), printable(filename)
    pos = exc.pos
    if pos is None:
        return f"{filename}: error: {message}"
    head = f"{filename}:{pos.line}:{pos.column}: error: {message}"
    if not pos.text:
        return head
    shown, caret = echo_source_line(pos.text, pos.column)
    return f"{head}\n    {shown}\n    {' ' * caret}^"
