"""Parse + interpret throughput on a long CAM program (issue 14: "≥ 200k lines/s").

Usage::

    .venv/bin/python bench/parser_bench.py --out bench/parser_results.json [--lines 200000]

The program is a CAM-style G1 spiral finishing pass (every line numbered, modal ``X Y``
moves, a feed change every 250 moves, a comment every 1000 lines), written to a temporary
file. Measured, best of three (a busy machine shows its quiet speed):

- ``interpret``: the call ``interpret_text(text)`` (text in memory, grammar built), with the
  fast lane (program/fastlane.py) and without it (``InterpretOptions(fast_lane=False)``);
- ``check``: the whole command ``nurbscnc check FILE`` in a fresh process (start-up, reading,
  interpretation, the geometry checks and the summary), with its peak memory, on this
  spiral, on the issue's G1 spiral (bench/run.py ``g1_program``) and on the CAM spiral with
  N numbers and G64 blends (bench/plan_bench.py ``cam_spiral``);
- ``rs274``: LinuxCNC's ``rs274 -g FILE`` (the speed anchor) on each, when it is installed.

The machine, load, versions and commit are those of ``bench/machine_info.run_info()``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine_info import run_info  # noqa: E402

from nurbscnc.program.interpret import InterpretOptions, interpret_text  # noqa: E402


def spiral_lines(n_lines: int):
    """A CAM-style Archimedean spiral of exactly ``n_lines`` lines (module doc)."""
    header = [
        "%",
        "(parser benchmark: CAM-style spiral, G1)",
        "G21 G17 G90 G94",
        "G64 P0.01",
        "G0 Z5",
        "G0 X2 Y0",
        "G1 Z0 F300",
    ]
    footer = ["G0 Z5", "M2", "%"]
    yield from header
    theta = 0.0
    for k in range(n_lines - len(header) - len(footer)):
        line_no = len(header) + k + 1
        r = 2.0 + 0.5 * theta / math.tau
        if line_no % 1000 == 0:
            yield f"(pass {line_no // 1000}: spiral r = {r:.3f})"
            continue
        theta += 0.05 / r
        words = f"N{10 * (k % 9999 + 1)} X{r * math.cos(theta):.4f} Y{r * math.sin(theta):.4f}"
        if k == 0:
            words = words.replace(" X", " G1 X", 1)
        if k % 250 == 0:
            words += f" F{1200 + 600 * ((k // 250) % 3)}"
        yield words
    yield from footer


def best_of(fn, repeat: int = 3) -> tuple[float, float]:
    """Best wall and best CPU time [s] of ``repeat`` calls of ``fn`` in this process."""
    walls, cpus = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus)


def run_measured(cmd, cwd=None, env=None) -> tuple[float, float, float]:
    """Wall time [s], CPU time (user + system) [s] and peak resident memory [MB] of one run
    of the command ``cmd``, as ``/usr/bin/time`` reports them. (Not this process's own
    ``wait4``: a child forked from this process, which holds an interpreted 200,000-line
    program, inherits its peak memory across ``exec``.) On a shared machine the wall time
    is the CPU time stretched by the load."""
    with tempfile.NamedTemporaryFile("r", suffix=".time") as report:
        timed = ["/usr/bin/time", "-o", report.name, "-f", "%e %U %S %M", *cmd]
        done = subprocess.run(
            timed, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=cwd, env=env
        )
        if done.returncode != 0:
            raise RuntimeError(f"{cmd} exited with {done.returncode}")
        wall, user, system, rss_kb = report.read().split()[-4:]
    return float(wall), float(user) + float(system), float(rss_kb) / 1024.0


def command_case(cmd, n_lines: int, repeat: int = 3, cwd=None, env=None) -> dict:
    """Best of ``repeat`` runs of a whole command on an ``n_lines`` program: wall time,
    lines/s, and the CPU time and peak memory of that run."""
    wall, cpu, rss = min(run_measured(cmd, cwd, env) for _ in range(repeat))
    return {
        "seconds": wall,
        "lines_per_s": n_lines / wall,
        "cpu_seconds": cpu,
        "lines_per_cpu_s": n_lines / cpu,
        "max_rss_mb": rss,
    }


def programs(n: int):
    """The programs ``check`` is timed on (name, description, lines): this module's spiral,
    the issue's G1 spiral (bench/run.py) and the CAM spiral with N numbers and G64 blends
    (bench/plan_bench.py)."""
    from plan_bench import cam_spiral
    from run import g1_program

    yield "spiral", f"CAM-style G1 spiral, {n} lines (this module)", spiral_lines(n)
    yield "g1_spiral", f"G1 spiral of bench/run.py g1_program, {n} lines", g1_program(n)
    yield "cam_spiral", f"CAM spiral of bench/plan_bench.py cam_spiral, {n} lines", cam_spiral(n)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    ap.add_argument("--lines", type=int, default=200_000)
    args = ap.parse_args(argv)
    n = args.lines
    text = "\n".join(spiral_lines(n)) + "\n"
    interpret_text("G1 X1 F100\n")  # build the grammar outside the timing
    cases = {}
    for label, options in (
        ("interpret_fast_lane", InterpretOptions()),
        ("interpret_line_by_line", InterpretOptions(fast_lane=False)),
    ):
        seconds, cpu = best_of(lambda o=options: interpret_text(text, o))
        cases[label] = {
            "seconds": seconds,
            "lines_per_s": n / seconds,
            "cpu_seconds": cpu,
            "lines_per_cpu_s": n / cpu,
        }
    exe = Path(sys.executable).with_name("nurbscnc")
    rs274 = shutil.which("rs274")
    described = {}
    with tempfile.TemporaryDirectory() as tmp:
        # Bytecode as an installed package has it (pip compiles at install): with
        # PYTHONDONTWRITEBYTECODE (set in some shells) every start would compile the
        # package's sources again (~0.15 s). The cache goes to the temporary folder, and one
        # untimed run of a small program fills it.
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = str(Path(tmp) / "pycache")
        warm = Path(tmp) / "warm.ngc"
        warm.write_text("\n".join(spiral_lines(50)) + "\n")
        run_measured([str(exe), "check", str(warm)], env=env)
        for name, about, lines in programs(n):
            path = Path(tmp) / f"{name}.ngc"
            path.write_text("\n".join(lines) + "\n")
            described[name] = about
            cases[f"check_command_{name}"] = command_case(
                [str(exe), "check", str(path)], n, env=env
            )
            if rs274:
                cases[f"linuxcnc_rs274_g_{name}"] = command_case(
                    [rs274, "-g", str(path)], n, cwd=tmp
                )
    for label, case in cases.items():
        rss = f"  cpu {case['cpu_seconds']:6.3f} s  {case['lines_per_cpu_s']:>10,.0f} lines/cpu-s"
        rss += f"  {case['max_rss_mb']:5.0f} MB" if "max_rss_mb" in case else ""
        print(f"{label:34s} {case['seconds']:7.3f} s  {case['lines_per_s']:>10,.0f} lines/s{rss}")
    result = {
        **run_info(),
        "programs": described,
        "bytecode": "cached, as in an installed package (PYTHONPYCACHEPREFIX in a temporary "
        "folder, filled by one untimed run)",
        "cases": cases,
    }
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
