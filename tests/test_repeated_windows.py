"""A cut repeated at another place starts its levers loop from the repeated cut's final
levers (plan/windows.py ``SeenWindows``): checked as any other, so within ε_max by an
independent simulation, and as fast as the repeated one."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from nurbscnc.machine.profile import load_machine
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.lookahead import plan_windows
from nurbscnc.program.interpret import interpret_text
from tests.servo_reference import lsim_actual_mm, segment_distance_mm

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from scale_bench import airfoils_program  # noqa: E402


def test_translated_airfoils_reuse_the_levers_and_stay_within_eps():
    machine = load_machine()
    prog = interpret_text(airfoils_program(count=3, chord_mm=20.0, pitch_mm=30.0))
    windows = list(plan_windows(prog, machine))
    assert len(windows) == 3
    # The three cuts are one airfoil 30 mm apart (the rapids before them differ: from the
    # origin, then between airfoils): the first is planned from the kinematic levers, the
    # others from its final ones, and pass their first check.
    assert windows[0].iterations > 0
    assert windows[1].iterations == 0 and windows[2].iterations == 0
    plan = windows[-1].plan
    t = np.append(plan.profile.piece_start_time_s[: len(plan.pieces)], plan.profile.duration_s)
    rapid = np.asarray(plan.pieces.rapid, dtype=bool)
    cut_s = []
    for w in windows:
        first_feed = w.first + int(np.flatnonzero(~rapid[w.first : w.end])[0])
        cut_s.append(float(t[w.end] - t[first_feed]))
    assert max(cut_s) - min(cut_s) <= 1e-9
    # The whole run: the tool within ε_max of the planned path (lsim, exact distances).
    run = run_program(prog, machine, RunOptions())
    s = run.samples
    actual = lsim_actual_mm(s.points_mm, machine)[: len(s.points_mm)]
    cut = ~np.isin(s.line, [g.line for g in prog.segments if g.kind == "rapid"])
    err = segment_distance_mm(actual[cut], s.points_mm)
    assert err.max() <= machine.limits.contour_tolerance_mm + 0.5e-3


def test_a_different_cut_is_not_taken_for_a_repeat():
    """The third airfoil 0.1 % larger: no warm start (its levers loop runs), still a plan."""
    machine = load_machine()
    text = airfoils_program(count=2, chord_mm=20.0, pitch_mm=30.0)
    other = airfoils_program(count=1, chord_mm=20.02, pitch_mm=30.0).splitlines()
    cut = [ln for ln in other if ln.startswith(("G0", "G6.2", "K"))]
    moved = []
    for ln in cut:  # the larger airfoil 60 mm along X
        words = []
        for w in ln.split():
            words.append(f"X{float(w[1:]) + 60.0:.6f}" if w.startswith("X") else w)
        moved.append(" ".join(words))
    text = text.replace("M2\n", "\n".join(moved) + "\nM2\n")
    windows = list(plan_windows(interpret_text(text), machine))
    assert len(windows) == 3 and windows[2].iterations > 0


def test_a_window_profile_is_its_rapids_and_its_cut_planned_apart():
    """OwnProfiles: the rapids and the cut of a window planned apart and spliced (as for a
    cut that repeats an earlier one) give the profile of the whole window (the junction
    between them is a rest) to the rounding of the times after it; a repeated cut's profile
    is the remembered one, and the plans of three airfoils are those made without
    remembering any."""
    from nurbscnc.plan.options import LookaheadOptions
    from nurbscnc.plan.plans import Limits, profile_over
    from nurbscnc.plan.setup import Setup
    from nurbscnc.plan.windows import OwnProfiles, cut_windows

    machine = load_machine()
    prog = interpret_text(airfoils_program(count=3, chord_mm=20.0, pitch_mm=30.0))
    st = Setup(prog, machine, LookaheadOptions(), None, False, 1 << 16)
    own = OwnProfiles(st)
    lv = st.initial
    lim = lv.limits()
    starts = cut_windows(st.pieces)
    ends = np.append(starts[1:], st.k)
    for a, b in zip(starts.tolist(), ends.tolist()):
        whole = profile_over(
            st.pieces.length_mm[a:b],
            lv.caps[a:b],
            st.smooth[a : b + 1],
            Limits(
                *(
                    x[a:b]
                    for x in (lim.a_up_mm_s2, lim.j_up_mm_s3, lim.a_down_mm_s2, lim.j_down_mm_s3)
                )
            ),
            None,
        )
        c = a + int(np.flatnonzero(~np.asarray(st.pieces.rapid[a:b], dtype=bool))[0])
        split = own(lv, a, b, c)  # as for a repeated cut starting at c
        # Speeds inside a unit are read at the pieces' start lengths, which the cut counts
        # from its own start: the same to rounding.
        np.testing.assert_allclose(
            split.junction_speeds_mm_s, whole.junction_speeds_mm_s, rtol=1e-12, atol=1e-12
        )
        np.testing.assert_allclose(
            split.piece_peak_speed_mm_s, whole.piece_peak_speed_mm_s, rtol=1e-12, atol=1e-12
        )
        np.testing.assert_allclose(
            split.piece_start_time_s, whole.piece_start_time_s, rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(split.piece_start_mm, whole.piece_start_mm, rtol=0, atol=1e-12)
        assert split.duration_s == pytest.approx(whole.duration_s, abs=1e-12)
    assert len(own.kept) == 1  # the three cuts are one cut moved: planned once

    def plans(remember: bool):
        if not remember:
            original = OwnProfiles.__call__

            def afresh(self, lv, a, b, cut, base=0):
                self.kept.clear()
                return original(self, lv, a, b, cut, base)

            with pytest.MonkeyPatch.context() as mp:
                mp.setattr(OwnProfiles, "__call__", afresh)
                return list(plan_windows(prog, machine))
        return list(plan_windows(prog, machine))

    kept, fresh = plans(True), plans(False)
    for w_kept, w_fresh in zip(kept, fresh, strict=True):
        assert (w_kept.k0, w_kept.k1, w_kept.iterations) == (
            w_fresh.k0,
            w_fresh.k1,
            w_fresh.iterations,
        )
    np.testing.assert_array_equal(
        kept[-1].plan.profile.phase_start_time_s, fresh[-1].plan.profile.phase_start_time_s
    )
