"""Rotary axes on the card's wire: protocol version 4 (the CAPS's axis mask over X Y Z A B C,
one count per driven axis), the card simulator with up to six axes speaking 3 or 4, steps
per degree, a version-3 card refused for a program that moves A, axes a program does not
move standing where the card stands, and the positions in degrees (card-position, jog, the
stream report).

The machine: the bundled profile with 800 / 1000 / 400 steps per mm on X / Y / Z and
250 steps per degree on A, 40 on B (every axis different, so a mixed-up column shows).
The programs are hand-built samples (:class:`~nurbscnc.plan.timing.Samples`) of a move
whose text is given beside it; the card's expected steps are worked out here from that
text and the steps per unit, never taken from the code under test.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.app.mdi import jog_block, parse_jog
from nurbscnc.app.stream import (
    position_abc_deg,
    pulses_of_points,
    pulses_of_samples,
    sample_points,
    stream_report,
)
from nurbscnc.errors import EXIT_INPUT, CardAxesError, ConfigError
from nurbscnc.machine.model import RotaryAxis
from nurbscnc.machine.profile import load_machine
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.axes import axes_of_position, mask_of, names_of, stream_axes
from nurbscnc.output.stream.card import CardConfig, CardSim
from nurbscnc.output.stream.noise import ByteRelay
from nurbscnc.output.stream.simlink import simulate
from nurbscnc.plan.timing import Samples

STEPS_MM = (800.0, 1000.0, 400.0)
A_STEPS_DEG = 250.0
B_STEPS_DEG = 40.0
PERIOD_S = 1e-3


def rotary_machine(wrapped_a: bool = False, a_steps: float = A_STEPS_DEG):
    """The bundled machine with distinct steps per unit, an A (and a B) axis."""
    m = load_machine()
    steps = dataclasses.replace(m.steps, per_mm=STEPS_MM)
    return dataclasses.replace(
        m,
        steps=steps,
        rotary_axes={
            "a": RotaryAxis("a", 60.0, 400.0, 4000.0, wrapped=wrapped_a, steps_per_deg=a_steps),
            "b": RotaryAxis("b", 60.0, 400.0, 4000.0, -30.0, 30.0, steps_per_deg=B_STEPS_DEG),
        },
    )


def samples_of_move(start, end, abc_start, abc_end, duration_s: float, rotary=("a",)):
    """Samples of one straight move from ``start`` to ``end`` [mm] with A B C moving
    linearly along it from ``abc_start`` to ``abc_end`` [deg] (trivkins: in step with the
    path), on a rest-to-rest smootherstep profile of ``duration_s`` at 1 kHz."""
    n = int(round(duration_s / PERIOD_S)) + 1
    t = np.arange(n) * PERIOD_S
    x = t / t[-1]
    u = x**3 * (10.0 + x * (-15.0 + 6.0 * x))  # 0 → 1, at rest at both ends
    p0, p1 = np.asarray(start, float), np.asarray(end, float)
    q0, q1 = np.asarray(abc_start, float), np.asarray(abc_end, float)
    points = p0 + u[:, None] * (p1 - p0)
    abc = q0 + u[:, None] * (q1 - q0)
    length = float(np.linalg.norm(p1 - p0))
    return Samples(
        t,
        t,
        u * length,
        np.gradient(u * length, t),
        np.zeros(n),
        np.zeros(n, dtype=np.int64),
        points,
        None,
        np.full(n, 7, dtype=np.int64),
        abc_deg=abc,
        rotary_axes=tuple(rotary),
    )


# -- the protocol ----------
def test_axis_masks_name_x_y_z_a_b_c_in_order():
    assert mask_of("xyz") == 0b000111 == p.XYZ_MASK
    assert mask_of("xyza") == 0b001111 and mask_of("xyzabc") == 0b111111
    assert mask_of("xyzb") == 0b010111 and names_of(0b010111) == "xyzb"
    assert stream_axes(("c", "a")) == "xyzac" and stream_axes(()) == "xyz"
    with pytest.raises(ValueError, match="'u' is not an axis"):
        mask_of("xyzu")


def test_version_4_caps_carries_the_axis_mask_and_version_3_is_unchanged():
    v3 = p.Caps(3, 3, 127, 256, 1000, 0xDEADBEEF, 0, (1, -2, 3))
    raw3 = p.encode_message(v3)
    assert len(raw3) == 37  # docs/protocol.md: CAPS 37 bytes with 3 axes
    # the version-3 layout: head, then the position right after the state byte
    assert raw3[6 + 15 : 6 + 15 + 12] == np.array([1, -2, 3], "<i4").tobytes()
    (frame,) = p.FrameDecoder().feed(raw3)
    assert p.decode_message(frame) == v3 and v3.axis_mask == 0b111

    v4 = p.Caps(4, 5, 127, 256, 1000, 7, 0, (1, 2, 3, 4, 5), axis_mask=0b110111)
    raw4 = p.encode_message(v4)
    assert len(raw4) == 10 + 15 + 1 + 4 * 5  # one mask byte more, one i32 per axis
    assert raw4[6 + 15] == 0b110111
    (frame,) = p.FrameDecoder().feed(raw4)
    assert p.decode_message(frame) == v4


def test_a_version_4_caps_whose_mask_does_not_fit_its_positions_is_refused():
    bad = p.encode_message(p.Caps(4, 4, 127, 256, 1000, 7, 0, (1, 2, 3, 4), axis_mask=0b111))
    (frame,) = p.FrameDecoder().feed(bad)
    with pytest.raises(p.ProtocolError, match="axis mask 0x07 does not fit 4 positions"):
        p.decode_message(frame)


def test_the_card_simulator_speaks_3_or_4():
    v3 = CardSim(CardConfig(speed=None), seed=1)
    assert (v3.config.version, v3.caps().version, v3.caps().axis_mask) == (3, 3, 0b111)
    v4 = CardSim(CardConfig(speed=None, axis_names="xyzac", position_steps=(1, 2, 3, 4, 5)))
    caps = v4.caps()
    assert (caps.version, caps.axes, caps.axis_mask) == (4, 5, 0b101111)
    assert caps.position_steps == (1, 2, 3, 4, 5)
    six = CardConfig(axis_names="XYZABC")
    assert (six.axes, six.version, six.position_steps) == (6, 4, (0,) * 6)
    # a 6-axis int8 BATCH: (255 − 1 − 24) / 6 = 38 periods
    assert p.max_batch_periods(6) == 38
    with pytest.raises(ConfigError, match="protocol 3 drives X Y Z, not X Y Z A"):
        CardConfig(axis_names="xyza", version=3)
    with pytest.raises(ConfigError, match="in the order XYZABC"):
        CardConfig(axis_names="xyaz")


# -- quantisation ----------
def test_rotary_steps_per_degree_with_the_same_rounding_as_xyz():
    """G1 X10 A90 from 0: X 10 × 800 = 8000 steps, A 90 × 250 = 22500 steps; every period's
    running sum is round(a_k · 250) (the remainder carried, no drift)."""
    mach = rotary_machine()
    s = samples_of_move((0, 0, 0), (10, 0, 0), (0, 0, 0), (90, 0, 0), 0.6)
    prog = pulses_of_samples(s, mach)
    assert prog.axes == "xyza" and prog.pulses.shape == (600, 4)
    assert tuple(prog.end_steps) == (8000, 0, 0, 22500)
    running = prog.start_steps + np.cumsum(prog.pulses, axis=0)
    np.testing.assert_array_equal(running[:, 3], np.rint(s.abc_deg[1:, 0] * 250.0))
    np.testing.assert_array_equal(running[:, 0], np.rint(s.points_mm[1:, 0] * 800.0))
    assert np.all(prog.line == 7)


def test_an_axis_without_steps_per_degree_cannot_be_streamed():
    mach = rotary_machine(a_steps=0.0)
    s = samples_of_move((0, 0, 0), (1, 0, 0), (0, 0, 0), (10, 0, 0), 0.1)
    with pytest.raises(ConfigError, match=r"no steps per degree for A .*cannot be streamed"):
        pulses_of_samples(s, mach)
    with pytest.raises(ConfigError, match="has no C axis"):
        pulses_of_points(np.zeros((2, 4)), mach, None, "xyzc")


def test_the_pulse_ceiling_holds_per_axis_and_names_the_rotary_axis():
    """90° in 0.1 s at 250 steps/deg peaks at 1.875 · 22500 / 100 ≈ 422 steps per period
    (smootherstep's peak slope 15/8), over the card's 127."""
    mach = rotary_machine()
    s = samples_of_move((0, 0, 0), (0.1, 0, 0), (0, 0, 0), (90, 0, 0), 0.1)
    with pytest.raises(Exception, match=r"pulses on A, more than the card's limit of 127"):
        pulses_of_samples(s, mach)


def test_samples_that_use_b_but_carry_no_column_are_refused():
    s = dataclasses.replace(
        samples_of_move((0, 0, 0), (1, 0, 0), (0, 0, 0), (0, 5, 0), 0.1, ("b",)), abc_deg=None
    )
    with pytest.raises(Exception, match="move B but carry no A B C column"):
        sample_points(s)


# -- streaming to the simulated card ----------
def test_a_rotary_program_ends_at_the_steps_of_its_text():
    """G1 X10 Y-2 Z-1.25 A90 B-12.5 from the card's (0, 0, 0, A 10°, B 0): the card ends at
    (10·800, −2·1000, −1.25·400, 90·250, −12.5·40) = (8000, −2000, −500, 22500, −500)."""
    mach = rotary_machine()
    s = samples_of_move((0, 0, 0), (10, -2, -1.25), (10, 0, 0), (90, -12.5, 0), 1.0, ("a", "b"))
    prog = pulses_of_samples(s, mach)
    card = CardConfig(speed=1.0, axis_names="xyzab", position_steps=(0, 0, 0, 2500, 0))
    r = simulate(prog, card)
    assert r.completed and r.exact(prog), r.error
    assert r.report.final_position_steps == (8000, -2000, -500, 22500, -500)
    assert r.report.axes == "xyzab"
    report = stream_report("part.nc", None, [r.report], mach)
    assert report["final_position_mm"] == [10.0, -2.0, -1.25]
    assert report["final_abc_deg"] == {"a": 90.0, "b": -12.5}


def test_axes_the_program_does_not_move_stand_where_the_card_stands():
    """An A program on a card driving X Y Z A C: C (at 777 steps) gets 0 pulses every
    period and stands; an XYZ program on a version-4 card with A leaves A at its 123 steps."""
    mach = rotary_machine()
    s = samples_of_move((0, 0, 0), (5, 0, 0), (0, 0, 0), (-45, 0, 0), 0.5)
    prog = pulses_of_samples(s, mach)
    r = simulate(prog, CardConfig(speed=None, axis_names="xyzac", position_steps=(0,) * 4 + (777,)))
    assert r.completed, r.error
    ran = r.card.executed_pulses()
    assert ran.shape == (500, 5) and not ran[:, 4].any()
    np.testing.assert_array_equal(ran[:, :4], prog.pulses)
    assert r.report.final_position_steps == (4000, 0, 0, -11250, 777)

    xyz = pulses_of_points(s.points_mm, mach)
    r = simulate(xyz, CardConfig(speed=None, axis_names="xyza", position_steps=(0, 0, 0, 123)))
    assert r.completed and r.report.final_position_steps == (4000, 0, 0, 123)
    np.testing.assert_array_equal(r.card.executed_pulses()[:, :3], xyz.pulses)


def test_a_version_3_card_is_refused_before_anything_streams():
    mach = rotary_machine()
    s = samples_of_move((0, 0, 0), (5, 0, 0), (0, 0, 0), (30, 0, 0), 0.5)
    r = simulate(pulses_of_samples(s, mach), CardConfig(speed=None))
    assert not r.completed and isinstance(r.error, CardAxesError)
    assert r.error.message == "the card speaks protocol 3 (X Y Z only); this program moves A"
    assert r.error.exit_code == EXIT_INPUT == 2
    assert r.card.executed_pulses().shape[0] == 0 and r.card.state is p.CardState.FILLING
    assert r.card.frames_received == r.link.state.hellos  # HELLOs only: no BATCH, no END
    # a version-4 card without B refuses a B program the same way, naming what it drives
    sb = samples_of_move((0, 0, 0), (5, 0, 0), (0, 0, 0), (0, 10, 0), 0.5, ("b",))
    r = simulate(pulses_of_samples(sb, mach), CardConfig(speed=None, axis_names="xyza"))
    assert r.error.message == "the card drives X Y Z A; this program moves B"


def test_an_xyz_program_to_a_version_3_card_is_sent_as_before():
    """The same frames as version 3 had: the BATCH/END bytes of an XYZ program do not
    depend on the card's version (only the HELLO's version byte is 4)."""
    mach = rotary_machine()
    s = samples_of_move((0, 0, 0), (3, 2, -1), (0, 0, 0), (0, 0, 0), 0.3, ())
    prog = pulses_of_samples(s, mach)
    assert prog.axes == "xyz" and prog.pulses.shape[1] == 3
    sent = []
    r = simulate(prog, CardConfig(speed=None), to_card=lambda b: sent.append(b) or b)
    assert r.completed and r.exact(prog)
    assert r.report.final_position_steps == (2400, 2000, -400)
    frames = [f for b in sent for f in p.FrameDecoder().feed(b)]
    batches = [p.decode_message(f) for f in frames if f.type == p.MsgType.BATCH]
    assert all(b.pulses.shape[1] == 3 for b in batches)
    np.testing.assert_array_equal(np.vstack([b.pulses for b in batches]), prog.pulses)


def test_a_noisy_line_with_a_rotary_axis_still_runs_every_period_once():
    """2 % of the bytes flipped both ways on an X + A program (the frames one count longer
    per period), to a card executing periods as they arrive (as the XYZ noisy-line tests:
    at 2 % a real-time card would underrun): every period runs once, in order, and the card
    ends where the program's text says."""
    mach = rotary_machine()
    s = samples_of_move((0, 0, 0), (8, 0, 0), (0, 0, 0), (180, 0, 0), 1.5)
    prog = pulses_of_samples(s, mach)
    card = CardConfig(speed=None, axis_names="xyza")
    r = simulate(
        prog,
        card,
        to_card=ByteRelay(corrupt_rate=0.02, seed=3),
        to_host=ByteRelay(corrupt_rate=0.02, seed=4),
        max_time_s=600.0,
    )
    assert r.completed and r.exact(prog), r.error
    assert r.report.final_position_steps == (6400, 0, 0, 45000)
    assert r.report.retransmits > 0


