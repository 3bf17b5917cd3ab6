"""Rotary programs streamed end to end through the CLI to the card simulator on a pty: the
program text interpreted and planned with A and B, the card driving X Y Z A B (protocol 4),
a version-3 card refused, ``card-position`` and ``jog`` in degrees.

The machine: the bundled profile with 800 / 1000 / 400 steps per mm on X / Y / Z, and A
(250 steps per degree) and B (40 steps per degree) axes: every axis different, so a
mixed-up column shows. The card's expected steps are worked out here from the program's
text (its last X Y Z A B words) and these steps per unit, never taken from the code under
test. These tests need the interpreter's and the planner's rotary axes (issue 37's other
layers): they skip, saying so, on a tree without them.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.output.stream.card import CardConfig
from tests.stream_helpers import card_on, continue_when_at_rest, write_mixed_steps_machine

ROTARY_TABLES = """
[axis_limits.a]
v_max_deg_min = 6000.0
a_max_deg_s2 = 800.0
j_max_deg_s3 = 20000.0
steps_per_deg = 250.0

[axis_limits.b]
v_max_deg_min = 3000.0
a_max_deg_s2 = 400.0
j_max_deg_s3 = 10000.0
steps_per_deg = 40.0
"""
MACHINE = ["--machine", "m.toml"]
A_DEG, B_DEG = 250.0, 40.0
START = (0, 0, 0, 2500, 0)  # the card at A = 10°


#: Mixed X Z A moves, an M0 after line 4 (the card at X20 Z-1 A90), then Y, Z, A and B.
MIXED = """G21 G90 G94
G0 X0 Y0 Z2 A0
G1 Z-1 F100
G1 X20 A90 F400
M0 (turn the vice)
G1 X20 Y10 Z-2 A180
G1 Y0 A180 B15
G1 Z2 F600
M2
"""


def run_cli(args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture
def here(tmp_path, monkeypatch):
    folder = write_mixed_steps_machine(tmp_path, monkeypatch)
    with open(folder / "m.toml", "a", encoding="utf-8") as fh:
        fh.write(ROTARY_TABLES)
    return folder


def test_a_rotary_program_waits_at_m0_and_ends_at_the_steps_of_its_text(here):
    """From a card at A 10°: at M0 the card stands at X20 Z-1 A90 = (16000, 0, -400, 22500,
    0) while the stream waits; SIGUSR2 continues to X20 Y0 Z2 A180 B15 = (16000, 0, 800,
    45000, 600)."""
    (here / "part.nc").write_text(MIXED)
    seen = {}
    at_m0 = [16000, 0, -400, 22500, 0]
    cfg = CardConfig(speed=None, axis_names="xyzab", position_steps=START)
    with card_on("pty", cfg) as (sim, ep):
        thread = continue_when_at_rest(sim, at_m0, seen, 60.0, 0.3)
        r = run_cli(["stream", "part.nc", "--port", ep.path, "--json", *MACHINE])
        thread.join(60.0)
        final = sim.position.tolist()
    assert r.exit_code == 0, r.output
    assert seen["still"] == ("DONE", at_m0)
    assert final == [16000, 0, 800, 45000, 600]
    body = json.loads(r.stdout.strip().splitlines()[-1])
    assert body["final_position_mm"] == [20.0, 0.0, 2.0]
    assert body["final_abc_deg"] == {"a": 180.0, "b": 15.0}
    assert body["sections"] == 2 and body["axes"] == "xyzab"


def test_a_version_3_card_is_refused_with_exit_2(here):
    (here / "part.nc").write_text(MIXED)
    with card_on("pty", CardConfig(speed=None)) as (sim, ep):
        r = run_cli(["stream", "part.nc", "--port", ep.path, *MACHINE])
        executed = sim.executed_pulses().shape[0]
    assert r.exit_code == 2, r.output
    assert "the card speaks protocol 3 (X Y Z only); this program moves A B" in r.stderr
    assert "Traceback" not in r.output and executed == 0


def test_an_indexer_of_rotary_only_moves_ends_where_its_text_says(here):
    """LinuxCNC's B indexer (tests/programs/rotary/b_indexer.ngc): four G91 B90 rapids,
    then G0 B0; it ends at X0 Y0 Z20 B0, A held at the card's 10°: (0, 0, 8000, 2500, 0)."""
    text = (
        "G21 G90 G94 G17\nG0 X0 Y0 Z20 B0\no100 repeat [4]\n  G0 Z5\n  G1 Z-3 F120\n"
        "  G0 Z20\n  G91\n  G0 B90\n  G90\no100 endrepeat\nG0 B0\nM2\n"
    )
    (here / "index.nc").write_text(text)
    cfg = CardConfig(speed=None, axis_names="xyzab", position_steps=START)
    with card_on("pty", cfg) as (sim, ep):
        r = run_cli(["stream", "index.nc", "--port", ep.path, "--quiet", *MACHINE])
        final = sim.position.tolist()
        ran = sim.executed_pulses()
    assert r.exit_code == 0, r.output
    assert final == [0, 0, 8000, 2500, 0]
    # B went forward four quarter turns (4 · 90 · 40 = 14400 steps) and back
    assert int(ran[:, 4].clip(min=0).sum()) == 14400 == -int(ran[:, 4].clip(max=0).sum())


