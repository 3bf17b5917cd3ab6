"""Streaming while planning (issue 14): the card runs the first cut windows of a program
while the planner still works on the later ones.

Everything runs in virtual time (:func:`simulate_job`, the card simulator over a simulated
line) except the threaded planner of the first test, which plans for real on its own thread.
What is checked, against independent references:

- the first period leaves before the last window is planned: the planner thread is held
  before its last window until the card has executed a period (an event order, no clock; a
  stream that waited for the whole plan would never execute one);
- a planner ahead of the card: the card executes exactly the pulses of ``run``'s reference
  points (the plain run of the same program, planned whole by ``plan_checked``) and the points
  the job quantised equal ``run``'s to 1e-9 mm; each window after the first is adopted while
  the card moves (a margin measured for each);
- a planner that fails after the first window: the card stops at rest at that window's end
  (the plan's rest point) and the planner's error is raised there;
- a slowed planner (windows released late, in virtual time): the card waits at rest at the
  end of a cut window — every planning hold at a planned rest (speed 0 there in the plan and
  in the streamed periods), the card's position there the plan's rest point — the holds and
  the time held reported, and the card ends at the program's end.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from nurbscnc.controller import job as job_module
from nurbscnc.controller.feed import ScheduledFeed, WindowFeed
from nurbscnc.controller.job import Job
from nurbscnc.controller.simulate import simulate_job
from nurbscnc.errors import PlanningError
from nurbscnc.machine.profile import default_profile_text, parse_machine
from nurbscnc.output.stream.card import CardConfig
from nurbscnc.output.stream.quantise import quantise
from nurbscnc.pipeline import run_program, window_plans
from nurbscnc.plan.lookahead import plan_windows
from nurbscnc.program.interpret import interpret_text

POINTS_MM = 1e-9

#: Four cuts, each after rapids, then a rapid up: five cut windows.
CUTS = """G21 G90 G17
G0 X0 Y0 Z1
G1 Z0 F600
G1 X10 F1200
G1 Y5
G0 Z1
G0 X20 Y0
G1 Z0 F600
G2 X30 Y0 I5 J0 F1200
G0 Z1
G0 X0 Y10
G1 Z0 F600
G1 X10 Y15 F1200
G0 Z1
G0 X40 Y5
G1 Z0 F600
G3 X40 Y15 I0 J5 F900
G0 Z5
M2
"""


def _setup():
    prog = interpret_text(CUTS)
    mach = parse_machine(default_profile_text())
    return prog, mach, run_program(prog, mach)


def _recording(monkeypatch):
    """Every finished section's track (what the job quantised) and how it ended."""
    done = []
    original = Job.section_done

    def section_done(self, executed_periods):
        sec = self.section
        done.append((sec.track, sec.at_horizon))
        return original(self, executed_periods)

    monkeypatch.setattr(Job, "section_done", section_done)
    return done


def test_first_period_leaves_before_the_last_window_is_planned():
    prog, mach, run = _setup()
    events: list = []
    card_ran = threading.Event()

    def planner():
        for w in window_plans(prog, mach):
            if w.end == len(w.plan.pieces):  # the last window: not before the card runs
                assert card_ran.wait(120.0), "the card never ran before the whole plan"
            events.append(("planned", w.index))
            yield w

    job = Job(None, prog, mach, feed=WindowFeed(planner()))
    update = job.update

    def watched(link):
        status = link.state.status
        if status is not None and status.executed_periods > 0 and not card_ran.is_set():
            events.append(("card ran", None))
            card_ran.set()
        update(link)

    job.update = watched
    r = simulate_job(job, CardConfig(speed=1.0))
    assert r.completed
    n = len(list(plan_windows(prog, mach)))
    assert n == 5  # four cuts after rapids, then the closing rapid
    assert events.index(("card ran", None)) < events.index(("planned", n - 1))
    assert job.report()["planning"]["windows"] == n
    assert np.array_equal(
        r.card.position, np.rint(run.samples.points_mm[-1] * mach.steps.per_mm).astype(int)
    )