# -- positions in degrees, jog ----------
def test_positions_split_into_mm_and_degrees():
    mach = rotary_machine()
    assert axes_of_position(3, mach) == "xyz" and axes_of_position(5, mach) == "xyzab"
    assert position_abc_deg((800, 0, 0, 25, -40), mach) == {"a": 0.1, "b": -1.0}
    assert position_abc_deg((800, 0, 0), mach) == {}
    with pytest.raises(ConfigError, match="the card has 4 axes, the machine profile 5"):
        axes_of_position(4, mach)


def _jog_end_abc_deg(block: str, mach, at_deg: float, parameters: dict) -> tuple:
    """Where the interpreter takes A B C [deg, machine] with the jog ``block`` from A =
    ``at_deg`` with the parameter file's ``parameters`` (its work offsets)."""
    from nurbscnc.program.interpret import InterpretOptions, interpret_text

    prog = interpret_text(
        block,
        InterpretOptions(
            rotary_axes=mach.rotary_axes,
            start_abc_deg=(at_deg, 0.0, 0.0),
            parameters=parameters,
        ),
    )
    return prog.segments[-1].abc_end_deg


@pytest.mark.parametrize(
    ("at_deg", "delta_deg"), [(350.0, 20.0), (350.0, -20.0), (10.0, -10.0), (725.0, 359.5), (0, 90)]
)
@pytest.mark.parametrize("a_offset_deg", [0.0, 30.0, -200.0])
def test_a_jog_of_a_wrapped_axis_turns_by_the_asked_amount(at_deg, delta_deg, a_offset_deg):
    """The card's A + Δ whatever the A work offset (G54 A = parameter 5224): a G53 word of a
    wrapped axis is unwrapped about the offsets, so A 10 + 10 with a 30° offset went to 40."""
    mach = rotary_machine(wrapped_a=True)
    steps = (0, 0, 0, round(at_deg * A_STEPS_DEG), 0)
    block = jog_block(["A" + f"{delta_deg:+g}"], steps, mach)
    assert block == f"G91 G0 A{delta_deg:+.6f}"
    end = _jog_end_abc_deg(block, mach, at_deg, {5224: a_offset_deg})
    assert end == pytest.approx((at_deg + delta_deg, 0.0, 0.0), abs=1e-9)


