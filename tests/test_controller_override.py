"""Feed override above 100 %: the rest re-planned within V, A and J, checked on what the
simulated card executed (finite differences of its positions at 1e5 steps/mm, independent of
the planner's own checks), and the progress (position in mm, part done, time left).

Expected speeds come from the program text (F) and the profile's limits, never from the
code under test.
"""

from __future__ import annotations

import numpy as np
import pytest

from nurbscnc.controller.job import Job
from nurbscnc.controller.simulate import simulate_job
from nurbscnc.machine.profile import default_profile_text, parse_machine
from nurbscnc.output.stream.card import CardConfig
from nurbscnc.pipeline import run_program
from nurbscnc.program.interpret import interpret_text

FINE = {
    "steps.per_mm.x": 1e5,
    "steps.per_mm.y": 1e5,
    "steps.per_mm.z": 1e5,
    "steps.max_pulses_per_period": 32767,
}
T = 1e-3
PER_MM = 1e5
# Exact stops (G61) at every corner: rests where a raised override can take effect.
SQUARE = """G21 G90 G17 G61
G1 X20 F900
G1 Y10
G2 X30 Y20 I10 J0
G1 X0
G1 Y0
M2
"""
F_MM_S = 900 / 60.0


def planned(text: str):
    prog = interpret_text(text)
    mach = parse_machine(default_profile_text(), overrides=FINE)
    return prog, mach, run_program(prog, mach)


def executed_mm(card) -> np.ndarray:
    """Every position the card stood at, from 0, [mm]."""
    steps = np.vstack([np.zeros((1, 3)), np.cumsum(card.executed_pulses(), axis=0)])
    return steps / PER_MM


def speeds(pos: np.ndarray, h: int):
    """|v|, |a|, |j| by finite differences of every h-th position (stride h periods)."""
    d = pos[::h]
    out = []
    for _ in range(3):
        d = np.diff(d, axis=0) / (h * T)
        out.append(np.linalg.norm(d, axis=1))
    return out


def run_at(override: float, events=()):
    prog, mach, run = planned(SQUARE)
    job = Job(run.plan, prog, mach, override=override)
    cfg = CardConfig(speed=1.0, max_pulses_per_period=32767)
    r = simulate_job(job, cfg, events=list(events))
    assert r.completed
    return job, r, mach, run


def check_limits(pos: np.ndarray, mach) -> None:
    """Speed, tangential acceleration and jerk along the path the card executed within the
    profile's V, A, J (the planner's limits are tangential; on an arc the vector's normal
    part v²κ is bounded by the normal cap, checked here as |a| ≤ A as well). The path
    length is the sum of the chords of every h-th position: each chord is off by at most
    √2·1e-5 mm (the rounding of its two ends), which bounds each difference below."""
    lim = mach.limits
    h = 4
    eps = np.sqrt(2.0) * 1e-5
    chords = np.linalg.norm(np.diff(pos[::h], axis=0), axis=1)
    v = chords / (h * T)
    a_t = np.diff(v) / (h * T)
    j_t = np.diff(a_t) / (h * T)
    assert v.max() <= lim.v_max_mm_s + eps / (h * T)
    assert np.abs(a_t).max() <= lim.a_max_mm_s2 + 2 * eps / (h * T) ** 2
    assert np.abs(j_t).max() <= lim.j_max_mm_s3 + 4 * eps / (h * T) ** 3
    a_vec = speeds(pos, h)[1]
    assert a_vec.max() <= lim.a_max_mm_s2 + 4e-5 / (h * T) ** 2


@pytest.mark.parametrize("override", [1.5, 2.0])
def test_override_above_100_from_the_start_raises_the_feed_within_v_a_j(override):
    job100, r100, mach, run = run_at(1.0)
    job, r, _, _ = run_at(override)
    end = np.rint(run.samples.points_mm[-1] * PER_MM).astype(int)
    assert np.array_equal(r.card.position, end)
    pos = executed_mm(r.card)
    check_limits(pos, mach)
    v = speeds(pos, 1)[0]
    # The long lines cruise at override × F (below V_max = 58.3 mm/s here), to rounding.
    assert v.max() == pytest.approx(override * F_MM_S, abs=0.02)
    assert speeds(executed_mm(r100.card), 1)[0].max() == pytest.approx(F_MM_S, abs=0.02)
    t100 = sum(rep.executed_periods for rep in r100.reports)
    t = sum(rep.executed_periods for rep in r.reports)
    assert t < t100 * (1.0 + 1.0 / override) / 2  # clearly faster
    assert job.override == override


def test_override_capped_by_v_max():
    text = SQUARE.replace("F900", "F3000")  # 50 mm/s; ×2 = 100 > V_max = 58.3 mm/s
    prog, mach, run = planned(text)
    job = Job(run.plan, prog, mach, override=2.0)
    r = simulate_job(job, CardConfig(speed=1.0, max_pulses_per_period=32767))
    assert r.completed
    pos = executed_mm(r.card)
    check_limits(pos, mach)
    v = speeds(pos, 1)[0]
    assert v.max() == pytest.approx(mach.limits.v_max_mm_s, abs=0.02)


