"""Start-up: each command imports only the modules it needs (issue 14).

Structural, not timed (the times are in bench/startup_bench.py): every case runs in a fresh
interpreter (``python -c``), calls the CLI in-process there, and reports ``sys.modules``
after it, so a module counts as imported when any import of the run loaded it. The heavy
modules are numpy, scipy, rich, lark, matplotlib and pyserial; ``--help``, shell completion
and importing the CLI need none of them (click only), ``check`` never needs the servo model's
scipy.signal or matplotlib, ``run`` without ``--plot`` never needs matplotlib.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NACA = ROOT / "programs" / "naca2415.nc"

#: Top-level packages no help text, completion or import of the CLI may load.
HEAVY = ("numpy", "scipy", "rich", "lark", "matplotlib", "serial")

#: A program of lines and an arc (no NURBS): ~6 s of motion.
TINY = "G21 G90 G17\nG0 X0 Y0 Z0\nG1 X10 Y0 F600\nG2 X20 Y0 I5 J0\nG1 X20 Y10\nG1 X0 Y0\nM2\n"

# Run in the child: for each argument list, call the CLI (click's standalone mode, as the
# console script does) and record the exit code and the modules loaded so far. The report
# goes to a file (stdout belongs to the commands).
_CHILD = """
import json, sys
report, runs = sys.argv[1], json.loads(sys.argv[2])
rows = []
if runs is None:  # only import the CLI
    import nurbscnc.cli.main
    rows.append({"code": None, "modules": sorted(sys.modules)})
else:
    from nurbscnc.cli.main import main
    for args in runs:
        try:
            main(args, prog_name="nurbscnc")
            code = 0
        except SystemExit as exc:
            code = exc.code
        rows.append({"args": args, "code": code, "modules": sorted(sys.modules)})
with open(report, "w") as fh:
    json.dump(rows, fh)
