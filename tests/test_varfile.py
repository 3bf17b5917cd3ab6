"""LinuxCNC's parameter file (program/varfile.py, app/varfile.py, output/varfile.py), the
program events M6 / M0 / M1 / user M-codes (program/executor.py), and the soft limits in
machine coordinates naming the offsets (plan/limits.py), from the interpreter to the CLI.
The moves and written values against LinuxCNC itself: tests/test_varfile_linuxcnc.py."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.errors import ConfigError, ProgramError
from nurbscnc.program.interpret import InterpretOptions, interpret_text
from nurbscnc.program.varfile import REQUIRED_PARAMETERS, format_var_text, parse_var_text


def run_cli(args, env=None):
    return CliRunner().invoke(main, [str(a) for a in args], env=env)


# -- the file's text ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("5220 1\njunk here\n", "p.var:2: not a parameter line"),
        ("5220 1\n5221 abc\n", "p.var:2: parameter #5221 value 'abc' is not a number"),
        ("5221 1\n5220 1\n", "p.var:2: parameter #5220 after #5221: the numbers must increase"),
        ("5221 1\n5221 2\n", "p.var:2: parameter #5221 after #5221"),
        ("0 1\n", "p.var:1: parameter number 0 out of range 1..5601"),
        ("5602 1\n", "p.var:1: parameter number 5602 out of range"),
        ("5221 nan\n", "p.var:1: parameter #5221 value nan is not a finite number"),
        ("5221 1e12\n", r"p.var:1: parameter #5221 = 1e\+12 mm is out of range"),
        ("5220 10\n", "p.var:1: parameter #5220 .* must be 1..9"),
        ("5220 1.5\n", "p.var:1: parameter #5220"),
    ],
)
def test_a_bad_line_is_named_with_the_file_and_line(text, message):
    with pytest.raises(ConfigError, match=message):
        parse_var_text(text, "p.var")


def test_the_text_as_linuxcnc_reads_and_writes_it():
    """Blank lines pass, tabs or spaces separate; written: the old file's numbers and the
    required ones, increasing, "%d\\t%f" (rs274ngc_pre.cc save_parameters)."""
    values = parse_var_text("\n31  2.5\n5220\t3.000000\n\n5241 -1e1\n", "p.var")
    assert values == {31: 2.5, 5220: 3.0, 5241: -10.0}
    text = format_var_text({31: 2.5, 5220: 3.0, 5241: -10.0, 32: 9.0}, values)
    lines = text.splitlines()
    assert [int(line.split("\t")[0]) for line in lines] == sorted({31, *REQUIRED_PARAMETERS})
    assert lines[0] == "31\t2.500000" and "5241\t-10.000000" in lines and "5220\t3.000000" in lines
    assert len(REQUIRED_PARAMETERS) == 9 + 9 + 10 + 1 + 9 * 10


# -- the interpreter -----------------------------------------------------------------------------
def ends(prog) -> list:
    return [tuple(round(v, 9) for v in s.end_mm) for s in prog.segments]


def test_the_active_system_and_g92_from_the_file():
    """#5220 = 2 with G55's offset: the program's X1 is machine 11; G92 applies only when
    #5210 is set (its values are kept either way and written back)."""
    base = {5220: 2.0, 5241: 10.0, 5242: 20.0, 5243: -30.0, 5211: 1.0, 5212: 2.0, 5213: 3.0}
    prog = interpret_text("G0 X1 Y1 Z1\nM2\n", InterpretOptions(parameters=base))
    assert ends(prog) == [(11.0, 21.0, -29.0)]
    assert prog.parameters[5211] == 1.0 and prog.parameters[5220] == 1.0  # M2: G54 again
    prog = interpret_text("G0 X1 Y1 Z1\nM2\n", InterpretOptions(parameters={**base, 5210: 1.0}))
    assert ends(prog) == [(12.0, 23.0, -26.0)]
    prog = interpret_text("G0 X1 Y1 Z1\n", InterpretOptions(parameters=base))
    assert prog.parameters[5220] == 2.0  # no M2: the system stays
    # the start point is the machine's: it does not move with the offsets
    assert list(prog.segments[0].start_mm) == [0.0, 0.0, 0.0]


def test_numbered_parameters_persist():
    prog = interpret_text("#31 = [#31 + 1]\nM2\n", InterpretOptions(parameters={31: 41.0}))
    assert prog.parameters[31] == 42.0


# -- program events ------------------------------------------------------------------------------
def test_m6_m0_m1_are_pauses_with_the_lines_text():
    prog = interpret_text(
        "G0 X1 Y2 Z3\nT7 M6 (6 mm end mill)\nM0 (MSG, check the clamp) (other)\nM1 ; look\n"
        "G0 X4 (no stop here)\nM0\nM2\n"
    )
    stops = [s for s in prog.segments if s.kind == "pause"]
    assert [(s.code, s.tool, s.message, s.line) for s in stops] == [
        ("M6", 7, "6 mm end mill", 2),
        ("M0", None, "check the clamp", 3),
        ("M1", None, "look", 4),
        ("M0", None, "", 6),
    ]
    assert stops[0].position_mm == (1.0, 2.0, 3.0) and stops[3].position_mm == (4.0, 2.0, 3.0)


