"""User-facing text in plain words: the planner's reasons (corners, limits) and the stream's
planning report say what happened without the paper's terms ("stop faster", "cut
window(s)", "V_max", equation numbers); the JSON keeps its machine-readable names."""

from __future__ import annotations

import re

from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.cli.stream import _planning_text
from nurbscnc.plan.corners import CornerAction, CornerWhy
from nurbscnc.plan.explain import CORNER_ACTION_TEXT, CORNER_WHY_TEXT, Limit

JARGON = re.compile(r"stop faster|cut window|unfinished|V_max|eq\. \d|SPEC|_")


def test_every_corner_reason_and_limit_has_plain_words():
    assert set(CORNER_WHY_TEXT) == set(CornerWhy)
    assert set(CORNER_ACTION_TEXT) == set(CornerAction)
    for text in [*CORNER_WHY_TEXT.values(), *CORNER_ACTION_TEXT.values()]:
        assert text and not JARGON.search(text), text
    for limit in Limit:
        assert not JARGON.search(limit.text), limit.text


def test_plan_explain_says_why_a_corner_stopped_in_plain_words(tmp_path):
    prog = tmp_path / "g61.nc"
    prog.write_text("G21 G90 G61 F3000\nG1 X10 Y0\nG1 X10 Y10\nG1 X0 Y10\nM2\n")
    result = CliRunner().invoke(main, ["plan", str(prog), "--explain"])
    assert result.exit_code == 0, result.output
    assert "corners: 2 stopped: exact path mode (G61)" in result.stdout
    assert "stop at line 2 (10.000, 0.000, 0.000), a 90.0° turn: exact path mode (G61)" in (
        result.stdout
    )
    assert not re.search(r"stop faster|exact_path|stop/", result.stdout)


def test_stream_planning_line_in_plain_words():
    planning = {
        "windows": 5,
        "first_window_s": 0.25,
        "planned_s": None,
        "plan_margin_min_s": 1.5,
        "holds": 1,
        "held_s": 0.125,
    }
    text = _planning_text(planning)
    assert text == (
        "planning: 5 parts planned while the card ran; the first ready after 0.250 s, all "
        "not before the stream ended; the planner stayed at least 1.500 s ahead of the card; "
        "the card waited for the planner 1 time, 0.125 s in all"
    )
    done = _planning_text({**planning, "windows": 1, "planned_s": 2.0, "holds": 0})
    assert "1 part planned" in done and "all after 2.000 s" in done and "0 times" in done
    assert not JARGON.search(text + done)
