"""The stream as a controller: program stops, feed hold, feed override, --zero, --from-line.

Everything runs in virtual time (:func:`simulate_job`: the sender's protocol against the card
simulator over a 115200-baud line, no thread, no sleep): the operator is a list of timed
events. What the card executed (its log of pulses) is checked against independent
references: the stop point's steps, finite differences of the card's positions against the
machine's acceleration and jerk limits, the S-curve closed forms of the planner's feedrate
module, the plain run's path and cycle time.
"""

from __future__ import annotations

import numpy as np
import pytest

from nurbscnc.controller.job import Job
from nurbscnc.controller.motion import phase_states, stop_phases
from nurbscnc.controller.simulate import simulate_job
from nurbscnc.controller.stops import program_stops, start_at_line
from nurbscnc.machine.profile import default_profile_text, parse_machine
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.card import CardConfig, CardSim
from nurbscnc.output.stream.linkstate import SenderOptions
from nurbscnc.pipeline import RunOptions, run_program
from nurbscnc.plan.feedrate import scurve_distance_mm, scurve_duration_s
from nurbscnc.plan.options import LookaheadOptions
from nurbscnc.program.interpret import interpret_text

FINE = {
    "steps.per_mm.x": 1e5,
    "steps.per_mm.y": 1e5,
    "steps.per_mm.z": 1e5,
    "steps.max_pulses_per_period": 32767,
}
T = 1e-3

PAUSES = """G21 G90 G17 G61
G0 X0 Y0 Z5
G1 Z0 F600
G1 X10 F1200
M0
G1 Y10
M1
G1 X0
M60
G1 Y0
M2
"""

SQUARE = """G21 G90 G17 G61
G1 X20 F600
G1 Y10
G2 X30 Y20 I10 J0
G1 X0
G1 Y0
M2
"""


def planned(text: str, overrides=None):
    prog = interpret_text(text)
    mach = parse_machine(default_profile_text(), overrides=overrides)
    return prog, mach, run_program(prog, mach)


def card_positions_mm(card: CardSim, start_steps, per_mm: float) -> np.ndarray:
    """Every position the card stood at, from the start, [mm]."""
    steps = np.vstack([start_steps, start_steps + np.cumsum(card.executed_pulses(), axis=0)])
    return steps / per_mm


def fd(x: np.ndarray, h: int, order: int) -> np.ndarray:
    """|order-th finite difference| of the rows of x at stride h samples, per second^order."""
    d = x[::h]
    for _ in range(order):
        d = np.diff(d, axis=0) / (h * T)
    return np.linalg.norm(d, axis=1)


