"""The corner allowances of the contour guarantee (nurbscnc.plan.allowance): a checked sample
is within the guarantee if it lies within ε_max of the planned path or within ε_max + P of
the programmed vertex of a G64 corner.

References independent of the code under test: the servo's Taylor coefficient c₂ in closed
form from the transfer function's coefficients, the independent servo simulation of
tests/servo_reference.py (scipy.signal.lsim) on the planned reference points, exact
point-to-segment distances to the programmed segments and to the planned points' polyline,
and the G64 vertices read from the program's segments here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan import allowance, turnarounds
from nurbscnc.plan.options import LookaheadOptions, PlanOptions
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.program.interpret import interpret_text
from tests.servo_reference import lsim_actual_mm, segment_distance_mm, stop_at_vertex_mm
from tests.test_turnarounds import _raster_program

ROOT = Path(__file__).resolve().parent.parent
LINUXCNC_LIMITS = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"


def _c2_s2(machine) -> float:
    """The servo's c₂ [s²] in closed form (1 − G(s) = c₁ s + c₂ s² + …), the larger of X, Y."""
    c2 = 0.0
    for ax in (machine.servo.x, machine.servo.y):
        c1 = (ax.a1 - ax.b1) / ax.a0
        c2 = max(c2, abs((ax.a2 - ax.b2 - ax.a1 * c1) / ax.a0 + 0.5 * c1 * c1))
    return c2


def test_stop_deceleration_takes_the_vertex_allowance():
    """A_s = min(A, max(ε / (c₂ s), (ε + P) / (r c₂))), s = sin θ below 90° and 1 from 90°
    on, r = 1.05 (the overshoot's largest ratio to c₂·a): the overshoot lies that far from
    the vertex at any turn; with P = 0 the old bound."""
    machine = load_machine(LINUXCNC_LIMITS)
    lim, c2 = machine.limits, _c2_s2(machine)
    eps = lim.contour_tolerance_mm
    turns = np.radians([30.0, 60.0, 90.0, 135.0, 170.0, 180.0])
    for tol in (0.0, 0.005, 0.015, 0.05):
        got = turnarounds.stop_deceleration_mm_s2(machine, turns, tol)
        s = np.where(turns < 0.5 * np.pi, np.sin(turns), 1.0)
        vertex = (eps + tol) / (1.05 * c2)
        expected = np.minimum(lim.a_max_mm_s2, np.maximum(eps / (c2 * s), vertex))
        np.testing.assert_allclose(got, expected, rtol=1e-9)
    # G64 without P on this profile (P = 15 µm): twice the old bound / r from 90° on.
    np.testing.assert_allclose(
        turnarounds.stop_deceleration_mm_s2(machine, np.radians([170.0]), 0.015),
        [2.0 * eps / (1.05 * c2)],
        rtol=1e-9,
    )
    # P = 50 µm: (ε + P)/(r c₂) ≈ 2171 mm/s², under an axis's 2450 mm/s²; P = 0.1 mm
    # above it (a stop along an axis is then bound by the axis alone).
    assert turnarounds.stop_deceleration_mm_s2(machine, np.radians([90.0]), 0.05)[0] < 2450.0
    assert turnarounds.stop_deceleration_mm_s2(machine, np.radians([90.0]), 0.1)[0] > 2450.0


def test_stop_overshoot_ratio_is_the_largest_in_an_independent_simulation():
    """The overshoot past the vertex of a stop ended at a constant deceleration a (lsim),
    over c₂·a, for stops from 5–58 mm/s at 300–2450 mm/s²: at most r = 1.05, and above 1.04
    somewhere (the ratio is tight)."""
    machine = load_machine(LINUXCNC_LIMITS)
    c2, period = _c2_s2(machine), machine.servo.period_s
    worst = 0.0
    for v in (5.0, 10.0, 25.0, 40.0, 58.3):
        for a in (300.0, 526.0, 800.0, 1052.0, 1300.0, 1578.0, 2000.0, 2450.0):
            n = int(np.ceil(v / (a * period)))
            ramp = np.maximum(v - a * period * np.arange(1, n + 1), 0.0)
            x = np.cumsum(np.concatenate([np.full(300, v), ramp, np.zeros(200)])) * period
            x -= x[300 + n - 1]  # the vertex at the origin
            act = lsim_actual_mm(np.column_stack([x, 0 * x, 0 * x]), machine, settle_s=0.0)
            worst = max(worst, float(act[:, 0].max()) / (c2 * a))
    assert 1.04 < worst <= turnarounds.STOP_OVERSHOOT_RATIO


