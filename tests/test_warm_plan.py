"""bench/warm_plan.py, compile_bench's second figure, times the work of ``nurbscnc plan
PROGRAM --json``: its plan gives the command's own JSON, key for key and bit for bit."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import warm_plan  # noqa: E402

from nurbscnc.cli.plan import plan as plan_command  # noqa: E402

#: Lines, an arc, a run of short moves with blended corners.
PROGRAM = (
    "G21 G90 G17 G64 P0.01 F900\nG0 X0 Y0 Z1\nG1 Z0\nG1 X10\nG2 X20 Y0 I5 J0\n"
    + "".join(f"G1 X{20 + k * 0.3:.2f} Y{(k % 5) * 0.02:.2f}\n" for k in range(1, 40))
    + "G0 Z5\nM2\n"
)


@pytest.mark.parametrize("dynamics", ["local", "off"])
def test_the_warm_plan_is_the_commands_json(tmp_path, dynamics):
    path = tmp_path / "part.nc"
    path.write_text(PROGRAM)
    fresh = subprocess.run(
        [sys.executable, "-m", "nurbscnc", "plan", str(path), "--json", "--dynamics", dynamics],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert fresh.returncode == 0, fresh.stderr
    summary, text = warm_plan.plan_once(plan_command, str(path), dynamics)
    assert json.loads(text) == json.loads(fresh.stdout)
    assert summary["cycle_time_s"] == json.loads(fresh.stdout)["cycle_time_s"]
    assert summary["piece_count"] > 20 and summary["pieces"].get("ph")  # blends: real work


def test_warm_plan_reports_start_up_apart_from_each_program(tmp_path):
    path = tmp_path / "part.nc"
    path.write_text(PROGRAM)
    done = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "warm_plan.py"), "--dynamics", "off", str(path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["dynamics"] == "off"
    for key in ("python_cpu_s", "imports_cpu_s", "warmup_cpu_s"):
        assert report[key] > 0.0
    row = report["rows"][str(path)]
    assert row["cpu_s"] > 0.0 and row["motion_s"] > 0.0 and row["json_chars"] > 100
