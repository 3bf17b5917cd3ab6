"""The command-line interface: ``check`` output, stdin, exit codes, help, error paths.

Run in-process with click's CliRunner (stdout and stderr apart). The reference numbers for
``programs/naca2415.nc`` come from the file itself, read by a tiny regex reader here (not the
project's parser), with scipy's BSpline and Gauss–Legendre quadrature as the length oracle
(the airfoil's weights are all 1, so the curve is a plain B-spline).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

import nurbscnc
import nurbscnc.cli.console as console
import nurbscnc.cli.handle as handle
from nurbscnc.cli.main import main
from nurbscnc.errors import NurbsCncError, OutputError, SourcePos, printable

ROOT = Path(__file__).resolve().parents[1]
NACA = ROOT / "programs" / "naca2415.nc"
NUM = r"(-?\d+(?:\.\d+)?)"


def error_report(stderr: str) -> str:
    """stderr without the leading line that says which machine profile the command used."""
    return stderr.split("\n", 1)[1] if stderr.startswith("machine: ") else stderr


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
    # Feeds are mm/s in every JSON (the program's F3500 is mm/min).
    f = float(re.search(r"^F(\d+)", NACA.read_text(), re.M).group(1)) / 60.0
    assert data["feed_range_mm_s"] == {"min": f, "max": f}


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


@pytest.mark.parametrize("command", [None, *main.list_commands(None)])
def test_help_of_every_subcommand(command):
    args = ["--help"] if command is None else [command, "--help"]
    result = run(args)
    assert result.exit_code == 0, result.output
    assert "Usage:" in result.stdout
    if command is not None:
        assert f" {command} " in result.stdout.splitlines()[0]


def test_expected_subcommands_exist():
    assert {"check", "corners", "ph"} <= set(main.list_commands(None))


def test_each_command_is_found_under_its_own_name():
    # The group imports a command's module when the command is looked up (cli/main.py
    # COMMANDS): each name must lead to the command of that name, an unknown one to none.
    for name in main.list_commands(None):
        command = main.get_command(None, name)
        assert isinstance(command, click.Command) and command.name == name
    assert main.get_command(None, "no-such-command") is None


# ------------------------------------------------------------------------------ error paths


def test_internal_error_exits_1_without_traceback(monkeypatch):
    def boom(*args, **kwargs):
        raise RuntimeError("simulated fault")

    monkeypatch.delenv("NURBSCNC_DEBUG", raising=False)
    monkeypatch.setattr("nurbscnc.program.interpret.interpret_text", boom)  # read at the call
    result = run(["check", NACA])
    assert result.exit_code == 1
    assert "internal error" in result.stderr
    assert "RuntimeError: simulated fault" in result.stderr
    assert "Traceback" not in result.output
    assert result.stdout == ""
    # With --json the failure is also the JSON error object (docs/json.md), still exit 1.
    result = run(["check", NACA, "--json"])
    assert result.exit_code == 1
    error = json.loads(result.stdout)
    assert error["ok"] is False and "RuntimeError: simulated fault" in error["errors"][0]["message"]


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


# ------------------------------------------------------------- hardening: user text is literal


@pytest.fixture
def bracket_program(tmp_path):
    """The airfoil under a file name that is rich markup: the folder "[" and the file "].nc"."""
    folder = tmp_path / "["
    folder.mkdir()
    path = folder / "].nc"
    path.write_bytes(NACA.read_bytes())
    return path


@pytest.mark.parametrize("command", [["check"], ["corners"], ["ph"], ["plan", "--dynamics", "off"]])
def test_markup_file_name_prints_literally(bracket_program, command):
    result = run([command[0], bracket_program, *command[1:]])
    assert result.exit_code == 0, result.output
    assert str(bracket_program) in result.stdout
    assert "Traceback" not in result.output


def test_markup_file_name_in_batch(bracket_program, tmp_path):
    result = run(
        [
            "run",
            "--output-dir",
            tmp_path / "out",
            "--jobs",
            "1",
            "--dynamics",
            "off",
            bracket_program,
        ]
    )
    assert result.exit_code == 0, result.output
    assert str(bracket_program) in result.stdout
    assert (tmp_path / "out" / "].csv").exists()


def test_emoji_codes_in_source_line_and_line_100_print_literally(tmp_path):
    path = tmp_path / "part.nc"
    lines = ["G21 G90 G1 X1 F100"] + ["X1"] * 98 + ["(:thumbs_up:) G33 (:smile:)"]
    path.write_text("\n".join(lines) + "\n")
    result = run(["check", path])
    assert result.exit_code == 2
    head, source, caret = error_report(result.stderr).splitlines()[:3]
    assert head.startswith(f"{path}:100:15: error: ")  # ":100:" is the 💯 shortcode
    assert source == "    (:thumbs_up:) G33 (:smile:)"
    assert caret == "    " + " " * 14 + "^"


def test_emoji_code_in_file_name_stays_in_json(tmp_path):
    path = tmp_path / "a:thumbs_up:b.nc"
    path.write_text("G21 G90 G1 X1 F600\nM2\n")
    result = run(["run", path, "-o", tmp_path / "p.csv", "--json", "--dynamics", "off"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["program"] == str(path)


# ------------------------------------------------------------- hardening: error reports


def test_long_source_line_is_cut_around_the_column():
    text = "(" + "a" * 5_000_000 + ") G28 (" + "b" * 5_000_000 + ")"
    column = text.index("G28") + 1
    exc = NurbsCncError("G28 is not supported", SourcePos(7, column, text))
    report = console.format_error(exc, "big.nc")
    head, shown, caret = report.splitlines()
    assert head == f"big.nc:7:{column}: error: G28 is not supported"
    assert len(shown) <= 4 + console.SOURCE_ECHO_CHARS + 2
    assert shown.startswith("    …") and shown.endswith("…")
    assert shown[len(caret) - 1 : len(caret) + 2] == "G28"  # the caret is under the G


@pytest.mark.parametrize("column", [1, 2, 60, 119, 121, 500, 999, 1000, 1001])
def test_cut_source_line_keeps_the_caret_on_its_character(column):
    text = "".join(chr(ord("A") + k % 26) for k in range(1000))
    shown, caret = console.echo_source_line(text, column)
    assert len(shown) <= console.SOURCE_ECHO_CHARS + 2
    if column <= len(text):
        assert shown[caret] == text[column - 1]
    else:
        assert caret == len(shown) - (1 if shown.endswith("…") else 0)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.text(max_size=400), st.data())
def test_cut_source_line_property(text, data):
    column = data.draw(st.integers(1, len(text) + 1))
    shown, caret = console.echo_source_line(text, column, width=40)
    spaced = text.replace("\t", " ")
    visible = printable(spaced)
    assert len(shown) <= 6 * 40 + 2  # an escape is at most 6 characters (\u202e)
    assert shown.strip("…") in visible
    assert not any(ord(c) < 0x20 or 0x7F <= ord(c) < 0xA0 for c in shown)
    if column <= len(text):
        assert shown[caret:].startswith(printable(spaced[column - 1]))
    if len(text) <= 40:
        assert shown == visible


def test_control_characters_in_source_line_are_escaped():
    exc = NurbsCncError("bad", SourcePos(1, 7, "\x1b[2J\x07\tX\rG28\x9b1m"))
    shown, caret_line = console.format_error(exc, "f.nc").splitlines()[1:]
    assert "\x1b" not in shown and "\x07" not in shown and "\r" not in shown
    assert shown == "    " + r"\x1b[2J\x07 X\x0dG28\x9b1m"
    assert shown[caret_line.index("^")] == "X"  # column 7 is the X, after two escapes


def test_control_characters_in_file_name_and_message_are_escaped():
    exc = NurbsCncError("bad word '\x1b]0;owned\x07'" + "x" * 5000, SourcePos(3, 1, "G1"))
    head = console.format_error(exc, "a\nb\x1b.nc").splitlines()[0]
    assert head.startswith(r"a\x0ab\x1b.nc:3:1: error: bad word '\x1b]0;owned\x07'")
    assert head.endswith(f"… ({len(exc.message)} characters)")
    assert len(head) < console.MESSAGE_CHARS + 100


def test_cli_error_on_long_line_is_short(tmp_path):
    path = tmp_path / "long.nc"
    path.write_text("G21 G90\n(" + "x" * 200_000 + ") G33\n")
    result = run(["check", path])
    assert result.exit_code == 2
    assert len(error_report(result.stderr)) < 600
    # Over the line limit (parse.MAX_LINE_CHARS) on the plain-word path too: the caret
    # marks the first character past it.
    assert error_report(result.stderr).startswith(
        f"{path}:2:65537: error: line is too long (200006 characters; at most 65536)"
    )


def test_run_names_errors_with_the_file(tmp_path):
    path = tmp_path / "bad.nc"
    path.write_text("G21 G90 G1 X1 F100\nG33\n")
    result = run(["run", path, "-o", tmp_path / "p.csv"])
    assert result.exit_code == 2
    assert error_report(result.stderr).startswith(f"{path}:2:1: error: ")
    assert "<stdin>" not in result.stderr
    assert not (tmp_path / "p.csv").exists()


def test_run_from_stdin_is_named_stdin(tmp_path):
    result = run(["run", "-", "-o", tmp_path / "p.csv"], input="G1 X1 F100\nG33\n")
    assert result.exit_code == 2
    assert error_report(result.stderr).startswith("<stdin>:2:1: error: ")


# ------------------------------------------------------------- hardening: files and exit codes


@pytest.mark.parametrize("command", ["check", "corners", "ph", "plan", "simulate"])
def test_directory_input_exits_3(tmp_path, command):
    result = run([command, tmp_path])
    assert result.exit_code == 3, result.output
    assert "Is a directory" in result.stderr


@pytest.mark.parametrize("option", ["--machine", "--tool-table"])
def test_directory_as_machine_or_tool_table_exits_3(tmp_path, option):
    command = "check" if option == "--tool-table" else "corners"
    result = run([command, NACA, option, tmp_path])
    assert result.exit_code == 3, result.output


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads unreadable files")
def test_unreadable_input_exits_3(tmp_path):
    path = tmp_path / "secret.nc"
    path.write_text("G1 X1 F100\n")
    path.chmod(0)
    result = run(["check", path])
    assert result.exit_code == 3
    assert "Permission denied" in result.stderr


def test_machine_profile_with_400_digit_integer_exits_2(tmp_path):
    text = cli_default_profile().replace("a_max_mm_s2 = 2450.0", "a_max_mm_s2 = " + "9" * 400)
    path = tmp_path / "m.toml"
    path.write_text(text)
    result = run(["corners", NACA, "--machine", path])
    assert result.exit_code == 2, result.output
    assert "limits.a_max_mm_s2 is too large" in result.stderr
    assert "(400 digits)" in result.stderr


def test_machine_profile_with_5000_digit_integer_exits_2(tmp_path):
    text = cli_default_profile().replace("a_max_mm_s2 = 2450.0", "a_max_mm_s2 = " + "9" * 5000)
    path = tmp_path / "m.toml"
    path.write_text(text)
    result = run(["corners", NACA, "--machine", path])
    assert result.exit_code == 2, result.output
    assert "more than" in result.stderr and len(result.stderr) < 500


def test_huge_count_and_huge_set_value_exit_2():
    result = run(["corners", NACA, "--set", "steps.max_pulses_per_period=" + "9" * 400])
    assert result.exit_code == 2, result.output
    assert "steps.max_pulses_per_period must be <= 2147483647" in result.stderr
    result = run(["corners", NACA, "--set", "limits.j_max_mm_s3=" + "9" * 5000])
    assert result.exit_code == 2, result.output


def cli_default_profile() -> str:
    from nurbscnc.machine.profile import default_profile_text

    text = default_profile_text()
    assert "a_max_mm_s2 = 2450.0" in text
    return text


# ------------------------------------------------------------- hardening: pipes (subprocesses)


def _nurbscnc(args, stdout, **kwargs):
    return subprocess.run(
        [sys.executable, "-m", "nurbscnc", *map(str, args)],
        stdout=stdout,
        stderr=subprocess.PIPE,
        timeout=120,
        **kwargs,
    )


def _closed_pipe():
    """The write end of a pipe whose reader is already gone: the first write gets EPIPE."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    return write_end


