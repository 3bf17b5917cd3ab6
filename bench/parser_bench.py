"""Parse + interpret throughput on a long CAM program (issue 14: "≥ 200k lines/s").

Usage::

    .venv/bin/python bench/parser_bench.py --out bench/parser_results.json [--lines 200000]

The program is a CAM-style G1 spiral finishing pass (every line numbered, modal ``X Y``
moves, a feed change every 250 moves, a comment every 1000 lines), written to a temporary
file. Measured, best of three (a busy machine shows its quiet speed):

- ``interpret``: the call ``interpret_text(text)`` (text in memory, grammar built), with the
  fast lane (program/fastlane.py) and without it (``InterpretOptions(fast_lane=False)``);
- ``check``: the whole command ``nurbscnc check FILE`` in a fresh process (start-up, reading,
  interpretation, the geometry checks and the summary);
- ``rs274``: LinuxCNC's ``rs274 -g FILE`` (the speed anchor), when it is installed.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from nurbscnc.program.interpret import InterpretOptions, interpret_text  # noqa: E402


def spiral_lines(n_lines: int):
    """A CAM-style Archimedean spiral of exactly ``n_lines`` lines (module doc)."""
    header = ["%", "(parser benchmark: CAM-style spiral, G1)", "G21 G17 G90 G94", "G64 P0.01",
              "G0 Z5", "G0 X2 Y0", "G1 Z0 F300"]  # fmt: skip
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


def best_of(fn, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    ap.add_argument("--lines", type=int, default=200_000)
    args = ap.parse_args(argv)
    n = args.lines
    text = "\n".join(spiral_lines(n)) + "\n"
    interpret_text("G1 X1 F100\n")  # build the grammar outside the timing
    cases = {}
    for label, options in (("interpret_fast_lane", InterpretOptions()),
                           ("interpret_line_by_line", InterpretOptions(fast_lane=False))):
        seconds = best_of(lambda o=options: interpret_text(text, o))
        cases[label] = {"seconds": seconds, "lines_per_s": n / seconds}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "spiral.ngc"
        path.write_text(text)
        exe = Path(sys.executable).with_name("nurbscnc")
        check = [str(exe), "check", str(path)]
        seconds = best_of(lambda: subprocess.run(check, check=True, capture_output=True))
        cases["check_command"] = {"seconds": seconds, "lines_per_s": n / seconds}
        rs274 = shutil.which("rs274")
        if rs274:
            cmd = [rs274, "-g", str(path)]
            seconds = best_of(lambda: subprocess.run(cmd, capture_output=True, cwd=tmp))
            cases["linuxcnc_rs274_g"] = {"seconds": seconds, "lines_per_s": n / seconds}
    for label, case in cases.items():
        print(f"{label:24s} {case['seconds']:7.3f} s  {case['lines_per_s']:>10,.0f} lines/s")
    result = {
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "machine": platform.platform(),
        "cpus": os.cpu_count(),
        "load_average": os.getloadavg(),
        "program": f"CAM-style G1 spiral, {n} lines",
        "cases": cases,
    }
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