def _stop_allowed_um(machine, decel_mm_s2: float, turn_deg: float, tol_mm: float) -> tuple:
    """(largest allowed error [µm], largest distance to the path [µm]) of the tool (lsim)
    around a stop at the vertex (the origin) of a two-segment path turning by ``turn_deg``:
    0.3 s at 25 mm/s along +X, a constant deceleration to rest at the vertex, the mirror
    image out along the outgoing segment. Allowed error: min(distance to the path, distance
    to the vertex − P)."""
    act, dense = stop_at_vertex_mm(machine, decel_mm_s2, turn_deg)
    d_path = segment_distance_mm(act, dense)
    allowed = np.minimum(d_path, np.linalg.norm(act, axis=1) - tol_mm)
    return 1000.0 * float(allowed.max()), 1000.0 * float(d_path.max())


@pytest.mark.parametrize("turn_deg", [45.0, 90.0, 120.0, 170.0, 180.0])
@pytest.mark.parametrize("tol_mm", [0.015, 0.03, 0.05])
def test_stop_at_the_allowance_bound_holds_in_an_independent_simulation(turn_deg, tol_mm):
    """Independently of the planner (lsim): a stop from 25 mm/s ended at the bound
    (:func:`stop_deceleration_mm_s2` with P) keeps every sample within ε of the path or
    within ε + P of the vertex; ended at A = 2450 mm/s² it does not for P ≤ 30 µm (61.8 µm
    past the vertex from 90° on); and at the bound from 90° on the overshoot leaves the path by more
    than ε (the allowance is used, not idle)."""
    machine = load_machine(LINUXCNC_LIMITS)
    eps_um = 1000.0 * machine.limits.contour_tolerance_mm
    a_s = float(turnarounds.stop_deceleration_mm_s2(machine, np.radians([turn_deg]), tol_mm)[0])
    allowed_um, off_um = _stop_allowed_um(machine, a_s, turn_deg, tol_mm)
    assert allowed_um <= eps_um
    if tol_mm < 0.04:  # at P = 50 µm a stop at A overshoots by 61.8 µm: within ε + P
        assert _stop_allowed_um(machine, 2450.0, turn_deg, tol_mm)[0] > eps_um
    if turn_deg >= 90.0:
        assert off_um > eps_um + 0.5 * 1000.0 * tol_mm


def _square(p_word: str) -> str:
    return "\n".join(
        [
            f"G21 G17 G90 {p_word}",
            "G0 X0 Y0 Z0",
            "G1 X10 F1500",
            "G1 Y10",
            "G1 X0",
            "G1 Y0",
            "G1 X10",
            "M2",
            "",
        ]
    )


def _reversal(p_word: str) -> str:
    """Out along +X, back at a 170° turn, and home: two sharp corners."""
    th = np.radians(170.0)
    end = np.array([10.0, 0.0]) + 10.0 * np.array([np.cos(th), np.sin(th)])
    return "\n".join(
        [
            f"G21 G17 G90 {p_word}",
            "G0 X0 Y0 Z0",
            "G1 X10 F1500",
            f"G1 X{end[0]:.6f} Y{end[1]:.6f}",
            "G1 X0 Y0",
            "M2",
            "",
        ]
    )


PROGRAMS = {
    "square_g64p005": lambda: _square("G64 P0.05"),
    "reversal_g64": lambda: _reversal("G64"),
    "raster_g64p01": lambda: _raster_program(3, 9.0, 0.5, 0.1),
}
MACHINES = {"default": None, "linuxcnc_limits": LINUXCNC_LIMITS}


def _run(text: str, machine):
    prog = interpret_text(text)
    opts = RunOptions(lookahead=LookaheadOptions(dynamics="local", plan=PlanOptions()))
    return prog, run_program(prog, machine, opts)


