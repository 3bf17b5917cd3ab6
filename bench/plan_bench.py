"""Plan + run benchmark on long CAM-style G1 programs (issue 7).

    .venv/bin/python bench/plan_bench.py --out bench/plan_results.json   # 1,000,000 lines
    .venv/bin/python bench/plan_bench.py --quick                          # 100,000 lines

The program is an Archimedean spiral finishing pass written as a CAM system writes it: one
``G1`` move per line at a 0.05 mm chord, coordinates rounded to 0.1 µm (4 decimals), every
line numbered, a feed change every 250 moves (F1200/1800/2400), a comment every 1000 lines,
under ``G64 P0.01``. Why G64 P: without a blend tolerance every vertex of the polyline is an
exact stop (G61, RS274/NGC's default for a tangent discontinuity), so the tool would stop
1,000,000 times; 0.01 mm is a usual finishing tolerance, and with ~1e-3 rad of turning per
vertex every blend stays far inside it (the trims reach half the chord first).

Each case runs in a fresh subprocess (so the resident-set peak is its own) through the
stages of ``nurbscnc run``, timed one by one: interpretation of the text (already in memory),
``plan_program`` (pieces, blends, look-ahead profile, interpolation to reference points,
dynamics check), and writing the reference points to a temporary ``.npz`` (deleted after).
Recorded: seconds per stage (wall; ``cpu_s`` the CPU time, to see whether the run had the
machine to itself), lines per second for the plan (lines / plan seconds) and for
the whole run (lines / (interpret + plan + write) seconds), reference points per second of
the run, the pieces, samples and cycle time, the dynamics iterations, and the peak RSS
(``ru_maxrss`` of the child) and VmHWM. ``--dynamics`` selects the check (default local,
as ``run``); the dynamics-off time of the plan is measured in a second subprocess.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cam_spiral(n_lines: int, blend_mm: float = 0.01):
    """A CAM-style spiral finishing pass of exactly ``n_lines`` lines (module doc)."""
    header = [
        "%",
        "(nurbscnc plan benchmark: CAM-style spiral, G1)",
        "G21 G17 G90 G94",
        f"G64 P{blend_mm:g}",
        "G0 Z5",
        "G0 X2 Y0",
        "G1 Z0 F300",
    ]
    footer = ["G0 Z5", "M2", "%"]
    yield from header
    theta = 0.0
    for k in range(n_lines - len(header) - len(footer)):
        line_no = len(header) + k + 1
        if line_no % 1000 == 0:
            yield f"(pass {line_no // 1000}: spiral r = {2 + 0.5 * theta / math.tau:.3f})"
            continue
        r = 2.0 + 0.5 * theta / math.tau
        theta += 0.05 / r
        n = 10 * (k % 9999 + 1)
        words = f"N{n} X{r * math.cos(theta):.4f} Y{r * math.sin(theta):.4f}"
        if k == 0:
            words = f"N{n} G1 X{r * math.cos(theta):.4f} Y{r * math.sin(theta):.4f}"
        if k % 250 == 0:
            words += f" F{1200 + 600 * ((k // 250) % 3)}"
        yield words
    yield from footer


def _vm_hwm_mb() -> float | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1e3
    except OSError:
        pass
    return None


def worker(program: str, dynamics: str) -> dict:
    """One case, in this (fresh) process: interpret, plan, write points; times and memory."""
    import numpy as np

    from nurbscnc.machine.profile import load_machine
    from nurbscnc.output.files import write_points
    from nurbscnc.pipeline import RunOptions, run_program
    from nurbscnc.plan.options import LookaheadOptions
    from nurbscnc.plan.report import plan_summary
    from nurbscnc.program.interpret import interpret_text

    text = Path(program).read_text()
    lines = text.count("\n")
    machine = load_machine()
    c0, t0 = time.process_time(), time.perf_counter()
    prog = interpret_text(text)
    c1, t1 = time.process_time(), time.perf_counter()
    del text
    rss_interp = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3
    run = run_program(prog, machine, RunOptions(lookahead=LookaheadOptions(dynamics=dynamics)))
    plan = run.plan
    c2, t2 = time.process_time(), time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        write_points(os.path.join(tmp, "points.npz"), run.samples)
    c3, t3 = time.process_time(), time.perf_counter()
    plan_summary(prog, machine, run.samples, run.plan, run.check)
    t4 = time.perf_counter()
    smp = run.samples
    samples = int(smp.t_s.size)
    run_s = t3 - t0
    return {
        "lines": lines,
        "segments": len(prog.segments),
        "dynamics": dynamics,
        "pieces": len(plan.pieces),
        "piece_kinds": plan.pieces.kind_counts(),
        "samples": samples,
        "cycle_time_s": plan.cycle_time_s,
        "dynamics_iterations": plan.iterations,
        "feed_median_mm_s": float(np.median(smp.v_mm_s)),
        "interpret_s": t1 - t0,
        "plan_s": t2 - t1,
        "write_s": t3 - t2,
        "summary_s": t4 - t3,
        "run_s": run_s,
        "cpu_s": {"interpret": c1 - c0, "plan": c2 - c1, "write": c3 - c2},
        "plan_lines_per_s": lines / (t2 - t1),
        "run_lines_per_s": lines / run_s,
        "run_samples_per_s": samples / run_s,
        "rss_after_interpret_mb": rss_interp,
        "rss_peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3,
        "vm_hwm_mb": _vm_hwm_mb(),
    }


def run_case(program: Path, dynamics: str) -> dict:
    proc = subprocess.run(
        [sys.executable, __file__, "--worker", str(program), "--dynamics", dynamics],
        capture_output=True,
        text=True,
        check=False,
        cwd=ROOT,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"worker failed ({proc.returncode}):\n{proc.stderr}")
    return json.loads(proc.stdout)


def machine_info() -> dict:
    cpu = None
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "platform": platform.platform(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="100,000 lines instead of 1M")
    parser.add_argument("--lines", type=int, default=None, help="program size (lines)")
    parser.add_argument("--dynamics", default="local", choices=["local", "global", "off"])
    parser.add_argument("--blend", type=float, default=0.01, help="G64 P [mm]")
    parser.add_argument("--out", default=None, help="write the results (JSON) here")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    from machine_info import use_bytecode

    use_bytecode()  # the children start as a user's installed nurbscnc does
    if args.worker:
        print(json.dumps(worker(args.worker, args.dynamics)))
        return 0
    n = args.lines or (100_000 if args.quick else 1_000_000)
    with tempfile.TemporaryDirectory() as tmp:
        program = Path(tmp) / f"spiral_{n}.nc"
        with program.open("w") as fh:
            for line in cam_spiral(n, args.blend):
                fh.write(line + "\n")
        cases = [run_case(program, args.dynamics)]
        if args.dynamics != "off":
            cases.append(run_case(program, "off"))
    report = {
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": machine_info(),
        "program": f"CAM-style G1 spiral, {n} lines, 0.05 mm chord, G64 P{args.blend:g}",
        "measured": "interpret_text + run_program (plan, check, interpolate) + "
        "write_points(.npz) + plan_summary, each timed; fresh subprocess per case",
        "cases": cases,
    }
    for c in cases:
        print(
            f"{c['lines']:>9} lines, dynamics {c['dynamics']}: interpret "
            f"{c['interpret_s']:.2f} s, plan {c['plan_s']:.2f} s, write {c['write_s']:.2f} s, "
            f"summary {c['summary_s']:.2f} s, "
            f"run {c['run_s']:.2f} s | plan {c['plan_lines_per_s']:.0f} lines/s, run "
            f"{c['run_lines_per_s']:.0f} lines/s, {c['run_samples_per_s']:.0f} samples/s | "
            f"{c['pieces']} pieces, {c['samples']} samples, {c['dynamics_iterations']} it | "
            f"peak RSS {c['rss_peak_mb']:.0f} MB"
        )
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
