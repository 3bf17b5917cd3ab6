"""Sender ↔ card simulator over a real pseudo-terminal and over loopback TCP (socket://).

The card runs in a thread of the test process (:func:`serve`), so its log of executed periods
and its counters can be compared with what the sender was given: every batch must run
exactly once and in order, whatever the injected faults. Only 127.0.0.1 is used, and every
test is bounded in time.
"""

from __future__ import annotations

import contextlib
import threading
import time

import numpy as np
import pytest
import serial

from nurbscnc.errors import EXIT_INTERRUPTED, StreamError
from nurbscnc.output.stream.card import CardConfig, CardSim, Faults, PtyEndpoint, serve
from nurbscnc.output.stream.quantise import quantise
from nurbscnc.output.stream.sender import Sender, SenderOptions, StreamInterrupted, open_port
from tests.stream_helpers import card_on

STEPS = (1000.0, 1000.0, 1000.0)


def circle_program(periods: int):
    """A 10 mm circle at about 31 mm/s (≈ 31 pulses per period), one point per ms."""
    t = np.arange(periods + 1) * 1e-3
    pts = np.column_stack([10 * np.sin(np.pi * t), 10 * np.cos(np.pi * t) - 10, 0.01 * t])
    return quantise(pts, STEPS, 1e-3)


def stream_to(endpoint, program, options=None, **kwargs):
    """Open the endpoint's port like `stream` does and run a sender; returns (sender, report)."""
    port = open_port(endpoint.path, allow_url=True)
    sender = Sender(port, options or SenderOptions(timeout_s=2.0), **kwargs)
    try:
        return sender, sender.stream(program)
    finally:
        port.close()


@pytest.mark.parametrize("kind", ["pty", "tcp"])
def test_clean_stream_runs_every_period_once(kind):
    prog = circle_program(700)
    with card_on(kind, CardConfig(speed=None)) as (card, ep):
        sender, report = stream_to(ep, prog)
    assert np.array_equal(card.executed_pulses(), prog.pulses)
    assert report.final_position_steps == tuple(prog.end_steps)
    assert tuple(prog.end_steps) == (round(10 * np.sin(0.7 * np.pi) * 1000),
                                     round((10 * np.cos(0.7 * np.pi) - 10) * 1000), 7)
    assert report.retransmits == 0 and card.crc_errors == 0 and card.duplicates == 0
    # 700 periods in 16-period frames: 44 batches + END, plus the HELLO (and any polls).
    assert report.frames_sent - report.polls == 1 + 44 + 1


@pytest.mark.parametrize("kind", ["pty", "tcp"])
@pytest.mark.parametrize("rate", [0.01, 0.10])
def test_faults_cost_retransmissions_never_a_wrong_pulse(kind, rate):
    prog = circle_program(1000)
    faults = Faults(drop_rate=rate, corrupt_rate=rate)
    with card_on(kind, CardConfig(speed=None, faults=faults), seed=11) as (card, ep):
        sender, report = stream_to(ep, prog)
    assert np.array_equal(card.executed_pulses(), prog.pulses)
    assert report.final_position_steps == tuple(prog.end_steps)
    assert card.state.name == "DONE" and card.overflows == 0
    if rate == 0.10:  # the faults really happened, both ways, and were repaired
        assert card.dropped_in and card.corrupted_in and card.dropped_out and card.corrupted_out
        assert report.retransmits > 0 and card.crc_errors > 0


def test_real_time_card_with_faults_and_delay():
    prog = circle_program(300)
    faults = Faults(drop_rate=0.01, corrupt_rate=0.01, delay_s=0.005)
    with card_on("pty", CardConfig(speed=1.0, faults=faults), seed=3) as (card, ep):
        t0 = time.monotonic()
        sender, report = stream_to(ep, prog)
        elapsed = time.monotonic() - t0
    assert np.array_equal(card.executed_pulses(), prog.pulses)
    assert card.alarm.name == "NONE"
    assert 0.3 <= elapsed < 2.0  # real time: 300 periods of 1 ms


def test_slow_card_never_gets_more_than_its_buffer():
    prog = circle_program(300)
    config = CardConfig(speed=1.0, buffer_periods=32, start_fill_periods=16)
    with card_on("tcp", config) as (card, ep):
        sender, report = stream_to(ep, prog)
    assert np.array_equal(card.executed_pulses(), prog.pulses)
    assert report.max_in_flight_periods == 32  # the credit was used up to the buffer, no more
    assert card.max_fill <= 32 and card.overflows == 0


def test_a_sender_ignoring_credit_is_caught_by_the_card():
    """The flow-control check above can fail: without credit the card must refuse batches."""
    prog = circle_program(300)
    config = CardConfig(speed=1.0, buffer_periods=32, start_fill_periods=16)
    with card_on("tcp", config) as (card, ep):
        with contextlib.suppress(StreamError):
            stream_to(ep, prog, SenderOptions(timeout_s=1.0), _ignore_credit=True)
    assert card.overflows > 0


def test_buffer_underrun_is_reported():
    # Replies 60 ms late: the sender's credit (32 periods) runs out long before the card's
    # first ACK arrives, and the card runs dry at period 33.
    config = CardConfig(speed=1.0, buffer_periods=32, start_fill_periods=16,
                        faults=Faults(delay_s=0.06))  # fmt: skip
    with card_on("pty", config) as (card, ep):
        with pytest.raises(StreamError, match=r"card alarm UNDERRUN: .*period 33 "):
            stream_to(ep, circle_program(300))
    assert card.executed_periods == 32


