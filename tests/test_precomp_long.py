"""``--precompensate`` on a program of many cuts (issue 13: long programs).

The compensated reference is made one segment per cut window
(:mod:`nurbscnc.precompensation.apply`, "cut-window segments"), so the planner's check of a
cut window costs that window, not the program. Speed is the benchmark's business (no timing
here); this pins what must hold whatever the segments: on a generated program of three cuts
(lines and half circles, rapids between the cuts: two joints, so a middle cut has a joint on
either side, the fewest that covers every kind of segment) the written reference keeps the
machine's limits on its samples (tests/servo_reference.limits_excess, within the plan's own
where the plan is above them), stays within 3 µm of the programmed path while cutting, and
the tool simulated by ``scipy.signal.lsim`` from it stays within ε_max of the cuts — all
measured independently of the planner (the test's own polylines of the lines and arcs).
"""

from __future__ import annotations

import numpy as np

from nurbscnc.interpolate.sample import reference_sampler
from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.timing import sample_count
from nurbscnc.precompensation.apply import (
    _segment_starts,
    precompensate_reference,
    precompensated_sampler,
)
from nurbscnc.program.interpret import interpret_text
from tests.servo_reference import limits_excess, lsim_actual_mm, segment_distance_mm

MACHINE = load_machine()
CUTS, PAIRS = 3, 1  # three cuts of one (line, half circle, line, half circle) each
WIDTH_MM, RADIUS_MM = 1.0, 0.5


