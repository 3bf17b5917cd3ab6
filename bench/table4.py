"""The paper's Table 4 and 5 on the 9 mm airfoil, as ``nurbscnc compare`` measures them: the
results file the README's comparison table quotes.

    .venv/bin/python bench/table4.py --out bench/table4_results.json   # make bench

Every algorithm (adaptive feed, curvature feed, the paper's PH look-ahead, ours) on the NURBS
block of programs/naca2415.nc, rest to rest, at 0°, 45° and −45° (Table 5), each simulated
on the default machine's servo model (:func:`nurbscnc.studies.compare.compare_block`, the
rows of ``compare --json``). tests/test_readme_figures.py checks that the README quotes
these numbers (:func:`readme_rows` renders them), so the README cannot drift from them.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from machine_info import run_info  # noqa: E402

PROGRAM = "programs/naca2415.nc"
ANGLES_DEG = (0.0, 45.0, -45.0)
#: The README's names of the algorithms (compare's ``algorithm``).
NAMES = {
    "adaptive": "ours: adaptive feed",
    "curvature": "ours: curvature feed",
    "ours": "**ours: best configuration**",
}


def measure() -> dict:
    """The compare rows of :data:`PROGRAM` at :data:`ANGLES_DEG`, with the run's machine."""
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.program.interpret import interpret_text
    from nurbscnc.studies.compare import compare_block, nurbs_block, row

    prog = interpret_text((ROOT / PROGRAM).read_text())
    runs = compare_block(nurbs_block(prog), load_machine(), ANGLES_DEG)
    return {
        **run_info(),
        "measured": "nurbscnc compare programs/naca2415.nc --rotate 0 --rotate 45 --rotate -45"
        " --json: the NURBS block rest to rest, each algorithm simulated on the default"
        " machine's servo model (µm, s)",
        "program": PROGRAM,
        "rows": [row(r) for r in runs],
    }


def readme_rows(results: dict) -> list[str]:
    """The README's Table 4 rows of our algorithms at 0° (the paper's rows are typed from
    the paper): eq. 29 max, RMS, true-distance max, X max / RMS, cycle time."""
    rows = []
    for r in results["rows"]:
        if r["angle_deg"] != 0.0 or r["algorithm"] not in NAMES:
            continue
        bold = r["algorithm"] == "ours"
        cells = [
            f"{r['contour_eq29_max_um']:.2f}",
            f"{r['contour_eq29_rms_um']:.2f}",
            f"{r['contour_true_max_um']:.2f}",
            f"{r['axis_x_max_um']:.2f} / {r['axis_x_rms_um']:.2f}",
            f"{r['cycle_time_s']:.4f}",
        ]
        if bold:
            cells = [f"**{c}**" if k in (0, 2, 4) else c for k, c in enumerate(cells)]
        rows.append("| " + " | ".join([NAMES[r["algorithm"]], *cells]) + " |")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(HERE / "table4_results.json"))
    parser.add_argument("--quick", action="store_true", help="the same (it takes seconds)")
    args = parser.parse_args()
    results = measure()
    Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    print("\n".join(readme_rows(results)))


if __name__ == "__main__":
    main()