def test_a_user_m_code_is_a_pause_with_its_argv():
    """M101 P Q → (path, "%f" P, "%f" Q), -1 for a word not given (LinuxCNC's unset
    p_number, q_number); after the block's tool change (LinuxCNC's convert_m order) and
    before its motion."""
    find = {101: "/opt/m/M101", 150: "/opt/m/M150"}.get
    prog = interpret_text(
        "G0 X1\nM101 P2.5 Q-3\nT2 M6 M150 G0 X5\nM101\nM2\n", InterpretOptions(find_user_m=find)
    )
    stops = [(s.kind, getattr(s, "code", ""), getattr(s, "argv", ())) for s in prog.segments]
    assert stops == [
        ("rapid", "", ()),
        ("pause", "M101", ("/opt/m/M101", "2.500000", "-3.000000")),
        ("pause", "M6", ()),
        ("pause", "M150", ("/opt/m/M150", "-1.000000", "-1.000000")),
        ("rapid", "", ()),
        ("pause", "M101", ("/opt/m/M101", "-1.000000", "-1.000000")),
    ]


def test_a_user_m_code_without_an_executable_is_refused_at_its_line():
    with pytest.raises(ProgramError, match="M102: no executable named M102") as info:
        interpret_text("G0 X1\nM102 P1\nM2\n", InterpretOptions(find_user_m=lambda c: None))
    assert (info.value.pos.line, info.value.pos.column) == (2, 1)
    with pytest.raises(ProgramError, match="M103: no executable"):
        interpret_text("M103\n")


# -- the command line ----------------------------------------------------------------------------
@pytest.fixture
def job(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path))
    for name in ("NURBSCNC_MACHINE", "NURBSCNC_VAR", "XDG_CONFIG_HOME"):
        monkeypatch.delenv(name, raising=False)
    (tmp_path / "part.nc").write_text(
        "G21 G90\nG0 X10 Y10 Z5\nG10 L20 P1 X0 Y0 Z0\nG1 X5 F600\nM2\n"
    )
    (tmp_path / "m.var").write_text("5220\t1.000000\n5223\t-50.000000\n")
    return tmp_path


def test_check_reads_the_file_and_never_writes_it(job):
    before = (job / "m.var").read_bytes()
    r = run_cli(["check", "part.nc", "--var", "m.var"])
    assert r.exit_code == 0, r.output
    assert (job / "m.var").read_bytes() == before
    r = run_cli(["check", "part.nc", "--var", "missing.var"])
    assert r.exit_code == 2 and "the parameter file missing.var does not exist" in r.stderr


def test_a_bad_file_is_an_error_naming_its_line_and_nothing_is_written(job):
    (job / "m.var").write_text("5220 1\n5221 x\n")
    for args in (["check", "part.nc"], ["run", "part.nc", "-o", "p.csv", "--write-var"]):
        r = run_cli([*args, "--var", "m.var"])
        assert r.exit_code == 2, r.output
        assert "m.var:2: parameter #5221 value 'x' is not a number" in r.stderr
        assert "Traceback" not in r.output
    assert (job / "m.var").read_text() == "5220 1\n5221 x\n" and not (job / "p.csv").exists()


def test_run_write_var_writes_the_offsets_back(job):
    """G10 L20 P1 X0 Y0 Z0 at machine (10, 10, -45): G54's offset becomes that point."""
    r = run_cli(["run", "part.nc", "-o", "p.csv", "--var", "m.var", "--write-var", "--quiet"])
    assert r.exit_code == 0, r.output
    values = parse_var_text((job / "m.var").read_text(), "m.var")
    assert (values[5221], values[5222], values[5223], values[5220]) == (10.0, 10.0, -45.0, 1.0)
    assert sorted(values) == sorted(REQUIRED_PARAMETERS)
    # without --write-var, run only reads it
    (job / "m.var").write_text("5223 -50\n")
    assert run_cli(["run", "part.nc", "-o", "p.csv", "--var", "m.var"]).exit_code == 0
    assert (job / "m.var").read_text() == "5223 -50\n"


def test_a_file_that_cannot_be_written_back_is_refused_before_the_work(job):
    r = run_cli(["run", "part.nc", "-o", "p.csv", "--var", "no/such/m.var", "--write-var"])
    assert r.exit_code == 2 and "its folder" in r.stderr and "does not exist" in r.stderr
    assert not (job / "p.csv").exists()


