"""4-axis benchmark (issue 37): a wrapped engraving and an indexer, against LinuxCNC 2.9.

    .venv/bin/python bench/rotary_bench.py --out bench/rotary_results.json    # make bench
    .venv/bin/python bench/rotary_bench.py --quick        # the G94 engraving only
    .venv/bin/python bench/rotary_bench.py --record-linuxcnc     # LinuxCNC live: ~3 min
    .venv/bin/python bench/rotary_bench.py --linuxcnc-csv DIR    # runs made apart

The programs (bench/programs/rotary/, written by make_rotary_programs.py): text and a wave
band engraved on a cylinder of radius 20 mm turning on A (X along it, A around it), as a
CAM wrapping post writes it, in G94 and in G93 inverse time; and a 4-face indexer
(``G0 A90`` then a 3-axis slot). The machine: LinuxCNC's simulated mill (X Y Z: 58.333 mm/s,
2450 mm/s² per axis) with the A axis of a Tormach PCNC 1100's 4th axis (30 deg/s,
400 deg/s²): bench/linuxcnc_sim_a/ for LinuxCNC (run_linuxcnc_a.sh, trivkins XYZA, 1 ms),
bench/programs/linuxcnc_sim_a.toml for nurbscnc (the same limits, no jerk limit).

**LinuxCNC** runs in real time (``--record-linuxcnc``: each program takes its motion time)
and its commanded X Y Z A at every 1 ms servo period are recorded as a golden,
tests/golden/linuxcnc_sim/rotary_<name>.json: the program's sha256, LinuxCNC's version and
configuration, the motion span [s], the largest A speed and acceleration by finite
differences, and the path decimated to within ``DECIMATE_TOL_MM`` (the Ramer–Douglas–Peucker
rule in the part-surface metric below; every kept vertex is a recorded sample). Otherwise the
committed golden is used (the runs need no LinuxCNC).

**nurbscnc** runs through its CLI as a user runs it, ``nurbscnc run PROGRAM --machine
bench/programs/linuxcnc_sim_a.toml --json -o points.csv`` (columns ``t,x,y,z,a,…``). A
refusal (a nurbscnc without rotary support, exit 2) is recorded with its message, a crash
(any other exit) as an error.

**Compared**: the cycle-time ratio (motion spans: the last sample at rest before the first
motion of any axis, A included, to the first at rest after the last) and the path agreement
in both directions: for each sample of one run, the nearest point of the other run's sampled
path (a polyline) in the part-surface metric (x, y, z, r·a·π/180), r the workpiece radius
(an A difference of δ degrees is r·δ·π/180 mm on the part's surface); the largest X Y Z
distance to that point [mm], the largest A difference [deg] and the largest surface distance
[mm]. LinuxCNC's path is the golden's decimated polyline (within ``DECIMATE_TOL_MM`` of every
sample), walked at ``DENSE_STEP_MM`` for the LinuxCNC → nurbscnc direction (so the figures
are within ``DECIMATE_TOL_MM`` + ``DENSE_STEP_MM``/2 of those of the full 1 ms samples).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from machine_info import linuxcnc_version, run_info, use_bytecode  # noqa: E402

SIM_DIR = HERE / "linuxcnc_sim_a"
LINUXCNC_SIM_A = SIM_DIR / "run_linuxcnc_a.sh"
SIM_INI = SIM_DIR / "config" / "mill_a.ini"
PROFILE = "bench/programs/linuxcnc_sim_a.toml"
GOLDEN_DIR = ROOT / "tests" / "golden" / "linuxcnc_sim"
SERVO_PERIOD_S = 1e-3
#: Largest distance [mm, part-surface metric] of a recorded sample from the golden's
#: decimated path.
DECIMATE_TOL_MM = 1e-3
#: Step [mm, part-surface metric] at which a path is walked: the vertices of the nearest-point
#: search (both directions), and LinuxCNC's points in the LinuxCNC → nurbscnc direction.
DENSE_STEP_MM = 0.01
#: Nearest vertices whose adjacent segments are searched for a point's nearest segment.
NEAREST_VERTICES = 12


@dataclasses.dataclass(frozen=True)
class Case:
    """One program; ``radius_mm``: the workpiece radius of the part-surface metric."""

    name: str
    program: str
    radius_mm: float = 20.0
    quick: bool = False


CASES = (
    Case("wrapped_engraving_g94", "bench/programs/rotary/wrapped_engraving_g94.ngc", quick=True),
    Case("wrapped_engraving_g93", "bench/programs/rotary/wrapped_engraving_g93.ngc"),
    Case("indexer_a90", "bench/programs/rotary/indexer_a90.ngc"),
)


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# --------------------------------------------------------------------------- geometry


def surface_coords(xyza: np.ndarray, radius_mm: float) -> np.ndarray:
    """(N, 4) x y z [mm], a [deg] → (N, 4) [mm]: a as the arc r·a·π/180 on the part."""
    out = np.array(xyza, dtype=float)
    out[:, 3] *= radius_mm * math.pi / 180.0
    return out


def motion_span(xyza: np.ndarray) -> tuple[int, int]:
    """Index of the last sample at rest before the first motion of any axis and of the first
    at rest after the last: (i0, i1); the motion span is (i1 − i0) periods."""
    moving = np.flatnonzero(np.any(np.diff(xyza, axis=0) != 0.0, axis=1))
    if moving.size == 0:
        return 0, 0
    return int(moving[0]), int(moving[-1]) + 1


def _segment_distances(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point p (m, d) to the segment a–b (m, d) (each row its own)."""
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    t = np.einsum("ij,ij->i", p - a, d) / np.where(dd > 0, dd, 1.0)
    foot = a + np.clip(t, 0.0, 1.0)[:, None] * d
    return np.linalg.norm(p - foot, axis=1)


