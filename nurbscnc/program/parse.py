"""Parse G-code text into blocks (one per source line) with lark's LALR parser.

The grammar lives in ``nurbscnc/grammars/gcode.lark``. The whole file is parsed in one call
with an inline transformer, so no parse tree is built: each line becomes a :class:`Block`
of words, parameter assignments and comments. Values are floats, or for anything involving
parameters or operators a small expression made of tuples (see :func:`is_constant`), which
the interpreter evaluates with the parameter values in force on that line.

Expression tuples:
``("#", ref)`` numbered parameter, ``("<", name)`` named parameter, ``("neg", v)``,
``("op", OP, a, b)`` with OP one of + - * / MOD ** EQ NE GT GE LT LE AND OR XOR,
``("fn", NAME, v)``, ``("atan", y, x)``, ``("exists", name)``, ``("existsn", index)``
(EXISTS[#n]: is n a parameter number).
"""

from __future__ import annotations

import functools
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from nurbscnc.errors import GCodeSyntaxError, NurbsCncError, SourcePos

if TYPE_CHECKING:
    from lark import Lark, UnexpectedCharacters, UnexpectedToken

# Start-up: lark (about 30 ms of CPU to import, and its parser built from the grammar) is
# imported by the first line the plain-word fast path does not take (_parser): a program of
# plain words, most CAM output, never loads it.


class Word(NamedTuple):
    """A letter and its value (float or expression tuple) at a 1-based column."""

    letter: str
    value: object
    column: int


class Assign(NamedTuple):
    """``#ref = value``: ``ref`` is ``("#", value)`` or ``("<", name)``."""

    target: tuple
    value: object
    column: int


class OWord(NamedTuple):
    """An O-word line: ``label`` ("100" or "<name>"), ``keyword`` ("sub", "call", ..., or
    "" for a Fanuc program number), ``args`` (bracketed expressions), 1-based ``column``."""

    label: str
    keyword: str
    args: tuple
    column: int


class Block(NamedTuple):
    """One source line: block-delete flag, words, assignments, comments, tape mark, O-word."""

    delete: bool
    words: tuple
    assigns: tuple
    comments: tuple
    percent: bool = False
    oword: OWord | None = None


EMPTY_BLOCK = Block(False, (), (), ())


def is_constant(value) -> bool:
    """True when a word value is a plain number (no parameter or operator)."""
    return type(value) is float


def _number(token) -> float:
    """A G-code decimal (blanks inside allowed, as LinuxCNC strips them) as a float."""
    text = str(token)
    if " " in text or "\t" in text:
        text = text.replace(" ", "").replace("\t", "")
    value = float(text)
    if not math.isfinite(value):  # e.g. 400 digits: float() gives inf
        raise GCodeSyntaxError(
            f"number {text[:12]}... is out of range", SourcePos(token.line, token.column)
        )
    return value


class _BlockCallbacks:
    """The inline transformer's callbacks (mixed into lark's ``Transformer`` by
    :func:`_parser`): they run as the LALR parser reduces, building plain data."""

    def start(self, lines):
        return lines

    def block(self, children):
        delete = False
        words = []
        assigns = []
        comments = []
        for child in children:
            kind = type(child)
            if kind is Word:
                words.append(child)
            elif kind is Assign:
                assigns.append(child)
            elif kind is tuple:  # a comment: ("comment", text, column)
                comments.append(child)
            elif child.type == "SLASH":
                delete = True
            # LINE_NUMBER tokens are dropped: N words have no effect.
        if not words and not assigns and not comments and not delete:
            return EMPTY_BLOCK
        return Block(delete, tuple(words), tuple(assigns), tuple(comments))

    def percent(self, children):
        return PERCENT_BLOCK

    def oword(self, children, label=None):
        delete = False
        keyword = ""
        args = []
        comments = []
        for child in children:
            kind = type(child)
            if kind is tuple and child and child[0] == "comment":
                comments.append(child)
            elif kind is float or kind is tuple:
                args.append(child)
            elif child.type == "SLASH":
                delete = True
            elif child.type == "O_LABEL":
                label = (_label_name(child), child.column)
            elif child.type == "O_KEYWORD":
                keyword = str(child).lower()
            elif child.type == "COMMENT":
                comments.append(("comment", str(child), child.column))
        return Block(
            delete, (), (), tuple(comments), False, OWord(label[0], keyword, tuple(args), label[1])
        )

    def oword_computed(self, children):
        # The child after O_COMPUTED is the label's value; the rest as in ``oword``.
        at = next(
            k
            for k, c in enumerate(children)
            if type(c) is not float and type(c) is not tuple and c.type == "O_COMPUTED"
        )
        marker, value = children[at], children[at + 1]
        block = self.oword([*children[:at], *children[at + 2 :]], (("#", value), marker.column))
        return block

    def comment(self, children):
        tok = children[0]
        return ("comment", str(tok), tok.column)

    def word(self, children):
        letter, value = children
        return Word(letter.upper(), value, letter.column)

    def assignment(self, children):
        target, value = children
        return Assign(target, value, 0)

    def number(self, children):
        return _number(children[0])

    def param(self, children):
        return children[0]

    def named_ref(self, children):
        return ("<", _param_name(children[0]))

    def numbered_ref(self, children):
        return ("#", children[0])

    def neg(self, children):
        v = children[0]
        return -v if type(v) is float else ("neg", v)

    def binop(self, children):
        a, op, b = children
        return ("op", op.upper(), a, b)

    def power(self, children):
        a, _, b = children
        return ("op", "**", a, b)

    def func(self, children):
        name, v = children
        return ("fn", name.upper(), v)

    def atan2(self, children):
        _, y, _, x = children
        return ("atan", y, x)

    def exists(self, children):
        return ("exists", _param_name(children[1]))

    def exists_numbered(self, children):
        return ("existsn", children[1])


