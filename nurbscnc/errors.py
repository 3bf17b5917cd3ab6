"""One error hierarchy for everything a user can get wrong.

Every stage raises a subclass of :class:`NurbsCncError`; only the CLI turns them into
messages (``file:line:col: error: ...`` with the source line and a caret) and exit codes.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Exit codes of the command-line interface.
EXIT_OK = 0
EXIT_INTERNAL = 1  # a bug in nurbscnc: never the answer to any input
EXIT_INPUT = 2  # bad program, bad option, bad file
EXIT_IO = 3  # cannot read or write a file, port trouble
EXIT_INTERRUPTED = 130


#: Characters a terminal acts on rather than shows, as printable escapes: the C0 controls,
#: DEL, the C1 controls (0x9B is a one-byte CSI) as ``\xNN``; the bidirectional embeddings,
#: overrides and isolates (U+202A-U+202E, U+2066-U+2069: text that displays in another
#: order than it reads) as ``\uNNNN``. Python's own escape notation, so an escape reads the
#: same as in a ``repr`` of the text.
_ESCAPES = {c: f"\\x{c:02x}" for c in (*range(0x20), *range(0x7F, 0xA0))} | {
    c: f"\\u{c:04x}" for c in (*range(0x202A, 0x202F), *range(0x2066, 0x206A))
}
#: The same without line feed and tab: for whole screens of output (their lines and columns).
_ESCAPES_KEEP_LAYOUT = {c: v for c, v in _ESCAPES.items() if c not in (0x0A, 0x09)}


def printable(text: str, keep_layout: bool = False) -> str:
    """``text`` safe to show on a terminal: every control character is written as its escape
    (ESC as ``\x1b``, BEL as ``\x07``, CSI as ``\x9b``, U+202E as ``\u202e``), so text from a
    program or a file (a ``(MSG, …)``, a source line, a file name) can neither move the
    cursor, retitle or clear the terminal, nor reorder what is shown. ``keep_layout`` keeps
    line feeds and tabs (a whole screen of output, not one line of user text)."""
    return str(text).translate(_ESCAPES_KEEP_LAYOUT if keep_layout else _ESCAPES)


@dataclass(frozen=True)
class SourcePos:
    """A position in a source text: 1-based line and column, and the line's text."""

    line: int
    column: int = 1
    text: str = ""


class NurbsCncError(Exception):
    """Base of all errors nurbscnc reports to a user.

    ``pos`` (optional) is where in the program the problem is; ``exit_code`` is what the CLI
    exits with.
    """

    exit_code = EXIT_INPUT

    def __init__(self, message: str, pos: SourcePos | None = None):
        super().__init__(message)
        self.message = message
        self.pos = pos

    def with_pos(self, pos: SourcePos) -> NurbsCncError:
        """Attach a position if the error has none yet; return self."""
        if self.pos is None:
            self.pos = pos
        return self


class ProgramError(NurbsCncError):
    """The NC program is wrong (syntax, modal rules, unsupported words, bad NURBS data)."""


class GCodeSyntaxError(ProgramError):
    """The text is not G-code the grammar accepts."""


class UnsupportedError(ProgramError):
    """Valid RS274/NGC that nurbscnc deliberately does not execute."""


class GeometryError(ProgramError):
    """Geometry that cannot be machined as written (degenerate arc, bad NURBS, ...)."""


class PlanningError(NurbsCncError):
    """The planner cannot meet the limits (depth cap reached, soft limits left, ...)."""


class ConfigError(NurbsCncError):
    """A bad machine profile or option value; the message names the key."""


class DataError(NurbsCncError):
    """A data file nurbscnc reads (reference points) has bad content; the message names the
    line and the value."""


class OutputError(NurbsCncError):
    """A file could not be read or written."""

    exit_code = EXIT_IO


class StreamError(NurbsCncError):
    """Trouble talking to the motion card."""

    exit_code = EXIT_IO


class CardAxesError(StreamError):
    """The card does not drive an axis the program moves (a version-3 card and a rotary
    axis): refused at the handshake, before anything is streamed; bad input, not port
    trouble."""

    exit_code = EXIT_INPUT
