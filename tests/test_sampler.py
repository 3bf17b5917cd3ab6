"""The planner's sampler contract (plan/sampler.py ``ReferenceSampler``): a sampler that is
not ``windowed`` is evaluated whole, once per check; a windowed one window by window; and
``check_begins`` is called as each check begins, with its first sample."""

from __future__ import annotations

import numpy as np

from nurbscnc.machine.profile import load_machine
from nurbscnc.plan.lookahead import plan_checked, plan_windows
from nurbscnc.plan.sampler import ReferenceSampler
from nurbscnc.program.interpret import interpret_text

MACHINE = load_machine()
#: One cut: a sharp-cornered contour, re-planned by the check.
CORNERS = "G21 G90 G17 G61 F3500\nG1 X10\nG1 Y8\nG1 X3 Y4\nG3 X-3 Y4 I-3 J-4\nG1 X0 Y0\nM2\n"
#: Three cuts after rapids, then a rapid: four cut windows.
CUTS = (
    "G21 G90 G17 F3000\n"
    + "".join(
        f"G0 Z2\nG0 X{x} Y0\nG1 Z-1\nG1 X{x + 6}\nG2 X{x + 6} Y4 I0 J2\nG1 X{x}\nG1 Y0\n"
        for x in (0, 20, 40)
    )
    + "G0 Z5\nM2\n"
)
WINDOW = 64  # servo samples per window of the check: many windows


class Recording(ReferenceSampler):
    """The exact sampler, recording ("begin", k0) per check and ("call", k0, k1) per
    sampling."""

    def __init__(self, windowed: bool):
        self.windowed = windowed
        self.events: list = []

    def __call__(self, pieces, profile, period_s, k0=0, k1=None):
        self.events.append(("call", k0, k1))
        return super().__call__(pieces, profile, period_s, k0, k1)

    def check_begins(self, k0: int) -> None:
        self.events.append(("begin", k0))

    def checks(self) -> list:
        """Per check: (its first sample, the (k0, k1) of every sampling in it)."""
        out: list = []
        for e in self.events:
            if e[0] == "begin":
                out.append((e[1], []))
            else:
                assert out, "sampled before any check began"
                out[-1][1].append(e[1:])
        return out


def test_a_sampler_without_windows_is_evaluated_whole_once_per_check():
    rec = Recording(windowed=False)
    plan, _ = plan_checked(
        interpret_text(CORNERS), MACHINE, reference=rec, keep_reference=False, window=WINDOW
    )
    checks = rec.checks()
    assert plan.iterations > 0 and len(checks) >= plan.iterations + 1
    assert all(first == 0 and calls == [(0, None)] for first, calls in checks)


def test_a_windowed_sampler_is_evaluated_window_by_window():
    rec = Recording(windowed=True)
    plan, _ = plan_checked(
        interpret_text(CORNERS), MACHINE, reference=rec, keep_reference=False, window=WINDOW
    )
    checks = rec.checks()
    assert len(checks) >= plan.iterations + 1
    window_starts = {a for a, _ in checks[0][1]}
    assert checks[0][1][0][0] == 0 and len(checks[0][1]) > 1
    for first, calls in checks:
        # A re-check may resume after the windows a re-plan left alike (the check's memo):
        # it then starts where one of the first check's windows starts.
        assert first == 0 and calls and calls[0][0] in window_starts
        for (a0, b0), (a1, _) in zip(calls, calls[1:]):
            # A window of WINDOW own rows and one row more on each side.
            assert b0 - a0 <= WINDOW + 2 and a1 == b0 - 2
    # The same plan as checked whole.
    whole, _ = plan_checked(
        interpret_text(CORNERS), MACHINE, reference=Recording(False), keep_reference=False
    )
    assert plan.cycle_time_s == whole.cycle_time_s
    assert np.array_equal(plan.caps_mm_s, whole.caps_mm_s)


def test_check_begins_is_called_with_each_checks_first_sample():
    """Cut windows: every check of a window begins at the window's first sample and samples
    nothing before the row ahead of it; without windows each check still begins at the
    window's first sample, its sampler called whole."""
    for windowed in (True, False):
        rec = Recording(windowed)
        windows = list(plan_windows(interpret_text(CUTS), MACHINE, reference=rec, window=WINDOW))
        assert len(windows) == 4  # the three cuts, then the last rapid
        checks = rec.checks()
        firsts = [first for first, _ in checks]
        assert firsts == sorted(firsts)
        assert sorted(set(firsts)) == [w.k0 for w in windows]
        assert len(checks) >= sum(w.iterations + 1 for w in windows)
        for first, calls in checks:
            assert calls
            if windowed:
                assert all(k1 is not None and k0 >= max(first - 1, 0) for k0, k1 in calls)
            else:
                assert calls == [(0, None)]


def test_keeping_the_reference_checks_the_final_plan_whole_from_sample_0():
    rec = Recording(windowed=True)
    plan_checked(interpret_text(CUTS), MACHINE, reference=rec, keep_reference=True, window=WINDOW)
    first, calls = rec.checks()[-1]
    assert first == 0 and calls == [(0, None)]
