"""The card simulator's state machine, driven directly with bytes and explicit times.

No threads, no ports: every reply and every executed period is checked against the protocol
rules of docs/protocol.md.
"""

from __future__ import annotations

import numpy as np
import pytest

from nurbscnc.errors import ConfigError
from nurbscnc.output.stream import protocol as p
from nurbscnc.output.stream.card import CardConfig, CardSim, Faults
from nurbscnc.output.stream.endpoints import parse_listen
from nurbscnc.output.stream.wire import Wire


def send(card, msg, seq=0, now=0.0):
    """Feed one message; return the decoded replies due by ``now``."""
    card.on_bytes(p.encode_message(msg, seq=seq), now)
    return replies(card, now)


def replies(card, now):
    return [p.decode_message(f) for f in p.FrameDecoder().feed(card.take_output(now))]


def batch(rows, start=(0, 0, 0)):
    return p.Batch(np.asarray(rows, dtype=np.int64), start)


def opened(**kwargs):
    card = CardSim(CardConfig(**kwargs), seed=1)
    (caps,) = send(card, p.Hello())
    assert caps.state == p.CardState.FILLING
    return card


def test_hello_reports_capabilities():
    card = CardSim(
        CardConfig(
            buffer_periods=100, max_pulses_per_period=50, period_s=2e-3, position_steps=(1, -2, 3)
        ),
        seed=5,
    )
    (caps,) = send(card, p.Hello())
    assert (
        caps.version,
        caps.axes,
        caps.max_pulses_per_period,
        caps.buffer_periods,
        caps.period_us,
        caps.position_steps,
    ) == (3, 3, 50, 100, 2000, (1, -2, 3))
    assert caps.session_id == card.session_id


def test_in_order_exactly_once_with_duplicates_and_gaps():
    card = opened(speed=None)
    a, b, c, d = [[1, 0, 0]] * 2, [[0, 2, 0]], [[0, 0, -3]] * 3, [[4, 4, 4]]
    b, c, d = batch(b, (2, 0, 0)), batch(c, (2, 2, 0)), batch(d, (2, 2, -9))
    # Starting is a state change (a STATUS); as fast as possible, the ACK finds it all run.
    assert send(card, batch(a), seq=0) == [
        p.Status(p.CardState.RUNNING, 0, 1, 254, 2, 0, (0, 0, 0)),
        p.Ack(1, 256),
    ]
    gap = p.Nak(1, 256, p.NakReason.SEQUENCE)
    assert send(card, c, seq=2) == [gap]  # frame 1 is missing: 2 is kept, not run
    assert send(card, d, seq=3) == [gap]
    assert send(card, c, seq=2) == [gap]  # a second copy of a kept frame
    assert send(card, batch(a), seq=0) == [p.Ack(1, 256)]  # duplicate: re-ACK, not re-run
    assert card.executed_pulses().tolist() == a
    assert send(card, b, seq=1) == [p.Ack(4, 256)]  # the gap is filled: 1, 2, 3 run
    assert card.executed_pulses().tolist() == a + [[0, 2, 0]] + [[0, 0, -3]] * 3 + [[4, 4, 4]]
    assert card.duplicates == 2
    out = send(card, p.End(7, (6, 6, -5)), seq=4)
    assert out[-1] == p.Status(p.CardState.DONE, 0, 5, 256, 0, 7, (6, 6, -5))


def test_early_frames_count_against_the_buffer():
    card = opened(speed=1.0, buffer_periods=10)
    send(card, batch([[0, 0, 0]] * 4), seq=0)  # 4 in the buffer
    assert send(card, batch([[0, 0, 0]] * 5), seq=2) == [p.Nak(1, 6, p.NakReason.SEQUENCE)]
    assert send(card, batch([[0, 0, 0]] * 2), seq=1) == [p.Nak(1, 6, p.NakReason.FULL)]
    assert card.overflows == 1 and card.max_fill == 9
    assert send(card, batch([[0, 0, 0]]), seq=1)[-1] == p.Ack(3, 0)
    assert card.max_fill == 10


def test_corrupted_frame_gets_a_crc_nak():
    card = opened(speed=None)
    frame = bytearray(p.encode_message(batch([[1, 1, 1]]), seq=0))
    frame[7] ^= 0x10  # the start position: the CRC-32 catches it
    card.on_bytes(bytes(frame), 0.0)
    assert replies(card, 0.0) == [p.Nak(0, 256, p.NakReason.CRC)]
    assert card.crc_errors == 1 and card.executed_periods == 0


