"""The parameter file against LinuxCNC 2.9: ``rs274 -g -v FILE`` on programs using
G54–G59.3, G10 L2/L20, the G92 family and G28.1/G30.1 with a parameter file
(``tests/programs/varfile/``): its moves and the file it writes back, recorded as goldens by
``tools/record_var_goldens.py`` (committed; CI needs no LinuxCNC). nurbscnc reads the same
file to the same moves and writes the same values.

rs274's machine is in inches (2.9's stand-alone interpreter has no mm machine), so its
parameter files are in inches: nurbscnc (a mm machine) gets each length × 25.4 and what it
writes back is compared ÷ 25.4, to LinuxCNC's printed precision (``%f``: 1e-6 in).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.program.interpret import InterpretOptions, interpret_text
from nurbscnc.program.varfile import LENGTH_PARAMETERS, format_var_text, parse_var_text

ROOT = Path(__file__).resolve().parent.parent
PROGRAMS = ROOT / "tests" / "programs" / "varfile"
GOLDEN = ROOT / "tests" / "golden" / "varfile"
NAMES = sorted(p.stem for p in PROGRAMS.glob("*.ngc"))
INCH_MM = 25.4
#: Both files print 6 decimals of an inch: each value within one unit of the last digit
#: (LinuxCNC's rounding and nurbscnc's, after × 25.4 ÷ 25.4).
VAR_TOL_IN = 1e-6


def scaled(values: dict, factor: float) -> dict:
    return {k: v * factor if k in LENGTH_PARAMETERS else v for k, v in values.items()}


def run_nurbscnc(name: str):
    """nurbscnc on program ``name`` with its parameter file: (program, the text it writes
    back in inches)."""
    inch = parse_var_text((PROGRAMS / f"{name}.var").read_text(), f"{name}.var")
    prog = interpret_text(
        (PROGRAMS / f"{name}.ngc").read_text(), InterpretOptions(parameters=scaled(inch, INCH_MM))
    )
    return prog, format_var_text(scaled(prog.parameters, 1.0 / INCH_MM), inch)


def kind_of(seg) -> str:
    if seg.kind == "pause":
        return "pause"
    return "traverse" if getattr(seg, "rapid", False) else "feed"


def compare(golden: dict, prog, written: str) -> None:
    tol = golden["tolerance_mm"]
    want, prev = [], [0.0, 0.0, 0.0]  # both start at machine 0
    for move in golden["moves"]:
        # a straight move to where the tool stands is no move (nurbscnc makes none)
        if "end" in move and np.allclose(move["end"][:3], prev, rtol=0, atol=1e-9):
            continue
        prev = move.get("end", prev)[:3]
        want.append(move)
    got = list(prog.segments)
    assert [kind_of(s) for s in got] == [m["kind"] for m in want]
    for i, (seg, move) in enumerate(zip(got, want)):
        if move["kind"] == "pause":
            assert seg.code == move["code"], i
            continue
        np.testing.assert_allclose(
            seg.end_mm, move["end"][:3], rtol=0, atol=tol, err_msg=f"move {i}, line {seg.line}"
        )
    ours = [line.split("\t") for line in written.splitlines()]
    assert [int(n) for n, _ in ours] == [n for n, _ in golden["written"]]
    for (number, value), (_, theirs) in zip(ours, golden["written"]):
        assert abs(float(value) - float(theirs)) <= VAR_TOL_IN, (number, value, theirs)


@pytest.mark.parametrize("name", NAMES)
def test_moves_and_written_file_as_linuxcnc(name):
    golden = json.loads((GOLDEN / f"{name}.json").read_text())
    assert golden["ended"]
    prog, written = run_nurbscnc(name)
    compare(golden, prog, written)


def test_the_comparison_fails_on_a_wrong_value():
    """A written value one digit off, or a move 0.01 mm off, fails the comparison."""
    golden = json.loads((GOLDEN / "offsets.json").read_text())
    prog, written = run_nurbscnc("offsets")
    compare(golden, prog, written)
    bad = json.loads(json.dumps(golden))
    k = next(i for i, (n, _) in enumerate(bad["written"]) if n == 5241)
    bad["written"][k][1] = f"{float(bad['written'][k][1]) + 1e-5:f}"
    with pytest.raises(AssertionError):
        compare(bad, prog, written)
    bad = json.loads(json.dumps(golden))
    bad["moves"][3]["end"][1] += 0.01
    with pytest.raises(AssertionError):
        compare(bad, prog, written)


@pytest.mark.parametrize("name", NAMES)
def test_live_rs274(name):
    """The same against LinuxCNC run now (skipped without it)."""
    if shutil.which("rs274") is None or not Path("/usr/bin/python3").exists():
        pytest.skip("live rs274 comparison skipped: LinuxCNC's rs274 is not installed")
    out = subprocess.run(
        ["/usr/bin/python3", str(ROOT / "tools" / "record_var_goldens.py"), "--stdout", name],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    prog, written = run_nurbscnc(name)
    compare(json.loads(out.stdout), prog, written)