def _program() -> tuple[str, np.ndarray]:
    """The G-code and a dense polyline of its cuts [mm] (NaN rows between cuts)."""
    lines = ["G21 G90 G17 G64", "G0 X0 Y0 Z0"]
    dense = []
    for c in range(CUTS):
        ox, oy = (c % 5) * 6.0, (c // 5) * 30.0
        lines += [f"G0 X{ox:.3f} Y{oy:.3f}", "G1 F1500"]
        y = oy
        for _ in range(PAIRS):
            lines += [
                f"G1 X{ox + WIDTH_MM:.3f} Y{y:.3f}",
                f"G3 X{ox + WIDTH_MM:.3f} Y{y + 2 * RADIUS_MM:.3f} I0 J{RADIUS_MM}",
                f"G1 X{ox:.3f} Y{y + 2 * RADIUS_MM:.3f}",
                f"G2 X{ox:.3f} Y{y + 4 * RADIUS_MM:.3f} I0 J{RADIUS_MM}",
            ]
            t = np.linspace(0.0, 1.0, 2001)
            a = np.linspace(-np.pi / 2, np.pi / 2, 4001)
            r = RADIUS_MM
            dense += [
                np.column_stack([ox + WIDTH_MM * t, np.full_like(t, y)]),
                np.column_stack([ox + WIDTH_MM + r * np.cos(a), y + r + r * np.sin(a)]),
                np.column_stack([ox + WIDTH_MM * (1 - t), np.full_like(t, y + 2 * r)]),
                np.column_stack([ox - r * np.cos(a), y + 3 * r + r * np.sin(a)]),
            ]
            y += 4 * RADIUS_MM
        dense.append(np.full((1, 2), np.nan))
    lines.append("M2")
    pts = np.vstack(dense)
    return "\n".join(lines) + "\n", np.column_stack([pts, np.zeros(len(pts))])


def test_many_cuts_precompensated_keep_limits_tube_and_contour():
    text, dense = _program()
    prog = interpret_text(text)
    run = run_program(prog, MACHINE, RunOptions(precompensate=True))
    plan = run.plan
    assert len(plan.pieces) >= CUTS * 4 * PAIRS
    period = MACHINE.servo.period_s
    ks = _segment_starts(plan.pieces, plan.profile, period, 10**9)
    assert ks.size - 1 >= CUTS  # one segment per cut (the first rapid's window with the first)
    # The planner's windows of rows (each from just before a joint) are the written rows.
    exact = reference_sampler("exact")
    whole = precompensate_reference(
        exact(plan.pieces, plan.profile, period), plan.pieces, plan.profile, MACHINE
    )[0]
    lead = whole.t_s.size - sample_count(plan.pieces, plan.profile, period)
    sample = precompensated_sampler(exact, MACHINE)
    for k in _segment_starts(plan.pieces, plan.profile, period, 10**12)[1:-1]:
        for a, b in ((k + lead - 2, k + lead + 50), (k + lead - 2, k + lead)):
            rows = sample(plan.pieces, plan.profile, period, int(a), int(b))
            for f in ("points_mm", "s_mm", "piece", "t_s"):
                np.testing.assert_array_equal(getattr(rows, f), getattr(whole, f)[a:b])
    pts, piece = run.samples.points_mm, run.samples.piece
    planned = reference_sampler("exact")(plan.pieces, plan.profile, period).points_mm
    lead = pts.shape[0] - planned.shape[0]
    assert lead >= 0
    planned = np.pad(planned, ((lead, 0), (0, 0)), mode="edge")
    # The limits on the samples (the plan's own where it is above them).
    excess = limits_excess(pts, MACHINE, planned)
    assert all(v <= 0.0 for v in excess.values()), excess
    # Cutting samples: not on a rapid, and not waiting at a cut's start after a rapid (the
    # planned reference at rest at the first point of the cut, as the planner's check).
    rapid = plan.pieces.rapid[piece]
    start = np.zeros(pts.shape[0], dtype=bool)
    for k in np.flatnonzero(rapid[:-1] & ~rapid[1:]) + 1:
        at = np.all(planned[k:] == planned[k], axis=1)
        stop = int(np.argmin(at)) if not at.all() else at.size
        start[k : k + stop] = True
    cutting = ~rapid & ~start
    segs = [d for d in np.split(dense, np.flatnonzero(np.isnan(dense[:, 0]))) if len(d) > 1]
    segs = [d[~np.isnan(d[:, 0])] for d in segs]

    def distance_mm(q):
        return np.min([segment_distance_mm(q, d) for d in segs], axis=0)

    # The reference within 3 µm of the programmed cuts.
    assert distance_mm(pts[cutting]).max() * 1000.0 <= 3.0 + 1e-6
    # The tool (lsim of the written reference, 0.3 s of settle after the end) within ε_max.
    actual = lsim_actual_mm(pts, MACHINE)
    on_cut = np.append(cutting, np.ones(actual.shape[0] - pts.shape[0], dtype=bool))
    err_um = distance_mm(actual[on_cut]) * 1000.0
    assert err_um.max() <= MACHINE.limits.contour_tolerance_mm * 1000.0


def _synthetic(n: int = 300) -> np.ndarray:
    """A planned reference (n, 3) [mm]: from rest along x and y with half the machine's
    jerk, then that acceleration (within every limit on the samples)."""
    period = MACHINE.servo.period_s
    j = 0.5 * float(
        np.min(np.minimum(MACHINE.limits.j_max_mm_s3, MACHINE.axis_limits.as_arrays()[2]))
    )
    t = np.arange(n) * period
    t1 = 0.005  # jerk for 5 ms, then that acceleration
    x = np.where(
        t < t1,
        j * t**3 / 6.0,
        j * t1**3 / 6.0 + 0.5 * j * t1**2 * (t - t1) + 0.5 * j * t1 * (t - t1) ** 2,
    )
    return np.column_stack([x, 0.5 * x, np.zeros(n)])


def test_a_joint_no_window_solves_is_the_plans_own(monkeypatch):
    """The joint of two segments (:func:`_join_segments`): the earlier segment ends on the
    plan's own samples, a later one far off its plan across the joint is re-projected, and
    where no window solves it (the LP made to fail) it is the plan's own samples: either way
    every row across the joint keeps the caps."""
    from dataclasses import replace

    from nurbscnc.plan.timing import Reference
    from nurbscnc.precompensation import apply as pc

    r = _synthetic()
    n = r.shape[0]
    zeros = np.zeros(n - 3)
    planned = Reference(
        zeros, zeros, zeros, zeros, zeros, np.zeros(n - 3, dtype=np.int64), r[3:], zeros
    )
    off = r[3:].copy()
    off[:5] += 2e-3  # a jump of 2 µm at the joint
    seg = replace(planned, points_mm=off)
    caps = pc.sample_limits(r, MACHINE)
    assert not (pc.limit_excess(r, caps) > 0.0).any()
    assert (pc.limit_excess(np.vstack([r[:3], off]), caps) > 0.0).any()
    joined = pc._join_segments(r[:3], r[:3], seg, planned, None, None, MACHINE, np.inf, None)
    u = np.vstack([r[:3], joined.points_mm])
    assert not (pc.limit_excess(u, caps) > 0.0).any()
    assert not np.array_equal(joined.points_mm, planned.points_mm)  # moved, not the plan
    monkeypatch.setattr(pc, "project_window", lambda *a: None)
    joined = pc._join_segments(r[:3], r[:3], seg, planned, None, None, MACHINE, np.inf, None)
    np.testing.assert_array_equal(joined.points_mm, planned.points_mm)


def test_projection_windows_are_bounded(monkeypatch):
    """A projection window moves at most PROJECT_MAX_WINDOW samples (longer ones in pieces);
    where that cannot solve the rows, the plan's own points (within the caps)."""
    from nurbscnc.precompensation import limits as pc

    r = _synthetic(400)
    n = r.shape[0]
    target = r + 3e-4 * np.sin(np.arange(n) * 1.3)[:, None] * np.array([1.0, -1.0, 0.0])
    caps = pc.sample_limits(r, MACHINE)
    basis = np.broadcast_to(np.eye(3), (n, 3, 3))
    lower, upper = np.full((n, 3), -np.inf), np.full((n, 3), np.inf)
    sizes = []
    real = pc.project_window

    def spy(u, r_, t, c, b, lo, up, j0, j1):
        sizes.append(j1 - j0)
        return real(u, r_, t, c, b, lo, up, j0, j1)

    monkeypatch.setattr(pc, "PROJECT_MAX_WINDOW", 64)
    monkeypatch.setattr(pc, "project_window", spy)
    u = pc.project_onto_limits(target, r, caps, basis, lower, upper)
    assert sizes and max(sizes) <= 64
    assert not (pc.limit_excess(u, caps) > 0.0).any()
    monkeypatch.setattr(pc, "project_window", lambda *a: None)
    u = pc.project_onto_limits(target, r, caps, basis, lower, upper)
    np.testing.assert_array_equal(u, r)