def test_silent_card_is_lost_communication_within_the_timeout():
    config = CardConfig(speed=None, faults=Faults(stall_after_frames=0))
    with card_on("pty", config) as (card, ep):
        t0 = time.monotonic()
        with pytest.raises(StreamError, match="lost communication with card"):
            stream_to(ep, circle_program(100), SenderOptions(timeout_s=0.3))
        elapsed = time.monotonic() - t0
    assert 0.3 <= elapsed < 1.0
    assert card.bytes_received > 0 and card.frames_sent == 0


def test_card_stalling_mid_stream_is_lost_communication():
    config = CardConfig(speed=1.0, faults=Faults(stall_after_frames=8))
    with card_on("tcp", config) as (card, ep):
        t0 = time.monotonic()
        with pytest.raises(StreamError, match="lost communication with card"):
            stream_to(ep, circle_program(1000), SenderOptions(timeout_s=0.3))
        assert time.monotonic() - t0 < 1.5
    assert card.stalled


def test_card_reset_mid_stream_is_fatal():
    config = CardConfig(speed=None, faults=Faults(reset_after_frames=5))
    with card_on("pty", config) as (card, ep):
        with pytest.raises(StreamError, match="reset during the stream.*not resuming"):
            stream_to(ep, circle_program(500))
    assert card.resets == 1 and card.state.name == "IDLE"
    assert card.executed_periods == 3 * 16  # frames 2-4 ran before the reset, nothing after


def test_pty_closed_mid_stream_is_a_clean_error():
    ep = PtyEndpoint()
    card = CardSim(CardConfig(speed=1.0), seed=1)
    stop = threading.Event()
    thread = threading.Thread(target=serve, args=(card, ep, stop), daemon=True)
    thread.start()

    def pull_the_plug():
        stop.set()
        thread.join(5.0)
        ep.close()

    timer = threading.Timer(0.25, pull_the_plug)
    timer.start()
    try:
        with pytest.raises(StreamError, match="lost (the port|communication)"):
            stream_to(ep, circle_program(1000), SenderOptions(timeout_s=1.0))
    finally:
        timer.join()
    assert 0 < card.executed_periods < 1000


def test_feed_hold_freezes_then_resume_finishes():
    prog = circle_program(400)
    seen = {}
    with card_on("pty", CardConfig(speed=1.0, start_fill_periods=32)) as (card, ep):
        port = open_port(ep.path)
        sender = Sender(port, SenderOptions(timeout_s=2.0))

        def operator():
            time.sleep(0.1)
            sender.request_hold()
            time.sleep(0.1)
            seen["state"], seen["a"] = card.state.name, card.executed_periods
            time.sleep(0.15)
            seen["b"] = card.executed_periods
            sender.request_resume()

        op = threading.Thread(target=operator)
        op.start()
        report = sender.stream(prog)
        op.join()
        port.close()
    assert seen["state"] == "HOLD" and seen["a"] == seen["b"] and 0 < seen["a"] < 400
    assert np.array_equal(card.executed_pulses(), prog.pulses)
    assert report.duration_s > 0.4 + 0.2  # the hold took its time


def test_abort_stops_the_card_and_raises_interrupted():
    prog = circle_program(2000)
    with card_on("pty", CardConfig(speed=1.0)) as (card, ep):
        port = open_port(ep.path)
        sender = Sender(port, SenderOptions(timeout_s=2.0))
        timer = threading.Timer(0.2, sender.request_abort)
        timer.start()
        with pytest.raises(StreamInterrupted, match="abort sent, the card stopped") as exc:
            sender.stream(prog)
        timer.join()
        port.close()
        time.sleep(0.05)
        executed = card.executed_periods
    assert exc.value.exit_code == EXIT_INTERRUPTED
    assert card.aborts_received >= 1 and card.state.name == "ABORTED"
    assert 0 < executed < 2000 and sender.abort_confirmed


def test_card_elsewhere_or_unfit_is_refused_before_any_batch():
    prog = circle_program(100)
    with card_on("pty", CardConfig(speed=None, position_steps=(5, 0, 0))) as (card, ep):
        with pytest.raises(StreamError, match=r"card is at \[5, 0, 0\] steps.*starts at \[0"):
            stream_to(ep, prog)
    assert card.frames_received == 1  # the HELLO only
    config = CardConfig(speed=None, period_s=2e-3, max_pulses_per_period=10)
    with card_on("tcp", config) as (card, ep):
        with pytest.raises(StreamError, match=r"period is 2000 µs.*at most 10 pulses"):
            stream_to(ep, prog)
    assert card.executed_periods == 0


def test_port_is_opened_exclusively():
    ep = PtyEndpoint()
    try:
        first = open_port(ep.path)
        with pytest.raises(StreamError, match="busy"):
            open_port(ep.path)
        first.close()
        open_port(ep.path).close()
    finally:
        ep.close()
    with pytest.raises(StreamError, match="cannot open port"):
        open_port("/nonexistent/ttyUSB9")
    assert issubclass(serial.SerialException, OSError)  # what open_port translates
