"""Time per source line, LinuxCNC 2.9 against nurbscnc, under LinuxCNC's limits (issue 35).

    .venv/bin/python bench/line_times.py --only 3dtest                 # from the goldens
    .venv/bin/python bench/line_times.py --only tort --linuxcnc-csv DIR --record
    .venv/bin/python bench/line_times.py --only tort --top 30 --out tort_lines.json

Where does a whole-program difference come from? Both streams (one point per 1 ms servo
period) are cut alike: within the motion span (bench/contour.py ``motion_span``), the period
from sample k to k + 1 is charged to the source line of sample k + 1 (LinuxCNC's ``line``
column: the line of the motion segment being executed; nurbscnc's ``line`` column of
``run -o points.npz``). A blend is charged to whichever line the planner gives it, so a
corner's time may move between two neighbouring lines; sums over runs of lines and over kinds
of move (rapid, line, arc, NURBS: nurbscnc's interpreter names them) do not depend on it.

LinuxCNC's side comes from a CSV that ``../shared/tools/linuxcnc-sim/run_linuxcnc.sh`` wrote
(``--linuxcnc-csv DIR``: ``DIR/<program stem>.csv``), or from the committed per-line golden
``tests/golden/linuxcnc_sim/<case>_lines.json`` (``--record`` writes it from the CSV), so the
comparison runs without LinuxCNC. nurbscnc runs twice: as cam_bench.py runs it, and with
``--dynamics off`` (no contour check): the second separates the kinematic plan from what the
15 µm guarantee costs.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from cam_bench import CASES, program_path  # noqa: E402
from machine_info import use_bytecode  # noqa: E402
from planner_bench import LINUXCNC_LIMITS_PROFILE, linuxcnc_version, run_nurbscnc, sha256  # noqa: E402

GOLDEN_DIR = ROOT / "tests" / "golden" / "linuxcnc_sim"
PERIOD_S = 1e-3


def line_seconds(points_mm: np.ndarray, lines: np.ndarray, period_s: float = PERIOD_S) -> dict:
    """Seconds per source line {line: s} of a stream (N, 3) with its lines (N,): within the
    motion span (first to last sample that moves), the period k → k + 1 is charged to line
    ``lines[k + 1]``. The values sum to the motion span."""
    pts = np.asarray(points_mm, dtype=float)
    step = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    moving = np.flatnonzero(step > 0.0)
    if moving.size == 0:
        return {}
    first, last = int(moving[0]), int(moving[-1]) + 1
    owner = np.asarray(lines, dtype=np.int64)[first + 1 : last + 1]
    line, count = np.unique(owner, return_counts=True)
    return {int(k): float(n) * period_s for k, n in zip(line, count)}


def line_kinds(path: Path) -> dict:
    """{source line: kind} of the program's moves (nurbscnc's interpreter: "rapid", "line",
    "arc", "nurbs", …); a line of several segments takes its first one's kind."""
    from nurbscnc.program.interpret import interpret_text

    kinds: dict = {}
    for s in interpret_text(path.read_text(errors="replace")).segments:
        kind = getattr(s, "kind", None)
        if kind is not None:
            kinds.setdefault(int(s.line), str(kind))
    return kinds


def by_kind(seconds: dict, kinds: dict) -> dict:
    """Sum of ``seconds`` {line: s} per kind of move ("other": lines without a move)."""
    out: dict = {}
    for line, s in seconds.items():
        kind = kinds.get(line, "other")
        out[kind] = out.get(kind, 0.0) + s
    return out


def linuxcnc_lines(name: str, path: Path, csv_dir: str | None, record: bool) -> dict | None:
    """LinuxCNC's seconds per line: from ``csv_dir``'s CSV (written to the golden when
    ``record``), else from the golden; None when neither is there or the golden's program
    differs."""
    golden = GOLDEN_DIR / f"{name}_lines.json"
    csv = Path(csv_dir) / f"{path.stem}.csv" if csv_dir else None
    if csv is not None and csv.is_file():
        data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
        seconds = line_seconds(data[:, 1:4], data[:, 4].astype(int))
        if record:
            doc = {
                "program": path.name,
                "program_sha256": sha256(path),
                "how": "../shared/tools/linuxcnc-sim/run_linuxcnc.sh (LinuxCNC 2.9 uspace, "
                "headless; config/mill.ini: 58.333 mm/s and 2450 mm/s² per axis and "
                "trajectory, 1 ms); seconds per source line by bench/line_times.py "
                "line_seconds (the period k → k + 1 charged to sample k + 1's line, within "
                "the motion span)",
                "linuxcnc_version": linuxcnc_version(),
                "cycle_time_s": round(sum(seconds.values()), 6),
                "seconds_by_line": {str(k): round(v, 6) for k, v in sorted(seconds.items())},
            }
            golden.write_text(json.dumps(doc, indent=1, ensure_ascii=False) + "\n")
        return seconds
    if not golden.is_file():
        return None
    doc = json.loads(golden.read_text())
    if doc["program_sha256"] != sha256(path):
        print(f"{name}: {golden.name} is of another version of the program", file=sys.stderr)
        return None
    return {int(k): float(v) for k, v in doc["seconds_by_line"].items()}