def test_real_time_execution_and_underrun_alarm():
    card = opened(speed=1.0, buffer_periods=8, start_fill_periods=4)
    send(card, batch([[1, 0, 0]] * 3), seq=0, now=0.0)
    assert card.state == p.CardState.FILLING  # 3 < start fill
    out = send(card, batch([[0, 1, 0]] * 3, (3, 0, 0)), seq=1, now=0.0)
    assert p.Status(p.CardState.RUNNING, 0, 2, 2, 6, 0, (0, 0, 0)) in out
    card.advance(0.0025)  # periods due at 0, 1, 2 ms
    assert card.executed_periods == 3 and card.position.tolist() == [3, 0, 0]
    card.advance(0.0055)  # 3 more due: the buffer holds exactly 3
    assert card.executed_periods == 6 and card.state == p.CardState.RUNNING
    card.advance(0.0061)  # the 7th period is due, nothing left, no END: underrun
    assert card.state == p.CardState.ALARM and card.alarm == p.AlarmCode.UNDERRUN
    out = replies(card, 0.0061)
    assert isinstance(out[0], p.Alarm) and out[0].code == p.AlarmCode.UNDERRUN
    assert "period 7" in out[0].text
    # Afterwards batches are answered with the alarm again, never executed.
    out = send(card, batch([[1, 1, 1]]), seq=2, now=0.007)
    assert out[0] == out[0].__class__(p.AlarmCode.UNDERRUN, card.alarm_text)
    assert card.executed_periods == 6


def test_frames_that_do_not_continue_are_refused():
    """A BATCH must start where the accepted batches end; END must name their period count and
    end position. Otherwise NAK reason POSITION, and nothing changes."""
    card = opened(speed=1.0, start_fill_periods=100)
    refused = p.Nak(0, 256, p.NakReason.POSITION)
    assert send(card, batch([[1, 2, 3]], (0, 0, 1)), seq=0) == [refused]
    assert send(card, batch([[1, 2, 3]]), seq=0) == [p.Ack(1, 255)]
    assert send(card, batch([[1, 0, 0]]), seq=1) == [p.Nak(1, 255, p.NakReason.POSITION)]
    assert send(card, p.End(1, (1, 2, 4)), seq=1) == [p.Nak(1, 255, p.NakReason.POSITION)]
    assert send(card, p.End(2, (1, 2, 3)), seq=1) == [p.Nak(1, 255, p.NakReason.POSITION)]
    # A kept frame that does not continue is dropped when the gap is filled: ACK, then NAK.
    assert send(card, batch([[0, 0, 0]], (9, 9, 9)), seq=2)[-1].reason == p.NakReason.SEQUENCE
    out = send(card, batch([[1, 0, 0]], (1, 2, 3)), seq=1)
    assert out == [p.Ack(2, 254), p.Nak(2, 254, p.NakReason.POSITION)]
    assert card.position_naks == 5 and card.fill == 2 and card.state == p.CardState.FILLING
    out = send(card, p.End(2, (2, 2, 3)), seq=2)
    assert out[-1] == p.Ack(3, 254) and out[0].state == p.CardState.RUNNING  # END starts it
    card.advance(0.0015)
    assert card.state == p.CardState.DONE and card.position.tolist() == [2, 2, 3]


def test_a_damaged_length_is_refused_at_once_and_a_cut_frame_after_the_gap():
    card = opened(speed=None)
    frame = bytearray(p.encode_message(batch([[1, 1, 1]]), seq=0))
    frame[1] ^= 0x80  # LEN 16 → 144: version 1 waited for 128 more bytes
    card.on_bytes(bytes(frame), 0.0)
    assert replies(card, 0.0) == [p.Nak(0, 256, p.NakReason.CRC)]
    card.on_bytes(p.encode_message(batch([[1, 1, 1]]), seq=0)[:12], 0.1)  # the rest is lost
    card.advance(0.1 + 0.5 * card.config.gap_s)
    assert replies(card, 0.1) == []
    assert card.next_event_s() == pytest.approx(0.1 + card.config.gap_s)
    card.advance(0.1 + card.config.gap_s + 1e-9)
    assert replies(card, 0.2) == [p.Nak(0, 256, p.NakReason.CRC)]
    assert send(card, batch([[1, 1, 1]]), seq=0, now=0.2)[-1] == p.Ack(1, 256)
    assert card.executed_periods == 1 and card.crc_errors == 2