def decimate(points: np.ndarray, tol: float) -> np.ndarray:
    """Indices of a Ramer–Douglas–Peucker decimation of the polyline ``points`` (N, d): every
    point lies within ``tol`` of the polyline through the kept ones (first and last kept)."""
    n = points.shape[0]
    keep = np.zeros(n, bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        i0, i1 = stack.pop()
        if i1 - i0 < 2:
            continue
        inner = points[i0 + 1 : i1]
        m = inner.shape[0]
        dist = _segment_distances(
            inner, np.repeat(points[i0 : i0 + 1], m, 0), np.repeat(points[i1 : i1 + 1], m, 0)
        )
        k = int(np.argmax(dist))
        if dist[k] > tol:
            split = i0 + 1 + k
            keep[split] = True
            stack += [(i0, split), (split, i1)]
    return np.flatnonzero(keep)


def densify(polyline: np.ndarray, step: float) -> np.ndarray:
    """The polyline (V, d) walked at ≤ ``step``: every vertex and evenly spaced points
    between them (segment i cut into n_i = ⌈|segment i| / step⌉ equal parts)."""
    seg = np.diff(polyline, axis=0)
    n = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / step).astype(int))
    which = np.repeat(np.arange(seg.shape[0]), n)
    within = np.arange(which.size) - np.repeat(np.cumsum(n) - n, n) + 1
    frac = within / np.repeat(n, n)
    return np.vstack([polyline[:1], polyline[which] + frac[:, None] * seg[which]])