def test_a_jog_of_x_and_a_wrapped_axis_is_two_blocks():
    mach = rotary_machine(wrapped_a=True)
    steps = (8000, 0, 0, 2500, 40)  # X 10 mm, A 10°, B 1°
    block = jog_block(["X-1", "A+10", "B+1"], steps, mach, 300.0)
    assert block == "G90 G53 G1 F300 X9.000000 B2.000000\nG91 G1 F300 A+10.000000"
    end = _jog_end_abc_deg(block, mach, 10.0, {5224: 30.0, 5225: 5.0})
    assert end == pytest.approx((20.0, 2.0, 0.0), abs=1e-9)


def test_jog_of_a_rotary_axis():
    mach = rotary_machine()
    steps = (8000, 0, 0, 2500, 40)  # X 10 mm, A 10°, B 1°
    assert parse_jog(["a+10", "X-1"]) == {3: 10.0, 0: -1.0}
    assert jog_block(["X-1", "A+10"], steps, mach) == "G90 G53 G0 X9.000000 A20.000000"
    assert jog_block(["B-2.5"], steps, mach, 300.0) == "G90 G53 G1 F300 B-1.500000"
    with pytest.raises(ConfigError, match=r"the machine has no C axis"):
        jog_block(["C+1"], steps, mach)
    with pytest.raises(ConfigError, match="the card does not drive A"):
        jog_block(["A+1"], (8000, 0, 0), mach)


