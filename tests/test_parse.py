"""The parser (nurbscnc/program/parse.py): blocks, words, columns and expression tuples.

Expected blocks are written out by hand from the RS274/NGC rules (LinuxCNC's reader): blanks
inside words, case folding, comments, block delete, tape marks, line ends, operator
precedence. Every check runs on both parse paths (regex fast path and lark).
"""

from __future__ import annotations

import pytest

from nurbscnc.errors import GCodeSyntaxError, NurbsCncError
from nurbscnc.program.parse import (
    EMPTY_BLOCK,
    Assign,
    Block,
    Word,
    grammar_text,
    is_constant,
    parse_text,
)

PATHS = pytest.mark.parametrize("fast", [True, False], ids=["fast", "lark"])


def one(text: str, fast: bool) -> Block:
    (block,) = parse_text(text, fast=fast)
    return block


def words(block: Block) -> list[tuple[str, object]]:
    return [(w.letter, w.value) for w in block.words]


@PATHS
def test_plain_words_and_columns(fast):
    block = one("G1 X1.5 Y-2 F300", fast)
    assert block == Block(
        False,
        (Word("G", 1.0, 1), Word("X", 1.5, 4), Word("Y", -2.0, 9), Word("F", 300.0, 13)),
        (),
        (),
    )


@PATHS
def test_blanks_inside_words(fast):
    """LinuxCNC drops blanks anywhere in a word: "G 1 X 1 . 5" is G1 X1.5."""
    block = one("G 1 X 1 . 5 Y- 2 Z1 2 3\tF\t6 0 0", fast)
    assert words(block) == [("G", 1.0), ("X", 1.5), ("Y", -2.0), ("Z", 123.0), ("F", 600.0)]
    assert [w.column for w in block.words] == [1, 5, 13, 18, 25]


@PATHS
def test_case_insensitive(fast):
    assert one("g1 x1 y2 f100", fast) == one("G1 X1 Y2 F100", fast)
    upper = one("G1 X[SIN[30] MOD 2 AND 1]", fast)
    assert one("g1 x[sin[30] mod 2 and 1]", fast) == upper
    assert one("g1 X[Sin[30] mOd 2 AnD 1]", fast) == upper


@PATHS
@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("X1.", 1.0),
        ("X.5", 0.5),
        ("X-.5", -0.5),
        ("X+1", 1.0),
        ("X0.125", 0.125),
        ("X-0", 0.0),
        ("X007", 7.0),
        ("X--1", 1.0),
        ("X-+2", -2.0),
    ],
)
def test_number_forms(fast, text, value):
    (word,) = one(text, fast).words
    assert word.value == value and is_constant(word.value)


@PATHS
def test_comments_and_notes_kept_with_columns(fast):
    block = one("G0 X1 (first) (MSG, hello world) Y2 ; rest (not a comment)", fast)
    assert words(block) == [("G", 0.0), ("X", 1.0), ("Y", 2.0)]
    assert block.comments == (
        ("comment", "(first)", 7),
        ("comment", "(MSG, hello world)", 15),
        ("comment", "; rest (not a comment)", 37),
    )


@PATHS
def test_comment_only_and_empty_lines(fast):
    blocks = parse_text("(header)\n\n   \n; note\nG0 X1\n", fast=fast)
    assert len(blocks) == 6  # one per physical line, the trailing newline included
    assert blocks[0].comments == (("comment", "(header)", 1),) and not blocks[0].words
    assert blocks[1] == blocks[2] == blocks[5] == EMPTY_BLOCK
    assert blocks[3].comments == (("comment", "; note", 1),)
    assert words(blocks[4]) == [("G", 0.0), ("X", 1.0)]


@PATHS
def test_block_delete_and_line_numbers(fast):
    block = one("/N120 G1 X2", fast)
    assert block.delete is True
    assert words(block) == [("G", 1.0), ("X", 2.0)]  # the N word is dropped
    assert one("/ N 1 2 G1", fast).delete is True
    assert one("N120 G1 X2", fast).delete is False
    assert one("/", fast) == Block(True, (), (), ())
    # N after the first word is an ordinary word (the interpreter refuses it).
    assert words(one("G1 N5", fast)) == [("G", 1.0), ("N", 5.0)]