@pytest.mark.parametrize(
    "args", [["check", NACA], ["run", NACA, "-o", "-"], ["check", NACA, "--json"]]
)
def test_closed_pipe_ends_quietly_with_141(args):
    fd = _closed_pipe()
    try:
        proc = _nurbscnc(args, stdout=fd)
    finally:
        os.close(fd)
    assert proc.returncode == 141, proc.stderr
    # nothing but, for check's summary, the line saying which profile it used
    assert error_report(proc.stderr.decode()) == ""


def test_head_on_run_output_is_quiet(tmp_path):
    """A real reader that stops after one line, as ``| head -1``."""
    path = tmp_path / "long.nc"
    path.write_text("G21 G90 G1 X200 F600\nM2\n")  # 20 s: ~20000 rows, far beyond a pipe buffer
    proc = subprocess.Popen(
        [sys.executable, "-m", "nurbscnc", "run", str(path), "-o", "-", "--dynamics", "off"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    first = proc.stdout.readline()
    proc.stdout.close()
    code = proc.wait(120)
    assert first == b"t,x,y,z,feed,piece,line\n"
    assert code == 141
    assert proc.stderr.read() == b""


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
@pytest.mark.parametrize(
    "args, message",
    [
        (["check", NACA], "cannot write to standard output: No space left on device"),
        (["run", NACA, "-o", "-"], "cannot write standard output: No space left on device"),
    ],
)
def test_stdout_to_dev_full_exits_3_with_a_message(args, message):
    with open("/dev/full", "wb") as full:
        proc = _nurbscnc(args, stdout=full)
    assert proc.returncode == 3, proc.stderr
    text = proc.stderr.decode()
    assert message in text
    assert "Traceback" not in text and "Exception ignored" not in text


# ---------------------------------------------------------------------------------- progress
STAGE_WORDS = ("reading and interpreting", "dynamics check", "interpolating", "writing")


def test_run_program_names_its_stages():
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.pipeline import run_program
    from nurbscnc.program.interpret import interpret_text

    stages = []
    prog = interpret_text("G1 X2 F3000\nG2 X2 Y0 I-2 J0\n")  # the check must re-plan it
    run = run_program(prog, load_machine(), progress=stages.append)
    assert stages[:3] == ["checking limits", "planning", "dynamics check"]
    replans = [f"dynamics check, re-plan {i}" for i in range(1, run.plan.iterations + 1)]
    assert run.plan.iterations >= 1 and stages[3:] == [*replans, "interpolating"]


@pytest.mark.parametrize("args", [["plan", "{p}"], ["run", "{p}", "-o", "{o}"], ["check", "{p}"]])
def test_no_progress_when_not_a_terminal(tmp_path, args):
    prog = tmp_path / "p.nc"
    prog.write_text("G1 X2 F3000\nG2 X2 Y0 I-2 J0\n")
    res = run([a.format(p=prog, o=tmp_path / "o.csv") for a in args])
    assert res.exit_code == 0, res.output
    assert not any(word in res.stderr for word in STAGE_WORDS), res.stderr


def _stderr_on_a_pty(args, cwd) -> bytes:
    """Run the CLI in ``cwd`` with stderr on a pseudo-terminal; everything written there."""
    import pty
    import select

    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "nurbscnc", *map(str, args)],
        stdout=subprocess.DEVNULL,
        stderr=slave,
        stdin=subprocess.DEVNULL,
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    os.close(slave)
    data = b""
    try:
        while True:
            ready, _, _ = select.select([master], [], [], 0.2)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:  # the child closed its end
                    break
                if not chunk:
                    break
                data += chunk
            elif proc.poll() is not None:
                break
    finally:
        os.close(master)
        proc.wait(timeout=120)
    assert proc.returncode == 0, data.decode(errors="replace")
    return data


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="pseudo-terminal test")
def test_progress_on_a_terminal_names_the_stages(tmp_path):
    prog = tmp_path / "p.nc"
    prog.write_text("G1 X2 F3000\nG2 X2 Y0 I-2 J0\n")
    shown = _stderr_on_a_pty(["run", "p.nc", "-o", "o.csv"], tmp_path)
    for word in ("dynamics check", "interpolating", "writing"):
        assert word.encode() in shown, shown
    quiet = _stderr_on_a_pty(["run", "p.nc", "-o", "o.csv", "--json"], tmp_path)
    assert not any(word.encode() in quiet for word in STAGE_WORDS), quiet