def test_card_position_reports_a_in_degrees(monkeypatch):
    """card-position on a card driving X Y Z A B: A and B in degrees from the profile."""
    from nurbscnc.cli import common
    from nurbscnc.cli.main import main
    from tests.stream_helpers import card_on

    mach = rotary_machine()
    monkeypatch.setattr(common, "load_machine_cli", lambda *a, **k: mach)
    cfg = CardConfig(speed=None, axis_names="xyzab", position_steps=(800, -1000, 400, 22500, -80))
    with card_on("pty", cfg) as (_card, ep):
        r = CliRunner().invoke(main, ["card-position", "--port", ep.path, "--json"])
        assert r.exit_code == 0, r.output
        body = json.loads(r.stdout.strip().splitlines()[-1])
        assert body["position_mm"] == [1.0, -1.0, 1.0]
        assert body["position_abc_deg"] == {"a": 90.0, "b": -2.0}
        r = CliRunner().invoke(main, ["card-position", "--port", ep.path])
        assert r.exit_code == 0 and "1.0000, -1.0000, 1.0000 mm, A 90.0000°, B -2.0000°" in r.stdout


def test_the_start_a_b_c_is_passed_on_to_the_interpreter():
    """A program streamed from a card at A 90° starts there: the interpreter's option
    ``start_abc_deg``."""
    from nurbscnc.app.load import start_abc_option

    assert start_abc_option(None) == {} and start_abc_option((0.0, 0.0, 0.0)) == {}
    assert start_abc_option((90, 0, -5)) == {"start_abc_deg": (90.0, 0.0, -5.0)}