@PATHS
def test_percent_tape_marks(fast):
    blocks = parse_text("%\nG0 X1\n% (end)\n", fast=fast)
    assert blocks[0].percent and blocks[2].percent
    assert not blocks[1].percent


def test_line_ends_and_bom():
    lf = parse_text("G0 X1\nG1 Y2 F3\n(c)\n")
    assert parse_text("G0 X1\r\nG1 Y2 F3\r\n(c)\r\n") == lf
    assert parse_text("G0 X1\rG1 Y2 F3\r(c)\r") == lf
    assert parse_text("\ufeffG0 X1\r\nG1 Y2 F3\n(c)\n") == lf
    assert parse_text("\ufeffG0 X1\r\nG1 Y2 F3\n(c)\n", fast=False) == lf


@PATHS
def test_parameters_and_assignments(fast):
    block = one("#1=[#2+1] #<Feed Rate> = 3 X#1 Y#<feedrate> Z##2", fast)
    assert block.assigns == (
        Assign(("#", 1.0), ("op", "+", ("#", 2.0), 1.0), 0),
        Assign(("<", "feedrate"), 3.0, 0),  # names fold case and drop blanks
    )
    assert words(block) == [("X", ("#", 1.0)), ("Y", ("<", "feedrate")), ("Z", ("#", ("#", 2.0)))]
    assert not is_constant(block.words[0].value)


@PATHS
@pytest.mark.parametrize(
    ("expr", "tree"),
    [
        # ** over * / MOD over + - over comparisons over logic; all left-associative.
        ("[1+2*3**2]", ("op", "+", 1.0, ("op", "*", 2.0, ("op", "**", 3.0, 2.0)))),
        ("[8-2-1]", ("op", "-", ("op", "-", 8.0, 2.0), 1.0)),
        ("[8/2/2]", ("op", "/", ("op", "/", 8.0, 2.0), 2.0)),
        ("[2**3**2]", ("op", "**", ("op", "**", 2.0, 3.0), 2.0)),
        ("[7 MOD 3 * 2]", ("op", "*", ("op", "MOD", 7.0, 3.0), 2.0)),
        ("[1+1 GT 1]", ("op", "GT", ("op", "+", 1.0, 1.0), 1.0)),
        ("[1 LT 2 AND 3 EQ 3]", ("op", "AND", ("op", "LT", 1.0, 2.0), ("op", "EQ", 3.0, 3.0))),
        ("[0 OR 1 XOR 1]", ("op", "XOR", ("op", "OR", 0.0, 1.0), 1.0)),
        ("[[1+2]*3]", ("op", "*", ("op", "+", 1.0, 2.0), 3.0)),
        ("[-#1]", ("neg", ("#", 1.0))),
        ("#-1", ("#", -1.0)),
        ("SQRT[4]", ("fn", "SQRT", 4.0)),
        ("abs[-2]", ("fn", "ABS", -2.0)),
        ("ATAN[1]/[-2]", ("atan", 1.0, -2.0)),
        ("EXISTS[#<Tool Len>]", ("exists", "toollen")),
        ("[1 NE 2 GE 0 LE 1]", ("op", "LE", ("op", "GE", ("op", "NE", 1.0, 2.0), 0.0), 1.0)),
    ],
)
def test_expression_tuples(fast, expr, tree):
    (word,) = one("X" + expr, fast).words
    assert word.value == tree


@PATHS
def test_syntax_error_position_on_a_later_line(fast):
    with pytest.raises(GCodeSyntaxError) as info:
        parse_text("G0 X1\n(ok)\nG1 X[1 + ] F1\n", fast=fast)
    assert (info.value.pos.line, info.value.pos.column) == (3, 10)
    assert info.value.pos.text == "G1 X[1 + ] F1"


