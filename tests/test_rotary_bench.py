"""The 4-axis benchmark's LinuxCNC goldens against their programs (issue 37).

bench/rotary_bench.py records LinuxCNC 2.9's real planner on a 4-axis simulated mill
(bench/linuxcnc_sim_a/: trivkins XYZA, A 30 deg/s and 400 deg/s²) running the programs of
bench/programs/rotary/ into tests/golden/linuxcnc_sim/rotary_<name>.json: the motion span and
the 1 ms path decimated to within ``tolerance_mm``. These tests check the goldens against the
program text and the machine's limits, independently of the recorder and of nurbscnc:

- the path visits every programmed end (X Y Z A), in program order: within the program's
  path tolerance (G64 P) where A stands still on both sides of the end (LinuxCNC's tangent
  arc blends keep P), else within half the two moves' lengths (a parabolic blend, which
  LinuxCNC 2.9 uses where A moves, spans at most half of each move: tp.c,
  tpComputeBlendVelocity, t_blend ≤ length / reachable speed; its P is not kept there: the
  engravings cut corners by up to 0.5 mm and 1.2°), plus the decimation tolerance;
- the motion span is no shorter than A's kinematic lower bound: between two turning points
  of the programmed A (where A's speed is 0) A covers at least the programmed distance less
  the visit tolerance at both ends, rest to rest, at A's limits — or at the larger speed and
  acceleration LinuxCNC reached (where two moves overlap in a parabolic blend A's speed and
  acceleration are both moves' sums, above [AXIS_A]'s: up to 35 deg/s and 600 deg/s²);
- in the indexer, where A moves alone (no blend), A keeps [AXIS_A]'s limits exactly;
- the nurbscnc profile of the benchmark has the sim's limits (both machines alike).

The program ends come from the text by a small parser of the generated programs' literal
words; the live test (skipped, saying why, without LinuxCNC) checks that parser against
``rs274 -g``. The helpers of the benchmark's path comparison are checked against brute force.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import math
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PROGRAMS = ROOT / "bench" / "programs" / "rotary"
GOLDEN = HERE / "golden" / "linuxcnc_sim"
SIM_INI = ROOT / "bench" / "linuxcnc_sim_a" / "config" / "mill_a.ini"
PROFILE = ROOT / "bench" / "programs" / "linuxcnc_sim_a.toml"
PROFILE_3AXIS = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"
NAMES = ("wrapped_engraving_g94", "wrapped_engraving_g93", "indexer_a90")
RS274 = "/usr/bin/rs274"
#: Workpiece radius [mm] of the part-surface metric (x, y, z, r·a·π/180) of the goldens.
RADIUS_MM = 20.0
SERVO_PERIOD_S = 1e-3


def _load(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def ini_sections(path: Path = SIM_INI) -> dict:
    out, section = {}, None
    for line in path.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line.startswith("["):
            section = out.setdefault(line.strip("[]"), {})
        elif "=" in line and section is not None:
            key, value = (x.strip() for x in line.split("=", 1))
            section[key] = value
    return out


def program_moves(text: str) -> list[dict]:
    """The moves of a generated program: ``{"line", "motion", "end": (x, y, z, a) [mm, deg],
    "inverse_time", "f"}`` from its literal words (G0 G1 G2 G3, X Y Z A, G93/G94, F; G90
    only), from the machine's start at 0."""
    pos = {"X": 0.0, "Y": 0.0, "Z": 0.0, "A": 0.0}
    motion, inverse, feed, moves = None, False, None, []
    for number, raw in enumerate(text.splitlines(), 1):
        words = re.findall(r"([A-Z])(-?[\d.]+)", re.sub(r"\(.*?\)", "", raw).upper())
        assert ("G", "91") not in words, "the parser reads absolute programs only"
        moved = False
        for letter, value in words:
            if letter == "G" and value in ("0", "1", "2", "3"):
                motion = int(value)
            elif letter == "G" and value in ("93", "94"):
                inverse = value == "93"
            elif letter == "F":
                feed = float(value)
            elif letter in pos:
                pos[letter] = float(value)
                moved = True
        if moved:
            end = (pos["X"], pos["Y"], pos["Z"], pos["A"])
            moves.append(
                {"line": number, "motion": motion, "end": end, "inverse_time": inverse, "f": feed}
            )
    return moves


