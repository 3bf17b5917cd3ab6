"""Rotary axes end to end: `nurbscnc run` of the rotary programs on a machine with A B C.

The references are independent of the planner:

- LinuxCNC's own moves (``tests/golden/linuxcnc_rotary/``): every programmed end is reached;
- finite differences of the written points against each axis's own limits (the divided
  differences are averages of the derivative, tests/test_limits_on_samples.py explains why
  |Δp/T| ≤ V, |Δ²p/T²| ≤ A, |Δ³p/T³| ≤ J hold exactly, with no discretisation allowance);
- the textbook jerk-limited rest-to-rest time (written out here) for a rotary-only move at its
  F in deg/min and for a G93 move at its programmed rate;
- a machine without the axis refuses the program at the word's line and column.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main

HERE = Path(__file__).resolve().parent
PROGRAMS = HERE / "programs" / "rotary"
GOLDENS = HERE / "golden" / "linuxcnc_rotary"
DEFAULT_PROFILE = HERE.parent / "nurbscnc" / "data" / "default_machine.toml"

#: The rotary axes' limits, unlike each other: v [deg/min], a [deg/s²], j [deg/s³].
ROTARY = {"a": (7200.0, 1200.0, 2.0e4), "b": (5400.0, 900.0, 1.5e4), "c": (3600.0, 600.0, 1.0e4)}
#: The path limits of the bundled profile (SPEC Table 3) [mm/s], [mm/s²], [mm/s³].
V_PATH, A_PATH, J_PATH = 3500.0 / 60.0, 2450.0, 5.0e4
PERIOD_S = 1e-3
#: Position error of the written points (9 decimals in the CSV) [mm or deg].
POINT_ERROR = 1e-9 + 5e-10
#: Rounding allowances of the finite differences (module doc of test_limits_on_samples).
TOL_V = 2 * POINT_ERROR / PERIOD_S
TOL_A = 4 * POINT_ERROR / PERIOD_S**2
TOL_J = 8 * POINT_ERROR / PERIOD_S**3


def profile_text(axes=("a", "b", "c")) -> str:
    text = DEFAULT_PROFILE.read_text()
    for name in axes:
        v, a, j = ROTARY[name]
        text += (
            f"\n[axis_limits.{name}]\nv_max_deg_min = {v}\na_max_deg_s2 = {a}\nj_max_deg_s3 = {j}\n"
        )
    return text


@pytest.fixture(scope="module")
def machine_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rotary") / "machine_abc.toml"
    path.write_text(profile_text())
    return path


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def run_points(program: Path, machine: Path, tmp_path: Path) -> dict:
    """The points CSV of ``nurbscnc run`` as columns (name → array)."""
    out = tmp_path / f"{program.stem}.csv"
    result = cli("run", program, "--machine", machine, "-o", out)
    assert result.exit_code == 0, result.output
    with out.open() as f:
        names = f.readline().strip().split(",")
    data = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, i] for i, name in enumerate(names)}


def golden_moves(name: str) -> list:
    return json.loads((GOLDENS / f"{name}.json").read_text())["moves"]


def rest_to_rest_s(distance: float, v: float, a: float, j: float) -> float:
    """The shortest time [s] of a rest-to-rest move of ``distance`` under velocity ``v``,
    acceleration ``a`` and jerk ``j`` (the textbook seven-phase S-curve; no planner code)."""

    # Ramp to a speed u and back: with a peak acceleration p = min(a, √(u j)), the ramp
    # takes u/p + p/j and covers u (u/p + p/j)/2.
    def ramp(u):
        p = min(a, math.sqrt(u * j))
        return u / p + p / j

    if distance >= v * ramp(v):  # the cruise speed is reached
        return distance / v + ramp(v)
    lo, hi = 0.0, v  # else the peak speed u solves u·ramp(u) = distance
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mid * ramp(mid) < distance else (lo, mid)
    return 2.0 * ramp(lo)


def monotone_run(p: np.ndarray, lo: float, hi: float) -> tuple[int, int]:
    """First and last index of the first run of samples that goes from ``lo`` to ``hi``
    monotonically (standing still allowed) inside that range."""
    sign = 1.0 if hi > lo else -1.0
    inside = (sign * (p - lo) >= -1e-9) & (sign * (hi - p) >= -1e-9)
    forward = np.append(sign * np.diff(p) >= -1e-12, False)
    start = None
    for k in range(p.size):
        if start is None:
            if inside[k] and abs(p[k] - lo) <= 1e-6:
                start = k
            continue
        if not inside[k] or not forward[k - 1]:
            if abs(p[k - 1] - hi) <= 1e-6:
                return start, k - 1
            start = k if inside[k] and abs(p[k] - lo) <= 1e-6 else None
    assert start is not None and abs(p[-1] - hi) <= 1e-6, (lo, hi)
    return start, p.size - 1


def half_speed_interval_s(t: np.ndarray, p: np.ndarray, lo: float, hi: float) -> float:
    """The time [s] between the instants an axis's speed passes half its peak, rising then
    falling, over its one move from ``lo`` to ``hi`` (positions inside that range).

    For a rest-to-rest move whose ramps are symmetric (a jerk-limited S-curve: u(R − τ) =
    v − u(τ) on a ramp of duration R), that interval is R + cruise = distance / v exactly,
    whatever the acceleration and jerk: the move's time at its programmed rate. The sampled
    speed is the mean over a period, which keeps that symmetry."""
    k0, k1 = monotone_run(p, lo, hi)
    speed = np.abs(np.diff(p[k0 : k1 + 1])) / PERIOD_S
    mid_t = t[k0:k1] + PERIOD_S / 2
    half = speed.max() / 2
    above = np.flatnonzero(speed >= half)
    i, j = above[0], above[-1]
    up = mid_t[i - 1] + (half - speed[i - 1]) / (speed[i] - speed[i - 1]) * PERIOD_S
    down = mid_t[j] + (speed[j] - half) / (speed[j] - speed[j + 1]) * PERIOD_S
    return float(down - up)


@pytest.mark.parametrize(
    "name", ["mixed_xyz_a", "arc_with_a", "abc_absolute", "a_incremental", "wrapped_engraving"]
)
def test_axes_within_their_limits_and_every_end_reached(name, machine_file, tmp_path):
    cols = run_points(PROGRAMS / f"{name}.ngc", machine_file, tmp_path)
    assert np.allclose(np.diff(cols["t"]), PERIOD_S, atol=1e-9)
    for axis, (v_min, a_lim, j_lim) in ROTARY.items():
        if axis not in cols:
            continue
        p = cols[axis]
        assert np.max(np.abs(np.diff(p))) / PERIOD_S <= v_min / 60.0 * (1 + 1e-9) + TOL_V
        assert np.max(np.abs(np.diff(p, 2))) / PERIOD_S**2 <= a_lim * (1 + 1e-9) + TOL_A
        assert np.max(np.abs(np.diff(p, 3))) / PERIOD_S**3 <= j_lim * (1 + 1e-9) + TOL_J
    xyz = np.column_stack([cols["x"], cols["y"], cols["z"]])
    speed = np.linalg.norm(np.diff(xyz, axis=0), axis=1) / PERIOD_S
    assert speed.max() <= V_PATH * (1 + 1e-9) + TOL_V
    # Every programmed end of LinuxCNC's moves is passed: A B C to the chord of one period
    # (exactly where a rate changes: a stop), X Y Z within the path tolerance (15 µm: corners
    # where A B C stand blend). The nearest point of the sampled 6-D polyline (mm and degrees
    # weighted alike) to each end.
    abc = np.column_stack([cols.get(a, np.zeros_like(cols["t"])) for a in "abc"])
    pts = np.column_stack([xyz, abc])
    seg = np.diff(pts, axis=0)
    for move in golden_moves(name):
        if move["kind"] not in ("feed", "traverse", "arc"):
            continue
        end = np.array(move["end"])
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.einsum("ij,ij->i", end - pts[:-1], seg) / np.einsum("ij,ij->i", seg, seg)
        u = np.clip(np.nan_to_num(u), 0.0, 1.0)
        near = pts[:-1] + u[:, None] * seg
        k = np.argmin(np.linalg.norm(near - end, axis=1))
        assert np.max(np.abs(near[k, 3:] - end[3:])) <= 2e-4, (move, near[k])
        assert np.linalg.norm(near[k, :3] - end[:3]) <= 15e-3 + 1e-6, (move, near[k])
    last = golden_moves(name)[-1]
    moves = [m for m in golden_moves(name) if "end" in m]
    assert np.allclose(abc[-1], moves[-1]["end"][3:], atol=1e-7), last


def test_rotary_only_moves_at_their_feed_in_degrees_per_minute(machine_file, tmp_path):
    cols = run_points(PROGRAMS / "rotary_only.ngc", machine_file, tmp_path)
    t, a = cols["t"], cols["a"]
    (va, aa, ja), (vb, ab, jb), (vc, ac, jc) = (
        (v / 60.0, acc, jerk) for v, acc, jerk in ROTARY.values()
    )
    # G1 A90 F3600: 60 deg/s; G1 A-90 F1800: 30 deg/s (F in deg/min for a rotary-only move).
    assert half_speed_interval_s(t, a, 0.0, 90.0) == pytest.approx(90.0 / 60.0, abs=1e-4)
    k0, k1 = monotone_run(a, 0.0, 90.0)
    assert np.max(np.abs(np.diff(a[k0 : k1 + 1]))) / PERIOD_S == pytest.approx(60.0, abs=1e-6)
    assert half_speed_interval_s(t, a, 90.0, -90.0) == pytest.approx(180.0 / 30.0, abs=1e-4)
    # The whole program takes the sum of its moves' shortest rest-to-rest times (every
    # rotary-only move starts and ends at rest): G0 Z5 on the path's limits, then each
    # rotary move on the limits of its axes, each scaled by the axis's share of the move.
    total = rest_to_rest_s(5.0, V_PATH, A_PATH, J_PATH)
    total += rest_to_rest_s(90.0, 60.0, aa, ja) + rest_to_rest_s(180.0, 30.0, aa, ja)
    dist = math.hypot(45.0, 45.0)  # G1 B45 C-45 F900: 15 deg/s along √(ΔB² + ΔC²)
    share = 45.0 / dist
    total += rest_to_rest_s(dist, 15.0, min(ab, ac) / share, min(jb, jc) / share)
    deltas = np.array([90.0, 45.0, 45.0])  # G0 A0 B0 C0 from A-90 B45 C-45: the axes' maxima
    dist = float(np.linalg.norm(deltas))
    shares = deltas / dist
    lims = [np.min(np.array(lim) / shares) for lim in ((va, vb, vc), (aa, ab, ac), (ja, jb, jc))]
    total += rest_to_rest_s(dist, *lims)
    assert t[-1] == pytest.approx(total, abs=2 * PERIOD_S)
    assert np.ptp(cols["x"]) == 0.0 and np.ptp(cols["y"]) == 0.0


def test_g93_moves_take_their_inverse_time(machine_file, tmp_path):
    cols = run_points(PROGRAMS / "g93_inverse_time.ngc", machine_file, tmp_path)
    t, x, y, a = cols["t"], cols["x"], cols["y"], cols["a"]
    # G1 X10 A90 F6: 1/6 min = 10 s (1 mm/s along X Y Z, 9 deg/s on A).
    first = a <= 90.0 + 1e-9
    assert half_speed_interval_s(t[first], x[first], 0.0, 10.0) == pytest.approx(10.0, abs=1e-4)
    assert np.max(np.abs(np.diff(x[first]))) / PERIOD_S == pytest.approx(1.0, abs=1e-6)
    # G1 A180 F2: rotary-only, 1/2 min for 90°.
    assert half_speed_interval_s(t, a, 90.0, 180.0) == pytest.approx(30.0, abs=1e-4)
    # G1 X0 Y10 A360 F0.5: 2 min along the 14.1 mm diagonal while A turns 180°.
    assert half_speed_interval_s(t, a, 180.0, 360.0) == pytest.approx(120.0, abs=1e-4)
    third = (a >= 180.0 - 1e-9) & (y <= 10.0 + 1e-9)
    assert half_speed_interval_s(t[third], y[third], 0.0, 10.0) == pytest.approx(120.0, abs=1e-4)


def test_machine_without_the_axis_refuses_at_the_word(tmp_path):
    machine = tmp_path / "xyz_a.toml"
    machine.write_text(profile_text(("a",)))
    program = PROGRAMS / "abc_absolute.ngc"
    result = cli("check", program, "--machine", machine)
    assert result.exit_code == 2, result.output
    lines = program.read_text().splitlines()
    first_b = next(i for i, s in enumerate(lines) if "B" in s.split("(")[0].upper())
    assert f"{program.name}:{first_b + 1}:" in result.output
    assert "Traceback" not in result.output


def test_three_axis_program_writes_no_rotary_column(machine_file, tmp_path):
    program = tmp_path / "square.ngc"
    program.write_text("G21 G90 G64\nG1 X10 F600\nY10\nX0\nY0\nM2\n")
    cols = run_points(program, machine_file, tmp_path)
    assert not {"a", "b", "c"} & set(cols)