def test_jog_of_an_axis_the_machine_lacks_is_a_clear_error(tmp_path, monkeypatch):
    """``jog A+10`` on the bundled 3-axis machine: exit 2, the axis named, the card not
    moved."""
    from nurbscnc.cli.main import main
    from tests.stream_helpers import card_on, write_mixed_steps_machine

    write_mixed_steps_machine(tmp_path, monkeypatch)
    with card_on("pty", CardConfig(speed=None)) as (card, ep):
        r = CliRunner().invoke(
            main, ["jog", "A+10", "--port", ep.path, "--machine", "m.toml", "--quiet"]
        )
        assert r.exit_code == 2, r.output
        assert "jog: the machine has no A axis ([axis_limits.a])" in r.stderr
        assert card.executed_pulses().shape[0] == 0


def test_card_sim_options_name_the_axes_and_the_protocol():
    from nurbscnc.cli.card import _card_axes

    assert _card_axes("XYZA") == (4, "xyza") and _card_axes("3") == (3, "")
    from nurbscnc.cli.main import main

    r = CliRunner().invoke(main, ["card-sim", "--axes", "XYZA", "--protocol", "3"])
    assert r.exit_code == 2 and "protocol 3 drives X Y Z, not X Y Z A" in r.stderr


# -- a rotary program streamed section by section -------------------------------------------------
def _staged_parts(mach):
    """Three moves with X, A (and a held B) split by M0 (waits), M1 (passes without
    --optional-stop) and M6 T2 (waits): X 0→4 mm with A 0→30°, X 4→6 with A 30→−15°, then
    X 6→9 with A −15→0°; B stands at 2.5° throughout."""
    from nurbscnc.controller.staged import StagedSection, split_pulses
    from nurbscnc.controller.stops import Stop

    moves = [((0, 0, 0), (4, 0, 0), 0, 30), ((4, 0, 0), (6, 0, 0), 30, -15)]
    moves.append(((6, 0, 0), (9, 0, 0), -15, 0))
    parts = [
        samples_of_move(p0, p1, (a0, 2.5, 0), (a1, 2.5, 0), 0.3, ("a", "b"))
        for p0, p1, a0, a1 in moves
    ]
    rows = [sample_points(parts[0])[0]] + [sample_points(s)[0][1:] for s in parts[1:]]
    pulses = pulses_of_points(np.vstack(rows), mach, None, "xyzab")
    ends = np.cumsum([len(r) for r in rows]) - 1
    stops = [Stop(0.0, 3, "M0", message="turn the part"), Stop(0.0, 5, "M1")]
    stops.append(Stop(0.0, 8, "M6", tool=2))
    split = split_pulses(pulses, [ends[0], ends[1], ends[1], ends[2]])
    return pulses, [StagedSection(p, s) for p, s in zip(split, [*stops, None])]


