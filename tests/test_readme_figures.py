"""The README's figures are the committed benchmark results', so they cannot drift silently:
the Table 4 rows of our algorithms (bench/table4_results.json, written by bench/table4.py),
the ratios quoted beside the table, and the demo program's plan time and lower bound
(bench/planner_results.json). When a results file is measured again, the README follows.
docs/reproduction.md's Table 4 at 0° and Table 5 on the 9 mm airfoil, and the figures its
text quotes from them, are the same file's too (read here from the report's own table cells,
not through the script that wrote them)."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from table4 import readme_rows  # noqa: E402

from nurbscnc.studies.compare import PAPER_TABLE4  # noqa: E402

README = (ROOT / "README.md").read_text()
REPRODUCTION = (ROOT / "docs" / "reproduction.md").read_text()
TABLE4 = json.loads((ROOT / "bench" / "table4_results.json").read_text())
PLANNER = json.loads((ROOT / "bench" / "planner_results.json").read_text())


def _ours(angle_deg: float) -> dict:
    (row,) = [r for r in TABLE4["rows"] if r["algorithm"] == "ours" and r["angle_deg"] == angle_deg]
    return row


def test_table4_rows_are_the_results_file():
    rows = readme_rows(TABLE4)
    assert len(rows) == 3
    for row in rows:
        assert f"\n{row}\n" in README, row
    # No other row of ours in the README's Table 4 than those rendered from the file.
    table = README[README.index("### The comparison on the 9 mm airfoil") :]
    table = table[: table.index("\n\n", table.index("| algorithm |"))]
    ours = [line for line in table.splitlines() if "ours:" in line]
    assert ours == rows


def test_ratios_beside_table4_are_the_results_file():
    paper_s = PAPER_TABLE4["ph-lookahead"]["cycle_time_s"]  # 0.9455 s
    share = round(100.0 * _ours(0.0)["cycle_time_s"] / paper_s)
    assert f"runs the airfoil in {share} % of the paper's time" in README
    base = _ours(0.0)["contour_true_max_um"]
    change = max(abs(_ours(a)["contour_true_max_um"] / base - 1.0) for a in (45.0, -45.0))
    assert f"maximum changes by at most {100.0 * change:.2f} % (Table 5)" in README


def test_demo_plan_time_is_the_planner_results_file():
    default = PLANNER["cases"]["naca2415"]["nurbscnc"]["default"]
    text = re.sub(r"\s+", " ", README)
    assert (
        f"the plan takes {default['cycle_time_s']:.3f} s against a bound of "
        f"{default['lower_bound_s']:.3f} s (`bench/planner_results.json`"
    ) in text


@pytest.mark.parametrize("path", ["bench/table4_results.json", "bench/planner_results.json"])
def test_results_files_say_where_they_ran(path):
    info = json.loads((ROOT / path).read_text())
    assert info["machine"]["cores"] and info["date"]


def _section_rows(text: str, heading: str) -> list[list[str]]:
    """The cells of the table rows under a markdown heading (up to the next heading)."""
    body = text[text.index(heading) + len(heading) :]
    body = body[: body.index("\n## ")] if "\n## " in body else body
    return [
        [cell.strip() for cell in line.strip().strip("|").split("|")]
        for line in body.splitlines()
        if line.startswith("|") and not line.startswith("|---")
    ][1:]


def test_reproduction_table4_is_the_results_file():
    """Each of our rows at 0° (all four algorithms): X max/RMS, Y max/RMS, eq. 29 max/RMS/
    mean, true-distance max at 0.01 µm, time at 0.1 ms, as the results file (and nothing
    else of ours in the table)."""
    rows = _section_rows(REPRODUCTION, "## Table 4: the airfoil at 0°")
    ours = {cells[0]: cells for cells in rows if cells[1] == "ours"}
    expected = {r["algorithm"]: r for r in TABLE4["rows"] if r["angle_deg"] == 0.0}
    assert set(ours) == set(expected) and len(ours) == 4
    cols = (
        "axis_x_max_um",
        "axis_x_rms_um",
        "axis_y_max_um",
        "axis_y_rms_um",
        "contour_eq29_max_um",
        "contour_eq29_rms_um",
        "contour_eq29_mean_um",
        "contour_true_max_um",
    )
    for name, cells in ours.items():
        row = expected[name]
        assert [float(c) for c in cells[2:10]] == pytest.approx(
            [row[c] for c in cols], abs=0.005 + 1e-9
        ), name
        assert float(cells[10]) == pytest.approx(row["cycle_time_s"], abs=5e-5 + 1e-12), name


def test_reproduction_table5_is_the_results_file():
    rows = _section_rows(REPRODUCTION, "## Table 5: orientation")
    assert len(rows) == 6
    for cells in rows:
        angle = float(cells[0].rstrip("°"))
        (row,) = [
            r for r in TABLE4["rows"] if r["algorithm"] == cells[1] and r["angle_deg"] == angle
        ]
        got = [float(c) for c in cells[2:8]]
        want = [
            row["contour_eq29_max_um"],
            row["contour_eq29_rms_um"],
            row["contour_true_max_um"],
            row["axis_x_max_um"],
            row["axis_y_max_um"],
        ]
        assert got[:5] == pytest.approx(want, abs=0.005 + 1e-9), cells
        assert got[5] == pytest.approx(row["cycle_time_s"], abs=5e-5 + 1e-12), cells


def test_reproduction_text_quotes_the_results_file():
    ours = _ours(0.0)
    text = re.sub(r"\s+", " ", REPRODUCTION)
    assert (
        f"{ours['cycle_time_s']:.4f} s against the paper's 0.9455 s at the same accuracy "
        f"(eq. 29 max {ours['contour_eq29_max_um']:.2f} µm, true distance "
        f"{ours['contour_true_max_um']:.2f} µm ≤ 15 µm)"
    ) in text
    by = {r["algorithm"]: r["contour_eq29_max_um"] for r in TABLE4["rows"] if r["angle_deg"] == 0}
    ad, cu, ou = by["adaptive"], by["curvature"], by["ours"]
    assert (
        f"adaptive-feed contour error max {ad:.1f} µm = {ad / cu:.1f}× the curvature-feed one "
        f"({cu:.1f} µm), which is {cu / ou:.1f}× ours ({ou:.1f} µm)"
    ) in text
    (ph,) = [r for r in TABLE4["rows"] if r["algorithm"] == "ph-lookahead" and r["angle_deg"] == 0]
    assert f"global rule is slower than the paper** ({ph['cycle_time_s']:.4f} s)" in text
    # The stale figure of an older plan is gone.
    assert "0.5530" not in REPRODUCTION