def test_pulse_limit_and_overflow():
    card = opened(speed=1.0, buffer_periods=4, max_pulses_per_period=10)
    assert send(card, batch([[0, 0, 0]] * 5), seq=0) == [p.Nak(0, 4, p.NakReason.FULL)]
    assert card.overflows == 1
    out = send(card, batch([[11, 0, 0]]), seq=0)
    assert card.alarm == p.AlarmCode.PULSE_LIMIT and isinstance(out[0], p.Alarm)


def test_hold_freezes_and_resume_does_not_burst():
    card = opened(speed=1.0, buffer_periods=16, start_fill_periods=1)
    send(card, batch([[1, 0, 0]] * 10), seq=0, now=0.0)
    card.advance(0.0015)
    assert card.executed_periods == 2
    assert send(card, p.Hold(), now=0.0016)[-1].state == p.CardState.HOLD
    card.advance(0.0500)
    assert card.executed_periods == 2  # held
    assert send(card, p.Resume(), now=0.0500)[-1].state == p.CardState.RUNNING
    card.advance(0.0505)  # one period due at resume, not the 48 missed during the hold
    assert card.executed_periods == 3


def test_abort_drops_the_buffer():
    card = opened(speed=1.0, start_fill_periods=1)
    send(card, batch([[1, 0, 0]] * 10), seq=0, now=0.0)
    card.advance(0.0005)
    out = send(card, p.Abort(), now=0.001)
    assert out[-1].state == p.CardState.ABORTED and out[-1].fill_periods == 0
    card.advance(1.0)
    assert card.executed_periods == 1 and card.aborts_received == 1


def test_reset_announces_a_new_session_and_loses_the_position():
    card = CardSim(CardConfig(speed=None, faults=Faults(reset_after_frames=3)), seed=2)
    (caps,) = send(card, p.Hello())
    send(card, batch([[5, 0, 0]]), seq=0)
    (again,) = send(card, batch([[5, 0, 0]], (5, 0, 0)), seq=1)  # frame 3: the card resets
    assert isinstance(again, p.Caps) and again.session_id != caps.session_id
    assert again.state == p.CardState.IDLE and again.position_steps == (0, 0, 0)
    (third,) = send(card, batch([[5, 0, 0]]), seq=2)  # IDLE: "I was reset", nothing runs
    assert isinstance(third, p.Caps) and card.executed_periods == 1


def test_stall_stops_every_answer():
    card = CardSim(CardConfig(speed=None, faults=Faults(stall_after_frames=1)), seed=2)
    assert len(send(card, p.Hello())) == 1
    assert send(card, p.StatusRequest()) == []
    assert card.stalled


def test_sequence_numbers_wrap():
    card = opened(speed=None)
    card.expected = 65535  # as after 65535 frames
    assert send(card, batch([[1, 0, 0]]), seq=65535)[-1] == p.Ack(0, 256)
    assert send(card, batch([[1, 0, 0]]), seq=65535) == [p.Ack(0, 256)]  # duplicate
    assert send(card, batch([[1, 0, 0]], (1, 0, 0)), seq=0) == [p.Ack(1, 256)]
    assert card.executed_periods == 2


def test_fault_rates_are_applied_per_frame():
    card = CardSim(CardConfig(speed=None, faults=Faults(drop_rate=0.1, corrupt_rate=0.1)), seed=7)
    for _ in range(2000):
        card.on_bytes(p.encode_message(p.StatusRequest()), 0.0)
    assert 140 < card.dropped_in < 260 and 140 < card.corrupted_in < 260  # 200 ± 4σ
    # Every intact request is answered, no damaged one is (a flipped sync bit makes noise,
    # any other flip a header or CRC error: a damaged LEN swallows nothing).
    assert card.frames_sent == 2000 - card.dropped_in - card.corrupted_in
    assert 0.7 * card.corrupted_in < card.crc_errors <= card.corrupted_in
    with pytest.raises(ConfigError):
        Faults(drop_rate=1.0)


def test_wire_paces_bytes_at_the_baud_rate():
    wire = Wire(115200)
    wire.push(bytes(100), 0.0)  # 100 bytes at 10 bits each: 8.68 ms
    assert len(wire.pop(0.004341)) == 50
    assert len(wire.pop(0.01)) == 50
    assert wire.pop(1.0) == b""


def test_listen_address_must_be_loopback():
    assert parse_listen("127.0.0.1:5555") == ("127.0.0.1", 5555)
    assert parse_listen("[::1]:0") == ("::1", 0)
    for bad in ("0.0.0.0:5555", "192.168.1.2:80", "localhost", "127.0.0.1:x"):
        with pytest.raises(ConfigError):
            parse_listen(bad)
