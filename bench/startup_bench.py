"""Start-up benchmark: wall time of short commands, and what each one imports.

Usage::

    .venv/bin/python bench/startup_bench.py --out bench/startup_results.json
    .venv/bin/python bench/startup_bench.py --quick          # 3 runs per command

Each command runs as a new process through the console script (``.venv/bin/nurbscnc``, what a
user types), so the figure is the whole process: interpreter start, imports, work, exit. The
commands: ``nurbscnc --help``, ``nurbscnc check --help``, shell completion of a command name
(click's ``_NURBSCNC_COMPLETE=bash_complete``), ``check`` and ``run -o /dev/null`` of a tiny
program (a few lines and an arc, written to a temporary folder; ~6 s of motion), ``run`` once
more with ``--dynamics off`` (no servo check). The wall time
is the median of ``--repeat`` runs (min and max recorded too), with the median CPU time (user +
system) beside it: the machine is shared, so the load average goes into the file with the
numbers, and the CPU time is the figure the load disturbs least.

Then every command runs once more under ``python -X importtime``: the file records the total
import time and, for each heavy module (numpy, scipy, scipy.signal, rich, lark, matplotlib,
serial), whether the command imported it and what the import cost (cumulative, µs → ms).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine_info import run_info, use_bytecode  # noqa: E402

#: The modules whose import a command should pay only when it needs them.
HEAVY = (
    "numpy",
    "scipy",
    "scipy.signal",
    "rich",
    "lark",
    "matplotlib",
    "serial",
    "nurbscnc.servo.model",
    "nurbscnc.pipeline",
)

#: A program with lines and an arc: ~6 s of motion, a few thousand reference points.
TINY_PROGRAM = """G21 G90 G17
G0 X0 Y0 Z0
G1 X10 Y0 F600
G2 X20 Y0 I5 J0
G1 X20 Y10
G1 X0 Y0
M2
"""

#: The completion request a shell sends for ``nurbscnc ch<TAB>``.
COMPLETE_ENV = {
    "_NURBSCNC_COMPLETE": "bash_complete",
    "COMP_WORDS": "nurbscnc ch",
    "COMP_CWORD": "1",
}


def commands(tiny: str) -> dict[str, tuple[list[str], dict]]:
    """name → (arguments after ``nurbscnc``, extra environment)."""
    return {
        "--help": (["--help"], {}),
        "check --help": (["check", "--help"], {}),
        "completion": ([], COMPLETE_ENV),
        "check tiny.nc": (["check", tiny], {}),
        "run tiny.nc -o /dev/null": (["run", tiny, "-o", os.devnull, "--quiet"], {}),
        # without the servo check (no contour error prediction): no scipy.signal to import
        "run tiny.nc -o /dev/null --dynamics off": (
            ["run", tiny, "-o", os.devnull, "--quiet", "--dynamics", "off"],
            {},
        ),
    }


def console_script() -> Path:
    """The ``nurbscnc`` script next to this interpreter (the venv's), as a user runs it."""
    script = Path(sys.executable).parent / "nurbscnc"
    if not script.exists():
        raise SystemExit(f"no console script at {script}: run `make install` first")
    return script


def _children_cpu_s() -> float:
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime


def timed_runs_s(argv: list[str], env: dict, repeat: int) -> tuple[list[float], list[float]]:
    """Wall times and CPU times (user + system) [s] of ``repeat`` runs of ``argv`` (each
    must exit 0). On a loaded machine the CPU time is the steadier figure: the wall time
    adds the time the process waited for a core."""
    walls, cpus = [], []
    for _ in range(repeat):
        cpu0, start = _children_cpu_s(), time.perf_counter()
        done = subprocess.run(argv, env=env, capture_output=True)
        walls.append(time.perf_counter() - start)
        cpus.append(_children_cpu_s() - cpu0)
        if done.returncode != 0:
            raise SystemExit(f"{argv} exited {done.returncode}: {done.stderr.decode()[-500:]}")
    return walls, cpus


def _belongs(name: str, module: str) -> bool:
    return name == module or name.startswith(module + ".")


def parse_importtime(text: str) -> dict:
    """``-X importtime`` output → total import time [ms] (the top-level imports' cumulative
    times) and, per heavy module, what importing it and its submodules cost [ms]: the
    cumulative times of its outermost entries (an entry inside another of the same module is
    counted in that one); None when the process never imported it.

    The output is in post-order (a module's line follows its imports' lines, indented two
    spaces per level), so read backwards each line's parent is the nearest shallower line."""
    entries = []
    for line in text.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        _, cumulative, name = line[len("import time:") :].split("|")
        depth = (len(name) - len(name.lstrip(" ")) - 1) // 2  # one space follows the bar
        entries.append((depth, int(cumulative), name.strip()))
    total_us = sum(us for depth, us, _ in entries if depth == 0)
    cost_us: dict[str, int | None] = dict.fromkeys(HEAVY)
    stack: list[tuple[int, str]] = []  # (depth, name) of the current line's ancestors
    for depth, us, name in reversed(entries):
        while stack and stack[-1][0] >= depth:
            stack.pop()
        for module in HEAVY:
            inside = any(_belongs(ancestor, module) for _, ancestor in stack)
            if _belongs(name, module) and not inside:
                cost_us[module] = (cost_us[module] or 0) + us
        stack.append((depth, name))
    heavy = {m: None if us is None else round(us / 1000.0, 3) for m, us in cost_us.items()}
    return {
        "imports_ms": round(total_us / 1000.0, 3),
        "heavy_imports_ms": heavy,
        "imported": [m for m, t in heavy.items() if t is not None],
    }


def import_profile(argv: list[str], env: dict) -> dict:
    """One run of ``argv`` (a Python script and its arguments) under ``-X importtime``:
    :func:`parse_importtime` of what it printed."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", *argv], env=env, capture_output=True, text=True
    )
    return parse_importtime(done.stderr)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "startup_results.json")
    ap.add_argument("--quick", action="store_true", help="3 runs per command")
    ap.add_argument("--repeat", type=int, default=None, help="runs per command (default 7)")
    args = ap.parse_args()
    use_bytecode()  # the children start as a user's installed nurbscnc does
    repeat = args.repeat or (3 if args.quick else 7)
    script = console_script()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        tiny = os.path.join(tmp, "tiny.nc")
        Path(tiny).write_text(TINY_PROGRAM)
        load_before = os.getloadavg()
        for name, (rest, extra) in commands(tiny).items():
            env = {**os.environ, **extra, "NO_COLOR": "1"}
            argv = [str(script), *rest]
            times, cpus = timed_runs_s(argv, env, repeat)
            row = {
                "median_s": round(statistics.median(times), 4),
                "min_s": round(min(times), 4),
                "max_s": round(max(times), 4),
                "cpu_median_s": round(statistics.median(cpus), 4),
                "runs": repeat,
                **import_profile(argv, env),
            }
            results[name] = row
            print(
                f"{name:40s} wall median {row['median_s']:.3f} s (min {row['min_s']:.3f}), "
                f"CPU {row['cpu_median_s']:.3f} s, imports {row['imports_ms']:.0f} ms: "
                f"{', '.join(row['imported']) or '-'}"
            )
    info = run_info()
    info["machine"]["load_average_before_1_5_15"] = list(load_before)
    doc = {
        **info,
        "goal_s": {"--help": 0.3, "check --help": 0.3, "completion": 0.3},
        "commands": results,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"load average {info['machine']['load_average_1_5_15']}; wrote {args.out}")


if __name__ == "__main__":
    main()