def test_a_program_planned_whole_waits_at_its_stops_and_ends_where_its_text_says():
    """The card waits at M0 and M6 (the operator's continue after 1 s each), passes M1, and
    ends at X 9 mm = 7200 steps, A 0, B 2.5° · 40 = 100 steps; it ran exactly the pulses of
    the whole plan, in three sections, each starting where the one before ended."""
    from nurbscnc.controller.simulate import simulate_job
    from nurbscnc.controller.staged import StagedJob

    mach = rotary_machine()
    pulses, sections = _staged_parts(mach)
    assert [None if s.pulses is None else s.pulses.periods for s in sections] == [
        300,
        300,
        None,
        300,
    ]
    for before, after in zip(sections[0:1] + sections[1:2], sections[1:2] + sections[3:4]):
        np.testing.assert_array_equal(after.pulses.start_steps, before.pulses.end_steps)
    job = StagedJob(sections, PERIOD_S, tools=None)
    assert job.plan.cycle_time_s == pytest.approx(0.9)
    cfg = CardConfig(speed=1.0, axis_names="xyzab", position_steps=(0, 0, 0, 0, 100))
    resume = [(t, lambda j, _c: j.resume()) for t in (2.0, 4.0)]
    r = simulate_job(job, cfg, events=resume)
    assert r.completed, r.error
    assert [w[2] for w in r.waits] == [
        "M0 at line 3: turn the part",
        "M6 at line 8: load tool 2 (not in the tool table)",
    ]
    assert r.reports[-1].final_position_steps == (7200, 0, 0, 0, 100)
    np.testing.assert_array_equal(r.card.executed_pulses(), pulses.pulses)
    assert job.report()["sections"] == 3 and job.finished


def test_a_feed_hold_of_a_program_planned_whole_is_the_cards_hold():
    """A hold 0.2 s into the first section: the card stops executing (HOLD) and the note
    says so; the continue 1 s later lets it finish that section exactly."""
    from nurbscnc.controller.simulate import simulate_job
    from nurbscnc.controller.staged import StagedJob

    mach = rotary_machine()
    pulses, sections = _staged_parts(mach)
    job = StagedJob([dataclasses.replace(sections[0], stop=None)], PERIOD_S)
    seen = {}

    def hold(j, c):
        j.request_hold()

    def look(j, c):
        seen["state"], seen["note"], seen["ran"] = c.state, j.note(), c.executed_periods

    def later(j, c):
        seen["ran_later"] = c.executed_periods
        j.resume()

    cfg = CardConfig(speed=1.0, axis_names="xyzab", position_steps=(0, 0, 0, 0, 100))
    r = simulate_job(job, cfg, events=[(0.3, hold), (0.5, look), (1.0, later)])
    assert r.completed, r.error
    assert seen["state"] is p.CardState.HOLD and seen["note"] == "waiting: feed hold"
    assert seen["ran"] == seen["ran_later"] < 300  # nothing ran during the hold
    np.testing.assert_array_equal(r.card.executed_pulses(), sections[0].pulses.pulses)


