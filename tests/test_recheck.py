"""A re-plan's check samples again only where the plan changed (plan/check.py
``Checker._same_rows``, plan/profile.py ``same_until_s``, plan/timing.py
``same_clock_until_s``): the rows before are taken from the last check, bit for bit what a
fresh check computes."""

from __future__ import annotations

import numpy as np
import pytest

from nurbscnc.machine.profile import load_machine
from nurbscnc.plan import lookahead as la
from nurbscnc.plan.check import Checker
from nurbscnc.plan.profile import ProfileInput, same_until_s
from nurbscnc.plan.profile_plan import plan_profile
from nurbscnc.plan.timing import same_clock_until_s, wall_to_profile_time
from nurbscnc.program.interpret import interpret_text

A, J = 2450.0, 50_000.0


def _profile(caps):
    k = len(caps)
    lengths = np.linspace(1.0, 3.0, k)
    junction = np.full(k + 1, np.inf)
    junction[[0, -1]] = 0.0
    return plan_profile(ProfileInput(lengths, np.asarray(caps, float), junction, A, J))


@pytest.mark.parametrize("changed", [3, 6, 9])
def test_profiles_sample_alike_before_same_until(changed):
    caps = np.full(12, 50.0)
    old = _profile(caps)
    caps[changed] = 12.0  # a lower cap on one piece: the braking before it changes too
    new = _profile(caps)
    t = same_until_s(old, new)
    assert 0.0 < t < min(old.duration_s, new.duration_s)
    tau = np.linspace(0.0, t, 20_001)[:-1]  # every τ < t
    for x, y in zip(old.sample(tau), new.sample(tau)):
        assert np.array_equal(x, y)
    # Not a vacuous bound: a little after it the samples differ, and the change is no
    # later than the braking into the lowered piece must start.
    late = np.linspace(t, t + 0.02, 200)
    assert not np.array_equal(old.sample(late)[0], new.sample(late)[0])
    assert t <= old.piece_start_time_s[changed]


def test_same_profiles_are_the_same_to_their_end_and_other_paths_not_at_all():
    a = _profile(np.full(5, 40.0))
    b = _profile(np.full(5, 40.0))
    assert same_until_s(a, b) == a.duration_s
    other = plan_profile(
        ProfileInput(
            np.linspace(1.0, 3.5, 5),
            np.full(5, 40.0),
            np.array([0, np.inf, np.inf, np.inf, np.inf, 0]),
            A,
            J,
        )
    )
    assert same_until_s(a, other) == 0.0


def test_dwell_schedules_map_alike_before_the_first_difference():
    at = np.array([0.5, 1.2, 2.0])
    old = (at, np.array([0.25, 0.1, 0.3]))
    assert same_clock_until_s(old, old) == np.inf
    longer = (at, np.array([0.25, 0.4, 0.3]))  # the second dwell longer
    t = same_clock_until_s(old, longer)
    assert t == pytest.approx(1.2 + 0.25, abs=1e-15)  # its wall start
    wall = np.linspace(0.0, t, 5001)[:-1]
    assert np.array_equal(wall_to_profile_time(wall, *old), wall_to_profile_time(wall, *longer))
    fewer = (at[:2], old[1][:2])  # the third dwell gone: the clocks part at its start
    assert same_clock_until_s(old, fewer) == pytest.approx(2.0 + 0.35, abs=1e-15)
    moved = (np.array([0.4, 1.2, 2.0]), old[1])
    assert same_clock_until_s(old, moved) == 0.4


PROGRAMS = {
    # Cut windows after rapids (settles, re-plans of later windows from their start).
    "cuts": "G21 G90 G17 F3000\n"
    + "".join(
        f"G0 Z2\nG0 X{x} Y0\nG1 Z-1\nG1 X{x + 6}\nG2 X{x + 6} Y4 I0 J2\nG1 X{x}\nG1 Y0\n"
        for x in (0, 20, 40)
    )
    + "G0 Z5\nM2\n",
    # One window, the whole program one chunk: re-plans of a sharp-cornered contour.
    "corners": "G21 G90 G17 G61 F3500\nG1 X10\nG1 Y8\nG1 X3 Y4\nG3 X-3 Y4 I-3 J-4\nG1 X0 Y0\nM2\n",
}


def _counting_reuse(monkeypatch) -> list:
    """Record what every check's :meth:`Checker._same_rows` returns (rows reused)."""
    reused: list = []
    real = Checker._same_rows

    def counting(self, *args):
        rows = real(self, *args)
        reused.append(rows)
        return rows

    monkeypatch.setattr(Checker, "_same_rows", counting)
    return reused


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_a_recheck_reusing_rows_gives_the_fresh_checks_plan(name, monkeypatch):
    """The plan, its check (every over-limit sample, piece runs, statistics) and the
    reference are those of checks that sample every row afresh — and rows were reused."""
    machine = load_machine()
    program = interpret_text(PROGRAMS[name])
    reused = _counting_reuse(monkeypatch)
    plan, check = la.plan_checked(program, machine, keep_reference=False)
    assert sum(reused) > 0 and plan.iterations > 0
    monkeypatch.setattr(Checker, "_same_rows", lambda self, *args: 0)
    fresh, fresh_check = la.plan_checked(program, machine, keep_reference=False)
    assert plan.cycle_time_s == fresh.cycle_time_s and plan.iterations == fresh.iterations
    assert np.array_equal(plan.caps_mm_s, fresh.caps_mm_s)
    for f in ("phase_start_time_s", "phase_jerk_mm_s3", "piece_start_time_s"):
        assert np.array_equal(getattr(plan.profile, f), getattr(fresh.profile, f))
    assert np.array_equal(plan.pieces.dwell_after_s, fresh.pieces.dwell_after_s)
    assert check.stats == fresh_check.stats
    for f in (
        "count",
        "index",
        "err_mm",
        "tau_s",
        "run_piece",
        "run_start",
        "restart_count",
        "worst_mm",
    ):
        assert np.array_equal(getattr(check.overs, f), getattr(fresh_check.overs, f)), f


