"""Hostile inputs a reliability campaign found (each a clear error, exit 2, never exit 1):

- a line of plain words over the line limit (the fast paths skipped it);
- a machine profile nested 1,000 deep (RecursionError);
- a corrupt NPZ, a .npy named .npz and other malformed NPZ files for ``simulate``;
- control characters from a program echoed raw to the terminal;
- profile values outside a physically meaningful range (a contour tolerance of 1e-300 um
  planned for a minute before anything was said).

The same inputs run in the fuzz test's regression corpus (tests/test_fuzz_cli.py).
"""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.errors import ConfigError, DataError, GCodeSyntaxError, printable
from nurbscnc.machine.discovery import default_profile_text
from nurbscnc.machine.profile import MAX_NESTING, parse_machine
from nurbscnc.machine.schema import RANGES, range_of
from nurbscnc.output.files import POINT_COLUMNS, read_points
from nurbscnc.program.interpret import interpret_text
from nurbscnc.program.parse import MAX_LINE_CHARS, parse_line, parse_text


def run(args, **kwargs):
    return CliRunner().invoke(main, [str(a) for a in args], **kwargs)


# -- 1. the line limit on every path -----------------------------------------------------------
#: One line of 10 MB of plain words (the campaign's input, a quarter of its size).
LONG_PLAIN = b"G21\nG1 X1 F600 " + b"G1 " * 3_400_000 + b"\nM2\n"