def test_program_parts_start_where_the_part_before_ends():
    """Segments cut at their stops: each part starts at the stop's X Y Z and at the A B C
    the part before ends at (a Line's abc_deg end, a Rotate's end)."""
    from nurbscnc.app.staged import part_points, program_parts
    from nurbscnc.geometry.segments import Line, Pause, Program, Rotate
    from nurbscnc.plan.rotary import moves_rotary
    from nurbscnc.program.columns import end_abc_deg

    segs = (
        Line((0, 0, 0), (4, 0, 0), 10.0, 1, abc_deg=(0, 0, 0, 30, 0, 0)),
        Pause((4, 0, 0), 2, "M0"),
        Rotate((4, 0, 0), (30, 0, 0), (30, 5, 0), 10.0, 3),
        Pause((4, 0, 0), 4, "M6", tool=3),
        Pause((4, 0, 0), 5, "M0"),
        Line((4, 0, 0), (5, 1, 0), 10.0, 6, abc_deg=(30, 5, 0, 30, 5, 0)),
    )
    prog = Program(segs, np.zeros(3), rotary_axes=("a", "b"), start_abc_deg=(0.0, 0.0, 0.0))
    parts = program_parts(prog)
    assert [None if p is None else len(p.segments) for p, _ in parts] == [1, 1, None, 1]
    assert [None if s is None else s.line for _, s in parts] == [2, 4, 5, None]
    assert parts[1][0].start_abc_deg == (30.0, 0.0, 0.0)
    assert parts[3][0].start_abc_deg == (30.0, 5.0, 0.0)
    assert tuple(parts[3][0].start_mm) == (4.0, 0.0, 0.0)
    assert end_abc_deg(segs, (0, 0, 0)) == (30.0, 5.0, 0.0)
    assert moves_rotary(segs[0]) and moves_rotary(segs[2]) and not moves_rotary(segs[5])
    still = samples_of_move((0, 0, 0), (1, 0, 0), (0, 0, 0), (0, 0, 0), 0.01, ())
    still = dataclasses.replace(still, abc_deg=None)
    held = part_points(still, "xyzb", (30.0, 5.0, 0.0))
    assert np.all(held[:, 3] == 5.0)


def test_a_program_holding_a_away_from_zero(monkeypatch):
    """A hand-built program with A held at 90° (the card's A: it never turns, so any
    planner can plan it) cut by an M0. ``stream`` takes it window by window as an X Y Z
    program, the card's A standing at 90 · 250 = 22500 steps; planned whole in sections
    (:func:`staged_job`) it carries A at 22500 throughout; X ends at 6 mm = 4800 steps.
    A program that turns A refuses --from-line before anything is planned."""
    from nurbscnc.app.staged import staged_job
    from nurbscnc.app.stream import stream_job
    from nurbscnc.controller.job import Job
    from nurbscnc.controller.simulate import simulate_job
    from nurbscnc.geometry.segments import Line, Pause, Program
    from nurbscnc.pipeline import RunOptions

    mach = rotary_machine()
    segs = (
        Line((0, 0, 0), (4, 0, 0), 20.0, 1, abc_deg=(90, 0, 0, 90, 0, 0)),
        Pause((4, 0, 0), 2, "M0"),
        Line((4, 0, 0), (6, 0, 0), 20.0, 3, abc_deg=(90, 0, 0, 90, 0, 0)),
    )
    prog = Program(segs, np.zeros(3), rotary_axes=("a",), start_abc_deg=(90.0, 0.0, 0.0))
    job, pulses = stream_job(prog, mach, RunOptions())
    assert pulses is None and isinstance(job, Job)
    cfg = CardConfig(speed=None, axis_names="xyza", position_steps=(0, 0, 0, 22500))
    r = simulate_job(job, cfg, events=[(3.0, lambda j, _c: j.resume())])
    job.feed.close()
    assert r.completed, r.error
    assert r.reports[0].final_position_steps == (3200, 0, 0, 22500)
    assert r.reports[-1].final_position_steps == (4800, 0, 0, 22500)

    staged = staged_job(prog, mach, RunOptions())
    first, second = (s.pulses for s in staged.parts)
    assert first.axes == "xyza" and tuple(first.start_steps) == (0, 0, 0, 22500)
    assert tuple(first.end_steps) == (3200, 0, 0, 22500) == tuple(second.start_steps)
    assert tuple(second.end_steps) == (4800, 0, 0, 22500)
    assert not first.pulses[:, 3].any() and not second.pulses[:, 3].any()

    turning = dataclasses.replace(
        prog, segments=(dataclasses.replace(segs[0], abc_deg=(90, 0, 0, 100, 0, 0)), *segs[1:])
    )
    with pytest.raises(ConfigError, match="this program moves A"):
        stream_job(turning, mach, RunOptions(), from_line=3)


