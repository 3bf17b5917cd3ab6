"""The README's figures are the committed benchmark results', so they cannot drift silently:
the Table 4 rows of our algorithms (bench/table4_results.json, written by bench/table4.py),
the ratios quoted beside the table, and the demo program's plan time and lower bound
(bench/planner_results.json). When a results file is measured again, the README follows."""

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
