"""Files and pipes as Unix users expect (issue 16): ``plan --dump-profile -`` puts only the
profile on stdout, ``run -o - | simulate -`` works (stdin recognised by content), ``--format``
and the output suffix never silently disagree, long cycle times also read as h:mm:ss."""

from __future__ import annotations

import io
import json
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.app.summary import clock_suffix
from nurbscnc.cli.main import main
from nurbscnc.output.files import PROFILE_COLUMNS, read_points

#: A short planar program (two lines, F1200 mm/min); its cycle time is well under a minute.
SHORT = "G21 G90 G17\nG1 X10 Y5 F1200\nG1 X20 Y0\nM2\n"
#: 100 mm at F60 mm/min = 1 mm/s: about 100 s, over a minute.
LONG = "G21 G90 G17\nG1 X100 F60\nM2\n"


@pytest.fixture
def short_nc(tmp_path):
    path = tmp_path / "short.nc"
    path.write_text(SHORT)
    return path


def invoke(args, **kwargs):
    return CliRunner().invoke(main, [str(a) for a in args], **kwargs)


# -- 1. plan --dump-profile - ------------------------------------------------------------------
def test_dump_profile_stdout_is_only_the_csv(short_nc, tmp_path):
    to_file = tmp_path / "profile.csv"
    assert invoke(["plan", short_nc, "--dump-profile", to_file]).exit_code == 0
    r = invoke(["plan", short_nc, "--dump-profile", "-"])
    assert r.exit_code == 0, r.output
    # stdout is exactly the file dump: header + rows, nothing else
    assert r.stdout == to_file.read_text()
    assert r.stdout.splitlines()[0] == ",".join(PROFILE_COLUMNS)
    table = np.loadtxt(io.StringIO(r.stdout), delimiter=",", skiprows=1)
    assert table.shape[1] == len(PROFILE_COLUMNS)
    assert "cycle time" in r.stderr  # the human summary moved to stderr


def test_dump_profile_stdout_with_json_is_refused(short_nc):
    r = invoke(["plan", short_nc, "--dump-profile", "-", "--json"])
    assert r.exit_code == 2
    assert "--json" in r.stderr and "stdout" in r.stderr
    # With --json the option error is also the JSON error object (docs/json.md), no CSV.
    error = json.loads(r.stdout)
    assert error["ok"] is False and "stdout" in error["errors"][0]["message"]


# -- 2. run -o - | simulate - ------------------------------------------------------------------
def test_simulate_stdin_points_equals_simulate_file(short_nc, tmp_path):
    points = tmp_path / "points.csv"
    assert invoke(["run", short_nc, "-o", points, "--quiet"]).exit_code == 0
    from_file = invoke(["simulate", points, "--json"])
    from_stdin = invoke(["simulate", "-", "--json"], input=points.read_text())
    assert from_stdin.exit_code == 0, from_stdin.output
    a, b = json.loads(from_file.stdout), json.loads(from_stdin.stdout)
    assert b["program"] == "<stdin>"
    for key in (
        "samples",
        "cycle_time_s",
        "contour_eq29_max_um",
        "contour_true_max_um",
        "axis_x_max_um",
    ):
        assert b[key] == a[key]


def test_simulate_stdin_program_still_plans(short_nc):
    from_file = json.loads(invoke(["simulate", short_nc, "--json"]).stdout)
    r = invoke(["simulate", "-", "--json"], input=SHORT)
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["cycle_time_s"] == from_file["cycle_time_s"]


