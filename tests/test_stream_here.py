"""``nurbscnc stream`` of a program starts where the card stands (as LinuxCNC's: the
program's first move goes from the current position), end to end through the CLI against
the card simulator on a pty, after a setup by ``mdi`` ("zero here") and ``jog``.

The machine: the bundled profile with 800 steps/mm in X, 1000 in Y, 400 in Z (different per
axis, so a mix-up of axes or of steps and mm shows). Every expected position is worked out
here from the card's start, the jog and the program's text (machine = start + relative
moves, or G54 offset + work position), never taken from the code under test.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.card import CardConfig
from nurbscnc.program.varfile import parse_var_text
from tests.stream_helpers import card_on, write_mixed_steps_machine

MACHINE = ["--machine", "m.toml"]
PER_MM = np.array([800.0, 1000.0, 400.0])
START_STEPS = (12345, -3000, -5000)  # machine (15.43125, -3, -12.5) mm
# After "zero here" at the start and a jog of X+2 Y+1: machine (17.43125, -2, -12.5) mm.
JOGGED_STEPS = (12345 + 1600, -3000 + 1000, -5000)
G54_MM = np.array(START_STEPS) / PER_MM


def run_cli(args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture
def here(tmp_path, monkeypatch):
    return write_mixed_steps_machine(tmp_path, monkeypatch)


@pytest.fixture
def setup_card(here):
    """The card at START_STEPS, G54 zeroed there (mdi), then jogged X+2 Y+1."""
    with card_on("pty", CardConfig(speed=None, position_steps=START_STEPS)) as (sim, ep):
        common = ["--port", ep.path, "--var", "m.var", *MACHINE]
        r = run_cli(["mdi", "G10 L20 P1 X0 Y0 Z0", *common])
        assert r.exit_code == 0, r.output
        r = run_cli(["jog", "X+2", "Y+1", *common])
        assert r.exit_code == 0, r.output
        assert sim.position.tolist() == list(JOGGED_STEPS)
        values = parse_var_text((here / "m.var").read_text(), "m.var")
        assert [values[k] for k in (5221, 5222, 5223)] == pytest.approx(G54_MM.tolist(), abs=0)
        yield sim, common


def stream(path, common, *extra):
    return run_cli(["stream", path, *common, *extra])


def test_relative_then_absolute_program_starts_where_the_card_stands(here, setup_card):
    """A relative program moves from the jogged position; an absolute one goes to its work
    positions in G54 (zeroed at the start), whatever the card's position before."""
    sim, common = setup_card
    (here / "rel.nc").write_text("G21 G91 G17 G61\nG1 X1.5 Y-0.5 F3000\nG1 Z-0.5\nM2\n")
    before = len(sim.executed_pulses())
    r = stream("rel.nc", common, "--json")
    assert r.exit_code == 0, r.output
    start = np.array(JOGGED_STEPS)
    corner = start + np.rint(np.array([1.5, -0.5, 0.0]) * PER_MM).astype(int)
    end = corner + np.array([0, 0, -200])  # Z -0.5 mm · 400
    assert sim.position.tolist() == end.tolist() and sim.positions_set == 0
    # The path from the card's position: through the corner (G61: exact stop).
    path = start + np.cumsum(sim.executed_pulses()[before:], axis=0)
    assert np.abs(path - corner).max(axis=1).min() == 0
    body = json.loads(r.stdout.strip().splitlines()[-1])
    assert body["final_position_mm"] == pytest.approx((end / PER_MM).tolist(), abs=1e-9)

    (here / "abs.nc").write_text("G21 G90 G17\nG1 X4 Y3 F3000\nG0 Z1\nG1 X-1 Y0.5\nM2\n")
    r = stream("abs.nc", common, "--json")
    assert r.exit_code == 0, r.output
    want_mm = G54_MM + np.array([-1.0, 0.5, 1.0])  # machine = G54 offset + work position
    assert sim.position.tolist() == np.rint(want_mm * PER_MM).astype(int).tolist()
    body = json.loads(r.stdout.strip().splitlines()[-1])
    assert body["coordinate_system"] == "G54"
    assert body["final_work_position_mm"] == pytest.approx([-1.0, 0.5, 1.0], abs=1e-9)


