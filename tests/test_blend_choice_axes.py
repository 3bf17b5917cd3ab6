"""The blend-or-stop choice under per-axis limits (plan/blend_choice.py).

On LinuxCNC's limits (bench/programs/linuxcnc_limits.toml: 2450 mm/s² per axis, the path
up to √3 × 2450) a corner's blend is held to the share of each axis's acceleration its
normal part may take, and the lines beside it to A_i/|t_i| on each axis; a choice costed
with the path's acceleration alone took blends slower than stopping. Where the kinematics
alone decide (rapids, never checked; a machine without a servo model) G64 P is never slower
than G61 on the same corners: checked against the closed-form time of the exact stops.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.options import LookaheadOptions, PlanOptions
from nurbscnc.program.interpret import interpret_text

ROOT = Path(__file__).resolve().parent.parent
LINUXCNC_LIMITS = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"
#: A 3dtest-like run of long moves (mm) with two wide corners (35°, 125°) and one reversal.
VERTICES = np.array([[0.0, 0.0, 0.0], [45.72, 31.75, 0.0], [0.0, 0.0, 0.0], [25.4, 0.0, 25.4]])


def _program(mode: str, motion: str) -> str:
    words = [f"G21 G17 G90 {mode}", "G0 X0 Y0 Z0"]
    feed = " F3500" if motion == "G1" else ""
    for x, y, z in VERTICES[1:]:
        words.append(f"{motion} X{x:g} Y{y:g} Z{z:g}{feed}")
    return "\n".join([*words, "M2", ""])


def _cycle_s(text: str, machine) -> float:
    opts = RunOptions(lookahead=LookaheadOptions(dynamics="off", plan=PlanOptions()))
    return run_program(interpret_text(text), machine, opts).plan.cycle_time_s


def _exact_stops_s(machine) -> float:
    """Rest to rest on every line, no jerk limit (1e9 mm/s³): L/v + v/a per line, with
    v = min(V, V_i/|t_i|) and a = min(A, A_i/|t_i|) (direction cosines t_i), each line long
    enough to reach v (L ≥ v²/a)."""
    v_i, a_i, _ = machine.axis_limits.as_arrays()
    lim = machine.limits
    total = 0.0
    for p, q in zip(VERTICES[:-1], VERTICES[1:]):
        length = float(np.linalg.norm(q - p))
        t = np.abs(q - p) / length
        with np.errstate(divide="ignore"):
            v = min(lim.v_max_mm_s, float(np.min(v_i / t)))
            a = min(lim.a_max_mm_s2, float(np.min(a_i / t)))
        assert length >= v * v / a
        total += length / v + v / a
    return total


def _without_servo(tmp_path: Path) -> Path:
    """LinuxCNC's limits with no servo model (no contour check): the [servo.*] tables out."""
    kept, skip = [], False
    for row in LINUXCNC_LIMITS.read_text().splitlines():
        if row.startswith("["):
            skip = row.startswith("[servo.")
        if not skip:
            kept.append(row)
    out = tmp_path / "limits_no_servo.toml"
    out.write_text("\n".join(kept) + "\n")
    return out


@pytest.mark.parametrize("motion", ["G0", "G1"])
@pytest.mark.parametrize("tolerance_mm", [0.5, 2.0])
def test_g64_p_is_never_slower_than_exact_stops_under_axis_limits(motion, tolerance_mm, tmp_path):
    """Rapids on the machine with its servo models (rapids are not checked); feed moves on
    the same limits without them (then nothing but the kinematics decides)."""
    machine = load_machine(LINUXCNC_LIMITS if motion == "G0" else _without_servo(tmp_path))
    assert machine.contour_check == (motion == "G0")
    exact = _exact_stops_s(machine)
    g61 = _cycle_s(_program("G61", motion), machine)
    assert g61 == pytest.approx(exact, abs=2e-3)  # the servo clock rounds up to 1 ms
    g64 = _cycle_s(_program(f"G64 P{tolerance_mm:g}", motion), machine)
    assert g64 <= g61 + 1e-9