"""


def loaded(tmp_path, runs, env=None) -> list[dict]:
    """One fresh interpreter runs the CLI with each argument list of ``runs`` in turn (None:
    only imports the CLI); per run, its exit code and the set of modules then loaded."""
    report = tmp_path / "modules.json"
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, str(report), json.dumps(runs)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, **(env or {})},
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    rows = json.loads(report.read_text())
    for row in rows:
        row["modules"] = set(row["modules"])
    return rows


def heavy_in(modules: set[str]) -> list[str]:
    """The heavy packages among ``modules`` (a package counts when any submodule of it is in)."""
    return sorted({m.split(".")[0] for m in modules} & set(HEAVY))


def test_importing_the_cli_loads_no_heavy_module(tmp_path):
    (row,) = loaded(tmp_path, None)
    assert "click" in row["modules"]  # the probe sees what was imported
    assert heavy_in(row["modules"]) == []


def test_help_of_the_group_and_of_every_command_loads_no_heavy_module(tmp_path):
    from nurbscnc.cli.main import main

    names = main.list_commands(None)
    assert {"check", "plan", "run", "simulate", "stream", "profile", "identify"} <= set(names)
    runs = [["--help"], ["--version"]] + [[name, "--help"] for name in names]
    rows = loaded(tmp_path, runs)
    assert [r["code"] for r in rows] == [0] * len(runs)
    # Modules accumulate from one run to the next: the first run that loads one is named.
    for row in rows:
        assert heavy_in(row["modules"]) == [], row["args"]


@pytest.mark.parametrize("words", ["nurbscnc ch", "nurbscnc run --dyn", "nurbscnc run --dynamics "])
def test_shell_completion_loads_no_heavy_module(tmp_path, words):
    # What bash sends on TAB: the words so far and the index of the one being completed.
    env = {
        "_NURBSCNC_COMPLETE": "bash_complete",
        "COMP_WORDS": words,
        "COMP_CWORD": str(len(words.split(" ")) - 1),
    }
    (row,) = loaded(tmp_path, [[]], env)
    assert row["code"] == 0
    assert heavy_in(row["modules"]) == []


@pytest.mark.parametrize("program", ["tiny", "naca"])
def test_check_loads_neither_the_servo_nor_matplotlib(tmp_path, program):
    path = NACA if program == "naca" else tmp_path / "tiny.nc"
    if program == "tiny":
        path.write_text(TINY)
    (row,) = loaded(tmp_path, [["check", str(path)]])
    assert row["code"] == 0
    mods = row["modules"]
    assert "nurbscnc.program.interpret" in mods  # it did parse
    assert not {m for m in mods if m.startswith(("scipy.signal", "nurbscnc.servo"))}
    assert not {m for m in mods if m.split(".")[0] in ("matplotlib", "serial")}


def test_plan_of_plain_words_loads_neither_lark_nor_the_other_commands(tmp_path):
    # Plain words (the fast path's lines: most CAM output) need no lark parser; a line with a
    # parameter or an expression builds it. Only the command that runs is imported.
    (tmp_path / "tiny.nc").write_text(TINY)
    (tmp_path / "expr.nc").write_text(TINY.replace("G1 X20 Y10", "#1=[5*2]\nG1 X20 Y#1"))
    plain, expr = loaded(tmp_path, [["plan", "tiny.nc", "--json"], ["plan", "expr.nc", "--json"]])
    assert plain["code"] == 0 and "nurbscnc.pipeline" in plain["modules"]  # it did plan
    assert "lark" not in plain["modules"]
    assert not {"nurbscnc.cli.stream", "nurbscnc.cli.card", "nurbscnc.cli.run"} & plain["modules"]
    assert not {"nurbscnc.output.files", "importlib.resources"} & plain["modules"]
    assert expr["code"] == 0 and "lark" in expr["modules"]


def test_plan_loads_no_numpy_ma(tmp_path):
    # np.unique's first call without indices imports numpy.ma (10 ms) to ask whether its
    # input is masked; the planner's distinct values come from geometry/distinct.py instead.
    # A polyline the smoothing fits, a NURBS program with the check, and one without it.
    poly = "G21 G90 G64 P0.01 F600\nG0 X0 Y0\nG1 Z-0.1\n" + "".join(
        f"G1 X{k * 0.2:.2f} Y{(k % 7) * 0.05:.2f}\n" for k in range(1, 80)
    )
    (tmp_path / "poly.nc").write_text(poly + "M2\n")
    runs = [["plan", "poly.nc", "--json"], ["plan", str(NACA), "--json"]]
    runs.append(["plan", str(NACA), "--json", "--dynamics", "off"])
    rows = loaded(tmp_path, runs)
    assert [r["code"] for r in rows] == [0, 0, 0]
    assert "nurbscnc.plan.smoothing" in rows[0]["modules"]  # it did smooth
    assert "numpy" in rows[-1]["modules"] and "numpy.ma" not in rows[-1]["modules"]


def test_run_without_plots_loads_no_matplotlib(tmp_path):
    (tmp_path / "tiny.nc").write_text(TINY)
    (row,) = loaded(tmp_path, [["run", "tiny.nc", "-o", "points.csv", "--quiet"]])
    assert row["code"] == 0 and (tmp_path / "points.csv").stat().st_size > 0
    assert "nurbscnc.pipeline" in row["modules"]  # it did plan
    assert not {m for m in row["modules"] if m.split(".")[0] in ("matplotlib", "serial")}


def test_run_without_the_servo_check_loads_no_scipy_signal(tmp_path):
    # --dynamics off: no contour check, so no servo simulation and no filter design.
    (tmp_path / "tiny.nc").write_text(TINY)
    (row,) = loaded(
        tmp_path, [["run", "tiny.nc", "-o", "points.csv", "--quiet", "--dynamics", "off"]]
    )
    assert row["code"] == 0 and (tmp_path / "points.csv").stat().st_size > 0
    assert not {m for m in row["modules"] if m.startswith("scipy.signal")}


@pytest.mark.parametrize("program", ["tiny", "naca"])
def test_run_with_the_servo_check_loads_no_scipy_signal(tmp_path, program):
    # The dynamics check simulates the servo (nurbscnc.servo.model) with scipy's compiled
    # IIR loop alone (the extension module scipy.signal._sigtools, loaded by itself): not
    # scipy.signal's package nor what it pulls in (scipy.stats).
    path = NACA if program == "naca" else tmp_path / "tiny.nc"
    if program == "tiny":
        path.write_text(TINY)
    (row,) = loaded(tmp_path, [["run", str(path), "-o", "points.csv", "--quiet"]])
    assert row["code"] == 0 and (tmp_path / "points.csv").stat().st_size > 0
    assert "nurbscnc.servo.model" in row["modules"]  # it did simulate the servo
    mods = row["modules"] - {"scipy.signal._sigtools", "scipy.optimize._zeros"}
    assert not {m for m in mods if m.startswith(("scipy.signal", "scipy.stats"))}
    # NURBS corners are found with scipy's compiled Brent loop alone (scipy.optimize._zeros),
    # not scipy.optimize's package (0.4–0.8 s of CPU).
    assert not {m for m in mods if m.startswith("scipy.optimize")}
    if program == "naca":
        assert "scipy.optimize._zeros" in row["modules"]  # it did search for corners


def test_a_console_kept_before_its_first_use_is_the_console(tmp_path):
    # `from nurbscnc.cli.console import err` before anything printed keeps the stand-in; every
    # use of it must reach the one rich Console the module then holds.
    code = """
