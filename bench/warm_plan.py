"""Compile time of programs inside an already-started process (bench/compile_bench.py's second
figure): what a CAM engineer compiling many files meets when the planner stays resident.

    .venv/bin/python bench/warm_plan.py --dynamics off PROGRAM [PROGRAM ...]

One process: Python starts, tunes itself as every command does
(:func:`nurbscnc.app.runtime.tune_process`: one BLAS thread, malloc's reuse of freed memory),
imports the ``plan`` command's modules (the CLI's command and the
pipeline it calls), plans :data:`WARMUP_PROGRAM` (lines, an arc, a run of short G1 moves the
smoothing fits: the modules a plan imports on first use, scipy's compiled kernels), then plans
each PROGRAM once, in the given order, timing each with ``time.process_time`` (CPU seconds of
this process). Each plan goes through what ``nurbscnc plan PROGRAM --json`` runs: the option
values click parses from that command line, :func:`nurbscnc.app.planning.make_plan` (read,
interpret, plan, check), :func:`nurbscnc.app.summary.summary_of` and
:func:`~nurbscnc.app.summary.summary_json` (the JSON text the command prints). Garbage is
collected between programs, outside the timed span.

No program is planned twice in one process: the planner's bounded memo of jerk-limited
flanks (``plan/gated.py``) lives as long as the process, as it would in a resident planner,
so a second plan of one program would meet its own flanks. The caller runs one process per
repeat and per ``--dynamics`` value.

Prints one JSON object: ``python_cpu_s`` (the process's CPU time when this file starts:
the interpreter's own start), ``imports_cpu_s`` (the ``plan`` command's imports, numpy's
included), ``warmup_cpu_s``, and per program ``cpu_s``, ``motion_s`` (the summary's
``cycle_time_s``) and ``json_chars``.
"""

from __future__ import annotations

import sys
import time

T_START = time.process_time()

import argparse  # noqa: E402
import gc  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

#: The warm-up: lines, an arc, a rapid, and 60 short G1 moves on a circle (smoothed).
WARMUP_PROGRAM = (
    "\n".join(
        ["G21 G17 G90 G94", "G0 X0 Y0 Z1", "G1 Z0 F600", "G1 X10 F1200", "G2 X20 Y0 I5 J0"]
        + [
            f"G1 X{20 + 5 * math.sin(k / 20):.4f} Y{5 - 5 * math.cos(k / 20):.4f}"
            for k in range(1, 61)
        ]
        + ["G0 Z5", "G0 X0 Y0", "M2"]
    )
    + "\n"
)


def plan_once(command, program: str, dynamics: str) -> tuple[dict, str]:
    """``nurbscnc plan PROGRAM --json --dynamics DYNAMICS`` without the process: the option
    values click parses from that command line, then the ``plan`` command's app calls."""
    from nurbscnc.app.planning import make_plan
    from nurbscnc.app.summary import summary_json, summary_of

    ctx = command.make_context("plan", [program, "--json", "--dynamics", dynamics])
    settings = dict(ctx.params)
    settings.pop("program")
    for key in ("as_json", "dump_profile", "explain", "explain_all", "plot_dir"):
        settings.pop(key, None)
    prog, mach, run = make_plan(program, **settings, text=None, progress=None)
    summary = summary_of(prog, mach, run)
    return summary, summary_json(summary)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dynamics", default="local", choices=("local", "off"))
    parser.add_argument("programs", nargs="+")
    args = parser.parse_args(argv)
    t_python = T_START
    t0 = time.process_time()
    # What every command does first (cli/main.py): one BLAS thread, the allocator's reuse of
    # freed memory; set before numpy is imported, which reads the BLAS setting then.
    from nurbscnc.app.runtime import tune_process

    tune_process()
    import nurbscnc.pipeline  # noqa: F401  (what make_plan imports on its first call)
    from nurbscnc.cli.plan import plan as command

    t_imports = time.process_time() - t0
    with tempfile.TemporaryDirectory() as tmp:
        warm = Path(tmp) / "warmup.nc"
        warm.write_text(WARMUP_PROGRAM)
        t0 = time.process_time()
        plan_once(command, str(warm), args.dynamics)
        t_warm = time.process_time() - t0
    rows = {}
    for program in args.programs:
        gc.collect()
        t0 = time.process_time()
        summary, text = plan_once(command, program, args.dynamics)
        cpu_s = time.process_time() - t0
        rows[program] = {
            "cpu_s": cpu_s,
            "motion_s": summary.get("cycle_time_s"),
            "json_chars": len(text),
        }
    print(
        json.dumps(
            {
                "python_cpu_s": t_python,
                "imports_cpu_s": t_imports,
                "warmup_cpu_s": t_warm,
                "dynamics": args.dynamics,
                "rows": rows,
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
