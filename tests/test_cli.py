"""The command-line interface: ``check`` output, stdin, exit codes, help, error paths.

Run in-process with click's CliRunner (stdout and stderr apart). The reference numbers for
``programs/naca2415.nc`` come from the file itself, read by a tiny regex reader here (not the
project's parser), with scipy's BSpline and Gauss–Legendre quadrature as the length oracle
(the airfoil's weights are all 1, so the curve is a plain B-spline).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.interpolate import BSpline

import nurbscnc
import nurbscnc.cli.main as cli
from nurbscnc.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
NACA = ROOT / "programs" / "naca2415.nc"
NUM = r"(-?\d+(?:\.\d+)?)"


def run(args, **kwargs):
    return CliRunner().invoke(main, [str(a) for a in args], **kwargs)


def read_g62(path: Path) -> dict:
    """Line numbers, order, knots, control points and weights of a one-block G6.2 file."""
    knots, ctrl, weights = [], [], []
    info = {}
    for number, raw in enumerate(path.read_text(encoding="ascii").splitlines(), 1):
        line = raw.strip()
        if re.fullmatch(rf"G0 X{NUM} Y{NUM}", line):
            info["rapid_line"] = number
        elif m := re.fullmatch(rf"G6\.2 P(\d+) K{NUM} X{NUM} Y{NUM} R{NUM}", line):
            info["nurbs_line"], info["order"] = number, int(m.group(1))
            knots.append(float(m.group(2)))
            ctrl.append((float(m.group(3)), float(m.group(4))))
            weights.append(float(m.group(5)))
        elif m := re.fullmatch(rf"K{NUM} X{NUM} Y{NUM} R{NUM}", line):
            knots.append(float(m.group(1)))
            ctrl.append((float(m.group(2)), float(m.group(3))))
            weights.append(float(m.group(4)))
        elif m := re.fullmatch(rf"K{NUM}", line):
            knots.append(float(m.group(1)))
    info.update(knots=np.array(knots), ctrl=np.array(ctrl), weights=np.array(weights))
    return info


def bspline_length_mm(knots, ctrl, degree, nodes=20) -> float:
    """Arc length of a B-spline: Gauss–Legendre (``nodes`` points) on every knot span."""
    curve = BSpline(knots, ctrl, degree)
    velocity = curve.derivative()
    x, w = np.polynomial.legendre.leggauss(nodes)
    spans = np.unique(knots)
    a, b = spans[:-1], spans[1:]
    u = (0.5 * (b - a))[:, None] * x[None, :] + (0.5 * (a + b))[:, None]
    speed = np.linalg.norm(velocity(u.ravel()), axis=-1).reshape(u.shape)
    return float(np.sum(0.5 * (b - a)[:, None] * w[None, :] * speed))


@pytest.fixture(scope="module")
def naca():
    info = read_g62(NACA)
    assert np.all(info["weights"] == 1.0)  # so the oracle may be non-rational
    info["length_mm"] = bspline_length_mm(info["knots"], info["ctrl"], info["order"] - 1)
    return info


# ------------------------------------------------------------------------------------- check


def test_check_json_fields(naca):
    result = run(["check", NACA, "--json"])
    assert result.exit_code == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["ok"] is True
    assert data["errors"] == []
    rapid, nurbs = data["segments"]
    # G0 X9 Y0 from the origin: a 9 mm rapid.
    assert rapid == {"kind": "rapid", "line": naca["rapid_line"], "length_mm": 9.0}
    assert nurbs["kind"] == "nurbs"
    assert nurbs["line"] == naca["nurbs_line"]
    assert nurbs["degree"] == naca["order"] - 1 == 3
    assert nurbs["control_points"] == len(naca["ctrl"]) == 79
    assert nurbs["knots"] == len(naca["knots"]) == 79 + 4
    # Gauss–Legendre on cubic spans with 20 nodes is exact to rounding for this smooth curve;
    # both sides integrate the same curve, so they agree far below 1e-10 relative.
    assert nurbs["length_mm"] == pytest.approx(naca["length_mm"], rel=1e-10)
    assert data["length_mm"] == pytest.approx(naca["length_mm"], rel=1e-10)  # feed moves only
    assert data["rapid_length_mm"] == 9.0
    assert data["counts"] == {"rapid": 1, "nurbs": 1}


def test_check_human_summary(naca):
    result = run(["check", NACA])
    assert result.exit_code == 0, result.stderr
    text = result.stdout
    assert f"{NACA}: ok" in text
    assert "1 nurbs, 1 rapid" in text
    assert f"{naca['length_mm']:.3f} mm at feed" in text
    assert "9.000 mm rapid" in text
    row = re.search(r"^\s*5\s*\S\s*XY\s*\S\s*3\s*\S\s*79\s*\S\s*83\s*\S\s*([\d.]+)\s*$", text, re.M)
    assert row, text
    assert float(row.group(1)) == pytest.approx(naca["length_mm"], abs=5e-5)


def test_check_reads_stdin():
    text = NACA.read_text(encoding="ascii")
    from_file = json.loads(run(["check", NACA, "--json"]).stdout)
    result = run(["check", "-", "--json"], input=text)
    assert result.exit_code == 0, result.stderr
    from_stdin = json.loads(result.stdout)
    assert from_stdin["program"] == "<stdin>"
    for key in ("segments", "length_mm", "counts", "bounding_box_mm", "blocks"):
        assert from_stdin[key] == from_file[key], key


def test_check_program_error_json_and_caret():
    result = run(["check", "-", "--json"], input="G1 X1 F100\nG33\n")
    assert result.exit_code == 2
    data = json.loads(result.stdout)
    assert data["ok"] is False
    assert data["errors"] == [{"line": 2, "column": 1, "message": data["errors"][0]["message"]}]
    assert "G33" in data["errors"][0]["message"]
    assert result.stderr.startswith("<stdin>:2:1: error: ")
    assert result.stderr.splitlines()[1:3] == ["    G33", "    ^"]


def test_missing_file_exits_3(tmp_path):
    missing = tmp_path / "nosuch.nc"
    result = run(["check", missing])
    assert result.exit_code == 3
    assert f"cannot read {missing}" in result.stderr
    assert "No such file" in result.stderr
    assert "Traceback" not in result.output


# ------------------------------------------------------------------------- version and help


def test_version():
    result = run(["--version"])
    assert result.exit_code == 0
    assert result.stdout.strip() == f"nurbscnc, version {nurbscnc.__version__}"


@pytest.mark.parametrize("command", [None, *sorted(main.commands)])
def test_help_of_every_subcommand(command):
    args = ["--help"] if command is None else [command, "--help"]
    result = run(args)
    assert result.exit_code == 0, result.output
    assert "Usage:" in result.stdout
    if command is not None:
        assert f" {command} " in result.stdout.splitlines()[0]


def test_expected_subcommands_exist():
    assert {"check", "corners", "ph"} <= set(main.commands)


# ------------------------------------------------------------------------------ error paths


def test_internal_error_exits_1_without_traceback(monkeypatch):
    def boom(*args, **kwargs):
        raise RuntimeError("simulated fault")

    monkeypatch.delenv("NURBSCNC_DEBUG", raising=False)
    monkeypatch.setattr(cli, "interpret_text", boom)
    result = run(["check", NACA])
    assert result.exit_code == 1
    assert "internal error" in result.stderr
    assert "RuntimeError: simulated fault" in result.stderr
    assert "Traceback" not in result.output
    assert result.stdout == ""


@pytest.mark.parametrize(
    "setting, key",
    [
        ("limits.a_max_mm_s2=-5", "limits.a_max_mm_s2"),
        ("limits.a_max_mm_s2=abc", "limits.a_max_mm_s2"),
        ("limits.v_max_mm_min=0", "limits.v_max_mm_min"),
        ("limits.no_such_key=1", "limits.no_such_key"),
    ],
)
@pytest.mark.parametrize("command", ["corners", "ph"])
def test_bad_set_value_exits_2_naming_the_key(command, setting, key):
    result = run([command, NACA, "--set", setting])
    assert result.exit_code == 2, result.output
    assert key in result.stderr
    assert "error" in result.stderr
    assert "Traceback" not in result.output


def test_set_without_equals_exits_2():
    result = run(["corners", NACA, "--set", "limits.a_max_mm_s2"])
    assert result.exit_code == 2
    assert "KEY=VALUE" in result.stderr


@pytest.mark.parametrize("command", ["corners", "ph"])
def test_machine_with_bad_toml_exits_2(tmp_path, command):
    bad = tmp_path / "machine.toml"
    bad.write_text("[limits\nv_max_mm_min = 3500\n", encoding="utf-8")
    result = run([command, NACA, "--machine", bad])
    assert result.exit_code == 2, result.output
    assert str(bad) in result.stderr
    assert "invalid TOML" in result.stderr
    assert "line 1" in result.stderr
    assert "Traceback" not in result.output
