"""Compile-speed benchmark: motion time over compile time, with and without the contour check.

    .venv/bin/python bench/compile_bench.py --out bench/compile_results.json   # make bench
    .venv/bin/python bench/compile_bench.py --quick                            # a subset
    .venv/bin/python bench/compile_bench.py --modes off --repeat 3             # best of 3, off

Every measurement is ``nurbscnc plan PROGRAM --json`` in a fresh process (as a user runs
it; :func:`scale_bench.measure`: wall time, CPU time, peak RSS), once with the contour check
(``--dynamics local``, the default) and once without (``--dynamics off``). The figure is the
real-time factor: the plan's motion time (its ``cycle_time_s``) over the wall time of the
whole command (start-up, parsing, planning, the check).

Programs: every program of the corpus's ``cam/`` folder (real CAM output), the corpus's
``linuxcnc/general/3dtest.ngc`` and ``tort.ngc``, and :func:`airfoils_rotated`: 32 distinct
NACA 4-digit airfoils (camber, camber position and thickness varied) each at ten rotations,
320 distinct closed G6.2 contours, a G0 between them (distinct geometry: no cut repeats
another, so caches of moved copies do not carry the figure).

Goals: ≥ 100× real time with the check, ≥ 300× without, on every program.

``--repeat N`` runs each command N times and keeps the run of least CPU time (a loaded,
shared machine moves CPU times by ±25 %); ``--modes`` leaves out the check or the runs
without it (a row then has no pass verdict).

The headline is the fresh process above (the goals are judged on it). A second figure,
labelled ``warm`` in the results (``--no-warm`` leaves it out), is the compile time a CAM
engineer compiling many files meets when the planner is already started: per mode and per
repeat one process (:mod:`warm_plan`) that imports the ``plan`` command's modules, plans a
warm-up program, then plans each program once through the ``plan`` command's own app calls
(the same JSON built), each timed with ``time.process_time``. Each row gets ``check_warm``
and ``off_warm`` (the least CPU time over the repeats, its real-time factor, and whether
its motion time is the fresh process's); the report's ``warm`` gives the start-up those
processes paid before the first program (Python's start, the imports, the warm-up), apart
from the work.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from machine_info import corpus_dir, corpus_program, run_info, use_bytecode  # noqa: E402
from scale_bench import NURBSCNC, measure  # noqa: E402

GOALS = {"realtime_factor_check": 100.0, "realtime_factor_off": 300.0}
CORPUS_GENERAL = ("general/3dtest.ngc", "general/tort.ngc")
#: The 32 airfoils: NACA m (max camber), p (its position), t (thickness), unit chord.
AIRFOIL_CAMBER = (0.0, 0.01, 0.02, 0.04)
AIRFOIL_CAMBER_AT = (0.3, 0.4)
AIRFOIL_THICKNESS = (0.09, 0.12, 0.15, 0.18)
ROTATIONS = 10


def airfoils_rotated(chord_mm: float = 60.0, pitch_mm: float = 80.0, count: int = 32) -> str:
    """``count`` distinct NACA 4-digit airfoils of ``chord_mm`` at :data:`ROTATIONS`
    rotations each (36° apart, about the chord's middle), on a 20-wide grid ``pitch_mm``
    apart about the origin (inside the soft limits), as G6.2 cubic B-splines
    (programs/make_programs.py's interpolation), G0 between them."""
    import importlib.util

    import numpy as np

    spec = importlib.util.spec_from_file_location(
        "make_programs", ROOT / "programs" / "make_programs.py"
    )
    mp = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mp)  # imports numpy/scipy: called in this driver only once
    shapes = [
        (m, p, t)
        for m in AIRFOIL_CAMBER
        for p in AIRFOIL_CAMBER_AT
        for t in AIRFOIL_THICKNESS
        if not (m == 0.0 and p != AIRFOIL_CAMBER_AT[0])
    ]
    # m = 0 makes p moot: thicknesses between the listed ones fill in the 32 shapes.
    extra = [(0.0, 0.3, t) for t in (0.06, 0.08, 0.10, 0.14, 0.16, 0.20, 0.21)]
    shapes = (shapes + [s for s in extra if s not in shapes])[:count]
    lines = [f"({len(shapes)} NACA airfoils x {ROTATIONS} rotations)", "G21 G17 G90 G94", "F3500"]
    cell = 0
    for m, p, t in shapes:
        mp.NACA_M, mp.NACA_P, mp.NACA_T = m, max(p, 1e-3), t
        pts = mp.airfoil_points_mm(chord_mm)
        knots, ctrl0 = mp.interpolating_cubic(pts)
        for r in range(ROTATIONS):
            a = 2.0 * np.pi * r / ROTATIONS
            rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            centre = np.array([(cell % 20 - 9.5) * pitch_mm, (cell // 20 - 7.5) * pitch_mm])
            c = (ctrl0 - [chord_mm / 2, 0.0]) @ rot.T + centre
            cell += 1
            xs, ys = [mp.fmt(v) for v in c[:, 0]], [mp.fmt(v) for v in c[:, 1]]
            ks = [mp.fmt(v) for v in knots]
            lines.append(f"G0 X{xs[0]} Y{ys[0]}")
            lines.append(f"G6.2 P4 K{ks[0]} X{xs[0]} Y{ys[0]} R1")
            lines += [f"K{ks[j]} X{xs[j]} Y{ys[j]} R1" for j in range(1, len(c))]
            lines += [f"K{k}" for k in ks[len(c) :]]
    lines.append("M2")
    return "\n".join(lines) + "\n"


def programs(tmp: Path, quick: bool) -> list[tuple[str, Path]]:
    """(name, path) of the benchmark's programs; corpus programs only where present."""
    out = []
    cam = corpus_dir() / "cam"
    if cam.is_dir():
        out += [(f"cam/{p.name}", p) for p in sorted(cam.iterdir()) if p.is_file()]
    for rel in CORPUS_GENERAL:
        found = corpus_program(rel)
        if found is not None:
            out.append((f"linuxcnc/{rel}", found))
    path = tmp / "airfoils_32x10.nc"
    path.write_text(airfoils_rotated())
    out.append(("airfoils_32x10", path))
    if quick:
        out = [o for o in out if "tort" not in o[0] and "pycut" not in o[0]]
    return out


def plan_row(path: Path, dynamics: str, caps, repeat: int = 1) -> dict:
    """``nurbscnc plan --json --dynamics ...`` of ``path``: wall and CPU time, motion time
    and the real-time factors; of ``repeat`` runs, the one of least CPU time (with every
    run's CPU time)."""
    runs = [
        measure([*NURBSCNC, "plan", str(path), "--json", "--dynamics", dynamics], *caps)
        for _ in range(repeat)
    ]
    r = min(runs, key=lambda run: run["cpu_s"])
    if repeat > 1:
        r["cpu_s_runs"] = [run["cpu_s"] for run in runs]
    data = r.pop("json", None) or {}
    r["motion_s"] = data.get("cycle_time_s")
    r["contour_true_max_um"] = data.get("contour_true_max_um")
    r["dynamics_iterations"] = data.get("dynamics_iterations")
    if r["motion_s"] is not None and r["exit"] == 0:
        r["realtime_factor"] = r["motion_s"] / r["wall_s"]
        r["realtime_factor_cpu"] = r["motion_s"] / r["cpu_s"]
    return r


def warm_figures(rows: list[dict], chosen, modes, caps, repeat: int) -> dict:
    """The second figure: per mode, ``repeat`` processes of :mod:`warm_plan` over the chosen
    programs; each row gets ``<mode>_warm`` (least CPU time, every run's, the real-time
    factor, the motion time and whether it equals the fresh process's). Returns the start-up
    those processes paid (Python, imports, warm-up: the least of each over the processes)."""
    by_path = {str(path): row for (_, path), row in zip(chosen, rows, strict=True)}
    startup = {}
    for dyn, key in modes:
        runs = [
            measure(
                [sys.executable, str(HERE / "warm_plan.py"), "--dynamics", dyn, *by_path],
                caps[0],
                caps[1] * len(by_path),
            )
            for _ in range(repeat)
        ]
        done = [r["json"] for r in runs if r["exit"] == 0 and r.get("json")]
        startup[key] = {
            f: min(d[f] for d in done) if done else None
            for f in ("python_cpu_s", "imports_cpu_s", "warmup_cpu_s")
        }
        for path, row in by_path.items():
            cpu = [d["rows"][path]["cpu_s"] for d in done]
            motion = done[0]["rows"][path]["motion_s"] if done else None
            fresh = row.get(key, {}).get("motion_s")
            row[key + "_warm"] = {
                "cpu_s": min(cpu) if cpu else None,
                "cpu_s_runs": cpu,
                "motion_s": motion,
                "motion_as_fresh": motion == fresh if fresh is not None else None,
                "realtime_factor_cpu": motion / min(cpu) if cpu and motion else None,
            }
    return startup


def _warm_text(key: str, r: dict) -> str:
    """One warm figure's text: CPU time and the real-time factor on it."""
    if r.get("cpu_s") is None:
        return f"{key}: failed"
    return f"{key}: {r['cpu_s']:.3f} s CPU (×{r['realtime_factor_cpu']:.0f})"


def _row_text(key: str, r: dict) -> str:
    """One run's line: motion, wall and CPU time, the real-time factors, the contour error."""
    return (
        f"{key}: motion {r.get('motion_s') or 0:.1f} s, {r['wall_s']:.2f} s wall, "
        f"{r['cpu_s']:.2f} s CPU (×{r.get('realtime_factor') or 0:.0f}, "
        f"×{r.get('realtime_factor_cpu') or 0:.0f} CPU; {r.get('contour_true_max_um')} µm) "
        f"{r.get('message', '')}"
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="leave out the two longest")
    parser.add_argument("--out", default=None, help="write the results (JSON) here")
    parser.add_argument("--only", default=None, help="only programs whose name contains this")
    parser.add_argument("--mem-cap-gb", type=float, default=4.0, help="RLIMIT_AS per command")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per command")
    parser.add_argument("--repeat", type=int, default=1, help="runs per command (least CPU)")
    parser.add_argument(
        "--modes", choices=("both", "check", "off"), default="both", help="which runs to make"
    )
    parser.add_argument(
        "--warm",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also the compile time inside an already-started process (the second figure)",
    )
    args = parser.parse_args(argv)
    modes = [m for m in (("local", "check"), ("off", "off")) if args.modes in ("both", m[1])]
    use_bytecode()
    caps = (args.mem_cap_gb, args.timeout)
    report = {
        **run_info(),
        "quick": args.quick,
        "modes": args.modes,
        "repeat": args.repeat,
        "goals": GOALS,
        "rows": [],
    }
    with tempfile.TemporaryDirectory() as tmp:
        chosen = [
            (name, path)
            for name, path in programs(Path(tmp), args.quick)
            if not args.only or args.only in name
        ]
        for name, path in chosen:
            row = {"program": name}
            for dyn, key in modes:
                row[key] = plan_row(path, dyn, caps, args.repeat)
            if len(modes) == 2:
                chk, off = row["check"], row["off"]
                for suffix in ("", "_cpu"):  # wall time as the goal says; CPU time (a loaded
                    # shared machine stretches the wall time, not the CPU time)
                    row["pass" + suffix] = bool(
                        (chk.get("realtime_factor" + suffix) or 0) >= GOALS["realtime_factor_check"]
                        and (off.get("realtime_factor" + suffix) or 0)
                        >= GOALS["realtime_factor_off"]
                    )
            report["rows"].append(row)
            print(f"{name}: " + "; ".join(_row_text(key, row[key]) for _, key in modes), flush=True)
            if args.out:  # after every row: a long run cut short keeps what it measured
                Path(args.out).write_text(json.dumps(report, indent=1, ensure_ascii=False) + "\n")
        if args.warm and chosen:
            report["warm"] = warm_figures(report["rows"], chosen, modes, caps, args.repeat)
            for row in report["rows"]:
                print(
                    f"{row['program']} (warm process): "
                    + "; ".join(_warm_text(key, row[key + "_warm"]) for _, key in modes),
                    flush=True,
                )
            if args.out:
                Path(args.out).write_text(json.dumps(report, indent=1, ensure_ascii=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