def _polyline_distance(q: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Exact distance [mm] of points q (n, 3) to the polyline ``vertices`` (m, 3)."""
    best = np.full(q.shape[0], np.inf)
    for a, b in zip(vertices[:-1], vertices[1:]):
        ab = b - a
        f = np.clip((q - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(q - a - f[:, None] * ab, axis=1))
    return best


def _g64_vertices(prog, path_tolerance_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """The programmed vertices between two feed lines, both under G64, and their P (G64
    without P: the machine's path tolerance), read from the segments here."""
    segs = prog.segments
    vertices, tols = [], []
    for a, b in zip(segs[:-1], segs[1:]):
        if a.kind != "line" or b.kind != "line":
            continue
        p = [path_tolerance_mm if np.isinf(s.blend_mm) else max(s.blend_mm, 0.0) for s in (a, b)]
        if min(p) > 0.0:
            vertices.append(a.end_mm)
            tols.append(min(p))
    return np.array(vertices, dtype=float), np.array(tols)


def _independent_check(prog, run, machine) -> dict:
    """The tool of the independent simulation on the feed samples: its distance to the
    programmed lines, to the planned points' polyline (1 ms apart: chords within 1 µm of
    the plan), to the G64 vertices less their P, and the allowed error (the least of the
    planned-path distance and the vertex distances)."""
    s = run.samples
    actual = lsim_actual_mm(s.points_mm, machine)[: len(s.points_mm)]
    feed = [g for g in prog.segments if g.kind == "line"]
    on = np.isin(s.line, [g.line for g in feed])
    tool = actual[on]
    programmed = np.array([feed[0].start_mm] + [g.end_mm for g in feed], dtype=float)
    d_prog = _polyline_distance(tool, programmed)
    d_plan = _polyline_distance(tool, s.points_mm)
    vertices, tols = _g64_vertices(prog, machine.limits.path_tolerance_mm)
    d_vertex = np.min(np.linalg.norm(tool[:, None, :] - vertices[None], axis=2) - tols, axis=1)
    return {
        "prog_um": 1000.0 * float(d_prog.max()),
        "plan_um": 1000.0 * float(d_plan.max()),
        "allowed_um": 1000.0 * float(np.minimum(d_plan, d_vertex).max()),
        "tol_um": 1000.0 * float(tols.max()),
    }


#: Time [s] the allowance must save at least per program and machine (measured: the
#: square's four stops 116 ms and the reversal 12.6 ms under LinuxCNC's limits, the raster's
#: two turn-arounds 41 ms; on the paper's machine the square and raster are blended, the
#: reversal 1.4 ms).
SAVED_S = {
    ("square_g64p005", "linuxcnc_limits"): 0.08,
    ("reversal_g64", "linuxcnc_limits"): 0.008,
    ("raster_g64p01", "linuxcnc_limits"): 0.025,
    ("reversal_g64", "default"): 0.0008,
}


@pytest.mark.parametrize("machine_name", list(MACHINES))
@pytest.mark.parametrize("name", list(PROGRAMS))
def test_allowance_plan_is_faster_and_within_the_guarantee(name, machine_name, monkeypatch):
    """Each program on each machine, planned with the corner allowances and without them
    (the check as it was): with them, no slower — faster by :data:`SAVED_S` where a stop's
    overshoot decided the time —; and in the independent simulation every feed sample
    within ε of the planned points' polyline or within ε + P of a G64 vertex (+1 µm for the
    chords), and within ε + P of the programmed path everywhere."""
    machine = load_machine(MACHINES[machine_name])
    text = PROGRAMS[name]()
    eps_um = 1000.0 * machine.limits.contour_tolerance_mm
    prog, run = _run(text, machine)
    got = _independent_check(prog, run, machine)
    assert got["allowed_um"] <= eps_um + 1.0
    assert got["prog_um"] <= eps_um + got["tol_um"] + 1.0
    summary = run.check.contour_stats()
    assert summary["contour_corner_samples"] >= 0
    monkeypatch.setattr(allowance, "CORNER_ALLOWANCE", False)
    _, before = _run(text, machine)
    saved_s = before.plan.cycle_time_s - run.plan.cycle_time_s
    assert saved_s >= SAVED_S.get((name, machine_name), -1e-9)
    if (name, machine_name) in SAVED_S:  # a stop's overshoot used the allowance
        assert summary["contour_corner_samples"] > 0
        assert summary["contour_corner_max_um"] > eps_um
        assert summary["contour_true_max_um"] == pytest.approx(
            summary["contour_corner_max_um"], abs=1e-9
        )


@pytest.mark.parametrize("machine_name", list(MACHINES))
def test_g61_plans_are_unchanged(machine_name, monkeypatch):
    """Under G61 (and G61.1) no corner has a tolerance: no allowance, the same plan."""
    machine = load_machine(MACHINES[machine_name])
    for word in ("G61", "G61.1"):
        for text in (_square(word), _reversal(word)):
            prog, run = _run(text, machine)
            monkeypatch.setattr(allowance, "CORNER_ALLOWANCE", False)
            _, before = _run(text, machine)
            monkeypatch.setattr(allowance, "CORNER_ALLOWANCE", True)
            assert run.plan.cycle_time_s == before.plan.cycle_time_s
            assert np.array_equal(run.samples.points_mm, before.samples.points_mm)
            assert run.check.contour_stats()["contour_corner_samples"] == 0


def test_allowance_vertices_are_the_g64_corners_between_feed_moves(monkeypatch):
    """The vertices granted: the G64 feed–feed corners the plan stops at, with the smaller
    P of the two moves (the machine's under G64 without P); none at a dwell, a G61 corner,
    a rapid's ends or the program's end."""
    machine = load_machine(LINUXCNC_LIMITS)
    text = "\n".join(
        [
            "G21 G17 G90 G64 P0.05",
            "G0 X0 Y0 Z0",
            "G1 X10 F1500",  # → (10, 0): a 170° reversal, G64 P0.05 both sides
            "G1 X0.151922 Y1.736482",
            "G64",  # → (0.15, 1.74): P0.05 into G64 without P: the smaller, 15 µm
            "G1 X0.151922 Y11.736482",
            "G4 P0.1",  # a dwell at (0.15, 11.74): no vertex
            "G1 X5.151922",
            "G61",  # (5.15, 11.74): into a G61 move: no tolerance
            "G1 Y1",
            "G64",
            "G0 Z5",  # a feed move meeting a rapid: no vertex
            "M2",
        ]
    )
    prog = interpret_text(text)
    pieces = segment_pieces(prog.segments, machine, PlanOptions(smooth=False))
    got = allowance.corner_allowance(pieces, machine)
    assert got is not None
    np.testing.assert_allclose(got.vertex_mm[:, :2], [[10.0, 0.0], [0.151922, 1.736482]])
    np.testing.assert_allclose(got.tol_mm, [0.05, 0.015])
    # A sample 40 µm past the reversal's vertex along +X on the piece before it is 40 − 50
    # µm beyond the allowance; one 40 µm off the second vertex 25 µm beyond its.
    beyond = got.beyond_mm(
        np.array([[10.04, 0.0, 0.0], [0.151922 - 0.04, 1.736482, 0.0]]), np.array([0, 1])
    )
    np.testing.assert_allclose(beyond, [-0.01, 0.025], atol=1e-9)
    monkeypatch.setattr(allowance, "CORNER_ALLOWANCE", False)
    assert allowance.corner_allowance(pieces, machine) is None


def test_plan_json_reports_the_corner_allowance(tmp_path):
    """``plan --json`` names the samples a corner's allowance took and their largest
    contour error to the planned path (docs/json.md)."""
    from click.testing import CliRunner

    from nurbscnc.cli.main import main

    program = tmp_path / "square.nc"
    program.write_text(_square("G64 P0.05"))
    res = CliRunner().invoke(
        main, ["plan", str(program), "--json", "--machine", str(LINUXCNC_LIMITS)]
    )
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    assert summary["contour_corner_samples"] > 0
    assert summary["contour_corner_max_um"] == pytest.approx(summary["contour_true_max_um"])
    assert 15.0 < summary["contour_corner_max_um"] <= 15.0 + 50.0