# ------------------------------------------------------------------------- shell completion
@pytest.mark.parametrize(
    "words, expected",
    [
        ("nurbscnc pl", {"plan"}),
        ("nurbscnc plan --expl", {"--explain", "--explain-all"}),
        ("nurbscnc plan x.nc --dynamics ", {"local", "global", "off"}),
    ],
)
def test_bash_completion_as_the_readme_says(words, expected):
    env = {
        "_NURBSCNC_COMPLETE": "bash_complete",
        "COMP_WORDS": words,
        "COMP_CWORD": str(len(words.split(" ")) - 1),
    }
    res = CliRunner().invoke(main, [], env=env, prog_name="nurbscnc")
    assert res.exit_code == 0, res.output
    got = {line.split(",", 1)[1] for line in res.stdout.splitlines() if "," in line}
    assert expected <= got, res.stdout
    assert "_NURBSCNC_COMPLETE=bash_source nurbscnc" in (ROOT / "README.md").read_text()


def test_reuse_freed_memory_is_harmless_without_glibc(monkeypatch):
    """The allocator setting (mallopt, glibc only) never fails a command: without glibc
    (confstr unknown, or no name) it does nothing; with it, calling it again is harmless."""
    from nurbscnc.app import runtime

    runtime.reuse_freed_memory()  # this machine's libc (glibc on Linux CI): set twice
    runtime.reuse_freed_memory()

    def no_confstr(name):
        raise ValueError(f"unrecognized configuration name {name!r}")

    calls = []
    monkeypatch.setattr(runtime.os, "confstr", no_confstr)
    monkeypatch.setattr("ctypes.CDLL", lambda *a, **k: calls.append(a))
    assert runtime.reuse_freed_memory() is None
    monkeypatch.setattr(runtime.os, "confstr", lambda name: None)  # musl: no glibc version
    assert runtime.reuse_freed_memory() is None
    assert calls == []  # libc never opened without glibc