def _label_name(token) -> str:
    """An O label: "<name>" (case folded, blanks dropped) or the number without leading zeros
    (its digits as written: ``int`` would refuse a label of more than 4300 digits)."""
    text = str(token)[1:].replace(" ", "").replace("\t", "")
    if text.startswith("<"):
        return text.lower()
    return text.lstrip("0") or "0"


def _param_name(token) -> str:
    """LinuxCNC folds case and drops blanks in parameter names: #<Feed Rate> is #<feedrate>."""
    return str(token)[1:-1].replace(" ", "").replace("\t", "").lower()


@functools.lru_cache(maxsize=1)
def _parser() -> Lark:
    from lark import Lark, Transformer

    to_blocks = type("_ToBlocks", (_BlockCallbacks, Transformer), {})
    return Lark(
        grammar_text(),
        parser="lalr",
        lexer="contextual",
        transformer=to_blocks(),
        maybe_placeholders=False,
    )


def grammar_text() -> str:
    """The grammar source (for property tests and documentation)."""
    return (Path(__file__).resolve().parents[1] / "grammars" / "gcode.lark").read_text("utf-8")


# Human names for the grammar's terminals in error messages.
_TERMINAL_NAMES = {
    "LETTER": "a word letter",
    "NUMBER": "a number",
    "LSQB": "'['",
    "RSQB": "']'",
    "__ANON_0": "'#'",
    "FUNC": "a function",
    "ATAN": "ATAN",
    "EXISTS": "EXISTS",
    "NAMED_PARAM": "a parameter name <...>",
    "COMMENT": "a comment",
    "_NL": "end of line",
    "$END": "end of file",
    "EQUAL": "'='",
    "MINUS": "'-'",
    "PLUS": "'+'",
    "SLASH": "'/'",
    "ADD_OP": "'+' or '-'",
    "MUL_OP": "'*' or MOD",
    "COMPARE_OP": "a comparison",
    "LOGIC_OP": "AND/OR/XOR",
    "LINE_NUMBER": "a line number",
    "PERCENT": "'%'",
    "HASH": "'#'",
    "POW": "'**'",
}


def _expected(names) -> str:
    readable = sorted({_TERMINAL_NAMES.get(n, n) for n in names})
    if not readable:
        return ""
    if len(readable) > 6:
        readable = readable[:6] + ["..."]
    return "; expected " + ", ".join(readable)


def _split_lines(text: str) -> list[str]:
    return split_lines(text)


