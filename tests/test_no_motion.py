"""Programs with no motion (offsets, tool changes, dwells): LinuxCNC runs them, so does
nurbscnc. ``run`` writes the tool at rest at its start point through the dwells, ``plan``
summarises that, ``stream`` has nothing to send (exit 0, the port untouched), ``check`` is
unchanged.

LinuxCNC's answer: ``tests/golden/interp_linuxcnc/nomotion.ngc`` is recorded with its
``gcode`` module (two dwells, no move; compared move by move in test_interpret_linuxcnc.py),
and a tool-change program is run live through ``rs274 -g`` (no motion call) when LinuxCNC
is installed.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.machine.profile import load_machine

HERE = Path(__file__).resolve().parent
NOMOTION = HERE / "golden" / "interp_linuxcnc" / "nomotion.ngc"
TOOL_PROGRAM = "G21 G90\nT1 M6\nG43 H1\nG10 L20 P1 X0 Y0\nM2\n"
TOOL_TABLE = "T1 P1 Z25.4 D6.35\n"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def period_s() -> float:
    return load_machine(None).servo.period_s


def test_linuxcnc_gives_only_the_dwells():
    """The golden (LinuxCNC's moves): two dwells on lines 8 and 9, nothing else."""
    data = json.loads(NOMOTION.with_suffix(".json").read_text())
    assert data["error"] is None
    assert data["moves"] == [
        {"kind": "dwell", "line": 8, "seconds": 0.25},
        {"kind": "dwell", "line": 9, "seconds": 0.0105},
    ]


def test_run_holds_the_start_point_through_the_dwells(tmp_path):
    out = tmp_path / "points.csv"
    result = cli("run", NOMOTION, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    summary = json.loads(result.stdout)
    t_dwell = 0.25 + 0.0105
    ts = period_s()
    n = math.ceil(t_dwell / ts - 1e-9) + 1  # samples k·T_s up to the first at or after the end
    assert summary["motion"] is False
    assert summary["cycle_time_s"] == pytest.approx(t_dwell, rel=1e-12)
    assert summary["samples"] == n
    assert summary["contour_true_max_um"] == 0.0
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert rows.shape == (n, 7)
    np.testing.assert_allclose(rows[:, 0], np.arange(n) * ts, rtol=0, atol=5e-7)
    assert np.all(rows[:, 1:5] == 0.0)  # x y z at the start (machine origin), feed 0
    # the line of the dwell under way: the first until 0.25 s, then the second
    expected_line = np.where(np.arange(n) * ts < 0.25 - 1e-12, 8, 9)
    assert np.array_equal(rows[:, 6], expected_line)


def test_run_of_offsets_only_is_one_row(tmp_path):
    prog = tmp_path / "offsets.ngc"
    prog.write_text("G21\nG10 L2 P1 X10 Y5\nG54\nM2\n")
    out = tmp_path / "points.csv"
    result = cli("run", prog, "-o", out)
    assert result.exit_code == 0, result.stderr
    assert "1 points, cycle time 0.0000 s" in result.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == "t,x,y,z,feed,piece,line"
    assert len(lines) == 2
    assert [float(v) for v in lines[1].split(",")] == [0.0] * 7


def test_run_npz_and_halstreamer(tmp_path):
    for name in ("p.npz", "p.hs"):
        result = cli("run", NOMOTION, "-o", tmp_path / name)
        assert result.exit_code == 0, result.stderr
    data = np.load(tmp_path / "p.npz")
    assert data["t"].size == math.ceil(0.2605 / period_s() - 1e-9) + 1


def test_plan_says_no_motion():
    result = cli("plan", NOMOTION)
    assert result.exit_code == 0, result.output
    assert "no motion" in result.stdout and "rests at X0 Y0 Z0 mm for 0.2605 s" in result.stdout


def test_stream_has_nothing_to_send(tmp_path):
    # A port that does not exist: opening it would fail (exit 3); it must not be opened.
    port = tmp_path / "no-such-port"
    result = cli("stream", NOMOTION, "--port", port)
    assert result.exit_code == 0, result.output
    assert "nothing to send" in result.stdout
    result = cli("stream", NOMOTION, "--port", port, "--json")
    assert result.exit_code == 0
    assert json.loads(result.stdout)["motion"] is False


def test_check_is_unchanged():
    result = cli("check", NOMOTION, "--json")
    assert result.exit_code == 0
    data = json.loads(result.stdout)
    assert data["ok"] is True
    assert [s["kind"] for s in data["segments"]] == ["dwell", "dwell"]


def test_tool_change_program_runs(tmp_path):
    prog = tmp_path / "tools.ngc"
    prog.write_text(TOOL_PROGRAM)
    table = tmp_path / "tools.tbl"
    table.write_text(TOOL_TABLE)
    out = tmp_path / "points.csv"
    result = cli("run", prog, "--tool-table", table, "-o", out)
    assert result.exit_code == 0, result.stderr
    rows = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    assert rows.shape == (1, 7) and np.all(rows[0, 1:4] == 0.0)


def test_tool_change_program_linuxcnc_live(tmp_path):
    """rs274 -g (LinuxCNC 2.9) makes no motion call for the tool-change program."""
    if shutil.which("rs274") is None:
        pytest.skip("live rs274 comparison skipped: LinuxCNC's rs274 is not installed")
    prog = tmp_path / "tools.ngc"
    prog.write_text(TOOL_PROGRAM)
    (tmp_path / "tools.tbl").write_text("T1 P1 Z1 D0.25\n")
    out = subprocess.run(
        ["rs274", "-g", "-t", "tools.tbl", "tools.ngc"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
    ).stdout
    assert "CHANGE_TOOL(1)" in out and "PROGRAM_END" in out
    for call in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED", "STRAIGHT_PROBE"):
        assert call not in out


def test_plan_explain_and_profile_dump(tmp_path):
    result = cli("plan", NOMOTION, "--explain")
    assert result.exit_code == 0, result.output
    assert "no motion" in result.stdout
    data = json.loads(cli("plan", NOMOTION, "--explain", "--json").stdout)
    assert data["motion"] is False and "explain" not in data
    dump = tmp_path / "profile.csv"
    result = cli("plan", NOMOTION, "--dump-profile", dump)
    assert result.exit_code == 0, result.output
    rows = np.loadtxt(dump, delimiter=",", skiprows=1)
    n = math.ceil(0.2605 / period_s() - 1e-9) + 1
    assert rows.shape == (n, 6)
    np.testing.assert_allclose(rows[:, 0], np.arange(n) * period_s(), rtol=0, atol=5e-7)
    assert np.all(rows[:, 1:] == 0.0)


def test_batch_reports_the_exact_cycle_time(tmp_path):
    result = cli("run", NOMOTION, "--output-dir", tmp_path, "--jobs", "1", "--json")
    assert result.exit_code == 0, result.output
    (row,) = json.loads(result.stdout)["results"]
    assert row["cycle_time_s"] == pytest.approx(0.2605, rel=1e-12)


def test_stream_writes_the_parameters_back(tmp_path):
    """An offset set-up program has run when there is nothing to send: its parameters
    persist as run --write-var writes them (G92 on: #5210 = 1)."""
    var = HERE / "golden" / "interp_linuxcnc" / "rs274ngc.var"
    streamed, ran = tmp_path / "s.var", tmp_path / "r.var"
    for path in (streamed, ran):
        path.write_text(var.read_text())
    result = cli("stream", NOMOTION, "--port", tmp_path / "no-such-port", "--var", streamed)
    assert result.exit_code == 0, result.output
    result = cli("run", NOMOTION, "-o", tmp_path / "p.csv", "--var", ran, "--write-var")
    assert result.exit_code == 0, result.output
    assert streamed.read_text() == ran.read_text() != var.read_text()
    assert "5210\t1.000000" in streamed.read_text()