@PATHS
@pytest.mark.parametrize(
    "text",
    [
        "G1 Xnan",
        "G1 Xinf",
        "G1 X1_0",
        "G1 X\u0661",
        "G1 X[1]]",
        "G1 X[1e5]",
        "G1 (a (b) c)",
        "G1 (open",
        "G1 X1)",
        "G1 X" + "9" * 400,
        "N1.5.5",
        "G1 X",
        "#1 =",
        "G1 X*2",
    ],
)
def test_not_gcode(fast, text):
    """What Python's float() takes but G-code does not, and other malformed lines."""
    with pytest.raises(GCodeSyntaxError):
        parse_text(text, fast=fast)


@PATHS
def test_exponent_and_hex_are_not_numbers(fast):
    """The letter after the digits starts a new word (the interpreter then refuses E or the
    repeated X): no exponent or hex notation sneaks in through float()."""
    assert words(one("X1e5", fast)) == [("X", 1.0), ("E", 5.0)]
    assert words(one("X0x10", fast)) == [("X", 0.0), ("X", 10.0)]


@PATHS
def test_overflowing_number_is_an_error(fast):
    with pytest.raises(GCodeSyntaxError, match="out of range") as info:
        parse_text("G0\nG1 F1 X" + "9" * 400, fast=fast)
    assert (info.value.pos.line, info.value.pos.column) == (2, 8)


@PATHS
def test_o_word_lines(fast):
    blocks = parse_text("G0 X1\n/ N5 o0100 sub\nO<My Sub> call [1] [#2+1] (c)\nO1234\n", fast)
    assert blocks[1].delete and blocks[1].oword == ("100", "sub", (), 6)
    label, keyword, args, column = blocks[2].oword
    assert (label, keyword, column) == ("<mysub>", "call", 1)
    assert args == (1.0, ("op", "+", ("#", 2.0), 1.0))
    assert blocks[2].comments == (("comment", "(c)", 27),)
    assert blocks[3].oword == ("1234", "", (), 1)


def test_errors_are_project_errors():
    assert issubclass(GCodeSyntaxError, NurbsCncError)


def test_grammar_text_is_the_lark_file():
    text = grammar_text()
    assert "start:" in text and "NUMBER" in text


@PATHS
@pytest.mark.parametrize(
    "line", [" " * 20000 + "%", "X1" + " \t" * 10000 + "%", "G1" + " 1" * 10000 + " $"]
)
def test_long_failing_lines_parse_in_linear_time(fast, line):
    """Regression: the fast-path regex backtracked cubically over blank runs (a line of
    1,000 blanks and a '%' took 8 s, 20,000 would take hours)."""
    import time

    t0 = time.perf_counter()
    try:
        parse_text(line, fast=fast)
    except NurbsCncError:
        pass
    assert time.perf_counter() - t0 < 1.0


def test_operator_keywords_do_not_swallow_the_next_word():
    """Found by the grammar fuzzer: in "G0GEXISTS[...]" LALR state merging offered the
    operator GE right after the number 0; operator keywords may not run into a letter."""
    from nurbscnc.program.parse import parse_text

    words = parse_text("G0GEXISTS[<a>]")[0].words
    assert [w.letter for w in words] == ["G", "G"]
    assert words[1].value == ("exists", "a")
    assert parse_text("X[1GE2]")[0].words[0].value == ("op", "GE", 1.0, 2.0)


@pytest.mark.parametrize("line", ["%%", "% X1", "% (a", "%)", "(a) %", "%\x00"])
def test_percent_lines_the_fast_path_leaves_to_lark(line):
    """Only "%" and comments make a tape mark: anything else on the line is lark's to refuse
    (or, for "(a) %", read as a comment and a stray %), the same with and without the fast
    path."""

    def outcome(fast):
        try:
            return parse_text(line, fast=fast)
        except GCodeSyntaxError as exc:
            return (exc.message, exc.pos)

    assert outcome(True) == outcome(False)
