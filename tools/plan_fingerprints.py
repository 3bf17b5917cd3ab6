"""Fingerprints of the planner's outputs over every program at hand, to show a refactor
changed nothing: the SHA-256 of each program's `run` points file and its `plan --json`
summary, under several planning options (the paper's machine and LinuxCNC's limits; the
contour check, pre-compensation, smoothing).

    python tools/plan_fingerprints.py --out before.json
    python tools/plan_fingerprints.py --out after.json --against before.json

Runs `python -m nurbscnc` from the checkout this file is in; the corpus comes from
NURBSCNC_CORPUS (default ../shared/corpus). A program taking longer than --timeout seconds
in one mode is recorded as a time-out.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The LinuxCNC-limits profile; NURBSCNC_LIMITS_TOML names another copy of it (the summary
#: prints the profile's path: two checkouts compared must read the same path).
LINUXCNC_LIMITS = os.environ.get(
    "NURBSCNC_LIMITS_TOML", str(ROOT / "bench" / "programs" / "linuxcnc_limits.toml")
)

#: (name, options, which programs): each program runs in every mode whose filter accepts it.
MODES = [
    ("default", [], lambda p: True),
    ("linuxcnc_limits", ["--machine", LINUXCNC_LIMITS], lambda p: "nurbs" not in p.parts),
    ("precompensate", ["--precompensate"], lambda p: p.parent.name in ("programs", "nurbs")),
    ("smooth", ["--smooth", "--machine", LINUXCNC_LIMITS], lambda p: p.parent.name == "cam"),
    ("dynamics_off", ["--dynamics", "off"], lambda p: True),
]


def programs() -> list[Path]:
    corpus = Path(os.environ.get("NURBSCNC_CORPUS", ROOT.parent / "shared" / "corpus"))
    found = sorted((ROOT / "programs").glob("*.nc"))
    found += sorted((ROOT / "tests" / "programs" / "cam").glob("*.ngc"))
    if corpus.is_dir():
        found += sorted(p for p in corpus.rglob("*") if p.suffix in (".nc", ".ngc"))
    return found


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def fingerprint(program: Path, options: list[str], timeout_s: float) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    base = [sys.executable, "-m", "nurbscnc"]
    with tempfile.TemporaryDirectory() as tmp:
        points = Path(tmp) / "points.csv"
        t0 = time.perf_counter()
        try:
            plan = subprocess.run(
                [*base, "plan", str(program), "--json", *options],
                capture_output=True,
                timeout=timeout_s,
                env=env,
                cwd=tmp,
            )
            run = subprocess.run(
                [*base, "run", str(program), "-o", str(points), *options],
                capture_output=True,
                timeout=timeout_s,
                env=env,
                cwd=tmp,
            )
        except subprocess.TimeoutExpired:
            return {"timeout": True}
        summary = plan.stdout
        try:  # the machine profile's path differs between checkouts; everything else must not
            doc = json.loads(summary)
            doc.pop("program", None)
            summary = json.dumps(doc, sort_keys=True).encode()
        except ValueError:
            pass
        return {
            "plan_exit": plan.returncode,
            "plan": digest(summary),
            "plan_stderr": digest(
                plan.stderr.replace(str(ROOT).encode(), b"ROOT").replace(
                    str(Path(LINUXCNC_LIMITS).parents[2]).encode(), b"ROOT"
                )
            ),
            "run_exit": run.returncode,
            "points": digest(points.read_bytes()) if points.exists() else None,
            "seconds": round(time.perf_counter() - t0, 2),
        }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--against", help="an earlier --out file to compare with")
    ap.add_argument("--timeout", type=float, default=240.0)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    tasks = [(p, name, opts) for p in programs() for name, opts, keep in MODES if keep(p)]
    if args.against:  # the quick ones first: a run stopped early has compared the most
        seconds = {
            k: v.get("seconds", 0.0) for k, v in json.loads(Path(args.against).read_text()).items()
        }
        tasks.sort(key=lambda t: seconds.get(f"{t[0].name}::{t[1]}", 0.0))
    progress = Path(args.out).with_suffix(".partial.jsonl")
    progress.write_text("")

    def one(task):
        p, name, opts = task
        key, result = f"{p.name}::{name}", fingerprint(p, opts, args.timeout)
        with progress.open("a") as f:  # one line per run as it ends
            f.write(json.dumps({key: result}) + "\n")
        return key, result

    with ThreadPoolExecutor(args.jobs) as pool:
        results = dict(pool.map(one, tasks))
    Path(args.out).write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
    if not args.against:
        print(f"{len(results)} fingerprints written to {args.out}")
        return 0
    before = json.loads(Path(args.against).read_text())
    keys = ("plan_exit", "plan", "plan_stderr", "run_exit", "points")
    differ = [
        k
        for k in sorted(before)
        if k in results and any(before[k].get(f) != results[k].get(f) for f in keys)
    ]
    missing = sorted(set(before) ^ set(results))
    for k in differ:
        print(f"differs: {k}")
    for k in missing:
        print(f"only in one: {k}")
    print(f"{len(results) - len(differ)} same, {len(differ)} differ, {len(missing)} unmatched")
    return 1 if differ or missing else 0


if __name__ == "__main__":
    raise SystemExit(main())