def test_collector_paused_and_thawed_around_the_plan_and_its_json():
    """make_plan freezes the program's objects for the planning only, and summary_json
    pauses the cycle collector for the encoding only: afterwards nothing stays frozen and
    the collector is as it was (on or off); the text is json.dumps's."""
    import gc

    from nurbscnc.app.planning import make_plan
    from nurbscnc.app.summary import summary_json, summary_of

    prog, mach, run = make_plan(str(ROOT / "programs" / "corners.nc"))
    assert gc.get_freeze_count() == 0 and gc.isenabled()
    summary = summary_of(prog, mach, run)
    assert summary_json(summary) == json.dumps(summary)
    assert gc.isenabled()
    gc.disable()
    try:
        summary_json({"a": 1.5})
        assert not gc.isenabled()
    finally:
        gc.enable()


@pytest.mark.parametrize(
    "signal_exc, code",
    [(KeyboardInterrupt(), 130), (handle.Terminated(15), 143), (handle.Terminated(1), 129)],
)
@pytest.mark.parametrize(
    "late",
    [
        OSError(28, "No space left on device"),
        OutputError("cannot write x.csv: closed"),
        ValueError("a writer's own error"),
    ],
)
def test_an_error_while_unwinding_from_a_signal_reports_the_signal(signal_exc, code, late, capsys):
    """A write cut short by Ctrl-C or SIGTERM can fail again as its file is closed on the
    way out: the exit code is the signal's, not the later error's (3 or 1)."""

    @handle.handle_errors
    def command():
        try:
            raise signal_exc
        except BaseException:
            raise late from None  # ``from None`` keeps the context, as the writers do

    with pytest.raises(SystemExit) as caught:
        command()
    assert caught.value.code == code
    assert "No space" not in capsys.readouterr().err