def distance_to_polyline(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance [mm] of each point to the polyline through ``poly`` (its vertices dense: the
    nearest vertex's two segments hold the nearest point)."""
    from scipy.spatial import cKDTree

    near = cKDTree(poly).query(points)[1]
    best = np.full(len(points), np.inf)
    for lo in (near - 1, near):
        i = np.clip(lo, 0, len(poly) - 2)
        a, ab = poly[i], poly[i + 1] - poly[i]
        ll = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
        t = np.clip(np.einsum("ij,ij->i", points - a, ab) / ll, 0.0, 1.0)
        d = points - (a + t[:, None] * ab)
        best = np.minimum(best, np.sqrt(np.einsum("ij,ij->i", d, d)))
    return best


# -- program stops ----------
def test_m0_stops_the_card_at_rest_and_waits_until_the_operator_continues():
    prog, mach, run = planned(PAUSES)
    job = Job(run.plan, prog, mach)
    seen = {}

    def look(job, card):  # just before the operator continues
        seen.update(
            state=card.state,
            position=card.position.copy(),
            waiting=job.waiting,
            executed=card.executed_periods,
        )

    r = simulate_job(
        job, CardConfig(speed=1.0), events=[(9.99, look), (10.0, lambda j, c: j.resume())]
    )
    assert r.error is None
    # M1 is passed (no --optional-stop); M60 waits like M0: the first wait ended by the
    # event at t = 10 s, the second still waiting (no one continued it).
    assert [w[2] for w in r.waits] == ["M0 at line 5", "M60 at line 9"]
    (start, end, _), (start2, end2, _) = r.waits
    assert end == 10.0 and 1.0 < start < 10.0 and start2 > 10.0 and end2 is None
    # At the wait the card was DONE (buffer drained) at the M0 point, X10 Y0 Z0.
    assert seen["state"] is p.CardState.DONE and seen["waiting"] == "M0 at line 5"
    assert seen["position"].tolist() == [10000, 0, 0]
    assert card_done_at(r.card, [0, 10000, 0]) and job.waiting == "M60 at line 9"


def card_done_at(card, steps) -> bool:
    return card.state is p.CardState.DONE and card.position.tolist() == steps


def test_every_wait_lasts_until_its_resume_event_and_m1_waits_only_with_optional_stop():
    prog, mach, run = planned(PAUSES)
    for optional, expected in (
        (False, ["M0 at line 5", "M60 at line 9"]),
        (True, ["M0 at line 5", "M1 at line 7", "M60 at line 9"]),
    ):
        job = Job(run.plan, prog, mach, optional_stop=optional)
        resumes = [(20.0 * (i + 1), lambda j, c: j.resume()) for i in range(len(expected))]
        r = simulate_job(job, CardConfig(speed=None), events=resumes)
        assert r.completed and job.finished, r.error
        assert [w[2] for w in r.waits] == expected
        assert [w[1] for w in r.waits] == [t for t, _ in resumes]
        assert card_done_at(r.card, [0, 0, 0])
        # The card ran the whole path: the same end and every section started where the
        # previous one stopped (the card's continuity check would have refused otherwise).
        assert len(r.reports) == len(expected) + 1


def test_without_the_operator_the_stream_keeps_waiting():
    prog, mach, run = planned(PAUSES)
    job = Job(run.plan, prog, mach)
    r = simulate_job(job, CardConfig(speed=None))
    assert not r.completed and r.waits[-1][1] is None and job.waiting == "M0 at line 5"
    assert card_done_at(r.card, [10000, 0, 0])


def test_stops_sit_where_the_program_stops():
    prog, _, run = planned(PAUSES)
    stops = program_stops(prog, run.plan)
    # G0 Z5 (5 mm), G1 Z0 (5), X10 (10): M0 at 20 mm; Y10: M1 at 30; X0: M60 at 40.
    lengths = np.cumsum([5.0, 5.0, 10.0, 10.0, 10.0, 10.0])
    assert [s.code for s in stops] == ["M0", "M1", "M60"]
    np.testing.assert_allclose([s.s_mm for s in stops], lengths[[2, 3, 4]], atol=1e-9)


# -- feed hold ----------
@pytest.mark.parametrize("v0, a0", [(50.0, 0.0), (9.0, 1500.0), (30.0, -800.0), (1.0, 2450.0)])
def test_stop_phases_are_the_shortest_stop_within_a_and_j(v0, a0):
    a_max, j_max = 2450.0, 5.0e4
    phases = stop_phases(v0, a0, a_max, j_max)
    total = sum(d for d, _ in phases)
    t = np.linspace(0.0, total, 20001)
    s, v, a, j = phase_states(0.0, v0, a0, phases, t)
    assert abs(v[-1]) < 1e-9 and abs(a[-1]) < 1e-6 and np.all(v >= 0.0)
    assert np.all(np.abs(a) <= a_max * (1 + 1e-9)) and np.all(np.abs(j) <= j_max * (1 + 1e-9))
    if a0 == 0.0:  # an S-curve to rest: the planner's closed forms (SPEC §7)
        assert s[-1] == pytest.approx(scurve_distance_mm(v0, 0.0, a_max, j_max), rel=1e-9)
        assert total == pytest.approx(scurve_duration_s(v0, 0.0, a_max, j_max), rel=1e-9)


def hold_run(hold_at: float, resume_at: float, lead: int | None = None):
    prog, mach, run = planned(SQUARE, FINE)
    job = Job(run.plan, prog, mach)
    cfg = CardConfig(speed=1.0, max_pulses_per_period=32767)
    r = simulate_job(
        job,
        cfg,
        options=SenderOptions(lead_periods=lead),
        events=[(hold_at, lambda j, c: j.request_hold()), (resume_at, lambda j, c: j.resume())],
    )
    return prog, mach, run, job, r


def test_feed_hold_decelerates_within_a_and_j_and_resumes_on_the_programmed_path():
    # Asked at 0.1 s, the hold (256 periods later) stops on the first, 20 mm line.
    _, mach, run, job, r = hold_run(0.1, 3.0)
    assert r.completed, r.error
    lim = mach.limits
    (hold,) = job.holds
    # The card had 256 periods buffered (the sender keeps its buffer full): the latency.
    assert hold.decel_start_period - hold.asked_period == pytest.approx(256, abs=20)
    assert hold.latency_s == pytest.approx(0.256, abs=0.02) and hold.decel_periods > 5
    assert [w[2] for w in r.waits] == ["feed hold"] and r.waits[0][1] == 3.0
    pos = card_positions_mm(r.card, np.zeros(3, dtype=np.int64), 1e5)
    k0, n = hold.decel_start_period, hold.decel_periods
    decel = pos[k0 - 2 : k0 + n + 3]
    # Finite differences of what the card received, at a stride of 4 periods (the 10 nm
    # steps' rounding adds at most 2 steps / (4 ms)² to a and 4 steps / (4 ms)³ to j).
    h = 4
    assert fd(decel, h, 2).max() <= lim.a_max_mm_s2 + 2e-5 / (h * T) ** 2
    assert fd(decel, h, 3).max() <= lim.j_max_mm_s3 + 4e-5 / (h * T) ** 3
    # At rest at the hold point until the resume: the first section ends there.
    first = r.reports[0].executed_periods
    # The first line runs along +X from the origin: the path length is x.
    assert first == k0 + n
    np.testing.assert_allclose(pos[first], [hold.s_mm, 0.0, 0.0], atol=1e-5)
    assert np.linalg.norm(pos[first] - pos[first - 1]) < 1e-9
    speed = fd(pos, 1, 1)
    assert speed[k0 - 1] > 5.0 and speed[k0 + n - 1] < 1e-3
    # The resumed path is the programmed one: every position within 1 µm of the plain run's
    # path (its points 1 ms apart), and the same end.
    plain = run.samples.points_mm
    assert distance_to_polyline(pos, plain).max() < 1e-3
    assert np.array_equal(r.card.position, np.rint(plain[-1] * 1e5).astype(int))


def test_the_hold_never_runs_faster_than_the_plan_at_the_same_place():
    _, _, run, job, r = hold_run(0.5, 1.5)
    assert r.completed
    # The plan's speed along the path vs the hold's, both from the card's first section.
    plain = run.samples
    (hold,) = job.holds
    s_plain, v_plain = plain.s_mm, plain.v_mm_s
    pos = card_positions_mm(r.card, np.zeros(3, dtype=np.int64), 1e5)
    k0, n = hold.decel_start_period, hold.decel_periods
    seg = pos[k0 : k0 + n + 1]
    s_hold = np.concatenate(
        [[plain.s_mm[k0]], plain.s_mm[k0] + np.cumsum(np.linalg.norm(np.diff(seg, axis=0), axis=1))]
    )
    v_hold = np.diff(s_hold) / T
    v_plan_there = np.interp(s_hold[1:], s_plain, v_plain)
    # (0.02 mm/s: the card's 10 nm steps over 1 ms are 0.01 mm/s)
    assert np.all(v_hold <= v_plan_there + 0.02)


def test_a_shorter_lead_makes_the_hold_act_sooner():
    """With --lead 128 the sender keeps at most 128 periods queued: the deceleration begins
    about 128 ms after the request instead of a whole buffer's 256."""
    _, _, _, job, r = hold_run(0.5, 1.5, lead=128)
    assert r.completed and r.card.alarm.name == "NONE"
    (hold,) = job.holds
    assert hold.latency_s == pytest.approx(0.128, abs=0.02)
    assert r.card.max_fill <= 128


def test_a_hold_after_the_last_frame_waits_at_the_end_of_the_section():
    prog, mach, run = planned(PAUSES)
    job = Job(run.plan, prog, mach)
    # Asked when the M0 section (2.75 s) has all its frames sent (the last 256 periods):
    # nothing left to cut, the card stops at M0 as programmed, one wait serves both.
    r = simulate_job(
        job,
        CardConfig(speed=1.0),
        events=[(2.6, lambda j, c: j.request_hold())]
        + [(t, lambda j, c: j.resume()) for t in (30.0, 60.0)],
    )
    assert r.completed and [w[2] for w in r.waits] == ["M0 at line 5", "M60 at line 9"]
    assert job.holds == [] and card_done_at(r.card, [0, 0, 0])


# -- feed override ----------
def test_override_50_percent_doubles_the_motion_time():
    prog, mach, run = planned(SQUARE)
    periods = {}
    for ov in (1.0, 0.5):
        job = Job(run.plan, prog, mach, override=ov)
        r = simulate_job(job, CardConfig(speed=None))
        assert r.completed and card_done_at(
            r.card, np.rint(run.samples.points_mm[-1] * 1e3).astype(int).tolist()
        )
        periods[ov] = sum(rep.executed_periods for rep in r.reports)
    motion = run.plan.cycle_time_s / T
    assert periods[1.0] == pytest.approx(motion, abs=1.0)
    assert periods[0.5] == pytest.approx(2 * motion, abs=2.0)


def test_override_change_while_running_is_smooth_and_scales_the_rest():
    prog, mach, run = planned(SQUARE, FINE)
    job = Job(run.plan, prog, mach)
    cfg = CardConfig(speed=1.0, max_pulses_per_period=32767)
    r = simulate_job(job, cfg, events=[(1.0, lambda j, c: j.set_override(0.5))])
    assert r.completed and job.override == 0.5 and not job.notes
    pos = card_positions_mm(r.card, np.zeros(3, dtype=np.int64), 1e5)
    lim = mach.limits
    h = 4  # finite differences of the card's positions, rounding bounds as above
    assert fd(pos, h, 2).max() <= lim.a_max_mm_s2 + 2e-5 / (h * T) ** 2
    assert fd(pos, h, 3).max() <= lim.j_max_mm_s3 + 4e-5 / (h * T) ** 3
    total = sum(rep.executed_periods for rep in r.reports)
    # The change is applied after the buffered periods (≈ 256 ms) by a ramp of a few ms:
    # the rest of the motion takes twice as long.
    motion = run.plan.cycle_time_s / T
    switch = 1000 + 256
    assert total == pytest.approx(switch + 2 * (motion - switch), rel=0.01)
    assert np.array_equal(r.card.position, np.rint(run.samples.points_mm[-1] * 1e5).astype(int))


def test_override_change_track_respects_a_and_j():
    prog, mach, run = planned(SQUARE)
    job = Job(run.plan, prog, mach)
    events = [(1.0, lambda j, c: j.set_override(0.4)), (3.0, lambda j, c: j.set_override(0.9))]
    tracks = []

    def keep(job, card):
        if job.section is not None:
            tracks.append(job.section.track)

    r = simulate_job(job, CardConfig(speed=1.0), events=[*events, (6.0, keep)])
    assert r.completed and job.override == 0.9
    tr = tracks[-1]
    lim = mach.limits
    # The closed forms a = s''r² + s'ṙ, j = s'''r³ + 3s''rṙ + s'r̈ on every period...
    assert np.abs(tr.a_mm_s2).max() <= lim.a_max_mm_s2 * (1 + 1e-6)
    assert np.abs(tr.j_mm_s3).max() <= lim.j_max_mm_s3 * (1 + 1e-6)
    # ... and the same from the path length by finite differences.
    s = tr.s_mm
    a_fd = np.diff(s, 2) / T**2
    assert np.abs(a_fd).max() <= lim.a_max_mm_s2 * 1.01


# -- --zero and --from-line ----------
def test_zero_declares_the_start_and_a_second_stream_needs_no_restart():
    prog, mach, run = planned(SQUARE)
    cfg = CardConfig(speed=None, position_steps=(1234, -5, 7))
    job = Job(run.plan, prog, mach)
    r = simulate_job(job, cfg, zero=True)
    assert r.completed and r.card.positions_set == 1
    end = np.rint(run.samples.points_mm[-1] * 1e3).astype(int).tolist()
    assert card_done_at(r.card, end)


def test_card_position_can_be_set_when_idle_and_is_refused_while_streaming():
    card = CardSim(CardConfig(speed=None))
    card.on_bytes(p.encode_message(p.SetPosition((5, 6, 7))), 0.0)
    (status,) = [p.decode_message(f) for f in p.FrameDecoder().feed(card.take_output(0.0))]
    assert status.position_steps == (5, 6, 7) and card.position.tolist() == [5, 6, 7]
    card.on_bytes(p.encode_message(p.Hello()), 0.0)
    card.on_bytes(p.encode_message(p.Batch(np.ones((4, 3), dtype=int), (5, 6, 7)), seq=0), 0.0)
    card.take_output(0.0)
    card.on_bytes(p.encode_message(p.SetPosition((0, 0, 0))), 0.0)
    replies = [p.decode_message(f) for f in p.FrameDecoder().feed(card.take_output(0.0))]
    assert card.state is p.CardState.RUNNING and replies == [p.Nak(1, 256, p.NakReason.STATE)]
    assert card.position.tolist() == [9, 10, 11]


FROM_LINE = """G21 G90 G17 G61
G0 X0 Y0 Z5
G1 Z-1 F600
G1 X20 F1500
G0 Z8
G0 X30 Y10
G1 Z-1 F600
G1 Y30 F1500
G1 X10
M2
"""


def test_from_line_moves_up_and_across_then_runs_the_plain_tail():
    # Without the dynamics check both plans are the planner's profile alone: the tail from
    # line 7 is planned from rest at its start in both (the plain run stops there: a rapid
    # then a feed move), so they must be the same periods. (With the check, its local
    # re-plans may lower a cap a little differently: the path is the same, the time not.)
    options = RunOptions(lookahead=LookaheadOptions(dynamics="off"))
    prog = interpret_text(FROM_LINE)
    mach = parse_machine(default_profile_text())
    run = run_program(prog, mach, options)
    tail_prog = start_at_line(prog, 7)  # G1 Z-1 at X30 Y10 (Z8 before it)
    lead = tail_prog.segments[:2]
    np.testing.assert_allclose([s.end_mm for s in lead], [(0, 0, 8), (30, 10, 8)], atol=1e-12)
    assert all(s.rapid for s in lead) and tail_prog.segments[2].line == 7
    job = Job(run_program(tail_prog, mach, options).plan, tail_prog, mach)
    r = simulate_job(job, CardConfig(speed=None))
    assert r.completed
    pos = card_positions_mm(r.card, np.zeros(3, dtype=np.int64), 1e3)
    # First straight up to Z8 on the spot, then across at Z8 to above line 7's start.
    up = np.flatnonzero(pos[:, 2] >= 8.0 - 1e-9)[0]
    assert np.all(pos[: up + 1, :2] == 0.0) and np.all(np.diff(pos[: up + 1, 2]) >= 0)
    there = np.flatnonzero(np.all(pos == [30.0, 10.0, 8.0], axis=1))[0]
    assert np.all(pos[up : there + 1, 2] == 8.0)
    # From there (at rest, after the settle time of the rapid) the plain run's tail.
    plain = np.rint(run.samples.points_mm * 1e3) / 1e3
    k = np.flatnonzero(np.all(plain == [30.0, 10.0, 8.0], axis=1))[0]
    tail, plain_tail = pos[there:], plain[k:]
    assert abs(len(tail) - len(plain_tail)) <= 1
    n = min(len(tail), len(plain_tail))
    # The same motion on the same path: the two sample grids differ by less than a period
    # (where the motion starts after the settle time between two samples), i.e. by less
    # than one period's travel at the fastest feed (F1500: 25 µm), and every point of one
    # lies on the other's path (rounding: 1 µm).
    assert np.abs(tail[:n] - plain_tail[:n]).max() <= 25.0 * T + 1e-6
    assert distance_to_polyline(tail, plain_tail).max() <= 1.5e-3
    assert np.array_equal(pos[-1], plain[-1])


def test_from_line_plunges_at_the_programmed_feed_and_never_below_the_program():
    prog = interpret_text(FROM_LINE)
    lead = start_at_line(prog, 8).segments  # G1 Y30 from X30 Y10 Z-1: down at F1500
    np.testing.assert_allclose(
        [s.end_mm for s in lead[:3]], [(0, 0, 8), (30, 10, 8), (30, 10, -1)], atol=1e-12
    )
    assert [s.rapid for s in lead[:3]] == [True, True, False] and lead[2].feed_mm_s == 25.0


def test_from_line_without_motion_after_it_is_an_error():
    prog, _, _ = planned(FROM_LINE)
    with pytest.raises(ValueError, match="no motion at or after line 99"):
        start_at_line(prog, 99)


@pytest.mark.parametrize("chunk", [4096, 500])
def test_untouched_job_executes_exactly_the_plain_runs_pulses(monkeypatch, chunk):
    """At 100 % with no operator, section by section and chunk by chunk (the periods are
    computed ahead of the link in chunks), the card runs the plain run's pulses."""
    import nurbscnc.controller.job as job_module
    from nurbscnc.output.stream.quantise import quantise

    monkeypatch.setattr(job_module, "CHUNK_PERIODS", chunk)
    prog, mach, run = planned(SQUARE)
    r = simulate_job(Job(run.plan, prog, mach), CardConfig(speed=None))
    assert r.completed and len(r.reports) == 1
    plain = quantise(run.samples.points_mm, mach.steps.per_mm, T)
    assert np.array_equal(r.card.executed_pulses(), plain.pulses)


def test_continue_during_the_deceleration_goes_on_once_the_card_stands():
    _, _, run, job, r = hold_run(0.5, 0.6)  # continue 100 ms after the hold, still queued
    assert r.completed and r.waits == [] and len(job.holds) == 1 and len(r.reports) == 2
    assert np.array_equal(r.card.position, np.rint(run.samples.points_mm[-1] * 1e5).astype(int))