def nearest_on_polyline(points: np.ndarray, polyline: np.ndarray, chunk: int = 20_000):
    """For each point (M, d) the nearest point of the polyline (V, d): (M, d) feet.

    The ``NEAREST_VERTICES`` nearest vertices (k-d tree) and the segments on both sides of
    each are searched; the foot on a segment a–b is a + clip(t, 0, 1)(b − a),
    t = (p − a)·(b − a)/|b − a|²."""
    pts = np.asarray(points, dtype=float)
    poly = np.asarray(polyline, dtype=float)
    if poly.shape[0] == 1:
        return np.repeat(poly, pts.shape[0], 0)
    tree = cKDTree(poly)
    k = min(NEAREST_VERTICES, poly.shape[0])
    last = poly.shape[0] - 2
    feet = np.empty_like(pts)
    for lo in range(0, pts.shape[0], chunk):
        p = pts[lo : lo + chunk]
        _, idx = tree.query(p, k=k)
        idx = idx.reshape(p.shape[0], k)
        seg = np.concatenate([np.clip(idx - 1, 0, last), np.clip(idx, 0, last)], axis=1)
        a = poly[seg]
        d = poly[seg + 1] - a
        dd = np.einsum("mkj,mkj->mk", d, d)
        t = np.einsum("mkj,mkj->mk", p[:, None, :] - a, d) / np.where(dd > 0, dd, 1.0)
        foot = a + np.clip(t, 0.0, 1.0)[..., None] * d
        best = np.argmin(np.linalg.norm(p[:, None, :] - foot, axis=2), axis=1)
        feet[lo : lo + chunk] = foot[np.arange(p.shape[0]), best]
    return feet


def one_way(points_xyza: np.ndarray, path_xyza: np.ndarray, radius_mm: float) -> dict:
    """Largest distances from the points to the path, both (N, 4) [mm, deg]: X Y Z [mm],
    A [deg] and on the part's surface [mm] (to the nearest point of the path in that
    metric)."""
    p = surface_coords(points_xyza, radius_mm)
    # the path walked at DENSE_STEP_MM, so that the nearest vertices of a point lie on its
    # nearest segments (a long straight segment has vertices near every point beside it)
    feet = nearest_on_polyline(p, densify(surface_coords(path_xyza, radius_mm), DENSE_STEP_MM))
    diff = p - feet
    scale = radius_mm * math.pi / 180.0
    return {
        "xyz_max_mm": float(np.linalg.norm(diff[:, :3], axis=1).max()),
        "a_max_deg": float(np.abs(diff[:, 3]).max() / scale),
        "surface_max_mm": float(np.linalg.norm(diff, axis=1).max()),
    }


def path_agreement(nc_xyza: np.ndarray, lc_path_xyza: np.ndarray, radius_mm: float) -> dict:
    """Both directions: nurbscnc's samples to LinuxCNC's path, LinuxCNC's path (walked at
    ``DENSE_STEP_MM``) to nurbscnc's sampled path."""
    dense = densify(surface_coords(lc_path_xyza, radius_mm), DENSE_STEP_MM)
    dense[:, 3] /= radius_mm * math.pi / 180.0
    return {
        "radius_mm": radius_mm,
        "resolution_mm": DECIMATE_TOL_MM + DENSE_STEP_MM / 2,
        "nurbscnc_to_linuxcnc": one_way(nc_xyza, lc_path_xyza, radius_mm),
        "linuxcnc_to_nurbscnc": one_way(dense, nc_xyza, radius_mm),
    }


def axis_peaks(xyza: np.ndarray) -> dict:
    """Largest A speed [deg/s] and acceleration [deg/s²] by finite differences of the 1 ms
    samples, and the largest X Y Z path speed [mm/s]."""
    a = xyza[:, 3]
    v = np.diff(a) / SERVO_PERIOD_S
    acc = np.diff(a, 2) / SERVO_PERIOD_S**2
    vxyz = np.linalg.norm(np.diff(xyza[:, :3], axis=0), axis=1) / SERVO_PERIOD_S
    return {
        "a_speed_max_deg_s": float(np.abs(v).max()) if v.size else 0.0,
        "a_accel_max_deg_s2": float(np.abs(acc).max()) if acc.size else 0.0,
        "xyz_speed_max_mm_s": float(vxyz.max()) if vxyz.size else 0.0,
    }


