"""Bad programs in the LinuxCNC test style: one file per case in ``tests/bad/``.

File format: the first line of every case is a comment naming what must be reported::

    ; <expected message substring> @ <line>:<column>

``<line>`` and ``<column>`` are 1-based and count the header line itself (so the program
body starts on line 2). Running ``nurbscnc check FILE`` must exit 2 (a bad program, never 1,
an internal error), print ``FILE:line:col: error: <message containing the substring>``
followed by the source line and a caret under the column, and never a traceback;
``--json`` must report ``ok: false`` with the same line, column and message.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.errors import NurbsCncError
from nurbscnc.program.interpret import interpret_text

BAD = Path(__file__).resolve().parent / "bad"
CASES = sorted(BAD.glob("*.nc"))
HEADER = re.compile(r"; (?P<message>.+) @ (?P<line>\d+):(?P<column>\d+)")

# A few cases also run through a real interpreter process (console entry, encoding, exit code).
SUBPROCESS_CASES = [
    "syntax_nonascii_digit.nc",
    "syntax_overflow_digits.nc",
    "g5_unclosed_eof.nc",
    "g6_interior_multiplicity.nc",
    "o_word_sub.nc",
]


def expected(path: Path) -> tuple[str, int, int, str]:
    """(message substring, line, column, source line at that line) from a case's header."""
    lines = path.read_text(encoding="utf-8").splitlines()
    match = HEADER.fullmatch(lines[0])
    assert match is not None, f"{path.name}: bad header {lines[0]!r}"
    line, column = int(match["line"]), int(match["column"])
    assert 2 <= line <= len(lines), f"{path.name}: line {line} outside the file"
    return match["message"], line, column, lines[line - 1]


def check_report(stderr: str, path: str, case: Path) -> None:
    """The three-line report: location + message, source line, caret under the column."""
    message, line, column, source = expected(case)
    assert "Traceback" not in stderr
    assert "internal error" not in stderr
    out = stderr.splitlines()
    if out and out[0].startswith("machine: "):  # which profile the command used, said first
        out = out[1:]
    head = f"{path}:{line}:{column}: error: "
    assert out[0].startswith(head), out[0]
    assert message in out[0][len(head) :]
    source = source.replace("\t", " ")
    if len(source) <= 120:
        assert out[1] == "    " + source
        assert out[2] == "    " + " " * (column - 1) + "^"
    else:  # a long line is cut to ~120 characters around the column, "…" where cut
        shown, caret = out[1][4:], len(out[2]) - 5
        assert len(shown) <= 122 and shown.strip("…") in source
        assert out[2].endswith("^") and shown[caret] == source[column - 1]


def test_enough_cases():
    assert len(CASES) >= 45


@pytest.mark.parametrize("case", CASES, ids=lambda p: p.stem)
def test_library_error_position(case):
    """interpret_text raises the project's error with the expected message and position."""
    message, line, column, source = expected(case)
    with pytest.raises(NurbsCncError) as info:
        interpret_text(case.read_text(encoding="utf-8"))
    exc = info.value
    assert message in exc.message
    assert (exc.pos.line, exc.pos.column, exc.pos.text) == (line, column, source)


@pytest.mark.parametrize("case", CASES, ids=lambda p: p.stem)
def test_cli_check(case):
    result = CliRunner().invoke(main, ["check", str(case)])
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert result.exit_code == 2, result.output
    check_report(result.stderr, str(case), case)


@pytest.mark.parametrize("case", CASES, ids=lambda p: p.stem)
def test_cli_check_json(case):
    message, line, column, _ = expected(case)
    result = CliRunner().invoke(main, ["check", "--json", str(case)])
    assert result.exit_code == 2
    report = json.loads(result.stdout)
    assert report["ok"] is False
    (error,) = report["errors"]
    assert (error["line"], error["column"]) == (line, column)
    assert message in error["message"]


@pytest.mark.parametrize("name", SUBPROCESS_CASES)
def test_cli_subprocess(name):
    case = BAD / name
    proc = subprocess.run(
        [sys.executable, "-m", "nurbscnc", "check", str(case)],
        capture_output=True,
        text=True,
        encoding="utf-8",
        timeout=60,
    )
    assert proc.returncode == 2, proc.stderr
    check_report(proc.stderr, str(case), case)


def test_cli_stdin_reports_stdin_name():
    """``-`` reads the program from stdin; the report names ``<stdin>``."""
    case = BAD / "div_zero.nc"
    result = CliRunner().invoke(main, ["check", "-"], input=case.read_bytes())
    assert result.exit_code == 2
    check_report(result.stderr, "<stdin>", case)
