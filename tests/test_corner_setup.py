"""The setup of corners shares its work: the turn-arounds smoothing judged are not fitted
again by the planner (the same answers, bit for bit), the space blends' servo caps come
from one servo coefficient, and their two-way deviations from one distance table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nurbscnc.geometry import turnaround
from nurbscnc.geometry.spaceblend import _polyline_distance_batch
from nurbscnc.machine.caps import servo_curve_cap_mm_s
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan import turnarounds
from nurbscnc.plan.blends import SERVO_BLEND_SHARE, servo_blend_caps_mm_s, servo_gain_s2
from nurbscnc.plan.options import PlanOptions
from nurbscnc.plan.pieces import SCALAR_COLUMNS, VECTOR_COLUMNS
from nurbscnc.plan.program_pieces import segment_pieces
from nurbscnc.program.interpret import interpret_text

#: The PieceList columns compared bit for bit.
COLUMNS = (
    *SCALAR_COLUMNS,
    *VECTOR_COLUMNS,
    "ph_rows",
    "ph_w",
    "ph_frame",
    "jump_rows",
    "jump_kn",
    "jump_cap_mm_s",
)


def _raster(passes: int, tol_mm: float) -> str:
    """Serpentine passes along Y of 0.5 mm chords over a wavy surface (dense: smoothed),
    0.6 mm stepovers in X between them (raster turn-arounds)."""
    out = [f"G21 G17 G90 G64 P{tol_mm:g}", "G0 Z3", "G0 X0 Y0", "G1 Z-2 F600", "F1500"]
    y = np.linspace(0.0, 8.0, 17)
    for k in range(passes):
        x = 0.6 * k
        ys = y if k % 2 == 0 else y[::-1]
        zs = -2.0 + 0.4 * np.sin(2 * np.pi * x / 10.0) * np.cos(2 * np.pi * ys / 12.0)
        if k > 0:
            out.append(f"G1 X{x:.4f} Z{zs[0]:.4f}")
        out.extend(f"G1 Y{a:.4f} Z{b:.4f}" for a, b in zip(ys[1:], zs[1:]))
    return "\n".join(out + ["G0 Z3", "M2", ""])


def _counted(monkeypatch) -> list:
    """turn_blend (the U fit) with its calls counted by their inputs."""
    calls = []
    fit = turnaround.turn_blend

    def counting(*args):
        calls.append(b"".join(np.asarray(a, dtype=float).tobytes() for a in args))
        return fit(*args)

    monkeypatch.setattr(turnaround, "turn_blend", counting)
    return calls


#: Tolerances at which this raster's U beats its two stops, so that smoothing keeps the
#: outer lines out of its runs and the planner asks again (at P ≤ 0.05 mm the stops, whose
#: overshoot may use the corner's tolerance, win: smoothing takes the lines and the planner
#: never asks).
U_TOLERANCES_MM = [0.1, 0.2]


@pytest.mark.parametrize("tol_mm", U_TOLERANCES_MM)
def test_turnarounds_fitted_once_with_the_same_pieces(monkeypatch, tol_mm):
    """Smoothing and the planner ask for the U of the same turn-arounds: each is fitted once
    (before, twice: once per asker), and the pieces are those of asking twice, every
    column and every object row bit for bit."""
    machine = load_machine()
    prog = interpret_text(_raster(6, tol_mm))
    calls = _counted(monkeypatch)
    shared = segment_pieces(prog.segments, machine, PlanOptions())
    assert len(calls) >= 5  # five turn-arounds, the plunge's corner may be tried too
    assert len(calls) == len(set(calls))
    assert shared.corners.action.size > 0

    # Asking twice: the memo ignored.
    plain = turnarounds.remembered_turn_choice
    monkeypatch.setattr(
        turnarounds, "remembered_turn_choice", lambda memo, *args: plain(None, *args)
    )
    calls.clear()
    twice = segment_pieces(prog.segments, machine, PlanOptions())
    assert len(calls) == 2 * len(set(calls))
    for name in COLUMNS:
        a, b = getattr(shared, name), getattr(twice, name)
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert a.tobytes() == b.tobytes(), name
    assert sorted(shared.objects) == sorted(twice.objects)
    for field in ("action", "why", "turning_rad", "point_mm", "line"):
        assert getattr(shared.corners, field).tobytes() == getattr(twice.corners, field).tobytes()


def test_servo_blend_caps_are_each_blends_formula():
    """The caps of many blends at once: √(share·ε / (g κ)) of each (SPEC §8), g the servo's
    2.85e-5 s² on the paper's machine, inf where κ = 0; bit for bit the cap of one blend
    at a time."""
    machine = load_machine()
    kappa = np.array([0.0, 1e-4, 0.5, 22.0, 300.0, 4.5e3])
    caps = servo_blend_caps_mm_s(machine, kappa)
    eps = SERVO_BLEND_SHARE * machine.limits.contour_tolerance_mm
    expect = [math.inf] + [math.sqrt(eps / (2.85e-5 * k)) for k in kappa[1:]]
    assert caps[0] == math.inf
    np.testing.assert_allclose(caps[1:], expect[1:], rtol=5e-3)
    gain = servo_gain_s2(machine)
    one = [float(servo_curve_cap_mm_s(float(k), eps, gain)) for k in kappa[1:]]
    assert caps[1:].tolist() == one


def _point_segment_mm(q, a, b) -> float:
    """Distance of q to the segment a–b in Python floats (math.fsum dot products)."""
    ab = [bi - ai for ai, bi in zip(a, b)]
    aq = [qi - ai for ai, qi in zip(a, q)]
    len2 = math.fsum(x * x for x in ab)
    t = 0.0 if len2 == 0.0 else min(1.0, max(0.0, math.fsum(x * y for x, y in zip(aq, ab)) / len2))
    return math.sqrt(math.fsum((x - t * y) ** 2 for x, y in zip(aq, ab)))


def test_space_blend_distances_against_point_to_segment_in_python():
    """The batched distance of each row's points to its own polyline (degenerate chords
    included) against an exact point-to-segment loop in Python floats: within 1e-12
    relative to the coordinates' scale."""
    rng = np.random.default_rng(35)
    for m, a, b in ((1, 5, 2), (3, 17, 9), (7, 40, 33)):
        q = rng.normal(size=(m, a, 3)) * 5.0 + 100.0
        pts = np.cumsum(rng.normal(size=(m, b, 3)), axis=1) + 100.0
        pts[:, 1] = pts[:, 0]  # a chord of length 0
        got = _polyline_distance_batch(q, pts)
        assert got.shape == (m, a)
        for r in range(m):
            for i in range(a):
                want = min(
                    _point_segment_mm(q[r, i], pts[r, j], pts[r, j + 1]) for j in range(b - 1)
                )
                assert abs(got[r, i] - want) <= 1e-12 * 110.0