def g93_programmed_s(text: str) -> float:
    """Sum of the programmed durations [s] of a program's inverse-time moves: 60 / F of
    every G1 under G93 (the generated programs' literal words; F on every G93 move)."""
    inverse, total = False, 0.0
    for raw in text.splitlines():
        words = re.findall(r"([A-Z])(-?[\d.]+)", re.sub(r"\(.*?\)", "", raw).upper())
        codes = {v for k, v in words if k == "G"}
        inverse = "93" in codes or (inverse and "94" not in codes)
        feeds = [float(v) for k, v in words if k == "F"]
        if inverse and "1" in codes and feeds:
            total += 60.0 / feeds[-1]
    return total


# --------------------------------------------------------------------------- LinuxCNC


def linuxcnc_available() -> bool:
    from shutil import which

    return LINUXCNC_SIM_A.is_file() and which("linuxcnc") is not None


def ini_settings(ini: Path = SIM_INI) -> dict:
    """The sim's limits: [TRAJ], [AXIS_X], [AXIS_A], [JOINT_3] and [KINS] keys of the ini."""
    keys, section = {}, ""
    for line in ini.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line.startswith("["):
            section = line.strip("[]")
        elif "=" in line and section in ("TRAJ", "KINS", "AXIS_X", "AXIS_A", "JOINT_3"):
            k, v = (x.strip() for x in line.split("=", 1))
            keys[f"{section}.{k}"] = v
    return keys


def read_csv(path: Path) -> dict:
    """A point CSV (LinuxCNC's ``t,x,y,z,a,line`` or nurbscnc's ``t,x,y,z,[a,…]``) as
    columns by name."""
    with open(path) as f:
        names = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {n: data[:, i] for i, n in enumerate(names)}


def linuxcnc_golden(case: Case, csv: Path) -> dict:
    """The golden of one LinuxCNC run (its CSV and ``.status.json``), or ``{"error": …}``."""
    status_file = Path(str(csv) + ".status.json")
    status = json.loads(status_file.read_text()) if status_file.is_file() else {}
    if not csv.is_file() or status.get("errors") or status.get("overruns"):
        return {"error": status.get("errors") or f"overruns {status.get('overruns')}"}
    cols = read_csv(csv)
    xyza = np.column_stack([cols["x"], cols["y"], cols["z"], cols["a"]])
    i0, i1 = motion_span(xyza)
    keep = decimate(surface_coords(xyza, case.radius_mm), DECIMATE_TOL_MM)
    rows = [
        [
            round(float(cols["t"][i]), 3),
            *(round(float(v), 6) for v in xyza[i]),
            int(cols["line"][i]),
        ]
        for i in keep
    ]
    path = ROOT / case.program
    return {
        "program": case.program,
        "program_sha256": sha256(path),
        "how": "bench/linuxcnc_sim_a/run_linuxcnc_a.sh (LinuxCNC 2.9 uspace, headless, "
        "real time; config/mill_a.ini: trivkins XYZA, X Y Z 58.333 mm/s and 2450 mm/s² per "
        "axis and trajectory, A 30 deg/s and 400 deg/s² (Tormach PCNC 1100's 4th axis), "
        "1 ms), recorded by bench/rotary_bench.py; time: the motion span of its commanded "
        "X Y Z A; path: its 1 ms samples decimated (Ramer–Douglas–Peucker) to within "
        "tolerance_mm in the part-surface metric (x, y, z, radius·a·π/180)",
        "linuxcnc_version": linuxcnc_version(),
        "ini_sha256": sha256(SIM_INI),
        "ini": ini_settings(),
        "radius_mm": case.radius_mm,
        "cycle_time_s": (i1 - i0) * SERVO_PERIOD_S,
        "samples": int(xyza.shape[0]),
        "sample_gaps": status.get("sample_gaps"),
        "overruns": status.get("overruns"),
        **axis_peaks(xyza),
        "path": {
            "tolerance_mm": DECIMATE_TOL_MM,
            "columns": ["t", "x", "y", "z", "a", "line"],
            "rows": rows,
        },
    }