def test_pipeline_run_to_simulate_subprocess(short_nc, tmp_path):
    points = tmp_path / "points.csv"
    assert invoke(["run", short_nc, "-o", points, "--quiet"]).exit_code == 0
    expected = json.loads(invoke(["simulate", points, "--json"]).stdout)
    cli = [sys.executable, "-m", "nurbscnc"]
    producer = subprocess.Popen(
        [*cli, "run", str(short_nc), "-o", "-"], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    consumer = subprocess.run(
        [*cli, "simulate", "-", "--json"],
        stdin=producer.stdout,
        capture_output=True,
        text=True,
        timeout=120,
    )
    producer.stdout.close()
    assert producer.wait(timeout=120) == 0
    assert consumer.returncode == 0, consumer.stderr
    got = json.loads(consumer.stdout)
    assert got["samples"] == expected["samples"]
    assert got["contour_true_max_um"] == expected["contour_true_max_um"]


@pytest.mark.parametrize("columns", [3, 4])
def test_read_points_short_headers(short_nc, tmp_path, columns):
    full = tmp_path / "full.csv"
    assert invoke(["run", short_nc, "-o", full, "--quiet"]).exit_code == 0
    lines = full.read_text().splitlines()
    cut = tmp_path / "cut.csv"
    cut.write_text("\n".join(",".join(line.split(",")[:columns]) for line in lines) + "\n")
    ref, got = read_points(str(full)), read_points(str(cut))
    for c in ("t", "x", "y"):
        np.testing.assert_array_equal(got[c], ref[c])
    np.testing.assert_array_equal(got["z"], ref["z"] if columns == 4 else 0.0)
    assert "feed" not in got and "piece" not in got and "line" not in got
    # and the CLI takes it from stdin, recognised by its header
    r = invoke(["simulate", "-", "--json"], input=cut.read_text())
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["samples"] == len(lines) - 1


# -- 3. --format and the suffix ----------------------------------------------------------------
def test_run_npz_suffix_without_format_writes_npz(short_nc, tmp_path):
    out = tmp_path / "points.npz"
    assert invoke(["run", short_nc, "-o", out, "--quiet"]).exit_code == 0
    assert zipfile.is_zipfile(out)
    ref = tmp_path / "points.csv"
    assert invoke(["run", short_nc, "-o", ref, "--quiet"]).exit_code == 0
    np.testing.assert_allclose(
        read_points(str(out))["x"], read_points(str(ref))["x"], rtol=0, atol=1e-9
    )  # the CSV keeps 9 decimals


def test_run_format_contradicting_suffix_is_refused(short_nc, tmp_path):
    out = tmp_path / "x.csv"
    r = invoke(["run", short_nc, "-o", out, "--format", "npz"])
    assert r.exit_code == 2
    assert "npz" in r.stderr and "x.csv" in r.stderr
    assert not out.exists()


def test_run_format_npz_on_unknown_suffix_writes_npz(short_nc, tmp_path):
    out = tmp_path / "points.dat"
    assert invoke(["run", short_nc, "-o", out, "--format", "npz", "--quiet"]).exit_code == 0
    assert zipfile.is_zipfile(out)


def test_run_npz_to_stdout_is_refused(short_nc):
    r = invoke(["run", short_nc, "-o", "-", "--format", "npz"])
    assert r.exit_code == 2
    assert "npz" in r.stderr and r.stdout == ""


# -- 4. h:mm:ss -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "seconds, text",
    [(545.4, " (0:09:05)"), (60.0, " (0:01:00)"), (3725.6, " (1:02:06)"), (59.9, ""), (0.5, "")],
)
def test_clock_suffix(seconds, text):
    assert clock_suffix(seconds) == text


def test_long_cycle_time_prints_clock_in_plan_and_run(tmp_path):
    program = tmp_path / "long.nc"
    program.write_text(LONG)
    summary = json.loads(invoke(["plan", program, "--json"]).stdout)
    total = round(summary["cycle_time_s"])
    assert 60 <= total < 3600
    clock = f"(0:{total // 60:02d}:{total % 60:02d})"
    r = invoke(["plan", program])
    assert f"cycle time: {summary['cycle_time_s']:.4f} s {clock}" in r.stdout
    assert clock not in invoke(["plan", program, "--json"]).stdout
    r = invoke(["run", program, "-o", tmp_path / "p.csv"])
    assert f"{summary['cycle_time_s']:.4f} s {clock}" in r.stderr