def test_a_planner_ahead_streams_exactly_runs_points(monkeypatch):
    prog, mach, run = _setup()
    monkeypatch.setattr(job_module, "CHUNK_PERIODS", 500)  # chunks cut at the horizons too
    done = _recording(monkeypatch)
    windows = list(plan_windows(prog, mach))
    # Window i ready at 0.1 s × i: well before the card reaches its start.
    feed = ScheduledFeed(windows, [0.1 * i for i in range(len(windows))])
    job = Job(None, prog, mach, feed=feed)
    r = simulate_job(job, CardConfig(speed=1.0))
    assert r.completed and len(r.reports) == 1 and r.waits == []
    plain = quantise(run.samples.points_mm, mach.steps.per_mm, mach.servo.period_s)
    assert np.array_equal(r.card.executed_pulses(), plain.pulses)
    ((track, at_horizon),) = done
    assert not at_horizon
    np.testing.assert_allclose(track.points_mm, run.samples.points_mm, rtol=0, atol=POINTS_MM)
    planning = job.report()["planning"]
    assert planning["windows"] == len(windows) and planning["holds"] == 0
    assert len(job.planning["margins_s"]) == len(windows) - 1
    assert planning["plan_margin_min_s"] > 0.0


def test_a_slow_planner_holds_at_rests_only(monkeypatch):
    prog, mach, run = _setup()
    done = _recording(monkeypatch)
    windows = list(plan_windows(prog, mach))
    final = windows[-1].plan
    # Each window later than the card could use it: 3 s apart (each cut lasts < 3 s).
    feed = ScheduledFeed(windows, [3.0 * i for i in range(len(windows))])
    job = Job(None, prog, mach, feed=feed)
    r = simulate_job(job, CardConfig(speed=1.0))
    assert r.completed
    holds = [track for track, at_horizon in done if at_horizon]
    assert len(holds) == job.report()["planning"]["holds"] == len(windows) - 1
    rests = {float(final.profile.piece_start_mm[w.end]): w for w in windows[:-1]}
    for track in holds:
        s_end = float(track.s_mm[-1])
        w = rests[min(rests, key=lambda s: abs(s - s_end))]
        assert abs(s_end - final.profile.piece_start_mm[w.end]) <= POINTS_MM
        assert final.profile.junction_speeds_mm_s[w.end] == 0.0  # a rest of the plan
        assert track.v_mm_s[-1] == 0.0  # and at rest in the streamed periods
        np.testing.assert_allclose(
            track.points_mm[-1], final.pieces.start_mm[:, w.end], rtol=0, atol=1e-6
        )
    waited = sum(b - a for a, b, why in r.waits if why == "planning")
    planning = job.report()["planning"]
    assert waited > 0.0 and abs(planning["held_s"] - waited) <= 1e-6
    assert np.array_equal(
        r.card.position, np.rint(run.samples.points_mm[-1] * mach.steps.per_mm).astype(int)
    )


def test_a_planner_error_stops_the_card_at_rest_at_the_planned_end():
    prog, mach, _ = _setup()
    windows = list(plan_windows(prog, mach))

    def failing():
        yield windows[0]
        raise PlanningError("line 7: planned too late for this test")

    job = Job(None, prog, mach, feed=WindowFeed(failing()))
    card = []
    original = job.section_done

    def section_done(executed_periods):
        card.append(job.section.track)
        return original(executed_periods)

    job.section_done = section_done
    with pytest.raises(PlanningError, match="planned too late"):
        simulate_job(job, CardConfig(speed=1.0))
    (track,) = card
    end = windows[0].end
    assert track.v_mm_s[-1] == 0.0
    np.testing.assert_allclose(
        track.points_mm[-1], windows[-1].plan.pieces.start_mm[:, end], rtol=0, atol=1e-6
    )


def test_closing_the_feed_stops_the_planner_after_its_window():
    """The stream over (an error, an abort): the planner thread plans no further window and
    has ended when ``close`` returns, so the process never exits while it is inside numpy."""
    import threading
    import time

    made = []

    def slow():
        for i in range(1000):
            time.sleep(0.02)  # a window's planning
            made.append(i)
            yield i

    feed = WindowFeed(slow())
    assert feed.first() == 0
    feed.close()
    assert not any(t.name == "nurbscnc-planner" and t.is_alive() for t in threading.enumerate())
    count = len(made)
    time.sleep(0.1)
    assert len(made) == count < 1000
