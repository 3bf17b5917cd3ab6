"""Planner v2 (issue 13): local shaping in the contour check, the settle after a rapid, the
fallback, and cycle time against the programmed feed.

Every contour error here is measured independently: the output reference points through
``scipy.signal.lsim`` of SPEC eq. 25 (tests/servo_reference.py, first-order hold, settling
appended), distance to a dense polyline of the programmed path built from the program's own
vertices (lines only, so the polyline is exact up to its vertex spacing).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nurbscnc.machine.profile import default_profile_text, load_machine, parse_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan import allowance, converge, lookahead, shaping, windows
from nurbscnc.plan import setup as plan_setup
from nurbscnc.plan.junctions import settle_time_s
from nurbscnc.plan.options import LookaheadOptions
from nurbscnc.program.interpret import interpret_text
from tests.servo_reference import distance_to_polyline_mm, lsim_actual_mm

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "tests" / "programs" / "planner"
MACHINE = load_machine()
EPS_MM = MACHINE.limits.contour_tolerance_mm
SPACING_MM = 2e-4  # polyline vertex spacing: adds ≤ h²/(8d) ≈ 0.3 nm at d = 15 µm


def _polyline(vertices: np.ndarray) -> np.ndarray:
    """Dense points along the straight edges between consecutive ``vertices`` (m, 3)."""
    out = []
    for a, b in zip(vertices[:-1], vertices[1:]):
        n = max(int(np.ceil(np.linalg.norm(b - a) / SPACING_MM)), 1)
        out.append(a + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a))
    return np.vstack(out)


def _cut_vertices(text: str) -> np.ndarray:
    """The vertices of the G1 path of a program of absolute XY moves: the end of the last
    rapid before the first G1, then every G1 end point (the parser of this test only)."""
    pts, cur, cutting = [], np.zeros(3), False
    for line in text.splitlines():
        words = line.split(";")[0].split()
        if not words:
            continue
        new = cur.copy()
        for w in words:
            if w[0] in "XYZ":
                new["XYZ".index(w[0])] = float(w[1:])
        if "G1" in words or (cutting and any(w[0] in "XY" for w in words) and "G0" not in words):
            if not cutting:
                pts.append(cur.copy())
                cutting = True
            pts.append(new.copy())
        cur = new
    return np.array(pts)


def _lsim_error_while_cutting_mm(run, machine=MACHINE) -> float:
    """Largest independent contour error [mm] from the first cutting sample on (samples
    on rapids and during the settle after one excluded), settling after the end included."""
    smp = run.samples
    actual = lsim_actual_mm(smp.points_mm, machine)
    prof = run.plan.profile
    cut_piece = ~run.plan.pieces.rapid[smp.piece]
    # The cut starts when the reference leaves the rapid's end point (the settle waits).
    moving = np.append(np.any(np.diff(smp.points_mm, axis=0) != 0.0, axis=1), False)
    first = int(np.argmax(cut_piece & moving))
    assert prof.duration_s > 0
    return actual, first


def _check_program(path: Path, machine=MACHINE):
    text = path.read_text()
    run = run_program(interpret_text(text), machine)
    actual, first = _lsim_error_while_cutting_mm(run, machine)
    d = distance_to_polyline_mm(actual[first:], _polyline(_cut_vertices(text)))
    return run, float(d.max())


@pytest.mark.parametrize("name", ["square_g61_f1000.nc", "square_g61_f3000.nc", "pentagram_g61.nc"])
def test_independent_contour_error_within_eps(name):
    run, err_mm = _check_program(PROGRAMS / name)
    assert err_mm <= EPS_MM + 1e-6


def test_g61_square_faster_at_higher_feed_and_stops_are_shaped_not_slowed():
    """F3000 beats F1000 (it did not: 8.81 s vs 8.62 s, issue 13); the edges cruise at
    the programmed feed (caps untouched) and the stops are shaped by the descent jerk."""
    slow, _ = _check_program(PROGRAMS / "square_g61_f1000.nc")
    fast, _ = _check_program(PROGRAMS / "square_g61_f3000.nc")
    assert fast.cycle_time_s < slow.cycle_time_s
    plan = fast.plan
    cut = ~plan.pieces.rapid
    np.testing.assert_array_equal(plan.caps_mm_s[cut], 50.0)
    assert plan.shaped_by_contour[cut].any() and plan.contour_transition[cut].any()
    assert not plan.contour_feed.any()
    j = MACHINE.limits.j_max_mm_s3
    assert np.all(plan.limits.j_down_mm_s3 <= j) and plan.limits.j_down_mm_s3[cut].min() < j
    # Every edge reaches its cruise: the time is the kinematic one plus a few ms per stop.
    off = run_program(
        interpret_text((PROGRAMS / "square_g61_f3000.nc").read_text()),
        MACHINE,
        RunOptions(lookahead=LookaheadOptions(dynamics="off")),
    )
    assert fast.cycle_time_s < off.cycle_time_s + 4 * 0.02


def test_pentagram_within_the_issue_target():
    """Five 38 mm edges at F3500 under G61, the rapid to the first vertex included: ≤ 4.3 s
    (LinuxCNC 3.75 s at 66–80 µm; the cap-lowering check took 20.1 s)."""
    run, err_mm = _check_program(PROGRAMS / "pentagram_g61.nc")
    assert err_mm <= EPS_MM + 1e-6
    assert run.cycle_time_s <= 4.3


def _slow_servo_machine():
    """The default machine with light-damped, slow X/Y servos (20 Hz, ζ = 0.35): a rapid's
    stop rings long enough to spoil the cut after it unless the cut waits."""
    text = default_profile_text()
    i, j = text.index("\n[servo.x]"), text.index("# [servo.z]")
    servo = "".join(f"\n[servo.{a}]\nbandwidth_hz = 20.0\ndamping = 0.35\n" for a in "xy")
    return parse_machine(text[:i] + servo + "\n" + text[j:])


def test_ringing_servo_never_crawls_on_a_nurbs_corpus_program():
    """On the 20 Hz ringing servo, G6_Curva_Delfino_v1 is within ε_max at most 2 % slower
    than its kinematic plan (45.46 s). The curve lever once halved the feed of two short
    pieces at every re-plan while the error there (the servo ringing from further back)
    stayed at 18.68 µm: 36,498 s of cycle time after 23 re-plans."""
    from tests.test_corpus import corpus_dir

    path = corpus_dir() / "linuxcnc" / "nurbs" / "G6_Curva_Delfino_v1.ngc"
    if not path.is_file():
        pytest.skip(f"corpus program {path} absent (set NURBSCNC_CORPUS to the corpus folder)")
    prog = interpret_text(path.read_text())
    slow = _slow_servo_machine()
    on, check = lookahead.plan_checked(prog, slow, keep_reference=False)
    off, _ = lookahead.plan_checked(
        prog, slow, LookaheadOptions(dynamics="off"), keep_reference=False
    )
    assert check.overs.worst_mm <= slow.limits.contour_tolerance_mm
    assert on.iterations <= converge.LOCAL_ITERATIONS
    assert on.cycle_time_s <= 1.02 * off.cycle_time_s


def _machine_with_jerk(j_mm_s3: float):
    text = default_profile_text().replace("j_max_mm_s3 = 5.0e4", f"j_max_mm_s3 = {j_mm_s3!r}")
    machine = parse_machine(text)
    assert machine.limits.j_max_mm_s3 == j_mm_s3
    return machine


@pytest.mark.parametrize("name", ["square_g61_f1000.nc", "square_g61_f3000.nc", "pentagram_g61.nc"])
def test_a_higher_jerk_limit_is_never_slower(name):
    """J = 1e9 (LinuxCNC's planner has no jerk limit) against the paper's 5e4: within ε_max
    (independent lsim) and no slower. A jerk phase far shorter than the servo's time
    constant is a step of acceleration to the servo, and softening it by a factor hardly
    moved the error, so the check took the stops as "ineffective" and lowered the feed:
    the pentagram took 35.5 s at J = 1e9 against 4.02 s at 5e4, the F1000 square 16.5 s
    against 4.95 s. Softening now starts from A·|p| (|p| the slowest servo pole's rate)."""
    paper_run, _ = _check_program(PROGRAMS / name)
    fast = _machine_with_jerk(1e9)
    run, err_mm = _check_program(PROGRAMS / name, fast)
    assert err_mm <= EPS_MM + 1e-6
    assert run.cycle_time_s <= paper_run.cycle_time_s


def test_settle_after_a_rapid_is_what_the_check_needs(tmp_path):
    """Zero on the paper's machine (the rapid's overshoot is over before the cut moves);
    on a ringing servo a wait shorter than 5/|pole|, and the cut within ε_max."""
    text = "G21 G90 G17\nG0 X30 Y0\nG1 X30 Y10 F300\nM2\n"
    path = tmp_path / "rapid_then_cut.nc"
    path.write_text(text)
    run, err_mm = _check_program(path)
    assert err_mm <= EPS_MM + 1e-6
    assert run.plan.settle_s[0] == 0.0
    slow = _slow_servo_machine()
    run, err_mm = _check_program(path, slow)
    assert err_mm <= EPS_MM + 1e-6
    assert 0.0 < run.plan.settle_s[0] < settle_time_s(slow)
    # The settle is a dwell of the plan: the reference rests at the cut's start that long.
    at_start = np.all(run.samples.points_mm == [30.0, 0.0, 0.0], axis=1)
    period = slow.servo.period_s
    assert at_start.sum() * period == pytest.approx(run.plan.settle_s[0], abs=2.5 * period)


def test_fallback_alone_converges(monkeypatch, tmp_path):
    """With no local re-plans the fallback (all levers of the blamed pieces, then of every
    cutting piece, scaled down) still ends within ε_max: error → 0 as v, a, j → 0."""
    monkeypatch.setattr(converge, "LOCAL_ITERATIONS", 0)
    run, err_mm = _check_program(PROGRAMS / "square_g61_f3000.nc")
    assert err_mm <= EPS_MM + 1e-6
    assert run.plan.iterations > 0 and run.plan.shaped_by_contour.any()


def test_airfoils_check_reaches_the_kinematic_plan_closely():
    """The 9 mm NACA 2415 block at 0°, ±45°: within ε_max (test_lookahead checks that
    independently) at most 5 % slower than the kinematic plan alone (--dynamics off); the
    cap-lowering check lost 13 %."""
    for name in ("naca2415.nc", "naca2415_rot45.nc", "naca2415_rot-45.nc"):
        prog = interpret_text((ROOT / "programs" / name).read_text())
        on = run_program(prog, MACHINE).plan
        off = run_program(
            prog, MACHINE, RunOptions(lookahead=LookaheadOptions(dynamics="off"))
        ).plan
        assert on.cycle_time_s <= 1.05 * off.cycle_time_s


_vertex = st.tuples(st.integers(-8, 8), st.integers(-8, 8))


@settings(
    max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    st.lists(_vertex, min_size=2, max_size=4, unique=True),
    st.sampled_from(["G61", "G64"]),
    st.integers(300, 3000),
    st.integers(100, 500),
)
def test_cycle_time_non_increasing_in_feed(vertices, mode, feed, step):
    """Raising the programmed feed never lengthens the cycle (issue 13). The shaped levers
    are bisected to within IMPROVE_RATIO of their bounds, so two plans may differ by that
    resolution: 0.5 % of the cycle."""

    def cycle(f):
        lines = ["G21 G90 G17", mode, f"G0 X{vertices[0][0]} Y{vertices[0][1]}", f"F{f}"]
        lines += [f"G1 X{x} Y{y}" for x, y in vertices[1:]]
        return run_program(interpret_text("\n".join(lines + ["M2"]) + "\n"), MACHINE).cycle_time_s

    assert cycle(feed + step) <= cycle(feed) * 1.005


def test_plan_uses_the_axes_piece_limits(monkeypatch):
    """plan_checked plans with nurbscnc.plan.axes.piece_limits: a piece given a lower feed,
    acceleration and jerk keeps them on the samples (finite differences of s)."""
    from nurbscnc.plan import axes

    real = axes.piece_limits

    def lowered(pieces, machine):
        lim = real(pieces, machine)
        v, a, j = lim.v_mm_s.copy(), lim.a_mm_s2.copy(), lim.j_mm_s3.copy()
        v[-1], a[-1], j[-1] = 20.0, 400.0, 8e3  # the last edge only
        return axes.PieceLimits(v, a, j)

    monkeypatch.setattr(plan_setup, "piece_limits", lowered)
    text = "G21 G90 G17\nG61\nG1 X20 F3000\nG1 X20 Y20\nM2\n"
    run = run_program(
        interpret_text(text), MACHINE, RunOptions(lookahead=LookaheadOptions(dynamics="off"))
    )
    smp = run.samples
    period = MACHINE.servo.period_s
    v = np.diff(smp.s_mm) / period
    a = np.diff(v) / period
    jerk = np.diff(a) / period
    last = run.plan.pieces.length_mm.size - 1
    on_last = smp.piece[1:] == last  # interval k → k+1 ends on the last edge
    assert v[on_last].max() <= 20.0 * (1 + 1e-9)
    assert v[on_last].max() == pytest.approx(20.0, rel=1e-6)  # it cruises there
    # A difference spanning the junction mixes both pieces: only wholly inside the last.
    inside = (smp.piece[:-2] == last) & (smp.piece[2:] == last)
    assert np.abs(a[inside]).max() <= 400.0 * (1 + 1e-6)
    inside3 = inside[:-1] & (smp.piece[3:] == last)
    assert np.abs(jerk[inside3]).max() <= 8e3 * (1 + 1e-6)
    # The first edge keeps the machine's limits (and uses them).
    first = (smp.piece[:-2] == 0) & (smp.piece[2:] == 0)
    assert np.abs(a[first]).max() > 400.0
    np.testing.assert_array_equal(run.plan.limits.a_up_mm_s2, [MACHINE.limits.a_max_mm_s2, 400.0])


def test_restores_raise_a_feed_the_joint_tries_left_low(monkeypatch):
    """After the improvement phase's joint tries, the feed caps with the most time to gain are
    tried alone at their upper brackets (RESTORE_PIECES; a joint try fails on any one lever,
    so a feed lowered where it did not help stayed low). A 2 mm square pocketed after a
    plunge (G64 P0.01, F1200): faster with them (measured 0.8592 → 0.8530 s), each kept
    plan within ε_max by the independent simulation. Its 2 mm edges take 0.1 s, so the
    curve rule lowers their feed only with long pieces' cruise not spared
    (``LONG_PIECE_S`` = inf; spared, 0.8544 s with or without the restores)."""
    path = PROGRAMS / "square_plunge_g64p.nc"
    monkeypatch.setattr(shaping, "LONG_PIECE_S", np.inf)
    run, err_mm = _check_program(path)
    monkeypatch.setattr(converge, "RESTORE_PIECES", 0)
    before, err_before_mm = _check_program(path)
    assert err_mm <= EPS_MM + 1e-6 and err_before_mm <= EPS_MM + 1e-6
    assert run.cycle_time_s < before.cycle_time_s - 0.003
    assert run.plan.iterations > before.plan.iterations
    # The restores changed feed caps only (raised them): the joint phase before them is the
    # same with or without them.
    assert np.all(run.plan.caps_mm_s >= before.plan.caps_mm_s)
    assert np.any(run.plan.caps_mm_s > before.plan.caps_mm_s * (1 + 1e-9))
    for name in ("a_up_mm_s2", "j_up_mm_s3", "a_down_mm_s2", "j_down_mm_s3"):
        np.testing.assert_array_equal(
            getattr(run.plan.limits, name), getattr(before.plan.limits, name)
        )
    np.testing.assert_array_equal(run.plan.settle_s, before.plan.settle_s)


def test_restores_in_each_cut_window(monkeypatch):
    """Two plunged squares, each a cut window of its own: the restores run in each window
    (feed caps raised in both, against RESTORE_PIECES = 0), the program is faster, and the
    independently simulated tool stays within ε_max of each square while it is cut (long
    pieces' cruise not spared: ``LONG_PIECE_S`` = inf, as in the test above)."""
    monkeypatch.setattr(shaping, "LONG_PIECE_S", np.inf)
    text = (
        "G21 G17 G90 G94\nG64 P0.01\nF1200\nG0 Z2\nG0 X0 Y0\nG1 Z-1\nG1 X2\nG1 Y2\n"
        "G1 X0\nG1 Y0\nG0 Z2\nG0 X6 Y0\nG1 Z-1\nG1 X9\nG1 Y3\nG1 X6\nG1 Y0\nM2\n"
    )
    cuts = [
        np.array([[0, 0, 2], [0, 0, -1], [2, 0, -1], [2, 2, -1], [0, 2, -1], [0, 0, -1]]),
        np.array([[6, 0, 2], [6, 0, -1], [9, 0, -1], [9, 3, -1], [6, 3, -1], [6, 0, -1]]),
    ]
    prog = interpret_text(text)
    run = run_program(prog, MACHINE)
    monkeypatch.setattr(converge, "RESTORE_PIECES", 0)
    before = run_program(prog, MACHINE)
    assert run.cycle_time_s < before.cycle_time_s - 0.005
    pieces = run.plan.pieces
    starts = windows.cut_windows(pieces)
    assert starts.size == 2
    raised = np.flatnonzero(run.plan.caps_mm_s > before.plan.caps_mm_s * (1 + 1e-9))
    assert (raised < starts[1]).any() and (raised >= starts[1]).any()
    smp = run.samples
    actual = lsim_actual_mm(smp.points_mm, MACHINE)  # the end's settling appended
    piece = np.append(smp.piece, np.full(actual.shape[0] - smp.piece.size, smp.piece[-1]))
    window = np.searchsorted(starts, piece, side="right") - 1
    moving = np.any(np.diff(smp.points_mm, axis=0) != 0.0, axis=1)
    moving = np.append(moving, np.zeros(actual.shape[0] - moving.size, dtype=bool))
    for w, vertices in enumerate(cuts):
        on_cut = (window == w) & ~pieces.rapid[piece]
        first = int(np.argmax(on_cut & moving))
        sel = on_cut & (np.arange(piece.size) >= first)
        d = distance_to_polyline_mm(actual[sel], _polyline(vertices.astype(float)))
        assert d.max() <= EPS_MM + 1e-6


LINUXCNC_LIMITS = ROOT / "bench" / "programs" / "linuxcnc_limits.toml"


def _arc_program_check(path: Path, machine):
    """Run ``path`` (lines and arcs) and measure it independently: the largest lsim allowed
    error [mm] of the cutting samples (bench/contour.py ``allowed_error_mm``: the distance
    to its dense polyline of the programmed path — its own closed-form arc sampling, tested
    in test_bench_tools.py — by point-to-segment distance, the nearest vertex would add up
    to h²/(8d), 0.6 µm at its 8.5 µm spacing on an arc and d = 15 µm; where that is over
    ε_max, the least of it, the distance to the planned points' polyline and the distance to
    a G64 vertex less its P: the guarantee of nurbscnc.plan.allowance)."""
    import sys

    sys.path.insert(0, str(ROOT / "bench"))
    import contour

    prog = interpret_text(path.read_text())
    run = run_program(prog, machine)
    actual, first = _lsim_error_while_cutting_mm(run, machine)
    polyline = contour.path_polyline_mm(prog.segments)
    d_mm = contour.distance_to_polyline_mm(actual[first:], polyline)
    corners = contour.g64_vertices(prog.segments, machine.limits.path_tolerance_mm)
    allowed = contour.allowed_error_mm(
        actual[first:], d_mm, run.samples.points_mm, corners, machine.limits.contour_tolerance_mm
    )
    return run, float(allowed.max())


def _line_time_s(run, line: int) -> float:
    return float(
        np.count_nonzero(run.plan.pieces.line[run.samples.piece] == line) * MACHINE.servo.period_s
    )


def test_stop_after_a_long_helix_softens_its_deceleration_not_its_feed(monkeypatch):
    """A 56.6 mm helix at F500 stopping into an arc of another plane (tort.ngc, LinuxCNC's
    limits; no corner allowance, nurbscnc.plan.allowance: its G64 vertex would hold this
    overshoot, the rule is for a stop that must keep within ε_max of the path)."""
    monkeypatch.setattr(allowance, "CORNER_ALLOWANCE", False)
    _helix_stop_case()


def _helix_stop_case():
    """A 56.6 mm helix at F500 stopping into an arc of another plane (tort.ngc, LinuxCNC's
    limits). Softening the stop's jerk hardly moves its overshoot there (J = 1e9: the jerk
    phase is a step to the servo), and the check used to answer with the helix's feed:
    F348 over all of it, 9.76 s. The stop's deceleration is the next lever: the helix keeps
    F500 (6.81 s), its descent is softer, the tool within ε_max (independent lsim)."""
    machine = load_machine(LINUXCNC_LIMITS)
    run, err_mm = _arc_program_check(PROGRAMS / "tort_helix_stop.nc", machine)
    assert err_mm <= machine.limits.contour_tolerance_mm + 1e-6
    plan = run.plan
    helix = np.flatnonzero(plan.pieces.line == 5)
    assert helix.size == 1
    np.testing.assert_allclose(plan.caps_mm_s[helix], 500.0 / 60.0, rtol=1e-12)
    assert not plan.contour_feed[helix].any() and plan.contour_transition[helix].all()
    off = run_program(
        interpret_text((PROGRAMS / "tort_helix_stop.nc").read_text()),
        machine,
        RunOptions(lookahead=LookaheadOptions(dynamics="off")),
    )
    assert plan.limits.a_down_mm_s2[helix] < off.plan.limits.a_down_mm_s2[helix]
    # The helix takes its kinematic time but for softer transitions (measured +23 ms; the
    # lowered feed cost it 2.96 s).
    assert _line_time_s(run, 5) <= _line_time_s(off, 5) + 0.030
    assert run.cycle_time_s < 8.0  # 10.88 s when its feed was lowered


def test_slowdown_after_a_long_arc_softens_the_transition_not_the_arc(monkeypatch):
    """A 16.8 mm arc at F620 slowing, tangent, into a G1 at F160 (tort.ngc, LinuxCNC's
    limits): the error where the tool turns from the arc into the line at the lower speed is
    the transition's. Answered like a stop's (its jerk, then its deceleration), the arc keeps
    F620 and the program is faster than when the arc's feed answered it (F387 on the whole
    arc, SLOWDOWN_PIECE_S = inf); the tool within ε_max either way (independent lsim). No
    corner allowance (nurbscnc.plan.allowance): the rule is for errors a G64 vertex does
    not hold."""
    monkeypatch.setattr(allowance, "CORNER_ALLOWANCE", False)
    machine = load_machine(LINUXCNC_LIMITS)
    path = PROGRAMS / "tort_arc_slowdown.nc"
    run, err_mm = _arc_program_check(path, machine)
    monkeypatch.setattr(shaping, "SLOWDOWN_PIECE_S", np.inf)
    monkeypatch.setattr(shaping, "LONG_PIECE_S", np.inf)  # nor a long piece's cruise spared
    before, err_before_mm = _arc_program_check(path, machine)
    eps = machine.limits.contour_tolerance_mm + 1e-6
    assert err_mm <= eps and err_before_mm <= eps
    arc = np.flatnonzero(run.plan.pieces.line == 7)
    np.testing.assert_allclose(run.plan.caps_mm_s[arc], 620.0 / 60.0, rtol=1e-12)
    assert not run.plan.contour_feed[arc].any()
    assert before.plan.caps_mm_s[arc].max() < 0.7 * 620.0 / 60.0
    assert run.cycle_time_s < before.cycle_time_s - 0.5  # measured 5.82 s against 6.79 s


def test_long_pieces_blamed_at_their_ends_keep_their_feed(monkeypatch):
    """A tangent chain of the corpus's Fusion 360 pocket at F1000 (LinuxCNC's limits): 20 mm
    arcs and a 9.8 mm line turning through 0.24 mm arcs. The error is made where the servo's
    lag meets those turns; the curve rule lowered every piece within its blame window, so
    the long arcs and the line ran at F677 over all their length (the improvement phase
    restores a few such caps per cut window, not the hundreds of a CAM pocket: it is off
    here, as it is in effect there). The long pieces keep F1000, the short arcs take the
    feed lever; the tool within ε_max (independent lsim); 4.83 s against 6.32 s."""
    machine = load_machine(LINUXCNC_LIMITS)
    path = PROGRAMS / "fusion_arc_turns.nc"
    monkeypatch.setattr(converge, "IMPROVE_ITERATIONS", 0)
    monkeypatch.setattr(converge, "RESTORE_PIECES", 0)
    monkeypatch.setattr(converge, "SETTLE_HALVINGS", 0)
    run, err_mm = _arc_program_check(path, machine)
    monkeypatch.setattr(shaping, "LONG_PIECE_S", np.inf)
    # Without the rule, and with the arcs sharing their blames whatever they are (the
    # blames of the tight arcs and the long pieces beside them differ: SHARE_RATIO now
    # keeps them apart, which alone takes the long pieces to F717–863).
    monkeypatch.setattr(shaping, "SHARE_RATIO", np.inf)
    before, err_before_mm = _arc_program_check(path, machine)
    eps = machine.limits.contour_tolerance_mm + 1e-6
    assert err_mm <= eps and err_before_mm <= eps
    line = run.plan.pieces.line
    long = np.isin(line, [8, 10, 12])
    tight = np.isin(line, [9, 11])
    np.testing.assert_allclose(run.plan.caps_mm_s[long], 1000.0 / 60.0, rtol=1e-12)
    assert not run.plan.contour_feed[long].any()
    assert np.all(run.plan.caps_mm_s[tight] < 700.0 / 60.0)
    assert np.all(before.plan.caps_mm_s[long] < 700.0 / 60.0)
    assert run.cycle_time_s < before.cycle_time_s - 1.4  # measured 4.833 s against 6.320 s


def test_a_failed_restore_is_shaped_again(monkeypatch):
    """The first rows of cds.ngc's pocket at F16 (inches), LinuxCNC's limits: restoring a
    row's feed alone fails at the stop that ends it, whose history sent it to the feed
    lever. Shaped again from its transition (RESHAPE_ITERATIONS), rows keep F16
    (6.773 mm/s) with softer stops: 47.37 s against 48.55 s without; the tool within ε_max
    either way (independent lsim). No corner allowance (nurbscnc.plan.allowance: the G64
    vertices would hold the stops' overshoot, 47.36 s either way). The stops descend by
    their jerk here (``shaping._step_jerk`` off): with their deceleration lowered instead
    no restore fails (47.369 s with or without RESHAPE_ITERATIONS)."""
    monkeypatch.setattr(allowance, "CORNER_ALLOWANCE", False)
    monkeypatch.setattr(shaping, "_step_jerk", lambda *args: False)
    machine = load_machine(LINUXCNC_LIMITS)
    path = PROGRAMS / "cds_pocket_rows.nc"
    run, err_mm = _arc_program_check(path, machine)
    monkeypatch.setattr(converge, "RESHAPE_ITERATIONS", 0)
    before, err_before_mm = _arc_program_check(path, machine)
    eps = machine.limits.contour_tolerance_mm + 1e-6
    assert err_mm <= eps and err_before_mm <= eps
    assert run.cycle_time_s < before.cycle_time_s - 0.5
    assert run.plan.iterations > before.plan.iterations
    feed = 16.0 * 25.4 / 60.0
    cut = ~run.plan.pieces.rapid
    at_feed = np.isclose(run.plan.caps_mm_s, feed, rtol=1e-12) & cut
    at_feed_before = np.isclose(before.plan.caps_mm_s, feed, rtol=1e-12) & cut
    assert np.count_nonzero(at_feed) > np.count_nonzero(at_feed_before)
    # Where a row got its feed back its transitions are softer instead.
    back = at_feed & ~at_feed_before
    lim = run.plan.limits
    off = run_program(
        interpret_text(path.read_text()),
        machine,
        RunOptions(lookahead=LookaheadOptions(dynamics="off")),
    ).plan.limits
    softer = (
        (lim.a_down_mm_s2 < off.a_down_mm_s2)
        | (lim.j_down_mm_s3 < off.j_down_mm_s3)
        | (lim.a_up_mm_s2 < off.a_up_mm_s2)
        | (lim.j_up_mm_s3 < off.j_up_mm_s3)
    )
    assert back.any() and softer[back].all()


def test_a_failed_restore_is_bisected_alone(monkeypatch, tmp_path):
    """A helix in space after a rapid, LinuxCNC's limits (no Z servo model): X and Y lag
    while Z follows, so the tool leaves the helix by an error that grows with the feed
    above about 32 mm/s. The levers loop lowered the feed to half (the first check's error
    was the rapid's settle), the joint tries were spent on the settle, and restoring the
    feed alone failed: F2903 kept 29.4 mm/s, F3169 26.4 mm/s (5 % slower at the higher F).
    The cap alone is then searched between its feasible value and the failed one (false
    position, RESTORE_SECANTS): both are faster, the tool within ε_max (independent lsim)."""
    machine = load_machine(LINUXCNC_LIMITS)
    for feed, before_s in ((2903, 0.3941), (3169, 0.3922)):
        path = tmp_path / f"helix{feed}.nc"
        path.write_text(f"G21 G90 G17\nG64 P0.01\nG0 X-1 Y-1 Z1\nF{feed}\nG3 X-6 Y0 Z-2 R9\nM2\n")
        run, err_mm = _arc_program_check(path, machine)
        with monkeypatch.context() as m:
            m.setattr(converge, "RESTORE_SECANTS", 0)
            alone, err_alone_mm = _arc_program_check(path, machine)
        eps = machine.limits.contour_tolerance_mm + 1e-6
        assert err_mm <= eps and err_alone_mm <= eps
        np.testing.assert_allclose(alone.cycle_time_s, before_s, atol=1e-4)  # the measured
        helix = run.plan.pieces.line == 5
        assert run.plan.caps_mm_s[helix].min() > 1.1 * alone.plan.caps_mm_s[helix].max()
        assert run.cycle_time_s < alone.cycle_time_s - 0.025  # measured 0.3508, 0.3508 s


def _linuxcnc_limits_with_z_servo():
    """LinuxCNC's limits (J = 1e9, per-axis accelerations) with a servo model on Z too (Y's):
    every axis lags, so the shaping's stop, slowdown and restore levers carry the plan."""
    text = LINUXCNC_LIMITS.read_text()
    i = text.index("[servo.y]")
    j = text.index("\n[", i + 1)
    text = text[:j] + "\n" + text[i:j].replace("[servo.y]", "[servo.z]") + text[j:]
    machine = parse_machine(text)
    assert machine.servo.z is not None and machine.limits.j_max_mm_s3 == 1e9
    return machine


_vertex3 = st.tuples(st.integers(-8, 8), st.integers(-8, 8), st.integers(-2, 2))


@settings(
    max_examples=20, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    st.lists(_vertex3, min_size=2, max_size=4, unique=True),
    st.lists(st.sampled_from([None, 6, 9, 12]), min_size=3, max_size=3),
    st.sampled_from(["G61", "G64", "G64 P0.01"]),
    st.integers(300, 3000),
    st.integers(100, 500),
)
def test_cycle_time_non_increasing_in_feed_under_linuxcnc_limits(vertices, radii, mode, feed, step):
    """The same property under LinuxCNC's limits (J = 1e9: stops whose jerk is no lever,
    softened by their acceleration, restores shaped again), on lines and helical arcs in
    space. (Without a Z servo model the X/Y lag alone takes the tool off an inclined line,
    an error that grows with F: 13 of 1,200 random pairs are still slower at the higher F,
    up to 5.1 %, 36 up to 28.9 % before the restores' false position: docs/benchmarks.md.)"""
    machine = _linuxcnc_limits_with_z_servo()
    moves = []
    for (x0, y0, _), (x, y, z), r in zip(vertices, vertices[1:], radii):
        half_chord = 0.5 * float(np.hypot(x - x0, y - y0))
        if r is None or half_chord == 0.0:  # an R arc needs two XY points R can join
            moves.append(f"G1 X{x} Y{y} Z{z}")
        else:
            moves.append(f"G2 X{x} Y{y} Z{z} R{max(float(r), half_chord + 1.0):g}")

    def cycle(f):
        x, y, z = vertices[0]
        lines = ["G21 G90 G17", mode, f"G0 X{x} Y{y} Z{z}", f"F{f}", *moves, "M2"]
        return run_program(interpret_text("\n".join(lines) + "\n"), machine).cycle_time_s

    assert cycle(feed + step) <= cycle(feed) * 1.005
