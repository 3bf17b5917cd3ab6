"""``nurbscnc mdi`` / ``jog`` / ``card-position`` with work coordinates, and a tool change
interpreted from the program text, end to end through the CLI against the card simulator
on a pty.

The machine: the bundled profile with 800 steps/mm in X, 1000 in Y, 400 in Z (different
per axis, so a mix-up of axes or of steps and mm shows). Expected numbers are worked out
here from the card's step counters and the blocks' text (steps / steps-per-mm, offset +
work position), never taken from the code under test.
"""

from __future__ import annotations

import json
import sys
import time
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.output.stream.card import CardConfig
from nurbscnc.program.varfile import parse_var_text
from tests.stream_helpers import card_on, continue_when_at_rest, write_mixed_steps_machine

MACHINE = ["--machine", "m.toml"]
START_STEPS = (12345, -3000, -5000)  # machine (15.43125, -3, -12.5) mm


def run_cli(args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture
def here(tmp_path, monkeypatch):
    return write_mixed_steps_machine(tmp_path, monkeypatch)


@pytest.fixture
def card():
    with card_on("pty", CardConfig(speed=None, position_steps=START_STEPS)) as (sim, ep):
        yield sim, ep.path


def mdi(port, *blocks, extra=()):
    return run_cli(["mdi", *blocks, "--port", port, "--var", "m.var", *MACHINE, *extra])


def card_json(port):
    r = run_cli(["card-position", "--port", port, "--json", "--var", "m.var", *MACHINE])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_zero_here_then_a_move_in_work_coordinates(here, card):
    """G10 L20 P1 X0 Y0 Z0 with the card at (12345, -3000, -5000) steps writes G54 =
    (12345/800, -3000/1000, -5000/400) mm without moving; G0 X3 Y4 then ends at machine
    G54 + (3, 4) (Z untouched): (18.43125·800, 1·1000, -5000) steps."""
    sim, port = card
    r = mdi(port, "G10 L20 P1 X0 Y0 Z0")
    assert r.exit_code == 0, r.output
    assert sim.position.tolist() == list(START_STEPS)
    assert sim.report()["executed_periods"] == 0
    values = parse_var_text((here / "m.var").read_text(), "m.var")
    assert values[5220] == 1.0
    assert [values[5221], values[5222], values[5223]] == [15.43125, -3.0, -12.5]

    body = card_json(port)
    assert body["position_steps"] == list(START_STEPS)
    assert body["position_mm"] == pytest.approx([15.43125, -3.0, -12.5], abs=1e-9)
    assert body["coordinate_system"] == "G54"
    assert body["work_position_mm"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)

    r = mdi(port, "G0 X3 Y4", extra=["--json"])
    assert r.exit_code == 0, r.output
    assert sim.position.tolist() == [14745, 1000, -5000]  # (15.43125 + 3)·800, (-3 + 4)·1000
    body = card_json(port)
    assert body["position_mm"] == pytest.approx([18.43125, 1.0, -12.5], abs=1e-9)
    assert body["work_position_mm"] == pytest.approx([3.0, 4.0, 0.0], abs=1e-9)
    values2 = parse_var_text((here / "m.var").read_text(), "m.var")
    assert [values2[k] for k in (5221, 5222, 5223)] == [15.43125, -3.0, -12.5]
    r = run_cli(["mdi", "G10 L20 P1 X0", "--port", port, *MACHINE])  # no parameter file
    assert r.exit_code == 0 and "the offsets and positions set here are not kept" in r.stderr


def test_card_position_text_names_the_work_system(here, card):
    _sim, port = card
    (here / "m.var").write_text("5220\t2.000000\n5241\t10.000000\n5242\t-5.000000\n")
    r = run_cli(["card-position", "--port", port, "--var", "m.var", *MACHINE])
    assert r.exit_code == 0, r.output
    # G55 (10, -5, 0): work = machine − offset = (5.43125, 2, -12.5)
    assert (
        "position [12345, -3000, -5000] steps (15.4313, -3.0000, -12.5000 mm, machine "
        "coordinates; 5.4313, 2.0000, -12.5000 mm in G55)" in r.stdout
    )
    r = run_cli(["card-position", "--port", port, "--json", *MACHINE])
    assert "work_position_mm" not in r.stdout  # no parameter file: machine coordinates only


def test_g28_goes_to_the_stored_position_in_machine_coordinates(here, card):
    """G28 with no axis words: straight to #5161-5163 (machine), whatever G54 is."""
    sim, port = card
    (here / "m.var").write_text(
        "5161\t10.000000\n5162\t20.000000\n5163\t-1.000000\n5221\t100.000000\n"
    )
    r = mdi(port, "G28")
    assert r.exit_code == 0, r.output
    assert sim.position.tolist() == [8000, 20000, -400]


def test_jog_moves_by_machine_axes(here, card):
    """X+1.5 Z-0.25: +1.5·800 and -0.25·400 steps, with a rotated G54 in force."""
    sim, port = card
    (here / "m.var").write_text("5221\t3.000000\n5230\t30.000000\n")
    r = run_cli(["jog", "X+1.5", "z-0.25", "--port", port, "--var", "m.var", *MACHINE])
    assert r.exit_code == 0, r.output
    assert sim.position.tolist() == [12345 + 1200, -3000, -5000 - 100]
    r = run_cli(["jog", "X+1.5", "Q2", "--port", port, *MACHINE])
    assert r.exit_code == 2 and "jog: 'Q2' is not a move" in r.stderr
    r = run_cli(["jog", "X1", "X2", "--port", port, *MACHINE])
    assert r.exit_code == 2 and "axis X named twice" in r.stderr


@pytest.mark.parametrize(
    ("blocks", "extra", "where"),
    [
        (["G0 X3 Y4 Q@"], [], "mdi:1:11: error: expected a value"),
        (["G0 X1", "G0 X30"], ["--set", "soft_limits.x.max_mm=25"], "mdi:2:1: error: the rapid"),
        (["G0 X1\nG1 Y2"], [], "mdi:2:"),  # a feed move without F
    ],
)
def test_bad_input_moves_nothing_and_writes_nothing(here, card, blocks, extra, where):
    """A syntax error, a move past the soft limits (G54 all zero: machine X 30 > 25), a G1
    without a feed: exit 2 at the block, the card not moved (no period
    executed, not even the good first block's), the parameter file untouched."""
    sim, port = card
    (here / "m.var").write_text("5220\t1.000000\n")
    r = mdi(port, *blocks, extra=extra)
    assert r.exit_code == 2, r.output
    assert where in r.stderr and "Traceback" not in r.output
    assert sim.position.tolist() == list(START_STEPS)
    assert sim.report()["executed_periods"] == 0
    assert (here / "m.var").read_text() == "5220\t1.000000\n"


def test_soft_limit_error_names_the_machine_position(here, card):
    _sim, port = card
    (here / "m.var").write_text("5221\t15.431250\n")
    r = mdi(port, "G0 X30", extra=["--set", "soft_limits.x.max_mm=40"])
    assert r.exit_code == 2
    assert "X reaches 45.4312 mm in machine coordinates (G54 offset X 15.4313)" in r.stderr
    assert "    G0 X30\n    ^" in r.stderr


SCRIPT = """#!{python}
import sys, time
open({record!r}, "w").write(" ".join(sys.argv[1:]))
time.sleep({sleep})
"""


@pytest.mark.parametrize(("sleep_s", "code"), [(0.0, 0), (3.0, 3)])
def test_a_user_m_code_alone_runs_and_the_profile_bounds_it(here, card, sleep_s, code):
    """M101 P2.5 Q-1 runs its executable with "2.500000 -1.000000"; the profile's
    program.user_m_timeout_s (0.5 s) kills one that sleeps 3 s (exit 3)."""
    _sim, port = card
    record = here / "args.txt"
    script = here / "M101"
    script.write_text(SCRIPT.format(python=sys.executable, record=str(record), sleep=sleep_s))
    script.chmod(0o755)
    t0 = time.monotonic()
    r = mdi(
        port,
        "M101 P2.5 Q-1",
        extra=["--user-m-path", here, "--set", "program.user_m_timeout_s=0.5"],
    )
    assert r.exit_code == code, r.output
    assert record.read_text() == "2.500000 -1.000000"  # LinuxCNC passes "%f"
    if code:
        assert "did not end within 0.5 s and was killed" in r.stderr
        assert time.monotonic() - t0 < 2.5


def test_interpreted_tool_change_pauses_at_rest_and_resumes_on_sigusr2(here):
    """T2 M6 in the program text (not a hand-made stop): the card stops DONE at X5 (the end
    of line 3: 5·800 steps), stays there while the stream waits, and goes on to X8 after
    SIGUSR2."""
    (here / "part.nc").write_text("G21 G90 G17\nG0 X0 Y0\nG1 X5 F3000\nT2 M6\nG1 X8\nM2\n")
    (here / "tools.tbl").write_text("T1 P1 Z10 D3 ;drill\nT2 P2 Z12.5 D6 ;6 mm end mill\n")
    seen = {}
    with card_on("pty", CardConfig(speed=None)) as (sim, ep):
        thread = continue_when_at_rest(sim, [4000, 0, 0], seen, 30.0, 0.5)
        args = ["stream", "part.nc", "--port", ep.path, "--tool-table", "tools.tbl", *MACHINE]
        r = run_cli(args)
        thread.join(30.0)
        final = sim.position.tolist()
    assert r.exit_code == 0, r.output
    assert seen["still"] == ("DONE", [4000, 0, 0])
    assert "stream: M6 at line 4: load tool 2 (length 12.5 mm, diameter 6 mm" in r.stderr
    assert final == [6400, 0, 0] and "in 2 part(s)" in r.stdout


# -- work coordinates in the stream's progress and end report ---------------------------------
def test_stream_end_report_gives_the_work_position(here):
    """G54 (10, -5, 0) from the file: G0 X3 Y4 ends at machine (13, -1, 0) mm =
    (10400, -1000, 0) steps, work (3, 4, 0) in G54."""
    (here / "part.nc").write_text("G21 G90\nG0 X3 Y4\nM2\n")
    (here / "m.var").write_text("5221\t10.000000\n5222\t-5.000000\n")
    with card_on("pty", CardConfig(speed=None)) as (sim, ep):
        r = run_cli(["stream", "part.nc", "--port", ep.path, "--var", "m.var", *MACHINE, "--json"])
        assert r.exit_code == 0, r.output
        assert sim.position.tolist() == [10400, -1000, 0]
    body = json.loads(r.stdout.strip().splitlines()[-1])
    assert body["final_position_mm"] == pytest.approx([13.0, -1.0, 0.0], abs=1e-9)
    assert body["coordinate_system"] == "G54"
    assert body["final_work_position_mm"] == pytest.approx([3.0, 4.0, 0.0], abs=1e-9)
    with card_on("pty", CardConfig(speed=None)) as (sim, ep):
        r = run_cli(["stream", "part.nc", "--port", ep.path, *MACHINE])
    assert r.exit_code == 0, r.output
    assert "ended at [2400, 4000, 0] steps (3.0000, 4.0000, 0.0000 mm)" in r.stdout  # no file
    with card_on("pty", CardConfig(speed=None)) as (sim, ep):
        r = run_cli(["stream", "part.nc", "--port", ep.path, "--var", "m.var", *MACHINE])
    assert r.exit_code == 0, r.output
    assert "(13.0000, -1.0000, 0.0000 mm; 3.0000, 4.0000, 0.0000 mm in G54)" in r.stdout


def test_progress_carries_the_cards_position():
    """Every progress snapshot's position is the card's at its executed count: the start
    plus the program's pulses summed over the executed periods."""
    import numpy as np

    from nurbscnc.output.stream.quantise import quantise
    from nurbscnc.output.stream.sender import Sender, SenderOptions, open_port

    s = np.linspace(0.0, 1.0, 1500)[:, None]
    prog = quantise(s * [30.0, -20.0, 5.0], (1000.0, 1000.0, 1000.0), 1e-3)
    seen = []
    with card_on("pty", CardConfig(speed=5.0)) as (_sim, ep):
        port = open_port(ep.path)
        try:
            Sender(port, SenderOptions(timeout_s=2.0), progress=seen.append).stream(prog)
        finally:
            port.close()
    cum = np.vstack([np.zeros((1, 3), int), np.cumsum(prog.pulses, axis=0)])
    moving = [pr for pr in seen if pr.position_steps and 0 < pr.executed < prog.periods]
    assert len(moving) >= 1
    for pr in moving:
        assert list(pr.position_steps) == cum[pr.executed].tolist()


def test_progress_text_shows_work_coordinates_only_when_they_hold():
    from nurbscnc.app.load import load_machine
    from nurbscnc.app.stream import progress_position
    from nurbscnc.app.varfile import ProgramInputs

    mach = load_machine(None, {})
    start = {5220: 1.0, 5221: 10.0, 5222: -5.0}
    inputs = ProgramInputs("m.var", "--var", start)
    where = progress_position(mach, inputs, SimpleNamespace(parameters=dict(start)))
    assert where((13000, -1000, 0)) == "13.000, -1.000, 0.000 mm (G54 3.000, 4.000, 0.000)"
    g10 = SimpleNamespace(parameters={**start, 5221: 12.0})  # G10 midway
    moved = progress_position(mach, inputs, g10)
    assert moved((13000, -1000, 0)) == "13.000, -1.000, 0.000 mm"
    assert progress_position(mach)((1, 2, 3)) == "0.001, 0.002, 0.003 mm"


def test_user_m_timeout_option_then_profile_then_default(here):
    """--user-m-timeout beats program.user_m_timeout_s beats 60 s; the key must be > 0."""
    from nurbscnc.app.load import load_machine
    from nurbscnc.app.varfile import user_m_timeout_s

    plain = load_machine("m.toml", {})
    keyed = load_machine("m.toml", {"program.user_m_timeout_s": "2.5"})
    assert user_m_timeout_s(plain) == 60.0
    assert user_m_timeout_s(keyed) == 2.5
    assert user_m_timeout_s(keyed, 7.0) == 7.0
    r = run_cli(["profile", "show", *MACHINE, "--set", "program.user_m_timeout_s=0"])
    assert r.exit_code == 2 and "program.user_m_timeout_s" in r.stderr, r.output


def test_mdi_opens_the_port_once(here, card, monkeypatch):
    """The card's position is read and the move streamed on one opening of the port."""
    from nurbscnc.output.stream import sender

    sim, port = card
    opened, real = [], sender.open_port
    monkeypatch.setattr(
        sender, "open_port", lambda p, *a, **k: opened.append(p) or real(p, *a, **k)
    )
    r = mdi(port, "G91 G0 X1")
    assert r.exit_code == 0, r.output
    assert opened == [port]
    assert sim.position.tolist() == [START_STEPS[0] + 800, *START_STEPS[1:]]