def test_card_position_and_jog_in_degrees(here):
    cfg = CardConfig(speed=None, axis_names="xyzab", position_steps=(800, 0, 0, 2500, -80))
    with card_on("pty", cfg) as (sim, ep):
        r = run_cli(["card-position", "--port", ep.path, "--json", *MACHINE])
        assert r.exit_code == 0, r.output
        body = json.loads(r.stdout.strip().splitlines()[-1])
        assert body["position_abc_deg"] == {"a": 10.0, "b": -2.0}
        r = run_cli(["jog", "A+20", "X+1", "--port", ep.path, "--json", "--quiet", *MACHINE])
        assert r.exit_code == 0, r.output
        final = sim.position.tolist()
        r = run_cli(["jog", "C+1", "--port", ep.path, "--quiet", *MACHINE])
        assert r.exit_code == 2 and "jog: the machine has no C axis" in r.stderr
    assert final == [1600, 0, 0, 2500 + 20 * 250, -80]


def test_a_points_file_with_an_a_column_streams_to_a_card_driving_a(tmp_path, monkeypatch):
    """``t,x,y,z,a``: X 0 → 2 mm and A 0 → 30° on a smootherstep over 0.4 s. The card ends at
    (2 · 800, 0, 0, 30 · 250) = (1600, 0, 0, 7500) steps, every period's running sum
    round(value · steps per unit); a version-3 card refuses it (exit 2)."""
    import numpy as np

    folder = write_mixed_steps_machine(tmp_path, monkeypatch)
    with open(folder / "m.toml", "a", encoding="utf-8") as fh:
        fh.write(ROTARY_TABLES)
    n = 401
    t = np.arange(n) * 1e-3
    x = t / t[-1]
    u = x**3 * (10.0 + x * (-15.0 + 6.0 * x))
    rows = np.column_stack([t, 2.0 * u, 0 * u, 0 * u, 30.0 * u])
    lines = ["t,x,y,z,a"] + [f"{r[0]:.6f},{r[1]:.9f},0,0,{r[4]:.9f}" for r in rows]
    (folder / "points.csv").write_text("\n".join(lines) + "\n")
    cfg = CardConfig(speed=None, axis_names="xyza")
    with card_on("pty", cfg) as (sim, ep):
        r = run_cli(["stream", "points.csv", "--port", ep.path, "--json", *MACHINE])
        final, ran = sim.position.tolist(), sim.executed_pulses()
    assert r.exit_code == 0, r.output
    assert final == [1600, 0, 0, 7500]
    x_steps = np.rint(np.round(2.0 * u, 9) * 800.0)
    a_steps = np.rint(np.round(30.0 * u, 9) * 250.0)
    np.testing.assert_array_equal(np.cumsum(ran[:, 0]), x_steps[1:])
    np.testing.assert_array_equal(np.cumsum(ran[:, 3]), a_steps[1:])
    assert json.loads(r.stdout.strip().splitlines()[-1])["final_abc_deg"] == {"a": 30.0}
    with card_on("pty", CardConfig(speed=None)) as (sim, ep):
        r = run_cli(["stream", "points.csv", "--port", ep.path, *MACHINE])
        assert sim.executed_pulses().shape[0] == 0
    assert (
        r.exit_code == 2
        and "the card speaks protocol 3 (X Y Z only); this program moves A" in r.stderr
    )
