"""A cut window's levers loop on the pieces around it only (plan/window_levers.py): the
same plan, bit for bit, as the loop over the whole program's levers (the span lo … hi the
program itself), as with the span cut tight at the window, and as with the rules run on
the whole program's levers (where the stop rule may reach past the span)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

import nurbscnc.plan.lookahead as lookahead
from nurbscnc.machine.profile import load_machine
from nurbscnc.plan.levers import Levers
from nurbscnc.plan.lookahead import plan_windows
from nurbscnc.plan.window_levers import WindowSetup, cut_levers, joined_levers
from nurbscnc.program.interpret import interpret_text

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from compile_bench import airfoils_rotated  # noqa: E402

LIMITS = ("a_up_mm_s2", "j_up_mm_s3", "a_down_mm_s2", "j_down_mm_s3")


class _Whole(WindowSetup):
    """The loop over every piece (what the loop did before it was cut to a span)."""

    @staticmethod
    def span(st, a, b, before):
        return 0, st.k


class _Tight(WindowSetup):
    """The span cut at the window's first piece (the stop rule may reach past it)."""

    @staticmethod
    def span(st, a, b, before):
        return a, min(b + 1, st.k)


def _windows(monkeypatch, view, text, machine=None):
    monkeypatch.setattr(lookahead, "WindowSetup", view)
    calls = {"whole": 0}
    original = WindowSetup._whole

    def counted(self, lv, rule):
        calls["whole"] += 1
        original(self, lv, rule)

    monkeypatch.setattr(WindowSetup, "_whole", counted)
    out = []
    for w in plan_windows(interpret_text(text), machine or load_machine()):
        plan = w.plan
        out.append(
            (
                w.first,
                w.end,
                w.iterations,
                plan.cycle_time_s,
                w.check.overs.worst_mm,
                [np.asarray(plan.caps_mm_s).tobytes(), np.asarray(plan.settle_s).tobytes()],
                [np.asarray(getattr(plan.limits, f)).tobytes() for f in LIMITS],
            )
        )
    return out, calls["whole"]


@pytest.fixture(scope="module")
def program_text():
    # One airfoil at ten rotations, after a short dense cut: ten windows whose levers loops
    # shape, fall back and improve, G0s between them.
    return airfoils_rotated(count=1)


def test_the_span_gives_the_whole_programs_plan(monkeypatch, program_text):
    whole, _ = _windows(monkeypatch, _Whole, program_text)
    monkeypatch.undo()
    cut, _ = _windows(monkeypatch, WindowSetup, program_text)
    assert len(whole) == 10
    assert sum(w[2] for w in whole) > 20  # the loops re-planned
    assert cut == whole


def test_a_tight_span_gives_the_same_plan(monkeypatch, program_text):
    whole, _ = _windows(monkeypatch, _Whole, program_text)
    monkeypatch.undo()
    tight, _ = _windows(monkeypatch, _Tight, program_text)
    assert tight == whole


def test_the_rules_on_the_whole_programs_levers_give_the_same_plan(monkeypatch, program_text):
    """Where the span's condition fails (a stop the rules may reach lies outside it), the
    rules run on the program's levers, the result cut back to the span: forced here."""
    whole, _ = _windows(monkeypatch, _Whole, program_text)
    monkeypatch.undo()
    monkeypatch.setattr(WindowSetup, "_exact", lambda self, profile, overs: False)
    forced, wholes = _windows(monkeypatch, _Tight, program_text)
    assert wholes > 20
    assert forced == whole


def test_levers_cut_and_joined_back():
    rng = np.random.default_rng(3)
    k = 40
    lev = Levers(
        *(rng.uniform(1, 2, k) for _ in range(5)),
        rng.uniform(0, 0.01, k),
        rng.uniform(size=k) > 0.5,
        rng.uniform(size=k) > 0.5,
    )
    blame = np.zeros(k)
    blame[[12, 15]] = 0.02
    factor = np.ones(k)
    factor[[12, 15]] = 0.9
    strikes = np.zeros(k, dtype=np.int8)
    strikes[15] = 1
    lev.cap_history = (blame, factor, strikes)
    lev.stop_history = {13: (0.02, 0.8, False), ("settle", 11): (0.02, 0.003)}
    part = cut_levers(lev, 10, 20)
    assert part.caps.size == 10 and part.stop_history == {
        3: (0.02, 0.8, False),
        ("settle", 1): (0.02, 0.003),
    }
    back = joined_levers(lev, part, 10)
    for f in Levers.PER_PIECE:
        assert np.array_equal(getattr(back, f), getattr(lev, f))
    for x, y in zip(back.cap_history, lev.cap_history):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert back.stop_history == lev.stop_history