def nurbscnc_lines(path: Path, extra: list[str]) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        res = run_nurbscnc(path, ["--machine", LINUXCNC_LIMITS_PROFILE, *extra], Path(tmp))
    if "error" in res:
        raise SystemExit(f"{path.name}: nurbscnc failed: {res['error']}")
    return line_seconds(res["points"], res["lines"])


def compare(name: str, path: Path, lc: dict, top: int) -> dict:
    """Print and return the per-kind and per-line differences (nurbscnc − LinuxCNC)."""
    kinds = line_kinds(path)
    source = path.read_text(errors="replace").splitlines()
    runs = {
        "check": nurbscnc_lines(path, []),
        "no_check": nurbscnc_lines(path, ["--dynamics", "off"]),
    }
    out = {"program": path.name, "linuxcnc_s": sum(lc.values()), "kinds": {}, "lines": []}
    lc_kind = by_kind(lc, kinds)
    for variant, nc in runs.items():
        out[f"nurbscnc_{variant}_s"] = sum(nc.values())
        nc_kind = by_kind(nc, kinds)
        every_kind = sorted(set(nc_kind) | set(lc_kind))
        out["kinds"][variant] = {k: nc_kind.get(k, 0.0) - lc_kind.get(k, 0.0) for k in every_kind}
    every = sorted(set(lc) | set(runs["check"]) | set(runs["no_check"]))
    for line in every:
        row = {
            "line": line,
            "kind": kinds.get(line, "other"),
            "linuxcnc_s": lc.get(line, 0.0),
            "check_s": runs["check"].get(line, 0.0),
            "no_check_s": runs["no_check"].get(line, 0.0),
        }
        out["lines"].append(row)
    print(
        f"{name}: LinuxCNC {out['linuxcnc_s']:.3f} s, nurbscnc {out['nurbscnc_check_s']:.3f} s "
        f"({out['nurbscnc_check_s'] / out['linuxcnc_s']:.4f}), without the contour check "
        f"{out['nurbscnc_no_check_s']:.3f} s ({out['nurbscnc_no_check_s'] / out['linuxcnc_s']:.4f})"
    )
    for variant, diff in out["kinds"].items():
        parts = ", ".join(f"{k} {v:+.3f} s" for k, v in diff.items())
        print(f"  nurbscnc − LinuxCNC by kind ({variant.replace('_', ' ')}): {parts}")
    worst = sorted(out["lines"], key=lambda r: r["linuxcnc_s"] - r["check_s"])[:top]
    print(f"  {'line':>5} {'kind':<6} {'LinuxCNC':>9} {'check':>9} {'no check':>9}  source")
    for r in worst:
        text = source[r["line"] - 1].strip()[:48] if 0 < r["line"] <= len(source) else ""
        print(
            f"  {r['line']:>5} {r['kind']:<6} {r['linuxcnc_s']:9.3f} {r['check_s']:9.3f} "
            f"{r['no_check_s']:9.3f}  {text}"
        )
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", default=None, help="run only this case")
    parser.add_argument("--linuxcnc-csv", default=None, help="LinuxCNC's runs: DIR/<stem>.csv")
    parser.add_argument("--record", action="store_true", help="write the per-line goldens")
    parser.add_argument("--top", type=int, default=15, help="lines listed (largest loss)")
    parser.add_argument("--out", default=None, help="write the comparison (JSON) here")
    args = parser.parse_args(argv)
    use_bytecode()
    results = {}
    for name, relative, corpus in CASES:
        if args.only and name not in args.only:
            continue
        path = program_path(relative, corpus)
        if path is None:
            print(f"{name}: corpus program {relative} not found (set NURBSCNC_CORPUS); skipped")
            continue
        lc = linuxcnc_lines(name, path, args.linuxcnc_csv, args.record)
        if lc is None:
            print(f"{name}: no LinuxCNC per-line figures (--linuxcnc-csv DIR --record)")
            continue
        results[name] = compare(name, path, lc, args.top)
    if args.out:
        Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