def test_a_rotary_program_over_a_pty_sections_and_all():
    """The real sender on a pseudo-terminal: the staged sections of an X + A + B program to
    a card driving X Y Z A B (the operator's continue at M0 and M6 given as soon as the job
    waits), then the same first section to a version-3 card: refused, nothing executed."""
    from nurbscnc.controller.run import run_job
    from nurbscnc.controller.staged import StagedJob
    from nurbscnc.output.stream.sender import Sender, SenderOptions, open_port
    from tests.stream_helpers import card_on

    mach = rotary_machine()
    pulses, sections = _staged_parts(mach)
    job = StagedJob(sections, PERIOD_S)

    def wait(j, _reports):
        assert j.waiting is not None
        j.resume()

    cfg = CardConfig(speed=None, axis_names="xyzab", position_steps=(0, 0, 0, 0, 100))
    with card_on("pty", cfg) as (card, ep):
        port = open_port(ep.path)
        try:
            reports = run_job(job, Sender(port, SenderOptions()), wait)
        finally:
            port.close()
    assert [r.final_position_steps for r in reports][-1] == (7200, 0, 0, 0, 100)
    np.testing.assert_array_equal(card.executed_pulses(), pulses.pulses)
    first = sections[0].pulses
    with card_on("pty", CardConfig(speed=None)) as (card, ep):
        port = open_port(ep.path)
        try:
            with pytest.raises(
                CardAxesError, match="protocol 3 \\(X Y Z only\\); this program moves A B"
            ):
                Sender(port, SenderOptions()).stream(first)
        finally:
            port.close()
    assert card.executed_pulses().shape[0] == 0


def test_an_xyz_job_replaced_chunk_by_chunk_on_a_card_with_a():
    """The window-by-window job of an X Y Z program (its sections cut into chunks of 500
    periods, each replacing the unsent rest of the link's program) to a version-4 card
    driving A at 321 steps: every chunk gets the A column of zeros, the card runs exactly
    ``run``'s X Y Z pulses and A stays at 321."""
    from nurbscnc.controller import job as job_module
    from nurbscnc.controller.feed import ScheduledFeed
    from nurbscnc.controller.job import Job
    from nurbscnc.controller.simulate import simulate_job
    from nurbscnc.output.stream.quantise import quantise
    from nurbscnc.pipeline import run_program
    from nurbscnc.plan.lookahead import plan_windows
    from nurbscnc.program.interpret import interpret_text

    text = "G21 G90 G0 X0 Y0 Z1\nG1 Z0 F600\nG1 X10 F1200\nG2 X20 Y0 I5 J0\nG0 Z2\nM2\n"
    prog, mach = interpret_text(text), load_machine()
    run = run_program(prog, mach)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(job_module, "CHUNK_PERIODS", 500)
        windows = list(plan_windows(prog, mach))
        feed = ScheduledFeed(windows, [0.0] * len(windows))
        job = Job(None, prog, mach, feed=feed)
        cfg = CardConfig(speed=1.0, axis_names="xyza", position_steps=(0, 0, 0, 321))
        r = simulate_job(job, cfg)
    assert r.completed, r.error
    plain = quantise(run.samples.points_mm, mach.steps.per_mm, mach.servo.period_s)
    ran = r.card.executed_pulses()
    assert ran.shape[1] == 4 and plain.periods > 1000
    np.testing.assert_array_equal(ran[:, :3], plain.pulses)
    assert not ran[:, 3].any() and r.card.position[3] == 321
    assert r.reports[-1].axes == "xyza"
