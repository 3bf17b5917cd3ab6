"""Interpolator throughput: reference points per second, exact and Taylor (issue 4).

Usage::

    .venv/bin/python bench/interp_bench.py --out bench/interp_results.json [--quick]

Each program is planned once with the default machine (dynamics off: this measures the
interpolator, not the planner); then ``sample_plan`` places the reference points at a period
small enough to give about a million samples (the cost per point does not depend on the
period; a 1 ms plan sampled at 10 µs is 100x as many points on the same pieces), with the
exact interpolator and with the paper's Taylor interpolator. Best of three runs, so a busy
machine shows its quiet speed; the first run (which builds the per-curve tables) is
reported too. Target: ≥ 1,000,000 points/s exact, ≥ 100,000 points/s Taylor, linear cost.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine_info import run_info  # noqa: E402

from nurbscnc.interpolate.sample import sample_plan  # noqa: E402
from nurbscnc.machine.profile import load_machine  # noqa: E402
from nurbscnc.plan.lookahead import plan_program  # noqa: E402
from nurbscnc.plan.options import LookaheadOptions  # noqa: E402
from nurbscnc.program.interpret import interpret_text  # noqa: E402

PROGRAMS = ("butterfly.nc", "naca2415_c40.nc", "corners.nc")


def measure(name: str, target_points: int, interpolator: str, repeat: int = 3) -> dict:
    machine = load_machine()
    prog = interpret_text((ROOT / "programs" / name).read_text())
    plan = plan_program(prog, machine, LookaheadOptions(dynamics="off"))
    period = plan.profile.duration_s / target_points
    times = []
    n = 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        samples = sample_plan(plan.pieces, plan.profile, period, interpolator=interpolator)
        times.append(time.perf_counter() - t0)
        n = samples.t_s.size
    return {
        "program": name,
        "interpolator": interpolator,
        "points": n,
        "period_s": period,
        "first_run_s": times[0],
        "best_s": min(times),
        "points_per_s": n / min(times),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    ap.add_argument("--quick", action="store_true", help="100,000 points per case")
    args = ap.parse_args(argv)
    target = 100_000 if args.quick else 1_000_000
    cases = []
    for name in PROGRAMS:
        for interp in ("exact", "taylor"):
            if interp == "taylor" and name == "corners.nc":
                continue  # no NURBS: Taylor is the exact path there
            r = measure(name, target, interp)
            cases.append(r)
            print(
                f"{name:18s} {interp:6s} {r['points']:>9d} points  "
                f"{r['points_per_s'] / 1e6:6.2f} M points/s (first run {r['first_run_s']:.2f} s)"
            )
    # Linearity: the same program at a quarter of the points.
    small = measure("butterfly.nc", target // 4, "exact")
    big = next(c for c in cases if c["program"] == "butterfly.nc" and c["interpolator"] == "exact")
    ratio = big["best_s"] / small["best_s"]
    print(f"butterfly exact: 4x the points costs {ratio:.2f}x the time")
    result = {
        **run_info(),
        "quick": args.quick,
        "cases": cases,
        "linearity_4x_time_ratio": ratio,
    }
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
