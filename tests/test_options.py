"""Options are validated where they are built (issue 12; Ruckig's InputParameter::validate).

A misspelt or differently capitalised choice, a negative tolerance, a zero look-ahead:
ConfigError at construction, never a silent fallback in the planner. Valid strings become
their enum members. Every command that plans declares the same planning options.
"""

from __future__ import annotations

import math

import click
import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.app.settings import PLANNING_KEYS, PROGRAM_INPUT_KEYS, run_options
from nurbscnc.cli.main import main
from nurbscnc.errors import ConfigError
from nurbscnc.interpolate.sample import Interpolator
from nurbscnc.pipeline import Algorithm, RunOptions
from nurbscnc.plan.options import CornerFeed, Dynamics, LookaheadOptions, PlanOptions


@pytest.mark.parametrize(
    "kwargs",
    [
        {"dynamics": "Global"},
        {"dynamics": "none"},
        {"dynamics": 1},
        {"max_iterations": -1},
        {"max_iterations": 2.5},
        {"max_iterations": True},
        {"lookahead_pieces": 0},
        {"lookahead_pieces": 3.0},
        {"plan": "piece"},
    ],
)
def test_bad_lookahead_options_raise(kwargs):
    with pytest.raises(ConfigError):
        LookaheadOptions(**kwargs)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"corner_feed": "paek"},
        {"corner_feed": "PEAK"},
        {"ph": "yes"},
        {"tolerance_mm": 0.0},
        {"tolerance_mm": -1e-3},
        {"tolerance_mm": math.nan},
        {"blend_tolerance_mm": -0.1},
        {"blend_tolerance_mm": math.inf},
        {"blend_tolerance_mm": "1"},
    ],
)
def test_bad_plan_options_raise(kwargs):
    with pytest.raises(ConfigError):
        PlanOptions(**kwargs)


@pytest.mark.parametrize(
    "kwargs", [{"algorithm": "fast"}, {"interpolator": "euler"}, {"interpolator": "Taylor"}]
)
def test_bad_run_options_raise(kwargs):
    with pytest.raises(ConfigError):
        RunOptions(**kwargs)


def test_valid_strings_become_members_and_lengths_are_mm():
    opt = LookaheadOptions(
        dynamics="global",
        lookahead_pieces=5,
        plan=PlanOptions(corner_feed="peak", tolerance_mm=1e-3, blend_tolerance_mm=0),
    )
    assert opt.dynamics is Dynamics.GLOBAL and opt.plan.corner_feed is CornerFeed.PEAK
    assert opt.plan.tolerance_mm == 1e-3 and opt.plan.blend_tolerance_mm == 0.0
    assert not hasattr(opt.plan, "tolerance_um")
    run = RunOptions(algorithm="adaptive", interpolator="taylor")
    assert run.algorithm is Algorithm.ADAPTIVE and run.interpolator is Interpolator.TAYLOR
    built = run_options("ph-lookahead", "peak", "off", 0.05, "exact", 7)
    assert built.lookahead == LookaheadOptions(
        dynamics="off",
        lookahead_pieces=7,
        plan=PlanOptions(corner_feed="peak", blend_tolerance_mm=0.05),
    )


def _params(command: str) -> set[str]:
    return {p.name for p in main.get_command(None, command).params if isinstance(p, click.Option)}


def test_every_planning_command_has_the_same_planning_options():
    want = set(PLANNING_KEYS) | set(PROGRAM_INPUT_KEYS) | {"machine", "overrides"}
    for command in ("plan", "run", "simulate", "stream"):
        assert want <= _params(command), command


def test_run_reads_the_tool_table_and_subroutine_path(tmp_path):
    """`run` takes the program-input options of `check`: G43 H1 with a 10 mm tool moves the
    machine Z by the tool length (LinuxCNC: machine = program + offset), and `o<lift> call`
    finds lift.ngc on --subroutine-path."""
    tools = tmp_path / "tools.tbl"
    tools.write_text("T1 P1 Z10 D4 ;ten millimetre tool\n")
    subs = tmp_path / "subs"
    subs.mkdir()
    (subs / "lift.ngc").write_text("o<lift> sub\nG0 Z#1\no<lift> endsub\nM2\n")
    prog = tmp_path / "part.nc"
    prog.write_text("G21 G90 T1 M6 G43 H1\nG0 X0 Y0 Z0\nG1 X5 F600\no<lift> call [2]\nM2\n")
    out = tmp_path / "p.csv"
    result = CliRunner().invoke(
        main,
        [
            "run",
            str(prog),
            "-o",
            str(out),
            "--dynamics",
            "off",
            "--tool-table",
            str(tools),
            "--subroutine-path",
            str(subs),
        ],
    )
    assert result.exit_code == 0, result.output
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert rows[-1, 1:4] == pytest.approx([5.0, 0.0, 12.0], abs=1e-12)  # Z2 + 10 mm tool
    # Where the G1 ends (X5) and the lift starts, Z is the program's 0 plus the 10 mm tool.
    # (the stop falls between two servo periods: the next sample is 0.3 nm up the lift)
    assert rows[rows[:, 1] == 5.0, 3].min() == pytest.approx(10.0, abs=1e-6)