def golden(name: str) -> dict:
    return json.loads((GOLDEN / f"rotary_{name}.json").read_text())


def surface(xyza) -> np.ndarray:
    out = np.array(xyza, dtype=float).reshape(-1, 4)
    out[:, 3] *= RADIUS_MM * math.pi / 180.0
    return out


def segment_distances(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance of the point p (4,) to every segment of the polyline (V, 4): (V − 1,)."""
    a, d = poly[:-1], np.diff(poly, axis=0)
    dd = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * d), axis=1)


def path_tolerance_mm(text: str) -> float:
    match = re.search(r"G64\s*P([\d.]+)", text)
    assert match, "the benchmark programs name their path tolerance"
    return float(match.group(1))


def rest_to_rest_s(d: float, v: float, a: float) -> float:
    """Least time [s] to move d ≥ 0 from rest to rest at speed ≤ v and acceleration ≤ a:
    d/v + v/a when the axis reaches v (d ≥ v²/a), else 2√(d/a) (the triangle)."""
    if d <= 0.0:
        return 0.0
    return d / v + v / a if d >= v * v / a else 2.0 * math.sqrt(d / a)


def a_lower_bound_s(ends_deg, slack_deg, v: float, a: float) -> float:
    """A's kinematic lower bound [s] of a path through the A ends (from rest, to rest),
    each end passed within its ``slack_deg``: split at the turning points of the programmed
    A (the path's A has a turning point, speed 0, within the slack of each), each run rest
    to rest over its programmed distance less the slack at both ends."""
    a_deg, slack = [float(ends_deg[0])], [float(slack_deg[0])]
    for x, e in zip(ends_deg[1:], slack_deg[1:]):
        if x != a_deg[-1]:
            a_deg.append(float(x))
            slack.append(float(e))
        else:  # A stands: the tighter of the two places bounds where the path's A is
            slack[-1] = min(slack[-1], float(e))
    steps = np.diff(a_deg)
    total, start = 0.0, 0
    for k, step in enumerate(steps):
        if k + 1 == len(steps) or np.sign(steps[k + 1]) != np.sign(step):
            d = abs(a_deg[k + 1] - a_deg[start]) - slack[start] - slack[k + 1]
            total += rest_to_rest_s(d, v, a)
            start = k + 1
    return total


def visit_tolerances_mm(text: str, decimation_mm: float) -> tuple[list[dict], np.ndarray]:
    """The program's moves and, per move end, how close the recorded path must pass [mm,
    part-surface metric]: P where A stands on both sides, else max(P, (L_in + L_out)/2);
    plus ``decimation_mm``; 0 + ``decimation_mm`` at the last end (the machine stops)."""
    moves = program_moves(text)
    p_mm = path_tolerance_mm(text)
    ends = surface([(0.0, 0.0, 0.0, 0.0)] + [m["end"] for m in moves])
    length = np.linalg.norm(np.diff(ends, axis=0), axis=1)
    a_moves = np.diff(np.array([0.0] + [m["end"][3] for m in moves])) != 0.0
    tol = np.empty(len(moves))
    for i in range(len(moves)):
        nxt = i + 1 < len(moves)
        half = 0.5 * (length[i] + (length[i + 1] if nxt else 0.0))
        a_near = a_moves[i] or (nxt and a_moves[i + 1])
        tol[i] = (max(p_mm, half) if a_near else p_mm) if nxt else 0.0
    return moves, tol + decimation_mm


# --------------------------------------------------------------------------- configuration


def test_profile_has_the_sim_limits():
    """The nurbscnc profile of the benchmark is the 3-axis LinuxCNC profile plus an A axis
    with the sim's [AXIS_A] and [JOINT_3] limits (deg/min = 60 × deg/s), and the sim's X Y Z
    limits are the 3-axis profile's."""
    ini = ini_sections()
    profile = tomllib.loads(PROFILE.read_text())
    a = profile["axis_limits"].pop("a")
    assert profile == tomllib.loads(PROFILE_3AXIS.read_text())
    for section in ("AXIS_A", "JOINT_3"):
        assert a["v_max_deg_min"] == 60.0 * float(ini[section]["MAX_VELOCITY"])
        assert a["a_max_deg_s2"] == float(ini[section]["MAX_ACCELERATION"])
        assert (a["min_deg"], a["max_deg"]) == (
            float(ini[section]["MIN_LIMIT"]),
            float(ini[section]["MAX_LIMIT"]),
        )
    assert a["wrapped"] is ("WRAPPED_ROTARY" in ini["AXIS_A"])
    assert a["j_max_deg_s3"] == profile["limits"]["j_max_mm_s3"]  # no jerk limit alike
    assert ini["KINS"]["KINEMATICS"] == "trivkins coordinates=XYZA"
    for axis in "xyz":
        limits = profile["axis_limits"][axis]
        v_mm_s = float(ini[f"AXIS_{axis.upper()}"]["MAX_VELOCITY"])  # 3500/60 to 9 decimals
        assert limits["v_max_mm_min"] == pytest.approx(60.0 * v_mm_s, rel=1e-10)
        assert limits["a_max_mm_s2"] == float(ini[f"AXIS_{axis.upper()}"]["MAX_ACCELERATION"])


def test_programs_are_the_generators():
    """The committed programs are what make_rotary_programs.py writes."""
    gen = _load(PROGRAMS / "make_rotary_programs.py", "make_rotary_programs")
    assert (PROGRAMS / "wrapped_engraving_g94.ngc").read_text() == gen.engraving(False)
    assert (PROGRAMS / "wrapped_engraving_g93.ngc").read_text() == gen.engraving(True)
    assert (PROGRAMS / "indexer_a90.ngc").read_text() == gen.indexer()
    assert gen.RADIUS_MM == RADIUS_MM


# --------------------------------------------------------------------------- goldens


@pytest.mark.parametrize("name", NAMES)
def test_golden_is_of_this_program_and_config(name):
    g = golden(name)
    program = ROOT / g["program"]
    assert program == PROGRAMS / f"{name}.ngc"
    assert hashlib.sha256(program.read_bytes()).hexdigest() == g["program_sha256"]
    assert hashlib.sha256(SIM_INI.read_bytes()).hexdigest() == g["ini_sha256"]
    assert g["radius_mm"] == RADIUS_MM
    assert g["sample_gaps"] == 0 and g["overruns"] == 0
    rows = np.array(g["path"]["rows"])
    # the path is the motion span: from the start at rest (t = 0) to the end at rest
    assert rows[0, 0] == 0.0
    assert rows[-1, 0] == pytest.approx(g["cycle_time_s"], abs=1e-9)
    assert np.all(np.diff(rows[:, 0]) > 0)
    assert g["samples"] == round(g["cycle_time_s"] / SERVO_PERIOD_S) + 1


@pytest.mark.parametrize("name", NAMES)
def test_golden_path_visits_every_programmed_end_in_order(name):
    """Each end (X Y Z A) of the program's moves lies within its visit tolerance
    (visit_tolerances_mm) of the recorded path, at or after the previous end's place; the
    path starts at the machine's start (0) and ends at the last end."""
    g = golden(name)
    text = (PROGRAMS / f"{name}.ngc").read_text()
    poly = surface(np.array(g["path"]["rows"])[:, 1:5])
    moves, tol = visit_tolerances_mm(text, g["path"]["tolerance_mm"])
    assert np.abs(poly[0]).max() <= 1e-9
    assert np.abs(poly[-1] - surface(moves[-1]["end"])[0]).max() <= 1e-6
    at = 0
    for move, tol_mm in zip(moves, tol):
        d = segment_distances(surface(move["end"])[0], poly)
        near = np.flatnonzero(d[at:] <= tol_mm)
        assert near.size, f"line {move['line']}: {move['end']} not within {tol_mm} mm"
        at += int(near[0])


@pytest.mark.parametrize("name", NAMES)
def test_golden_time_is_above_as_kinematic_bound(name):
    """The motion span ≥ A's lower bound (a_lower_bound_s) at A's limits, or at the larger
    speed and acceleration the golden records (LinuxCNC's parabolic blends exceed them)."""
    g = golden(name)
    text = (PROGRAMS / f"{name}.ngc").read_text()
    ini = ini_sections()
    v = max(float(ini["AXIS_A"]["MAX_VELOCITY"]), g["a_speed_max_deg_s"])
    a = max(float(ini["AXIS_A"]["MAX_ACCELERATION"]), g["a_accel_max_deg_s2"])
    moves, tol = visit_tolerances_mm(text, g["path"]["tolerance_mm"])
    deg_per_mm = 180.0 / (math.pi * RADIUS_MM)
    ends = [0.0] + [m["end"][3] for m in moves]
    bound = a_lower_bound_s(ends, [0.0, *(tol * deg_per_mm)], v, a)
    assert bound > 10.0  # the programs turn A by 360° or more: the bound is not vacuous
    assert g["cycle_time_s"] >= bound


def test_indexer_a_within_the_sims_limits():
    """Where A moves alone (the indexer's G0 A), LinuxCNC keeps [AXIS_A]'s speed and
    acceleration on the 1 ms samples (the golden's peaks, by finite differences) and
    reaches them (90° at 30 deg/s)."""
    g = golden("indexer_a90")
    ini = ini_sections()
    v, a = float(ini["AXIS_A"]["MAX_VELOCITY"]), float(ini["AXIS_A"]["MAX_ACCELERATION"])
    assert g["a_speed_max_deg_s"] == pytest.approx(v, rel=1e-6)
    assert a * (1 - 1e-6) <= g["a_accel_max_deg_s2"] <= a * (1 + 1e-6)


# --------------------------------------------------------------------------- helpers


def test_lower_bound_of_simple_runs():
    """0 → 90 → 0 at 30 deg/s and 400 deg/s²: two rest-to-rest runs of 90° (each
    90/30 + 30/400 = 3.075 s); a short run of 1° is a triangle, 2√(1/400) = 0.1 s."""
    assert a_lower_bound_s([0, 45, 90, 0], [0] * 4, 30.0, 400.0) == pytest.approx(6.15)
    assert a_lower_bound_s([0, 0, 1], [0] * 3, 30.0, 400.0) == pytest.approx(0.1)
    # 1° of slack at the turning point 90: two runs of 89°
    assert a_lower_bound_s([0, 90, 0], [0, 1, 0], 30.0, 400.0) == pytest.approx(
        2 * (89 / 30 + 30 / 400)
    )


def test_program_parser_on_a_small_program():
    text = "G21 G90 G64 P0.01\nG0 Z5 (up)\nG93 G1 X1 A90 F2\nG94 G0 A0\n"
    moves = program_moves(text)
    assert [m["end"] for m in moves] == [(0, 0, 5, 0), (1, 0, 5, 90), (1, 0, 5, 0)]
    assert [(m["motion"], m["inverse_time"], m["f"]) for m in moves] == [
        (0, False, None),
        (1, True, 2.0),
        (0, False, 2.0),
    ]


def test_bench_path_helpers_against_brute_force():
    """bench/rotary_bench.py's decimation keeps every sample within its tolerance, and its
    nearest points on a polyline are the brute-force nearest (every segment tried)."""
    bench = _load(ROOT / "bench" / "rotary_bench.py", "rotary_bench")
    rng = np.random.default_rng(37)
    t = np.linspace(0.0, 1.0, 3001)
    helix = np.column_stack([np.cos(9 * t), np.sin(9 * t), t, 100 * t**2])
    keep = bench.decimate(helix, 1e-3)
    assert keep[0] == 0 and keep[-1] == t.size - 1 and keep.size < t.size / 5
    worst = max(segment_distances(p, helix[keep]).min() for p in helix[::5])
    assert worst <= 1e-3
    points = helix[::97] + rng.normal(scale=0.05, size=(31, 4))
    feet = bench.nearest_on_polyline(points, helix[keep])
    for p, foot in zip(points, feet):
        assert np.linalg.norm(p - foot) == pytest.approx(
            segment_distances(p, helix[keep]).min(), abs=1e-12
        )
    dense = bench.densify(helix[keep], 0.01)
    assert np.linalg.norm(np.diff(dense, axis=0), axis=1).max() <= 0.01 + 1e-12
    assert all(np.isclose(dense, v).all(axis=1).any() for v in helix[keep])


def test_bench_runs_nurbscnc_without_crashing(tmp_path):
    """The benchmark's nurbscnc side on the indexer: nurbscnc runs it, and its CSV has the
    ``a`` column, the ratio and both ways of path agreement; never a crash or a refusal."""
    bench = _load(ROOT / "bench" / "rotary_bench.py", "rotary_bench")
    case = next(c for c in bench.CASES if c.name == "indexer_a90")
    row = bench.nurbscnc_row(case, golden("indexer_a90"), tmp_path)
    assert "error" not in row, row.get("error")
    assert "refused" not in row, row.get("refused")
    assert row["ratio"] == pytest.approx(
        row["cycle_time_s"] / golden("indexer_a90")["cycle_time_s"]
    )
    agreement = row["path_agreement"]
    assert set(agreement) >= {"nurbscnc_to_linuxcnc", "linuxcnc_to_nurbscnc"}


def test_recorder_trims_to_the_motion_of_any_axis(tmp_path):
    """bench/linuxcnc_sim_a/lcnc_raw2csv_a.py on a hand-made halsampler recording (tag,
    line, x y z in µm, a in millidegrees): a move of A alone is motion; the CSV keeps the
    last sample at rest before it and the first after it, in mm and degrees, t from 0."""
    raw = tmp_path / "samples.raw"
    a_mdeg = [0, 0, 0, 500, 1500, 2000, 2000, 2000]
    raw.write_text("".join(f"{k} 7 1000 0 -5 {a}\n" for k, a in enumerate(a_mdeg, 40)))
    status = tmp_path / "out.csv.status.json"
    status.write_text(json.dumps({"errors": [], "overruns": 0}))
    out = tmp_path / "out.csv"
    script = ROOT / "bench" / "linuxcnc_sim_a" / "lcnc_raw2csv_a.py"
    res = subprocess.run(
        [sys.executable, str(script), str(raw), str(out), str(status)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 0, res.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == "t,x,y,z,a,line"
    rows = np.array([[float(v) for v in r.split(",")] for r in lines[1:]])
    np.testing.assert_allclose(rows[:, 4], [0.0, 0.5, 1.5, 2.0])
    np.testing.assert_allclose(rows[:, 0], [0.0, 0.001, 0.002, 0.003])
    np.testing.assert_allclose(rows[:, 1:4], [[1.0, 0.0, -0.005]] * 4)
    recorded = json.loads(status.read_text())
    assert (recorded["samples"], recorded["cycle_time_s"], recorded["sample_gaps"]) == (
        4,
        0.003,
        0,
    )


# --------------------------------------------------------------------------- live


def _rs274_missing() -> str | None:
    if not shutil.which(RS274):
        return f"LinuxCNC's {RS274} is not installed (the goldens are checked without it)"
    return None


@pytest.mark.parametrize("name", NAMES)
def test_program_ends_are_what_rs274_says(name):
    """The parser's ends are LinuxCNC's interpreter's (rs274 -g: x y z a b c, 4 decimals)."""
    missing = _rs274_missing()
    if missing:
        pytest.skip(missing)
    path = PROGRAMS / f"{name}.ngc"
    res = subprocess.run([RS274, "-g", str(path)], capture_output=True, text=True, timeout=60)
    ends = []
    for line in res.stdout.splitlines():
        m = re.search(r"(STRAIGHT_TRAVERSE|STRAIGHT_FEED|ARC_FEED)\((.*)\)", line)
        if m:
            v = [float(x) for x in m.group(2).split(",")]
            # ARC_FEED (G17): first end, second end, centre (2), turn, axis end, a, b, c
            ends.append((v[0], v[1], v[5], v[6]) if m.group(1) == "ARC_FEED" else tuple(v[:4]))
    moves = program_moves(path.read_text())
    assert len(ends) == len(moves)
    np.testing.assert_allclose(np.array(ends), np.array([m["end"] for m in moves]), atol=6e-5)