def test_a_window_of_several_chunks_keeps_nothing(monkeypatch):
    """Memory: only a window checked in one chunk keeps its rows; checked 64 samples at a
    time, no rows are reused (whole chunks left alike are resumed after instead: their
    compact results and servo states, not their rows), and the plan is the same."""
    machine = load_machine()
    program = interpret_text(PROGRAMS["corners"])
    reused = _counting_reuse(monkeypatch)
    small, _ = la.plan_checked(program, machine, keep_reference=False, window=64)
    assert len(reused) > 1 and sum(reused) == 0
    whole, _ = la.plan_checked(program, machine, keep_reference=False)
    assert sum(reused) > 0
    assert small.cycle_time_s == whole.cycle_time_s
    assert np.array_equal(small.profile.phase_start_time_s, whole.profile.phase_start_time_s)


def _fresh_only(self, planned, profile, rows, *args):
    """:meth:`Checker._resume` that never resumes: every chunk simulated afresh."""
    self._chunks = None
    n = la.sample_count(planned, profile, self.machine.servo.period_s)
    return (n if rows is None else min(rows[1], n)), None, []


def _assert_same_plan_and_check(plan, check, fresh, fresh_check) -> None:
    assert plan.cycle_time_s == fresh.cycle_time_s and plan.iterations == fresh.iterations
    assert np.array_equal(plan.caps_mm_s, fresh.caps_mm_s)
    for f in ("phase_start_time_s", "phase_jerk_mm_s3", "piece_start_time_s"):
        assert np.array_equal(getattr(plan.profile, f), getattr(fresh.profile, f))
    assert check.stats == fresh_check.stats
    for f in ("count", "index", "err_mm", "tau_s", "run_piece", "run_start", "restart_count"):
        assert np.array_equal(getattr(check.overs, f), getattr(fresh_check.overs, f)), f
    assert check.overs.worst_mm == fresh_check.overs.worst_mm


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_a_recheck_resuming_after_alike_chunks_gives_the_fresh_checks_plan(name, monkeypatch):
    """Checked 97 samples at a time, a re-plan resumes after the leading chunks it left
    alike (their results and the servo state after them kept, :meth:`Checker._resume`):
    the plan and its check (every over-limit sample, piece runs, restart counts,
    statistics) are those of checks that simulate every chunk afresh — and chunks were
    resumed after."""
    machine = load_machine()
    program = interpret_text(PROGRAMS[name])
    resumed: list = []
    real = Checker._resume

    def counting(self, *args):
        out = real(self, *args)
        resumed.append(len(out[2]))
        return out

    monkeypatch.setattr(Checker, "_resume", counting)
    plan, check = la.plan_checked(program, machine, keep_reference=False, window=97)
    assert sum(resumed) > 0 and plan.iterations > 0

    monkeypatch.setattr(Checker, "_resume", _fresh_only)
    fresh, fresh_check = la.plan_checked(program, machine, keep_reference=False, window=97)
    _assert_same_plan_and_check(plan, check, fresh, fresh_check)


@pytest.mark.parametrize("name", ["cuts", "corners"])
def test_a_precompensated_check_keeps_nothing_and_gives_the_fresh_checks_plan(name, monkeypatch):
    """The pre-compensated reference inverts and optimises each cut window as a whole, so a
    re-plan later in a window moves its earlier rows too (the sampler is not ``causal``):
    no rows or chunks are kept, and the plan and check are those of fresh checks (a check
    that kept the rows before the change planned "cuts" 10 re-plans into another plan)."""
    from nurbscnc.plan.sampler import EXACT
    from nurbscnc.precompensation import precompensated_sampler

    machine = load_machine()
    program = interpret_text(PROGRAMS[name])
    sampler = precompensated_sampler(EXACT, machine)
    assert not sampler.causal and EXACT.causal
    reused = _counting_reuse(monkeypatch)
    plan, check = la.plan_checked(program, machine, reference=sampler, keep_reference=False)
    assert len(reused) > 1 and sum(reused) == 0 and plan.iterations > 0
    monkeypatch.setattr(Checker, "_same_rows", lambda self, *args: 0)
    monkeypatch.setattr(Checker, "_resume", _fresh_only)
    fresh, fresh_check = la.plan_checked(program, machine, reference=sampler, keep_reference=False)
    _assert_same_plan_and_check(plan, check, fresh, fresh_check)