# The fast path. Most CAM output is lines of plain words ("G1 X1.5 Y-2 F300 (cut)"); for
# those a regular expression that accepts exactly the plain-word subset of the grammar is ~5x
# faster than lark. Every other line (parameters, expressions, "%", anything malformed) goes
# to lark, which stays the definition of the language; a property test checks that both
# paths give identical blocks on lines generated from the grammar.
# Every blank run and digit run is possessive (``*+``, Python 3.11): the blanks between words,
# inside numbers and before a comment could otherwise be split in many ways, and a line that
# fails to match (say 10,000 blanks and a "%") would backtrack for minutes. Possessive runs
# accept the same lines here, because what a run gives back could never start the next part.
_NUM = r"[+-]?[ \t]*+(?:[0-9][0-9 \t]*+(?:\.[0-9 \t]*+)?|\.[ \t]*+[0-9][0-9 \t]*+)"
_SIMPLE_LINE = re.compile(
    r"[ \t]*+(/)?[ \t]*+(?:[nN][ \t]*+[0-9][0-9 \t]*+(?:\.[0-9 \t]*+)?)?"
    r"((?:[ \t]*+(?:[A-Za-z@^][ \t]*+" + _NUM + r"|\([^()\n]*+\)))*+)[ \t]*+(;.*)?"
)
_O_WORD = re.compile(
    r"[ \t]*+(?:/[ \t]*+)?(?:[nN][ \t]*+[0-9][0-9 \t]*+(?:\.[0-9 \t]*+)?)?[oO][ \t]*+[0-9<]"
)
_SIMPLE_ITEM = re.compile(r"([A-Za-z@^])[ \t]*(" + _NUM + r")|(\([^()\n]*\))")
# A tape mark: "%" and nothing but comments after it (the grammar's ``PERCENT COMMENT*``;
# the block keeps no comment of a % line). Taking it here spares a program whose every
# other line is plain building the lark parser at all (0.2–0.3 s).
_PERCENT_LINE = re.compile(r"[ \t]*+%[ \t]*+(?:(?:\([^()\n]*+\)|;.*)[ \t]*+)*+")
PERCENT_BLOCK = Block(False, (), (), (), True)


_INF = math.inf


def _fast_block(line: str, match) -> Block:
    """Build the block of a line that :data:`_SIMPLE_LINE` accepted.

    ``findall`` gives the items without match objects; each item's column is found with
    ``str.find`` from the end of the previous one (a number holds no letter and no "(", so
    the next item's first character cannot be found inside it; a comment is skipped whole).
    """
    words = []
    comments = []
    body = match.group(2)
    body_start = match.start(2) + 1
    pos = 0
    find = body.find
    for letter, text, comment in _SIMPLE_ITEM.findall(body):
        if letter:
            pos = find(letter, pos)
            try:
                value = float(text)  # leading / trailing blanks are fine for float()
            except ValueError:  # blanks between digits ("1 2.5")
                text = text.replace(" ", "").replace("\t", "")
                value = float(text)
            if value == _INF or value == -_INF:  # e.g. 400 digits (no nan: digits only)
                raise GCodeSyntaxError(
                    f"number {text.strip()[:12]}... is out of range",
                    SourcePos(
                        0,
                        body_start
                        + pos
                        + 1
                        + (len(body[pos + 1 :]) - len(body[pos + 1 :].lstrip(" \t"))),
                    ),
                )
            words.append(Word(letter.upper(), value, body_start + pos))
            pos += 1
        else:
            pos = find(comment, pos)
            comments.append(("comment", comment, body_start + pos))
            pos += len(comment)
    delete, semicolon = match.group(1, 3)
    if semicolon is not None:
        comments.append(("comment", semicolon, match.start(3) + 1))
    if not words and not comments and delete is None:
        return EMPTY_BLOCK
    return Block(delete is not None, tuple(words), (), tuple(comments))


#: Lines longer than this are refused, on every path (the plain-word fast path, lark, the
#: whole-file parse; the fast lane leaves them to the general path): LinuxCNC refuses
#: anything past 256 characters; this bound keeps the work on a hostile 10 MB line (of
#: nested brackets, or of plain words) to a fraction of a second.
MAX_LINE_CHARS = 65536

_LINE_BREAKS = re.compile(r"\r+\n|\r")


def split_lines(text: str) -> list[str]:
    """The physical lines of a program text: LF, CRLF, CR CR LF (one line end, as LinuxCNC's
    line reader counts it) and lone CR all end a line; a leading byte-order mark is dropped."""
    if text.startswith("\ufeff"):
        text = text[1:]
    if "\r" in text:
        text = _LINE_BREAKS.sub("\n", text)
    return text.split("\n")


def parse_line(line: str, line_no: int) -> Block:
    """Parse one physical line (``line_no`` 1-based, for error positions) into a Block."""
    if len(line) > MAX_LINE_CHARS:
        raise _too_long(line, line_no)
    match = _SIMPLE_LINE.fullmatch(line)
    if match is not None and not (("o" in line or "O" in line) and _O_WORD.match(line)):
        try:
            return _fast_block(line, match)
        except GCodeSyntaxError as exc:
            exc.pos = SourcePos(line_no, exc.pos.column, line)
            raise
    if "%" in line and _PERCENT_LINE.fullmatch(line) is not None:
        return PERCENT_BLOCK
    return _parse_lark(line, line_no - 1)[0]