def test_from_line_approaches_from_where_the_card_stands(here, setup_card):
    """Run from line 4 (G1 Y5, starting at work X5 Y0): up to the highest Z before it (Z2),
    across, down, then line 4 on: it ends at work (5, 5, -1) = G54 + that."""
    sim, common = setup_card
    text = "G21 G90 G17\nG0 X0 Y0 Z2\nG1 Z-1 F600\nG1 X5 F3000\nG1 Y5\nM2\n"
    (here / "part.nc").write_text(text)
    before = len(sim.executed_pulses())
    r = stream("part.nc", common, "--from-line", "5")
    assert r.exit_code == 0, r.output
    want_mm = G54_MM + np.array([5.0, 5.0, -1.0])
    assert sim.position.tolist() == np.rint(want_mm * PER_MM).astype(int).tolist()
    # The approach rises first: from the jogged Z (work 0) up to work Z2 on the spot.
    path = np.array(JOGGED_STEPS) + np.cumsum(sim.executed_pulses()[before:], axis=0)
    top = int(np.rint((G54_MM[2] + 2.0) * PER_MM[2]))
    up = int(np.flatnonzero(path[:, 2] == top)[0])
    assert np.all(path[: up + 1, :2] == np.array(JOGGED_STEPS)[:2])


def test_a_plan_error_from_the_cards_position_moves_nothing(here, setup_card):
    """G91 X30 fits the soft limits from machine zero (X max 40) but not from the card's
    X 17.43 mm: exit 2 after the card was asked where it stands, the card not moved, the
    parameter file untouched."""
    sim, common = setup_card
    (here / "far.nc").write_text("G21 G91\nG0 X30\nM2\n")
    var_before = (here / "m.var").read_text()
    executed = sim.report()["executed_periods"]
    r = stream("far.nc", common, "--set", "soft_limits.x.max_mm=40")
    assert r.exit_code == 2, r.output
    assert "X reaches 47.43" in r.stderr and "Traceback" not in r.output
    assert sim.position.tolist() == list(JOGGED_STEPS)
    assert sim.report()["executed_periods"] == executed
    assert (here / "m.var").read_text() == var_before


def test_a_bad_program_fails_before_the_port(here, setup_card):
    """A syntax error is found before the card is asked anything: not one byte sent."""
    sim, common = setup_card
    (here / "bad.nc").write_text("G21 G90\nG1 X1 F100\nG1 X2 Y#\nM2\n")
    received = sim.bytes_received
    r = stream("bad.nc", common)
    assert r.exit_code == 2, r.output
    assert "bad.nc:3:" in r.stderr and "Traceback" not in r.output
    assert sim.bytes_received == received
    assert sim.position.tolist() == list(JOGGED_STEPS)


def test_a_card_in_alarm_is_refused_and_zero_runs_from_machine_zero(here, setup_card):
    """The card's state is checked as mdi checks it; --zero declares the card at the
    program's start at machine zero instead of reading where it stands."""
    sim, common = setup_card
    (here / "abs.nc").write_text("G21 G90\nG53 G0 X0 Y0 Z0\nG53 G1 X2 Y1 F3000\nM2\n")
    sim.state = p.CardState.ALARM
    r = stream("abs.nc", common)
    assert r.exit_code == 3 and "the card is in ALARM" in r.stderr, r.output
    assert sim.position.tolist() == list(JOGGED_STEPS)
    sim.state = p.CardState.DONE
    r = stream("abs.nc", common, "--zero")
    assert r.exit_code == 0, r.output
    # declared at machine (0, 0, 0), then moved to machine (2, 1, 0) by G53
    assert sim.positions_set == 1 and sim.position.tolist() == [1600, 1000, 0]


def test_an_arc_valid_from_the_card_is_not_refused_from_machine_zero(here, setup_card):
    """G2 X6 Y1 R2.5 from the card at work (2, 1): 4 mm to the end, less than 2R = 5 mm, so
    the arc exists (from machine zero, 15 mm away, it would not): it runs and ends at work
    (6, 1, 0). With R1.5 (2R = 3 mm < 4 mm) it is an error from the card too: exit 2, not
    moved."""
    sim, common = setup_card
    (here / "bad_arc.nc").write_text("G21 G90 G17\nG2 X6 Y1 R1.5 F600\nM2\n")
    r = stream("bad_arc.nc", common)
    assert r.exit_code == 2 and "bad_arc.nc:2:" in r.stderr and "R1.5" in r.stderr, r.output
    assert sim.position.tolist() == list(JOGGED_STEPS)
    (here / "arc.nc").write_text("G21 G90 G17\nG2 X6 Y1 R2.5 F600\nM2\n")
    r = stream("arc.nc", common)
    assert r.exit_code == 0, r.output
    want_mm = G54_MM + np.array([6.0, 1.0, 0.0])
    assert sim.position.tolist() == np.rint(want_mm * PER_MM).astype(int).tolist()
    # --zero: from machine zero, work (-15.43, 3) in G54, to work (6, 1): 21.5 mm > 5 mm
    r = stream("arc.nc", common, "--zero")
    assert r.exit_code == 2 and "arc.nc:2:" in r.stderr, r.output