def test_an_error_without_a_signal_behind_it_keeps_its_code():
    @handle.handle_errors
    def command():
        try:
            raise ValueError("first")
        except ValueError:
            raise OutputError("cannot write x.csv: disk full") from None

    with pytest.raises(SystemExit) as caught:
        command()
    assert caught.value.code == 3


def test_run_never_writes_over_its_program(tmp_path):
    """``run x.nc -o x.nc`` (or through a link, or a batch whose output folder holds a
    program of the output's name) would replace the program by its points: refused before
    anything is planned, exit 2, the program untouched."""
    prog = tmp_path / "a.nc"
    text = "G1 X1 F100\nM2\n"
    prog.write_text(text)
    (tmp_path / "link.nc").symlink_to(prog)
    for out in (prog, tmp_path / "link.nc", tmp_path / "." / "a.nc"):
        result = run(["run", prog, "-o", out, "--format", "csv"])
        assert result.exit_code == 2, result.output
        assert "is the program" in result.stderr and str(prog) in result.stderr
        assert prog.read_text() == text
    csv_prog = tmp_path / "b.csv"  # a program whose name ends in .csv
    csv_prog.write_text(text)
    result = run(["run", csv_prog, "--output-dir", tmp_path])
    assert result.exit_code == 2 and "is the program" in result.stderr
    assert csv_prog.read_text() == text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.nc", "b.csv", "link.nc"]