def _too_long(line: str, line_no: int) -> GCodeSyntaxError:
    return GCodeSyntaxError(
        f"line is too long ({len(line)} characters; at most {MAX_LINE_CHARS})",
        SourcePos(line_no, MAX_LINE_CHARS + 1, line),
    )


def parse_text(text: str, fast: bool = True) -> list[Block]:
    """Parse a whole program; return one :class:`Block` per physical line (index = line − 1).

    Raises :class:`GCodeSyntaxError` with the line, column and source text of the first error.
    See :func:`split_lines` for line ends. ``fast`` selects the regular-expression path for
    plain-word lines (same result, see above). The interpreter parses lazily instead, line
    by line as it executes (:func:`parse_line`): text after M2 is never parsed.
    """
    lines = split_lines(text)
    if not fast:
        for index, line in enumerate(lines):
            if len(line) > MAX_LINE_CHARS:
                raise _too_long(line, index + 1)
        return _parse_lark("\n".join(lines), 0)
    return [parse_line(line, index + 1) for index, line in enumerate(lines)]


def _parse_lark(text: str, line_offset: int) -> list[Block]:
    """Parse ``text`` (a whole file, or the one line at index ``line_offset``) with lark."""
    try:
        return _parse_lark_raw(text)
    except NurbsCncError as exc:
        if line_offset and exc.pos is not None:
            exc.pos = SourcePos(exc.pos.line + line_offset, exc.pos.column, exc.pos.text)
        raise


def _parse_lark_raw(text: str) -> list[Block]:
    parser = _parser()  # lark is imported from here on
    from lark import UnexpectedCharacters, UnexpectedInput, UnexpectedToken
    from lark.exceptions import VisitError

    try:
        return parser.parse(text)
    except UnexpectedCharacters as exc:
        raise _character_error(text, exc) from None
    except UnexpectedToken as exc:
        raise _token_error(text, exc) from None
    except UnexpectedInput as exc:  # pragma: no cover - other lark input errors
        raise GCodeSyntaxError(str(exc).splitlines()[0], SourcePos(1, 1, "")) from None
    except (VisitError, NurbsCncError) as exc:
        # A transformer callback raised (an out-of-range number): report it with its line.
        inner = exc.orig_exc if isinstance(exc, VisitError) else exc
        if not isinstance(inner, NurbsCncError) or inner.pos is None:
            raise
        lines = _split_lines(text)
        line_no = inner.pos.line
        inner.pos = SourcePos(line_no, inner.pos.column, lines[line_no - 1])
        raise inner from None


def _character_error(text: str, exc: UnexpectedCharacters) -> GCodeSyntaxError:
    """The error for a character the grammar cannot take (comments named)."""
    lines = _split_lines(text)
    line_text = lines[exc.line - 1] if 0 < exc.line <= len(lines) else ""
    ch = text[exc.pos_in_stream] if exc.pos_in_stream < len(text) else ""
    if ch == "(":
        msg = "nested comment: '(' inside a comment"
        if ")" not in line_text[exc.column - 1 :]:
            msg = "unclosed comment: '(' with no ')' on the line"
    elif ch == ")":
        msg = "')' with no comment open"
    elif not ch.isascii():
        msg = f"unexpected character {ch!r} (G-code is ASCII)"
    else:
        msg = f"unexpected character {ch!r}" + _expected(exc.allowed or ())
    return GCodeSyntaxError(msg, SourcePos(exc.line, exc.column, line_text))


def _token_error(text: str, exc: UnexpectedToken) -> GCodeSyntaxError:
    """The error for a token out of place (an end of line, a letter for a value …)."""
    lines = _split_lines(text)
    line_no = exc.line if exc.line and exc.line > 0 else len(lines)
    line_text = lines[line_no - 1] if 0 < line_no <= len(lines) else ""
    tok = exc.token
    if tok.type == "$END":
        what = "unexpected end of line" if "\n" not in text else "unexpected end of file"
        column = len(line_text) + 1
    elif tok.type == "_NL":
        what = "unexpected end of line"
        column = len(line_text) + 1
    elif "NUMBER" in exc.expected and tok.type in ("LETTER", "FUNC", "LOGIC_OP"):
        what = f"expected a value (a number, [expression] or #parameter), got {str(tok)!r}"
        column = exc.column if exc.column and exc.column > 0 else 1
        return GCodeSyntaxError(what, SourcePos(line_no, column, line_text))
    else:
        what = f"unexpected {str(tok).strip()!r}"
        column = exc.column if exc.column and exc.column > 0 else 1
    return GCodeSyntaxError(what + _expected(exc.expected), SourcePos(line_no, column, line_text))