def test_raising_the_override_while_moving_applies_at_the_next_rest():
    """150 % asked 0.3 s in (on the first line, X20 at F900: 1.33 s): it applies at the
    exact stop at X20 Y0, then the rest runs at 22.5 mm/s; the card never exceeds A and J."""
    job100, r100, mach, run = run_at(1.0)
    job, r, _, _ = run_at(1.0, events=[(0.3, lambda j, c: j.set_override(1.5))])
    assert job.override == 1.5 and not job.notes
    pos = executed_mm(r.card)
    check_limits(pos, mach)
    v = speeds(pos, 1)[0]
    first = int(np.flatnonzero(np.abs(pos[:, 0] - 20.0) < 1e-9)[0])  # at X20 at rest
    assert pos[first].tolist() == pytest.approx([20.0, 0.0, 0.0], abs=1e-9)
    assert v[:first].max() == pytest.approx(F_MM_S, abs=0.02)  # the first line at 100 %
    assert v[first:].max() == pytest.approx(1.5 * F_MM_S, abs=0.02)
    assert len(r.reports) == 2  # cut at the rest: one more section
    assert sum(x.executed_periods for x in r.reports) < sum(
        x.executed_periods for x in r100.reports
    )


def test_progress_gives_the_position_in_mm_the_part_done_and_the_time_left():
    prog, mach, run = planned(SQUARE)
    job = Job(run.plan, prog, mach)
    assert job.progress_of(0) is None  # nothing streamed yet
    # The periods of the whole program, as the simulated card executed them.
    cfg = CardConfig(speed=None, max_pulses_per_period=32767)
    whole = simulate_job(Job(run.plan, prog, mach), cfg)
    assert whole.completed
    n = sum(rep.executed_periods for rep in whole.reports)
    program = job.next_section()  # its first chunk
    assert program.periods < n
    total_mm = 20 + 10 + np.pi * 10 / 2 + 30 + 20  # the square's path, from its text
    for k in (0, 1000, 2500, program.periods):
        pos, done, left = job.progress_of(k)
        steps = program.start_steps + program.pulses[:k].sum(axis=0)
        assert pos.tolist() == pytest.approx((steps / PER_MM).tolist(), abs=1e-12)
        s = float(job.section.track.s_mm[k])
        assert done == pytest.approx(s / total_mm, abs=1e-6)
        # At 100 % the time left is the periods left (the plan's own timing), to a period.
        assert left == pytest.approx((n - k) * T, abs=2 * T)
    note = job.note(2500)
    x, y, z = job.progress_of(2500)[0]
    assert f"X {x:.3f} Y {y:.3f} Z {z:.3f} mm" in note and "% done" in note


def test_stream_command_accepts_up_to_200_percent_and_reports_mm(tmp_path):
    """`stream --feed-override 150` (planned window by window while streaming): the card
    ends at the program's end, in about 2/3 of the periods (the moves cruise at F, no V_max
    in the way); 201 % is refused before the port."""
    import json

    from click.testing import CliRunner

    from nurbscnc.cli.stream import stream
    from tests.stream_helpers import card_on

    nc = tmp_path / "part.nc"
    nc.write_text("G21 G90 G17\nG0 X0 Y0\nG1 X5 Y2 F900\nG1 X8 Y0\nM2\n")
    periods = {}
    with card_on("pty", CardConfig(speed=None)) as (card, ep):
        for pct in (100, 150):
            args = [str(nc), "--port", ep.path, "--json", "--zero", "--feed-override", str(pct)]
            res = CliRunner().invoke(stream, args)
            assert res.exit_code == 0, res.output
            body = json.loads(res.stdout)
            assert body["final_position_steps"] == [8000, 0, 0]
            assert body["final_position_mm"] == [8.0, 0.0, 0.0]
            assert body["feed_override"] == pct / 100
            periods[pct] = body["executed_periods"]
        bad = CliRunner().invoke(stream, [str(nc), "--port", ep.path, "--feed-override", "201"])
        assert bad.exit_code == 2
    assert 0.6 * periods[100] < periods[150] < 0.75 * periods[100]


def test_plus_keys_while_moving_add_up_above_100_percent():
    """Seven + presses 0.2 s apart on the first line (before its rest at X20): 170 % from
    there on (each press counts from the override still pending)."""
    events = [(0.2 * i, lambda j, c: j.step_override(1)) for i in range(1, 8)]
    job, r, mach, _ = run_at(1.0, events)
    assert job.override == pytest.approx(1.7)
    pos = executed_mm(r.card)
    check_limits(pos, mach)
    assert speeds(pos, 1)[0].max() == pytest.approx(1.7 * F_MM_S, abs=0.02)


def test_a_raise_taken_back_before_the_rest_never_applies():
    """130 % asked, then 80 % before the rest where 130 % would apply: the card never goes
    faster than F, and the rest runs at 80 %."""
    events = [(0.2, lambda j, c: j.set_override(1.3)), (0.4, lambda j, c: j.set_override(0.8))]
    job, r, mach, _ = run_at(1.0, events)
    assert job.override == 0.8 and job.pending_override is None
    pos = executed_mm(r.card)
    check_limits(pos, mach)
    v = speeds(pos, 1)[0]
    assert v.max() == pytest.approx(F_MM_S, abs=0.02)
    assert v[-3000:].max() == pytest.approx(0.8 * F_MM_S, abs=0.02)  # the last lines


def test_an_override_above_100_never_slows_the_job_down():
    """programs/butterfly.nc: its rest re-planned at 150 % of F comes out slower than at
    100 % (the jerk-limited profile is not monotonic in its caps), so the job keeps the
    plan's speeds and says so; the card runs no more periods than at 100 %."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "programs" / "butterfly.nc").read_text()
    prog = interpret_text(text)
    mach = parse_machine(default_profile_text())
    run = run_program(prog, mach)
    periods = {}
    for ov in (1.0, 1.5):
        job = Job(run.plan, prog, mach, override=ov)
        r = simulate_job(job, CardConfig(speed=None))
        assert r.completed
        periods[ov] = sum(x.executed_periods for x in r.reports)
    assert periods[1.5] <= periods[1.0]
    assert any("is not faster than at 100 %" in n for n in job.notes)