def test_no_settle_halving_is_tried_where_confine_leaves_none(monkeypatch):
    """A settle of a period or more only outside the window (a margin piece of the span):
    halving it is undone by ``confine``, so the improvement phase plans nothing (it had
    re-planned the same plan once per window)."""
    from types import SimpleNamespace

    from nurbscnc.plan import converge

    k = 5
    lev = Levers(
        *(np.ones(k) for _ in range(5)),
        np.array([0.05, 0.0, 0.0, 0.0, 0.0]),
        np.zeros(k, dtype=bool),
        np.zeros(k, dtype=bool),
    )
    st = SimpleNamespace(period=0.001, eps_mm=0.015, checker=SimpleNamespace(keep=False))
    check = SimpleNamespace(overs=SimpleNamespace(worst_mm=0.01))
    monkeypatch.setattr(converge, "cycle_time_s", lambda result: 1.0)
    calls = []

    def evaluate(lv):
        calls.append(lv.settle_s.copy())
        return (None, None, check)

    def confine(lv):
        lv.settle_s[0] = 0.05  # outside the window: its final settle

    run = converge._Improvement(st, lev, (None, None, check), evaluate, confine)
    run.shorten_settles()
    assert calls == []
    lev.settle_s[2] = 0.004  # a settle of the window's own: halved and tried
    run = converge._Improvement(st, lev, (None, None, check), evaluate, confine)
    run.shorten_settles()
    assert len(calls) == 1 and calls[0][2] == 0.002


def _helices(copies: int) -> str:
    """Fusion 360's arc into a helical ramp (tests/programs/planner), ``copies`` times, each
    5 mm further along X, a G0 between: windows whose curve rule meets arcs (the junctions
    between two curves, each lowered by its own error where their errors differ)."""
    path = Path(__file__).resolve().parent / "programs" / "planner" / "fusion_arc_into_helix.nc"
    moves = path.read_text().splitlines()[2:-2]  # from the first G0 to before the retract
    out = ["G90 G94 G17 G21"]
    for i in range(copies):
        dx_mm = 5.0 * i
        out.append("G0 Z2")
        for line in moves:
            out.append(re.sub(r"X([-0-9.]+)", lambda m, d=dx_mm: f"X{float(m[1]) + d:.3f}", line))
    out += ["G0 Z5", "M2"]
    return "\n".join(out)


@pytest.mark.parametrize("view", [WindowSetup, _Tight])
def test_arcs_curve_rule_on_a_span_gives_the_whole_programs_plan(monkeypatch, view):
    text = _helices(3)
    whole, _ = _windows(monkeypatch, _Whole, text)
    monkeypatch.undo()
    cut, _ = _windows(monkeypatch, view, text)
    assert len(whole) >= 3
    assert sum(w[2] for w in whole) > 6  # the loops re-planned
    assert cut == whole


def _stops(copies: int) -> str:
    """tests/programs/planner's G64 stops between cuts (a star, 25 chords into a corner),
    ``copies`` times each 40 mm further along X, a G0 between: windows where the stop rule
    lowers the final descent's deceleration (LinuxCNC's limits: J above A·|p|)."""
    here = Path(__file__).resolve().parent / "programs" / "planner"
    out = ["G21 G17 G90 G64"]
    for i in range(copies):
        for name in ("stop_star_g64.nc", "stop_chords_g64.nc"):
            moves = (here / name).read_text().splitlines()[1:-1]  # without modes and M2
            dx_mm = 40.0 * i + (0.0 if name.startswith("stop_star") else 20.0)
            for line in moves:
                out.append(
                    re.sub(r"X([-0-9.]+)", lambda m, d=dx_mm: f"X{float(m[1]) + d:.4f}", line)
                )
    out.append("M2")
    return "\n".join(out)


@pytest.mark.parametrize("view", [WindowSetup, _Tight])
def test_the_stop_rules_final_descent_on_a_span_gives_the_whole_programs_plan(monkeypatch, view):
    machine = load_machine(
        Path(__file__).resolve().parents[1] / "bench" / "programs" / "linuxcnc_limits.toml"
    )
    text = _stops(2)
    whole, _ = _windows(monkeypatch, _Whole, text, machine)
    monkeypatch.undo()
    cut, _ = _windows(monkeypatch, view, text, machine)
    assert len(whole) >= 4
    assert sum(w[2] for w in whole) > 8  # the loops re-planned
    assert cut == whole
