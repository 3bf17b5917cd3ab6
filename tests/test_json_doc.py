"""docs/json.md lists exactly the keys each command prints with --json (issue 16: one JSON
vocabulary, documented).

Each command is run on programs that make every optional key appear; the keys printed
(flattened: ``a.b`` for objects, ``a[]`` for list elements, ``a.*`` for the maps the doc marks
as data-keyed) must equal the keys the doc lists in the sections whose heading names the
command. The stream report is checked against its dataclass (streaming needs a card).
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "json.md"
NACA = str(ROOT / "programs" / "naca2415.nc")
SPIRAL = str(ROOT / "tests" / "programs" / "cam" / "spiral2k.ngc")  # dense G1 chords
MIXED = "G0 X1\n(MSG, hello)\nG1 X2 F600\nG2 X4 I1\nG4 P0.1\nG1 Y1\n"
CORNER = "G61\nG1 X10 F3000\nG1 Y10\n"
ROTARY = "G1 X10 A90 F600\nG1 X20\n"  # A turns along the first move and stays at 90°


def doc_sections() -> list[tuple[set, set]]:
    """(command names in the heading's backticks, keys of its tables) per ## section."""
    sections = []
    for block in re.split(r"^## ", DOC.read_text(encoding="utf-8"), flags=re.M)[1:]:
        heading, _, body = block.partition("\n")
        names = set(re.findall(r"`([^`]+)`", heading))
        body = body.split("\n### ")[0]  # subsections (### Limits) list values, not keys
        keys = set(re.findall(r"^\| `([^`]+)` \|", body, flags=re.M))
        sections.append((names, keys))
    return sections


def doc_keys(command: str) -> set:
    return set().union(*(keys for names, keys in doc_sections() if command in names))


def flatten(obj, wild: set, prefix: str = "", out: set | None = None) -> set:
    out = set() if out is None else out
    if isinstance(obj, dict):
        for key, value in obj.items():
            path = f"{prefix}.{key}" if prefix else key
            if path + ".*" in wild:
                out.add(path + ".*")
                continue
            out.add(path)
            flatten(value, wild, path, out)
    elif isinstance(obj, list):
        for value in obj:
            flatten(value, wild, prefix + "[]", out)
    return out


def printed(*args, input=None, code=0) -> dict:
    res = CliRunner().invoke(main, [str(a) for a in args], input=input)
    assert res.exit_code == code, res.output
    return json.loads(res.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("json")
    (d / "mixed.nc").write_text(MIXED)
    (d / "corner.nc").write_text(CORNER)
    (d / "bad.nc").write_text("G1 X1 F600\nG1 Q\n")
    (d / "rest.nc").write_text("G10 L2 P1 X5\nG4 P0.5\n")  # no motion
    (d / "rotary.nc").write_text(ROTARY)
    return d


def rotary_printed(*args) -> dict:
    """The JSON of ``args`` (a ``plan``, ``run`` or ``simulate`` command) on a machine with
    an A axis (60°/s)."""
    axis = ("v_max_deg_min=3600", "a_max_deg_s2=400", "j_max_deg_s3=4000")
    sets = [w for key in axis for w in ("--set", f"axis_limits.a.{key}")]
    return printed(*args, *sets, "--json")


def keys_of(command: str, outputs) -> set:
    wild = {k for k in doc_keys(command) if k.endswith(".*")}
    return set().union(*(flatten(o, wild) for o in outputs))


def check(command: str, outputs, skip: str | None = None) -> None:
    """Printed keys == documented keys (those starting with ``skip`` left out: documented
    for another command of the section)."""
    got, documented = keys_of(command, outputs), doc_keys(command)
    if skip:
        documented = {k for k in documented if not k.startswith(skip)}
    assert got - documented == set(), f"{command}: printed but not in docs/json.md"
    assert documented - got == set(), f"{command}: in docs/json.md but never printed"


def test_check(files):
    check(
        "check", [printed("check", NACA, "--json"), printed("check", files / "mixed.nc", "--json")]
    )


def test_corners_and_ph():
    check("corners", [printed("corners", NACA, "--json")])
    check("ph", [printed("ph", NACA, "--json")])


def test_plan_and_run(files, tmp_path):
    from nurbscnc.plan.corners import CornerLog

    outputs = [
        printed("plan", NACA, "--json", "--explain"),
        printed("plan", NACA, "--json", "--algorithm", "adaptive"),
        printed("plan", SPIRAL, "--json", "--dynamics", "off"),  # smoothed (the default)
        printed("plan", files / "rest.nc", "--json"),
        rotary_printed("plan", files / "rotary.nc"),
    ]
    explained = printed("plan", files / "corner.nc", "--json", "--explain")
    if not explained["explain"]["corners"]:
        # The planner does not log its corners yet: the keys of one logged corner, as printed.
        from nurbscnc.app.planning import make_plan
        from nurbscnc.plan.explain import explain_plan

        prog, mach, run = make_plan(str(files / "corner.nc"))
        log = CornerLog(
            np.array([2]),
            np.zeros((1, 3)),
            np.array([np.pi / 2]),
            np.array([2], dtype=np.int8),
            np.array([2], dtype=np.int8),
        )
        expl = dataclasses.replace(explain_plan(prog, mach, run.plan), corners=log)
        explained["explain"].update(corners=expl.corner_dicts(), corner_counts=expl.corner_counts())
    check("plan", [*outputs, explained, rotary_plan_json(explain=True)])
    runs = [
        rotary_plan_json(explain=False),
        printed("run", NACA, "-o", tmp_path / "p.csv", "--json"),
        printed("run", NACA, "-o", tmp_path / "b.csv", "--json", "--algorithm", "adaptive"),
        printed("run", files / "mixed.nc", "-o", tmp_path / "m.csv", "--json"),
        printed("run", SPIRAL, "-o", tmp_path / "s.csv", "--json", "--dynamics", "off"),
        printed("run", files / "rest.nc", "-o", tmp_path / "r.csv", "--json"),
        rotary_printed("run", files / "rotary.nc", "-o", tmp_path / "a.csv"),
    ]
    check("run", runs, skip="explain")  # --explain is plan's


def rotary_plan_json(explain: bool) -> dict:
    """The JSON of a plan that turns A (the interpreter reads A words in a later layer: the
    program is built as it makes them), summary and explanation as ``plan --json`` prints."""
    from nurbscnc.app.summary import summary_json, summary_of
    from nurbscnc.geometry.segments import Line, Program, Rotate
    from nurbscnc.machine.model import RotaryAxis
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.pipeline import run_program
    from nurbscnc.plan.explain import explain_plan

    mach = dataclasses.replace(
        load_machine(), rotary_axes={"a": RotaryAxis("a", 60.0, 400.0, 4000.0)}
    )
    prog = Program(
        segments=(
            Line((0.0, 0.0, 0.0), (10.0, 0.0, 0.0), 20.0, 1, abc_deg=(0.0, 0, 0, 300.0, 0, 0)),
            Rotate((10.0, 0.0, 0.0), (300.0, 0.0, 0.0), (0.0, 0.0, 0.0), 30.0, 2),
        ),
        start_mm=(0.0, 0.0, 0.0),
        rotary_axes=("a",),
    )
    run = run_program(prog, mach)
    summary = summary_of(prog, mach, run)
    if explain:
        summary["explain"] = explain_plan(prog, mach, run.plan).as_dict()
    return json.loads(summary_json(summary))


def test_run_batch(files, tmp_path):
    # --jobs 1: the batch in this process (no fork of the test process, whose threads
    # from earlier tests can hold locks a forked worker would wait on)
    out = printed(
        "run",
        files / "mixed.nc",
        files / "bad.nc",
        "--output-dir",
        tmp_path,
        "--json",
        "--jobs",
        "1",
        code=2,
    )
    check("run --output-dir", [out])


def test_simulate_and_compare(files, tmp_path):
    points = tmp_path / "p.csv"
    assert (
        CliRunner().invoke(main, ["run", str(files / "mixed.nc"), "-o", str(points)]).exit_code == 0
    )
    from nurbscnc.output.files import write_points
    from tests.test_rotary_outputs import samples

    turned = tmp_path / "a.csv"  # reference points with an A column
    write_points(str(turned), samples(("a",)))
    check(
        "simulate",
        [
            printed("simulate", points, "--json"),
            printed("simulate", files / "mixed.nc", "--json"),
            rotary_printed("simulate", turned),
        ],
    )
    check("compare", [printed("compare", NACA, "--json", "--algorithm", "ours")])


def test_profile_show():
    check("profile show", [printed("profile", "show", "--json")])


def test_identify(tmp_path):
    from scipy import signal

    n = 3000
    u = np.zeros(n)
    u[100:] = 1.0
    u[1500:] = -0.5
    wn = 2 * np.pi * 30.0
    _, y, _ = signal.lsim(([wn * wn], [1.0, 1.4 * wn, wn * wn]), u, np.arange(n) * 1e-3)
    trace = tmp_path / "trace.txt"
    trace.write_text("\n".join(f"{a:.9f} {b:.9f}" for a, b in zip(u, y)) + "\n")
    check("identify", [printed("identify", trace, "--period-ms", "1", "--order", "2", "--json")])


def test_errors_program_file_and_option(files):
    outputs = [
        printed("check", files / "bad.nc", "--json", code=2),
        printed("plan", files / "missing.nc", "--json", code=3),
        printed("plan", files / "corner.nc", "--json", "--bogus", code=2),
        printed("plan", files / "corner.nc", "--json", "--dynamics", "x", code=2),
        printed("plan", "--json", code=2),
    ]
    check("error", outputs)
    assert outputs[0]["errors"][0]["line"] == 2 and outputs[0]["errors"][0]["column"] >= 1
    assert "--bogus" in outputs[2]["errors"][0]["message"]


#: Keys of the stream controller's job report (feed hold, override, sections), documented
#: with the stream's.
JOB_KEYS = {
    "final_position_mm",
    "final_abc_deg",
    "coordinate_system",
    "final_work_position_mm",
    "sections",
    "feed_override",
    "holds",
    "holds[].latency_s",
    "holds[].stop_s",
    "holds[].stopped_at_mm",
    "notes",
    "notes[].line",
    "notes[].message",
}


def test_stream_report_keys_are_documented():
    from nurbscnc.output.stream.linkstate import StreamReport

    fields = {f.name for f in dataclasses.fields(StreamReport)} | {"ok", "program"}
    assert fields <= doc_keys("stream")
    assert doc_keys("stream") - fields <= JOB_KEYS


def test_limits_table_lists_every_limit():
    from nurbscnc.plan.explain import LIMIT_OF_KEY

    text = DOC.read_text(encoding="utf-8")
    table = text[text.index("### Limits") :].split("\n## ")[0]
    assert set(re.findall(r"^\| `([^`]+)` \|", table, flags=re.M)) == set(LIMIT_OF_KEY)
