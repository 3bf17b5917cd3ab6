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