def test_plain_word_line_over_the_limit_is_refused_by_the_fast_path():
    line = "G1 " * (MAX_LINE_CHARS // 3 + 1)
    assert len(line) > MAX_LINE_CHARS
    with pytest.raises(GCodeSyntaxError, match="line is too long") as info:
        parse_line(line, 7)
    assert (info.value.pos.line, info.value.pos.column) == (7, MAX_LINE_CHARS + 1)


def test_a_line_at_the_limit_is_still_read():
    line = "G1 X1" + " " * (MAX_LINE_CHARS - 5)
    assert len(line) == MAX_LINE_CHARS and parse_line(line, 1).words


def test_whole_file_parse_applies_the_limit():
    text = "G21\n" + "X1 " * (MAX_LINE_CHARS // 3 + 1) + "\n"
    for fast in (True, False):
        with pytest.raises(GCodeSyntaxError, match="line is too long") as info:
            parse_text(text, fast=fast)
        assert info.value.pos.line == 2


def test_fast_lane_leaves_a_long_plain_line_to_the_general_path():
    """A run of plain moves (the bulk lane) with one 70,000-character plain line in it: its
    number (1.000…) is a valid coordinate, so only the limit refuses it."""
    lines = [f"G1 X{k} Y{k} F600" for k in range(20)]
    lines.insert(12, "G1 X1." + "0" * 70_000)
    with pytest.raises(GCodeSyntaxError, match="line is too long") as info:
        interpret_text("\n".join(lines) + "\nM2\n")
    assert info.value.pos.line == 13


@pytest.mark.parametrize("via", ["file", "stdin"])
def test_check_refuses_a_10_mb_plain_line_with_its_position(tmp_path, via):
    path = tmp_path / "long.nc"
    path.write_bytes(LONG_PLAIN)
    if via == "file":
        result = run(["check", path])
        name = str(path)
    else:
        result = run(["check", "-"], input=LONG_PLAIN)
        name = "<stdin>"
    assert result.exit_code == 2
    head, source, caret = _error_lines(result.stderr)[:3]
    assert head == (
        f"{name}:2:{MAX_LINE_CHARS + 1}: error: line is too long "
        f"({len(LONG_PLAIN) - 8} characters; at most {MAX_LINE_CHARS})"
    )
    assert source.startswith("    … G1 G1") and caret.strip() == "^"
    assert len(result.stderr) < 600


# -- 2. a profile nested 1,000 deep --------------------------------------------------------------
DEEP_TOML = "a = " + "[" * 1000 + "]" * 1000 + "\n"


@pytest.mark.parametrize(
    "text",
    [
        DEEP_TOML,  # tomllib itself recurses
        "a = " + "[" * (MAX_NESTING + 1) + "]" * (MAX_NESTING + 1) + "\n",  # parses, too deep
        "a = " + "{b = " * 100 + "1" + "}" * 100 + "\n",  # inline tables
        default_profile_text() + "\n[soft_limits.q]\nv = " + "[" * 300 + "]" * 300 + "\n",
    ],
    ids=["arrays1000", "arrays33", "tables100", "inside_a_table"],
)
def test_deeply_nested_profile_is_a_config_error(text):
    with pytest.raises(ConfigError, match=f"nested more than {MAX_NESTING} deep") as info:
        parse_machine(text, "deep.toml")
    assert info.value.message.startswith("deep.toml: invalid profile:")


@pytest.mark.parametrize(
    ("depth", "words"), [(1000, "is not a value"), (100, f"nested more than {MAX_NESTING} deep")]
)
def test_deeply_nested_override_is_a_config_error(depth, words):
    value = "[" * depth + "]" * depth
    with pytest.raises(ConfigError, match=words):
        parse_machine(default_profile_text(), "m.toml", {"limits.v_max_mm_min": value})


def test_nesting_within_the_limit_reaches_the_schema_check():
    text = "a = " + "[" * MAX_NESTING + "]" * MAX_NESTING + "\n"
    with pytest.raises(ConfigError, match="a is not a known key"):
        parse_machine(text, "p.toml")


def test_deep_local_profile_read_with_no_option_exits_2(tmp_path, monkeypatch):
    (tmp_path / "nurbscnc.toml").write_text(DEEP_TOML)
    (tmp_path / "p.nc").write_text("G21 G1 X1 F600\nM2\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("NURBSCNC_MACHINE", raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    result = run(["check", "p.nc"])
    assert result.exit_code == 2
    assert "./nurbscnc.toml: invalid profile: arrays or tables nested more than" in result.stderr
    assert "RecursionError" not in result.output + result.stderr


# -- 3. malformed NPZ point files --------------------------------------------------------------
N_POINTS = 40


def _columns() -> dict:
    t = np.arange(N_POINTS) * 1e-3
    return {
        "t": t,
        "x": 5.0 * np.sin(t),
        "y": 5.0 * np.cos(t),
        "z": np.zeros(N_POINTS),
        "feed": np.full(N_POINTS, 10.0),
        "piece": np.zeros(N_POINTS, dtype=np.int64),
        "line": np.ones(N_POINTS, dtype=np.int64),
    }


def _npz(path, columns: dict, raw: dict | None = None) -> str:
    """An NPZ of ``columns`` (np.save'd), and ``raw`` members as given bytes."""
    with zipfile.ZipFile(path, "w") as archive:
        for name, values in columns.items():
            buf = io.BytesIO()
            np.save(buf, values, allow_pickle=True)
            archive.writestr(f"{name}.npy", buf.getvalue())
        for name, data in (raw or {}).items():
            archive.writestr(f"{name}.npy", data)
    return str(path)


def _huge_header() -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": "<f8", "fortran_order": False, "shape": (10**12,)}
    )
    return buf.getvalue() + bytes(64)


def _bad_central_directory(path) -> str:
    good = _npz(path, _columns())
    data = bytearray(open(good, "rb").read())
    k = data.rfind(b"PK\x01\x02")
    data[k : k + 4] = b"XXXX"
    path.write_bytes(bytes(data))
    return str(path)


def _npy_renamed(path) -> str:
    with open(path, "wb") as fh:
        np.save(fh, np.zeros((N_POINTS, 7)))
    return str(path)


def _truncated(path) -> str:
    good = _npz(path, _columns())
    data = open(good, "rb").read()
    path.write_bytes(data[: len(data) // 2])
    return str(path)


def _with(**changes):
    def make(path) -> str:
        cols = _columns()
        for k, v in changes.items():
            if v is None:
                del cols[k]
            else:
                cols[k] = v
        return _npz(path, cols)

    return make


BAD_NPZ = {
    "bad_central_directory": (_bad_central_directory, "Bad magic number for central directory"),
    "npy_renamed": (_npy_renamed, "a single .npy array"),
    "truncated": (_truncated, "not a reference-point NPZ file"),
    "empty_file": (lambda p: (p.write_bytes(b""), str(p))[1], "not a zip archive"),
    "text_file": (lambda p: (p.write_text("t,x,y\n0,0,0\n"), str(p))[1], "not a zip archive"),
    "missing_array": (_with(line=None), "missing arrays line"),
    "two_d_array": (_with(y=np.zeros((N_POINTS, 2))), "must be numeric, 1-D"),
    "short_array": (_with(x=np.zeros(N_POINTS - 1)), "of one length"),
    "strings": (_with(y=np.array(["a"] * N_POINTS)), "must be numeric"),
    "objects": (_with(y=np.array([None] * N_POINTS, dtype=object)), "holds Python objects"),
    "nan": (_with(x=np.where(np.arange(N_POINTS) == 3, np.nan, 0.0)), "x = nan is not finite"),
    "inf": (_with(t=np.full(N_POINTS, np.inf)), "t = inf is not finite (row 1)"),
    "empty_arrays": (_with(**{c: np.zeros(0) for c in POINT_COLUMNS}), "non-empty"),
    "huge_header": (
        lambda p: _npz(p, {k: v for k, v in _columns().items() if k != "x"}, {"x": _huge_header()}),
        "declares 8,000,000,000,000 bytes",
    ),
    "damaged_member": (
        lambda p: _npz(p, {k: v for k, v in _columns().items() if k != "x"}, {"x": b"\x93NUMPY"}),
        "not a reference-point NPZ file",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_NPZ))
def test_malformed_npz_is_a_data_error(tmp_path, case):
    make, words = BAD_NPZ[case]
    path = make(tmp_path / "points.npz")
    with pytest.raises(DataError) as info:
        read_points(path)
    assert words in info.value.message


@pytest.mark.parametrize("case", ["bad_central_directory", "npy_renamed", "huge_header", "nan"])
def test_simulate_of_a_malformed_npz_exits_2(tmp_path, case):
    make, words = BAD_NPZ[case]
    path = make(tmp_path / "points.npz")
    result = run(["simulate", path])
    assert result.exit_code == 2, result.output
    assert f"{path}: error: " in result.stderr and words in result.stderr


def test_a_good_npz_still_reads(tmp_path):
    cols = _columns()
    data = read_points(_npz(tmp_path / "good.npz", cols))
    for c in POINT_COLUMNS:
        np.testing.assert_array_equal(data[c], cols[c].astype(float))


# -- 4. control characters from the program -------------------------------------------------------
HOSTILE_MSG = b"G21\n(MSG,\x1b]0;pwned\x07\x1b[2J)\n(DEBUG, \x9b31m\xe2\x80\xae)\nG1 X1 F600\nM2\n"
RAW = ("\x1b", "\x07", "\x9b", "\u202e")


def test_printable_escapes_what_a_terminal_acts_on():
    assert printable("\x1b]0;pwned\x07\x1b[2J") == r"\x1b]0;pwned\x07\x1b[2J"
    assert printable("a\r\nb\t\x7f\x9b\u202e\u2066é") == r"a\x0d\x0ab\x09\x7f\x9b\u202e\u2066é"
    assert printable("x\ny\tz", keep_layout=True) == "x\ny\tz"
    assert printable("G1 X1 (plain text, µm)") == "G1 X1 (plain text, µm)"


def test_check_escapes_a_message_with_terminal_controls(tmp_path):
    path = tmp_path / "msg.nc"
    path.write_bytes(HOSTILE_MSG)
    result = run(["check", path])
    assert result.exit_code == 0
    assert not any(c in result.output for c in RAW)
    assert r"note (line 2): message: \x1b]0;pwned\x07\x1b[2J" in result.output


def test_check_json_keeps_the_message_as_data(tmp_path):
    path = tmp_path / "msg.nc"
    path.write_bytes(HOSTILE_MSG)
    result = run(["check", path, "--json"])
    assert not any(c in result.stdout for c in RAW)
    notes = json.loads(result.stdout)["notes"]
    assert notes[0]["message"] == "message: \x1b]0;pwned\x07\x1b[2J"


def test_error_source_line_escapes_controls(tmp_path):
    path = tmp_path / "bad.nc"
    path.write_bytes(b"G21\nG1 X1 F600 (\x1b[2J\x07) G33\nM2\n")
    result = run(["check", path])
    assert result.exit_code == 2
    assert not any(c in result.stderr for c in RAW)
    head, source, caret = _error_lines(result.stderr)[:3]
    assert source == r"    G1 X1 F600 (\x1b[2J\x07) G33"
    assert source[caret.index("^") :].startswith("G33")


# -- 5. profile values in physically meaningful ranges ------------------------------------------
def _profile_with(key: str, value: str) -> str:
    table, _, leaf = key.rpartition(".")
    lines, inside, done = [], False, False
    for line in default_profile_text().splitlines():
        if line.startswith("["):
            if inside and not done:
                lines.append(f"{leaf} = {value}")
                done = True
            inside = line == f"[{table}]"
        if inside and line.split("=")[0].strip() == leaf:
            line, done = f"{leaf} = {value}", True
        lines.append(line)
    if not done:
        lines += ([f"[{table}]"] if not inside else []) + [f"{leaf} = {value}"]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("limits.contour_tolerance_um", "1e-300"),
        ("limits.contour_tolerance_um", "0.01"),
        ("limits.chord_tolerance_um", "1e-9"),
        ("limits.v_max_mm_min", "1e300"),
        ("limits.a_max_mm_s2", "1e-30"),
        ("limits.j_max_mm_s3", "1e12"),
        ("limits.kappa_ref_per_mm", "1e9"),
        ("servo.period_ms", "1e-300"),
        ("servo.period_ms", "1e6"),
        ("servo.x.a0", "1e200"),
        ("servo.y.a4", "1e-200"),
        ("steps.per_mm.z", "1e-9"),
        ("soft_limits.x.max_mm", "1e15"),
    ],
)
def test_profile_value_outside_its_range_names_key_and_range(key, value):
    low, high = range_of(key)
    with pytest.raises(ConfigError) as info:
        parse_machine(_profile_with(key, value), "m.toml")
    assert info.value.message == (
        f"m.toml: {key} must be >= {low:g} and <= {high:g} (a physically meaningful range), "
        f"got {float(value)!r}"
    )


ROTARY_KEYS = ("_deg_min", "_deg_s2", "_deg_s3", "min_deg", "max_deg", "steps_per_deg")


@pytest.mark.parametrize(
    "key", sorted(k for k in RANGES if k.startswith(("limits.", "axis_limits.", "steps.")))
)
def test_the_range_ends_are_accepted(key):
    """Both ends pass the range check (another check may still refuse an end: at 1e6 mm/min
    the default 127 steps per period do not suffice)."""
    low, high = RANGES[key]
    for value in (low, high):
        if key.endswith(ROTARY_KEYS):  # a rotary axis's table: its required keys, then this one
            leaf = key.rpartition(".")[2]
            table = {"v_max_deg_min": 3600.0, "a_max_deg_s2": 100.0, "j_max_deg_s3": 1000.0}
            table[leaf] = float(value)
            rows = "".join(f"{k} = {v!r}\n" for k, v in table.items())
            text = default_profile_text() + f"\n[axis_limits.a]\n{rows}"
        else:
            text = _profile_with(key.replace("*", "y"), repr(float(value)))
        try:
            parse_machine(text, "m.toml")
        except ConfigError as exc:
            assert "max_pulses_per_period" in exc.message, exc.message


def test_default_profile_is_inside_every_range():
    parse_machine(default_profile_text(), "default")  # no error
    assert range_of("servo.z.damping") == RANGES["servo.*.damping"]
    assert range_of("limits.max_points") is None


def test_contour_tolerance_out_of_range_exits_2_before_work(tmp_path):
    machine = tmp_path / "m.toml"
    machine.write_text(_profile_with("limits.contour_tolerance_um", "1e-300"))
    program = tmp_path / "p.nc"
    program.write_text("G21 G1 X1 F600\nM2\n")
    result = run(["plan", program, "--machine", machine])
    assert result.exit_code == 2
    assert "limits.contour_tolerance_um must be >= 0.1 and <= 10000" in result.stderr


def test_console_escapes_text_objects_and_keeps_its_own_styles():
    """Whatever prints (a str, a rich Text of a progress line or a table cell) goes through
    the console's escape; rich's own style codes still reach a terminal."""
    from rich.text import Text

    from nurbscnc.cli import console

    buf = io.StringIO()
    term = console._rich_console_class()(
        file=buf, force_terminal=True, color_system="standard", markup=False, width=200
    )
    term.print(Text("line 3: \x1b]0;pwned\x1b[2J", style="bold"), "\x9b31m\ttab")
    out = buf.getvalue()
    assert r"line 3: \x1b]0;pwned\x1b[2J" in out and r"\x9b31m" in out  # (tabs: spaces)
    assert "\x1b[1m" in out  # bold, rich's own escape
    assert "\x1b]" not in out and "\x1b[2J" not in out and "\x9b" not in out


def _error_lines(stderr: str) -> list:
    """The error's lines of ``check``'s stderr (after the line naming the machine profile)."""
    return [line for line in stderr.splitlines() if not line.startswith("machine: ")]