def test_a_write_that_fails_leaves_the_old_file_whole(job, monkeypatch):
    before = (job / "m.var").read_bytes()

    def refuse(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", refuse)
    r = run_cli(["run", "part.nc", "-o", "-", "--var", "m.var", "--write-var", "--quiet"])
    assert r.exit_code == 3, r.output
    assert "cannot write the parameter file m.var: No space left on device" in r.stderr
    assert (job / "m.var").read_bytes() == before
    assert sorted(p.name for p in job.iterdir()) == ["m.var", "part.nc"]


def test_the_environment_and_the_profile_name_the_file(job):
    (job / "e.var").write_text("5223 -50\n")
    r = run_cli(["profile", "show"], env={"NURBSCNC_VAR": "e.var"})
    assert "# parameter file (--var, $NURBSCNC_VAR, program.var_file): e.var ($NURBSCNC_VAR)" in (
        r.stdout
    )
    (job / "machine.toml").write_text(
        (Path(__file__).parent.parent / "nurbscnc" / "data" / "default_machine.toml").read_text()
        + '\n[program]\nvar_file = "sub/p.var"\n'
    )
    r = run_cli(["profile", "show", "--machine", "machine.toml"])
    assert f"{job / 'sub' / 'p.var'} (program.var_file)" in r.stdout
    assert 'var_file = "sub/p.var"' in r.stdout
    # the soft limits see the environment's offsets: Z 5 is machine -45
    limit = ["--set", "soft_limits.z.max_mm=0"]
    assert run_cli(["check", "part.nc", *limit]).exit_code == 2
    r = run_cli(["check", "part.nc", *limit], env={"NURBSCNC_VAR": "e.var"})
    assert r.exit_code == 0, r.output


def test_soft_limits_in_machine_coordinates_name_the_offset(job):
    """The CAM program in work coordinates: refused without the offset (Z reaches 5 mm),
    accepted with the parameter file's G54 Z -50."""
    (job / "cam.nc").write_text("G21 G90\nG0 X10 Y10 Z5\nG1 Z-2 F300\nM2\n")
    limits = ["--set", "soft_limits.z.min_mm=-100", "--set", "soft_limits.z.max_mm=0"]
    r = run_cli(["check", "cam.nc", *limits])
    assert r.exit_code == 2
    assert (
        "cam.nc:2:1: error: the rapid leaves the soft limits: Z reaches 5 mm in machine "
        "coordinates (G54 offset Z 0), outside [-100, 0] mm" in r.stderr
    )
    (job / "g55.var").write_text("5220 2\n5243 -2\n")
    r = run_cli(["check", "cam.nc", "--var", "g55.var", *limits])
    assert "Z reaches 3 mm in machine coordinates (G55 offset Z -2)" in r.stderr
    assert run_cli(["check", "cam.nc", "--var", "m.var", *limits]).exit_code == 0


def test_user_m_codes_from_the_user_m_path(job):
    (job / "mc.nc").write_text("G0 X1\nM101 P3\nM2\n")
    r = run_cli(["check", "mc.nc"])
    assert r.exit_code == 2 and "mc.nc:2:1: error: M101: no executable named M101" in r.stderr
    folder = job / "mcodes"
    folder.mkdir()
    (folder / "M101").write_text("#!/bin/sh\n")
    (folder / "m101").write_text("#!/bin/sh\n")
    os.chmod(folder / "m101", 0o755)  # the name is M101, capital M (LinuxCNC's lookup)
    os.chmod(folder / "M101", 0o644)
    assert run_cli(["check", "mc.nc", "--user-m-path", f"/nowhere:{folder}"]).exit_code == 2
    os.chmod(folder / "M101", 0o755)
    r = run_cli(["check", "mc.nc", "--user-m-path", f"/nowhere:{folder}"])
    assert r.exit_code == 0, r.output
    r = run_cli(["check", "mc.nc", "--set", f"program.user_m_path={folder}"])
    assert r.exit_code == 0, r.output


def test_stream_reads_the_offsets_and_writes_them_back_at_the_end(tmp_path):
    """Against the card simulator: G54 X 0.5 from the file puts X1 at machine 1.5; G10 L20
    there makes it G54's origin; X2 then ends at machine 3.5 (3500 steps at 1000 steps/mm);
    once the card is done the file holds the new origin (1.5, 1)."""
    from tests.stream_helpers import card_on

    nc = tmp_path / "part.nc"
    nc.write_text("G21 G90\nG0 X1 Y1\nG10 L20 P1 X0 Y0\nG1 X2 F3000\nM2\n")
    var = tmp_path / "m.var"
    var.write_text("5221\t0.500000\n")
    with card_on("pty") as (card, ep):
        r = run_cli(["stream", nc, "--port", ep.path, "--json", "--var", var])
    assert r.exit_code == 0, r.output
    assert card.position.tolist() == [3500, 1000, 0]
    values = parse_var_text(var.read_text(), "m.var")
    assert (values[5221], values[5222], values[5220]) == (1.5, 1.0, 1.0)


def test_work_position_of_a_machine_position():
    """G55 at (10, 20, -30) turned 90°, G92 (1, 0, 0) on: machine (10, 21, -25) is
    R(-90°)·(0, 1) − G92 = (1, 0) − (1, 0) in X Y, 5 in Z."""
    from nurbscnc.program.varfile import work_position_mm

    values = {5220: 2, 5241: 10, 5242: 20, 5243: -30, 5250: 90, 5210: 1, 5211: 1}
    name, work = work_position_mm(values, (10, 21, -25))
    assert name == "G55"
    assert work == pytest.approx([0.0, 0.0, 5.0], abs=1e-12)
    assert work_position_mm({}, (1, 2, 3)) == ("G54", [1.0, 2.0, 3.0])