def test_inputs_are_bounded(monkeypatch, tmp_path):
    """A stream that never ends (/dev/urandom, /dev/zero) or a file past MAX_INPUT_BYTES, as
    the program, a tool table, a point file or a trace, or a machine profile past
    MAX_PROFILE_CHARS, is refused after reading that much, exit 2: each filled the memory
    until the OOM killer (exit 137) or a MemoryError (exit 1)."""
    import nurbscnc.output.inputs as inputs

    monkeypatch.setattr(inputs, "MAX_INPUT_BYTES", 1 << 16)
    result = run(["check", "/dev/urandom"])
    assert result.exit_code == 2
    assert (
        "the program is larger than 65,536 bytes (0.0625 MiB), the most nurbscnc reads"
        in result.stderr
    )
    prog = tmp_path / "a.nc"
    prog.write_text("G1 X1 F100\nM2\n")
    for args, what in (
        (["plan", prog, "--tool-table", "/dev/zero"], "the tool table"),
        (["identify", "/dev/zero"], "the trace"),
        (["plan", prog, "--machine", "/dev/zero"], "machine profile"),
    ):
        result = run(args)
        assert result.exit_code == 2, (args, result.output)
        assert what in result.stderr and (
            "larger than" in result.stderr or "longer than" in result.stderr
        )
    points = tmp_path / "p.csv"
    points.write_text("t,x,y\n" + "0.0,0.0,0.0\n" * 6000)
    result = run(["simulate", points])
    assert result.exit_code == 2 and "the point file is larger than" in result.stderr
    big = tmp_path / "big.nc"
    big.write_text("G1 X1 F100\n" * 6000)  # 66,000 bytes
    result = run(["check", big])
    assert result.exit_code == 2 and "the most nurbscnc reads" in result.stderr
    result = run(["check", "-"], input="G1 X1 F100\n" * 6000)
    assert result.exit_code == 2 and "the most nurbscnc reads" in result.stderr
    big.write_text("G1 X1 F100\n" * 5957)  # 65,527 bytes: read
    assert run(["check", big]).exit_code == 0