import io, sys
import nurbscnc.cli.main
import nurbscnc.cli.console as m
kept = m.err
assert "rich" not in sys.modules
kept.file = io.StringIO()  # set through the stand-in (rich's Live does this)
with kept:
    kept.print("hello [b]x[/b]")
real = m.err
assert type(real).__mro__[1].__module__ == "rich.console", type(real).__mro__
assert real is not kept and real.file is kept.file
assert real.file.getvalue() == "hello [b]x[/b]\\n", repr(real.file.getvalue())
"""
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=120
    )
    assert done.returncode == 0, done.stderr


def test_the_benchmark_reads_importtime_output_by_hand_computed_sums():
    # bench/startup_bench.py's reader on a made-up -X importtime listing (post-order, two
    # spaces per level). scipy.signal is imported inside scipy.optimize and on its own; numpy
    # inside scipy.signal counts for numpy and, as part of it, for scipy.signal and scipy.
    sys.path.insert(0, str(ROOT / "bench"))
    from startup_bench import parse_importtime

    text = "\n".join(
        [
            "import time: self [us] | cumulative | imported package",
            "import time:       100 |        100 | click",
            "import time:       300 |        300 |       numpy",
            "import time:       200 |        500 |     scipy.signal._x",
            "import time:        50 |        550 |   scipy.signal",
            "import time:        40 |        590 | scipy.optimize",
            "import time:        10 |         10 |   scipy.signal.windows",
            "import time:         5 |         15 | nurbscnc.servo.model",
            "some output of the command",
        ]
    )
    r = parse_importtime(text)
    assert r["imports_ms"] == pytest.approx((100 + 590 + 15) / 1000)
    heavy = r["heavy_imports_ms"]
    assert heavy["numpy"] == pytest.approx(0.3)
    assert heavy["scipy.signal"] == pytest.approx((550 + 10) / 1000)  # two outermost entries
    assert heavy["scipy"] == pytest.approx((590 + 10) / 1000)
    assert heavy["nurbscnc.servo.model"] == pytest.approx(0.015)
    assert heavy["rich"] is None and heavy["matplotlib"] is None
    assert set(r["imported"]) == {"numpy", "scipy", "scipy.signal", "nurbscnc.servo.model"}
