"""Parse + interpret benchmark: lines per second and peak memory (issue 2, "Benchmark").

Usage::

    .venv/bin/python bench/run.py --out bench/results.json     # full run (make bench)
    .venv/bin/python bench/run.py --quick --out /tmp/quick.json  # 10x smaller smoke test

Generates, in a temporary folder, a CAM-style G1 program (an Archimedean spiral with a slow Z
ramp, N numbers, modal X Y moves, feed changes and a comment every 1000 lines) and a G6.2
program (a few long cubic rational NURBS blocks, ``G6.2 P4 K X Y R`` then ``K X Y R`` lines
and four knot-only ``K`` lines each). Each case is also run at a quarter of its size, to show
that memory grows linearly with the program.

Every case runs in fresh subprocesses, so that the resident-set peak belongs to that case
alone: one run times :func:`nurbscnc.program.interpret.interpret_text` on the text (already
read; the LALR parser is built beforehand on a one-line program) and reads the peak RSS
(``getrusage(...).ru_maxrss``) before and after; a second run measures the peak of Python
allocations during the same call with ``tracemalloc`` (which slows Python down, so it is
not timed). The results (date, machine, versions, per case: lines, seconds, lines_per_s,
peak_mb, RSS) go to ``--out`` as JSON and a short table is printed.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MB = 1e6

#: name -> (generator, lines in the full run). Quarter-size twins show linear memory growth.
FULL_CASES = {
    "g1_1M": ("g1", 1_000_000),
    "g1_250k": ("g1", 250_000),
    "g62_100k": ("g62", 100_000),
    "g62_25k": ("g62", 25_000),
}
QUICK_DIVISOR = 10
#: Pairs (large, quarter) compared for the linearity of memory.
PAIRS = (("g1_1M", "g1_250k"), ("g62_100k", "g62_25k"))


# -- program generators ----------------------------------------------------------------------
# Generators yield the lines one by one and the file is written as they come, so the driver
# process stays small: a child inherits its parent's ru_maxrss across fork + exec on Linux,
# and a large parent would mask the children's own peaks.
def g1_program(n_lines: int):
    """A CAM-style spiral finishing pass of exactly ``n_lines`` lines.

    Archimedean spiral r = 2 + 0.5 θ/(2π) mm at a 0.05 mm chord, Z ramping down 1 µm per move,
    every line numbered (N, wrapping at 99990), modal G1 with X Y (and Z every tenth line),
    a feed change every 250 moves and a comment every 1000 lines.
    """
    header = [
        "%",
        "(nurbscnc benchmark: CAM-style spiral, G1)",
        "G21 G17 G90 G94",
        "G0 Z5",
        "G0 X2 Y0",
        "G1 Z0 F300",
    ]
    footer = ["G0 Z5", "M2", "%"]
    yield from header
    theta, z = 0.0, 0.0
    for k in range(n_lines - len(header) - len(footer)):
        line_no = len(header) + k + 1
        if line_no % 1000 == 0:
            yield f"(pass {line_no // 1000}: spiral r = {2 + 0.5 * theta / math.tau:.3f})"
            continue
        r = 2.0 + 0.5 * theta / math.tau
        theta += 0.05 / r
        z -= 0.001
        n = 10 * (k % 9999 + 1)
        words = f"N{n} X{r * math.cos(theta):.4f} Y{r * math.sin(theta):.4f}"
        if k % 10 == 0:
            words = f"N{n} G1 X{r * math.cos(theta):.4f} Y{r * math.sin(theta):.4f} Z{z:.4f}"
        if k % 250 == 0:
            words += f" F{1200 + 600 * ((k // 250) % 3)}"
        yield words
    yield from footer


def g62_program(n_lines: int, blocks: int = 4):
    """``blocks`` cubic rational NURBS blocks (G6.2 P4), chained, ``n_lines`` lines in all.

    Each block: ``G6.2 P4 K0 X Y R1`` (its first control point is the current position), then
    ``K X Y R`` lines and four knot-only ``K`` lines; clamped uniform knots 0,0,0,0,1,2,…
    Control points follow a wavy spiral; weights vary in [0.8, 1.2].
    """
    header = [
        "%",
        "(nurbscnc benchmark: long G6.2 NURBS blocks)",
        "G21 G17 G90 G94",
        "G0 X5 Y0",
        "F2000",
    ]
    footer = ["M2", "%"]
    body = n_lines - len(header) - len(footer)
    yield from header
    x, y = 5.0, 0.0
    i = 0  # global control point index along the spiral
    for b in range(blocks):
        n_ctrl = body // blocks + (1 if b < body % blocks else 0) - 4
        yield f"G6.2 P4 K0 X{x:.4f} Y{y:.4f} R1"
        for k in range(1, n_ctrl):
            i += 1
            theta = 0.02 * i
            r = 5.0 + 0.02 * theta + 0.3 * math.sin(7.0 * theta)
            x, y = round(r * math.cos(theta), 4), round(r * math.sin(theta), 4)
            weight = 1.0 + 0.2 * math.sin(0.37 * i) if k < n_ctrl - 1 else 1.0
            yield f"K{max(0, k - 3)} X{x:.4f} Y{y:.4f} R{weight:.4f}"
        for _ in range(4):
            yield f"K{n_ctrl - 3}"
    yield from footer


def write_program(path: Path, kind: str, n_lines: int) -> None:
    """Write the ``kind`` program ("g1" or "g62") of ``n_lines`` lines to ``path``."""
    count = 0
    with open(path, "w", encoding="ascii", newline="\n") as fh:
        for line in GENERATORS[kind](n_lines):
            fh.write(line + "\n")
            count += 1
    assert count == n_lines, (kind, count, n_lines)


GENERATORS = {"g1": g1_program, "g62": g62_program}


# -- worker: one measurement in a fresh process ----------------------------------------------
def _rss_mb() -> float:
    """Peak resident set size of this process so far [MB] (ru_maxrss: KiB on Linux)."""
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak * (1.0 if sys.platform == "darwin" else 1024.0) / MB


def _current_rss_mb() -> float:
    """Resident set size of this process now [MB] (/proc/self/statm; else the peak so far)."""
    try:
        with open("/proc/self/statm", encoding="ascii") as fh:
            pages = int(fh.read().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / MB
    except (OSError, ValueError):
        return _rss_mb()


def _vm_hwm_mb() -> float | None:
    """Peak RSS of this process image [MB] (VmHWM, Linux; not inherited across exec)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024 / MB
    except (OSError, ValueError):
        pass
    return None