def record_linuxcnc(case: Case, tmp: Path) -> Path:
    """Run LinuxCNC's 4-axis sim on the case's program: the CSV it wrote."""
    out = tmp / f"{case.name}.csv"
    proc = subprocess.run(
        [str(LINUXCNC_SIM_A), str(ROOT / case.program), str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        print(proc.stderr[-2000:], file=sys.stderr)
    return out


def golden_path(case: Case) -> Path:
    return GOLDEN_DIR / f"rotary_{case.name}.json"


def golden_xyza(golden: dict) -> np.ndarray:
    return np.array(golden["path"]["rows"], dtype=float)[:, 1:5]


# --------------------------------------------------------------------------- nurbscnc


def run_nurbscnc(case: Case, tmp: Path) -> dict:
    """``nurbscnc run PROGRAM --machine linuxcnc_sim_a.toml --json -o points.csv``: its
    summary and the points, or the refusal (message and exit code)."""
    out = tmp / "points.csv"
    cmd = [sys.executable, "-m", "nurbscnc", "run", case.program]
    cmd += ["--machine", PROFILE, "--json", "-o", str(out)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != 0 or not out.is_file():
        # exit 2: nurbscnc refused the program (bad input, or no rotary support); any other
        # failure is a crash, recorded as an error
        key = "refused" if proc.returncode == 2 else "error"
        return {key: (proc.stderr or proc.stdout).strip()[-2000:], "exit": proc.returncode}
    try:
        summary = json.loads(proc.stdout)
    except json.JSONDecodeError:
        summary = {}
    cols = read_csv(out)
    return {"summary": summary, "columns": cols, "wall_s": wall}


def nurbscnc_row(case: Case, golden: dict | None, tmp: Path) -> dict:
    """nurbscnc's figures on one case, with the comparison to LinuxCNC's golden."""
    res = run_nurbscnc(case, tmp)
    if "refused" in res or "error" in res:
        return res
    cols = res["columns"]
    if "a" not in cols:
        return {"error": f"no a column in nurbscnc's CSV (columns {sorted(cols)})"}
    xyza = np.column_stack([cols["x"], cols["y"], cols["z"], cols["a"]])
    i0, i1 = motion_span(xyza)
    row = {"wall_s": res["wall_s"], "cycle_time_s": (i1 - i0) * SERVO_PERIOD_S}
    for key in ("cycle_time_s", "lower_bound_s"):
        if key in res["summary"]:
            row[f"summary_{key}"] = res["summary"][key]
    row["samples"] = int(xyza.shape[0])
    row.update(axis_peaks(xyza))
    if golden:
        row["ratio"] = row["cycle_time_s"] / golden["cycle_time_s"]
        row["path_agreement"] = path_agreement(xyza, golden_xyza(golden), case.radius_mm)
    return row


# --------------------------------------------------------------------------- main


def _linuxcnc_golden(case: Case, args, tmp: Path) -> dict | None:
    """Record (live or from ``--linuxcnc-csv``) and write the golden, or read the committed
    one; None when there is none. A golden of another program text is marked stale."""
    csv = None
    if args.linuxcnc_csv:
        csv = Path(args.linuxcnc_csv) / f"{Path(case.program).stem}.csv"
    elif args.record_linuxcnc and linuxcnc_available():
        csv = record_linuxcnc(case, tmp)
    if csv is not None and csv.is_file():
        golden = linuxcnc_golden(case, csv)
        if "error" in golden:
            print(f"{case.name}: LinuxCNC failed: {golden['error']}", file=sys.stderr)
            return None
        golden_path(case).write_text(json.dumps(golden, indent=None, ensure_ascii=False) + "\n")
    if not golden_path(case).is_file():
        return None
    golden = json.loads(golden_path(case).read_text())
    if golden["program_sha256"] != sha256(ROOT / case.program):
        golden["stale"] = "the program changed since this LinuxCNC run"
    return golden


def _linuxcnc_summary(case: Case, golden: dict | None) -> dict | None:
    if golden is None:
        return None
    keep = ("cycle_time_s", "samples", "a_speed_max_deg_s", "a_accel_max_deg_s2")
    out = {k: golden[k] for k in (*keep, "xyz_speed_max_mm_s", "stale") if k in golden}
    out["golden"] = str(golden_path(case).relative_to(ROOT))
    return out


def print_table(cases: dict) -> None:
    print(f"{'program':24} {'LinuxCNC':>10} {'nurbscnc':>10} {'ratio':>7}  agreement")
    for name, r in cases.items():
        lc, nc = r.get("linuxcnc") or {}, r.get("nurbscnc") or {}
        lc_t = f"{lc['cycle_time_s']:.3f} s" if "cycle_time_s" in lc else "–"
        failed = next((k for k in ("refused", "error") if k in nc), None)
        if failed:
            why = nc[failed].split("error:", 1)[-1].strip()[:70]
            print(f"{name:24} {lc_t:>10} {failed:>10} {'–':>7}  {why}")
            continue
        nc_t = f"{nc['cycle_time_s']:.3f} s" if "cycle_time_s" in nc else "–"
        ratio = f"{nc['ratio']:.3f}" if "ratio" in nc else "–"
        agree = nc.get("path_agreement")
        text = ""
        if agree:
            a, b = agree["nurbscnc_to_linuxcnc"], agree["linuxcnc_to_nurbscnc"]
            text = (
                f"nc→lc {a['xyz_max_mm']:.4f} mm / {a['a_max_deg']:.4f}°, "
                f"lc→nc {b['xyz_max_mm']:.4f} mm / {b['a_max_deg']:.4f}°"
            )
        print(f"{name:24} {lc_t:>10} {nc_t:>10} {ratio:>7}  {text}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="write the results (JSON) here")
    parser.add_argument("--quick", action="store_true", help="the G94 engraving only")
    parser.add_argument("--only", action="append", default=None, help="run only this case")
    parser.add_argument("--record-linuxcnc", action="store_true", help="run LinuxCNC live")
    parser.add_argument("--linuxcnc-csv", default=None, help="read LinuxCNC's runs from DIR")
    parser.add_argument("--linuxcnc-only", action="store_true", help="do not run nurbscnc")
    args = parser.parse_args(argv)
    use_bytecode()
    cases = {}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        for case in CASES:
            if (args.only and case.name not in args.only) or (args.quick and not case.quick):
                continue
            print(f"{case.name}: {case.program}", file=sys.stderr)
            golden = _linuxcnc_golden(case, args, tmp)
            entry = {
                "program": case.program,
                "program_sha256": sha256(ROOT / case.program),
                "linuxcnc": _linuxcnc_summary(case, golden),
            }
            g93_s = g93_programmed_s((ROOT / case.program).read_text())
            if g93_s:
                entry["g93_programmed_s"] = g93_s
            if not args.linuxcnc_only:
                usable = golden if golden and "stale" not in golden else None
                entry["nurbscnc"] = nurbscnc_row(case, usable, tmp)
            cases[case.name] = entry
    print_table(cases)
    if args.out:
        report = {
            **run_info(),
            "issue": "issue 37: a 4-axis wrapped engraving and an indexer against LinuxCNC 2.9",
            "machine_profile": PROFILE,
            "linuxcnc_config": {
                "script": str(LINUXCNC_SIM_A.relative_to(ROOT)),
                "ini": str(SIM_INI.relative_to(ROOT)),
                "ini_sha256": sha256(SIM_INI),
                "settings": ini_settings(),
                "version": linuxcnc_version(),
            },
            "cases": cases,
        }
        Path(args.out).write_text(json.dumps(report, indent=1, ensure_ascii=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