def worker(mode: str, program: str) -> dict:
    """Measure one interpret_text call on ``program``: ``time`` (wall, RSS) or ``trace``."""
    import time
    import tracemalloc

    from nurbscnc.program.interpret import interpret_text

    text = Path(program).read_text(encoding="ascii")
    interpret_text("G0 X0\n")  # builds (and caches) the LALR parser: not part of the rate
    if mode == "time":
        rss_base = _current_rss_mb()
        t0, c0 = time.perf_counter(), time.process_time()
        prog = interpret_text(text)
        seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
        return {
            "seconds": seconds,
            "cpu_seconds": cpu_seconds,
            "segments": len(prog.segments),
            "rss_base_mb": rss_base,
            "rss_peak_mb": _rss_mb(),
            "vm_hwm_mb": _vm_hwm_mb(),
        }
    tracemalloc.start()
    prog = interpret_text(text)
    current, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {"peak_mb": peak / MB, "retained_mb": current / MB, "segments": len(prog.segments)}


def start_worker(mode: str, program: Path) -> subprocess.Popen:
    """A fresh interpreter measuring ``program`` (see :func:`worker`)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", mode, str(program)]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish_worker(proc: subprocess.Popen) -> dict:
    stdout, stderr = proc.communicate()
    if proc.returncode != 0:
        raise SystemExit(f"benchmark worker failed ({' '.join(proc.args[-2:])}):\n{stderr}")
    return json.loads(stdout.strip().splitlines()[-1])


# -- the driver ------------------------------------------------------------------------------
def machine_info() -> dict:
    info = {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor() or None,
        "cpu_count": os.cpu_count(),
    }
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("model name"):
                    info["cpu"] = line.split(":", 1)[1].strip()
                    break
        with open("/proc/meminfo", encoding="ascii") as fh:
            info["mem_total_mb"] = int(fh.readline().split()[1]) * 1024 / MB
    except OSError:
        pass
    return info


def versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    found = {}
    for name in ("nurbscnc", "lark", "numpy"):
        try:
            found[name] = version(name)
        except PackageNotFoundError:
            found[name] = None
    return found


def run_cases(quick: bool, workdir: Path) -> list[dict]:
    """Generate every case, time them one after the other (nothing else running), then run
    the slow tracemalloc measurements side by side (their timing is not used). With
    ``quick`` only the quarter-size cases are traced (a smoke test must be fast)."""
    programs, timings = {}, {}
    for name, (kind, full_lines) in FULL_CASES.items():
        lines = full_lines // QUICK_DIVISOR if quick else full_lines
        programs[name] = (kind, lines, workdir / f"{name}.ngc")
        write_program(programs[name][2], kind, lines)
    for name, (_, lines, program) in programs.items():
        timings[name] = finish_worker(start_worker("time", program))
        print(f"  {name}: {lines} lines in {timings[name]['seconds']:.2f} s", flush=True)
    print("  tracemalloc runs ...", flush=True)
    # tracemalloc costs ~8x the run time: the smoke test traces the quarter-size cases only.
    traced_names = [small for _, small in PAIRS] if quick else list(programs)
    tracing = {name: start_worker("trace", programs[name][2]) for name in traced_names}
    no_trace = {"peak_mb": None, "retained_mb": None, "segments": None}
    results = []
    for name, (kind, lines, program) in programs.items():
        timed = timings[name]
        traced = finish_worker(tracing[name]) if name in tracing else no_trace
        assert traced["segments"] in (None, timed["segments"])
        results.append(
            {
                "case": name if not quick else f"{name}/{QUICK_DIVISOR}",
                "program": kind.upper().replace("G62", "G6.2"),
                "lines": lines,
                "bytes": program.stat().st_size,
                "segments": timed["segments"],
                "seconds": timed["seconds"],
                "cpu_seconds": timed["cpu_seconds"],
                "lines_per_s": lines / timed["seconds"],
                "peak_mb": traced["peak_mb"],
                "retained_mb": traced["retained_mb"],
                "peak_bytes_per_line": _ratio(traced["peak_mb"], lines / MB),
                "rss_base_mb": timed["rss_base_mb"],
                "rss_peak_mb": timed["rss_peak_mb"],
                "rss_growth_mb": timed["rss_peak_mb"] - timed["rss_base_mb"],
                "vm_hwm_mb": timed["vm_hwm_mb"],
            }
        )
    return results


def _ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a is not None and b else None


def _fmt(value: float | None, width: int, digits: int) -> str:
    return f"{value:>{width}.{digits}f}" if value is not None else f"{'-':>{width}}"


def linearity(results: list[dict]) -> list[dict]:
    """Per pair (large, quarter): the ratios of lines, tracemalloc peak and RSS growth."""
    by_name = {r["case"].split("/")[0]: r for r in results}
    rows = []
    for big, small in PAIRS:
        b, s = by_name[big], by_name[small]
        rows.append(
            {
                "cases": [big, small],
                "lines_ratio": b["lines"] / s["lines"],
                "peak_mb_ratio": _ratio(b["peak_mb"], s["peak_mb"]),
                "rss_growth_ratio": _ratio(b["rss_growth_mb"], s["rss_growth_mb"]),
            }
        )
    return rows


def print_table(report: dict) -> None:
    head = (
        f"{'case':<14}{'lines':>10}{'seconds':>9}{'lines/s':>10}{'peak MB':>9}"
        f"{'B/line':>8}{'RSS MB':>9}{'RSS +MB':>9}"
    )
    print(head)
    print("-" * len(head))
    for r in report["cases"]:
        print(
            f"{r['case']:<14}{r['lines']:>10}{r['seconds']:>9.2f}{r['lines_per_s']:>10.0f}"
            f"{_fmt(r['peak_mb'], 9, 1)}{_fmt(r['peak_bytes_per_line'], 8, 0)}"
            f"{r['rss_peak_mb']:>9.1f}{r['rss_growth_mb']:>9.1f}"
        )
    for row in report["linearity"]:
        print(
            f"{' / '.join(row['cases'])}: lines x{row['lines_ratio']:.2f}, "
            f"tracemalloc peak x{_fmt(row['peak_mb_ratio'], 0, 2).strip()}, "
            f"RSS growth x{_fmt(row['rss_growth_ratio'], 0, 2).strip()}"
        )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=ROOT / "bench" / "results.json",
        help="JSON results file (default: bench/results.json)",
    )
    parser.add_argument(
        "--quick", action="store_true", help=f"programs {QUICK_DIVISOR}x smaller (a smoke test)"
    )
    parser.add_argument("--worker", nargs=2, metavar=("MODE", "PROGRAM"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    from machine_info import use_bytecode

    use_bytecode()  # the children start as a user's installed nurbscnc does
    if args.worker:
        print(json.dumps(worker(*args.worker)))
        return 0
    print(f"nurbscnc parse+interpret benchmark{' (quick)' if args.quick else ''}", flush=True)
    with tempfile.TemporaryDirectory(prefix="nurbscnc-bench-") as tmp:
        cases = run_cases(args.quick, Path(tmp))
    report = {
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "machine": machine_info(),
        "python": sys.version.split()[0],
        "python_implementation": platform.python_implementation(),
        "versions": versions(),
        "quick": args.quick,
        "measured": "nurbscnc.program.interpret.interpret_text(text): lark LALR parse with an "
        "inline transformer + interpretation to segments; text already in memory",
        "cases": cases,
        "linearity": linearity(cases),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp_out = args.out.with_name(args.out.name + ".tmp")
    tmp_out.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    tmp_out.replace(args.out)
    print_table(report)
    print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
