"""The controller at a tool change (M6) and a user M-code (M100–M199), against a card
simulator on a pty.

The interpreter's own M6 and M1xx events are another change; here the program's stops are
made as segments: a program with M0 at the stop's line, interpreted, its Pause replaced by
the stop under test (``code``, ``tool``, ``message``, ``argv``: the interface of
``geometry.segments.Pause``). Expected positions come from the program text (1000 steps/mm),
the arguments from what a script records, never from the code under test.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import sys
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

import nurbscnc.app.stream as app_stream
from nurbscnc.cli.stream import stream
from nurbscnc.controller.stops import Stop, describe_stop, is_user_m
from nurbscnc.output.stream.card import CardConfig
from nurbscnc.program.interpret import interpret_text
from nurbscnc.program.tooltable import parse_tool_table
from tests.stream_helpers import card_on

# The stop on line 4 at X5 (5000 steps); the program ends at X8 (8000 steps).
PAUSED = "G21 G90 G17\nG0 X0 Y0\nG1 X5 F3000\nM0\nG1 X8\nM2\n"
TOOLS = "T1 P1 Z10 D3 ;3 mm drill\nT2 P2 Z12.5 D6 ;6 mm flat end mill\n"


def program_with_stop(**stop):
    """PAUSED interpreted, its M0 (line 4) replaced by a Pause with the fields ``stop``."""
    prog = interpret_text(PAUSED)
    segs = tuple(dataclasses.replace(s, **stop) if s.kind == "pause" else s for s in prog.segments)
    return dataclasses.replace(prog, segments=segs)


def stream_with(monkeypatch, prog, args, when_at=None, timeout_s=30.0):
    """``stream`` in-process with the program's interpretation giving ``prog`` (the card
    starts at machine zero); ``when_at(card)`` runs on a thread once the card is DONE at the
    stop (5000 steps; returns what it saw)."""
    monkeypatch.setattr(app_stream.ProgramStream, "interpret", lambda *_a, **_k: prog)
    seen = {}
    with card_on("pty", CardConfig(speed=None)) as (card, ep):

        def watch() -> None:
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                if card.state.name == "DONE" and card.position.tolist() == [5000, 0, 0]:
                    seen.update(when_at(card))
                    return
                time.sleep(0.01)

        thread = threading.Thread(target=watch, daemon=True)
        if when_at is not None:
            thread.start()
        res = CliRunner().invoke(stream, ["part.nc", "--port", ep.path, *map(str, args)])
        thread.join(timeout_s) if when_at is not None else None
        final = card.position.tolist()
    return res, seen, final


def test_tool_table_comment_and_the_tool_change_message():
    tools = parse_tool_table(TOOLS)
    assert tools[2].comment == "6 mm flat end mill" and tools[2].length_mm == 12.5
    m6 = Stop(5.0, 4, "M6", tool=2)
    assert describe_stop(m6, tools) == (
        "M6 at line 4: load tool 2 (length 12.5 mm, diameter 6 mm, 6 mm flat end mill)"
    )
    assert describe_stop(Stop(5.0, 4, "M6", tool=7), tools) == (
        "M6 at line 4: load tool 7 (not in the tool table)"
    )
    assert describe_stop(Stop(5.0, 9, "M0", message="turn the part over")) == (
        "M0 at line 9: turn the part over"
    )
    assert [is_user_m(c) for c in ("M99", "M100", "M199", "M200", "M6", "M1")] == [
        False,
        True,
        True,
        False,
        False,
        False,
    ]


def test_m6_stops_at_rest_names_the_tool_and_resumes_on_sigusr2(tmp_path, monkeypatch):
    """T2 M6: the card stops DONE at the tool change's point and stays there until SIGUSR2;
    the message names the tool and its table entry; then the program runs to its end."""
    table = tmp_path / "tools.tbl"
    table.write_text(TOOLS)
    prog = program_with_stop(code="M6", tool=2)

    def at_stop(card):
        time.sleep(0.5)  # waiting: the card must not move meanwhile
        still = (card.state.name, card.position.tolist())
        os.kill(os.getpid(), signal.SIGUSR2)
        return {"still": still}

    res, seen, final = stream_with(monkeypatch, prog, ["--tool-table", table], at_stop)
    assert res.exit_code == 0, res.output
    assert seen["still"] == ("DONE", [5000, 0, 0])
    assert (
        "stream: M6 at line 4: load tool 2 (length 12.5 mm, diameter 6 mm, "
        "6 mm flat end mill): the card is at rest; SIGUSR2 continues" in res.stderr
    )
    assert final == [8000, 0, 0] and "in 2 part(s)" in res.stdout


SCRIPT = """#!{python}
import sys, time
with open({record!r}, "w") as fh:
    fh.write("\\n".join(sys.argv[1:]))
print("spindle off, coolant on")
time.sleep({sleep})
sys.exit({status})
"""


def user_script(tmp_path: Path, status: int = 0, sleep: float = 0.5) -> tuple[Path, Path]:
    """An executable M101 that records its arguments, prints a line, sleeps, exits
    ``status``; returns (script, record file)."""
    record = tmp_path / "args.txt"
    script = tmp_path / "M101"
    script.write_text(
        SCRIPT.format(python=sys.executable, record=str(record), sleep=sleep, status=status)
    )
    script.chmod(0o755)
    return script, record


def test_user_m_code_runs_at_rest_with_p_and_q_then_the_stream_goes_on(tmp_path, monkeypatch):
    script, record = user_script(tmp_path)
    prog = program_with_stop(code="M101", argv=(str(script), "2.5", "-1"))

    def while_running(card):
        deadline = time.monotonic() + 10.0
        while not record.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.1)  # the script sleeps 0.5 s: the stream waits for it
        return {"args": record.read_text(), "at": (card.state.name, card.position.tolist())}

    res, seen, final = stream_with(monkeypatch, prog, [], while_running)
    assert res.exit_code == 0, res.output
    assert seen["args"] == "2.5\n-1"
    assert seen["at"] == ("DONE", [5000, 0, 0])
    assert f"stream: M101 at line 4: running {script} 2.5 -1" in res.stderr
    assert "spindle off, coolant on" in res.stderr
    assert final == [8000, 0, 0] and "in 2 part(s)" in res.stdout


def test_user_m_code_failing_stops_the_stream_with_exit_3(tmp_path, monkeypatch):
    script, record = user_script(tmp_path, status=4, sleep=0.0)
    prog = program_with_stop(code="M101", argv=(str(script), "1", "2"))
    res, _, final = stream_with(monkeypatch, prog, [])
    assert res.exit_code == 3, res.output
    assert record.read_text() == "1\n2"
    assert (
        f"line 4: M101 ({script}) exited with status 4: the stream stops here; "
        "the card stands at [5000, 0, 0] steps (5.0000, 0.0000, 0.0000 mm)" in res.stderr
    )
    assert "Traceback" not in res.output
    assert final == [5000, 0, 0]  # nothing after the failed M-code was sent


def test_user_m_code_past_its_timeout_is_killed_and_the_stream_stops(tmp_path, monkeypatch):
    script, _ = user_script(tmp_path, sleep=30.0)
    prog = program_with_stop(code="M101", argv=(str(script), "0", "0"))
    t0 = time.monotonic()
    res, _, final = stream_with(monkeypatch, prog, ["--user-m-timeout", "0.5"])
    assert time.monotonic() - t0 < 20.0
    assert res.exit_code == 3, res.output
    assert "did not end within 0.5 s and was killed" in res.stderr
    assert final == [5000, 0, 0]


@pytest.mark.parametrize("missing", ["no-such-M101"])
def test_user_m_code_that_cannot_run_is_a_clear_error(tmp_path, monkeypatch, missing):
    prog = program_with_stop(code="M101", argv=(str(tmp_path / missing), "0", "0"))
    res, _, final = stream_with(monkeypatch, prog, [])
    assert res.exit_code == 3, res.output
    assert f"line 4: M101: cannot run {tmp_path / missing}: No such file" in res.stderr
    assert final == [5000, 0, 0]


def test_ctrl_c_while_a_user_m_code_runs_kills_it_and_exits_130(tmp_path, monkeypatch):
    script, record = user_script(tmp_path, sleep=30.0)
    prog = program_with_stop(code="M101", argv=(str(script), "0", "0"))

    def interrupt(card):
        deadline = time.monotonic() + 10.0
        while not record.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        os.kill(os.getpid(), signal.SIGINT)
        return {}

    t0 = time.monotonic()
    res, _, final = stream_with(monkeypatch, prog, ["--user-m-timeout", "60"], interrupt)
    assert time.monotonic() - t0 < 20.0  # killed, not waited for
    assert res.exit_code == 130, res.output
    assert "interrupted while M101 at line 4 ran: it was killed" in res.stderr
    assert final == [5000, 0, 0]


def test_stops_in_a_row_wait_and_run_in_order_in_virtual_time():
    """M6, then M101 on the next line (the same point), then M101 at the program's end: the
    tool change waits for the operator, each user M-code runs once with its arguments, in
    program order, and the card ends at the program's end."""
    from nurbscnc.controller.job import Job
    from nurbscnc.controller.run import UserMResult
    from nurbscnc.controller.simulate import simulate_job
    from nurbscnc.machine.profile import default_profile_text, parse_machine
    from nurbscnc.pipeline import run_program

    prog = interpret_text("G21 G90 G17\nG0 X0 Y0\nG1 X5 F3000\nM0\nM0\nG1 X8\nM0\nM2\n")
    stops = iter(
        [
            {"code": "M6", "tool": 2},
            {"code": "M101", "argv": ("/m/M101", "1", "2")},
            {"code": "M102", "argv": ("/m/M102", "3", "4")},
        ]
    )
    prog = dataclasses.replace(
        prog,
        segments=tuple(
            dataclasses.replace(s, **next(stops)) if s.kind == "pause" else s for s in prog.segments
        ),
    )
    mach = parse_machine(default_profile_text())
    job = Job(run_program(prog, mach).plan, prog, mach)
    ran = []

    def run_user_m(stop):
        ran.append((stop.code, stop.line, stop.argv, job.waiting))
        return UserMResult(0)

    r = simulate_job(
        job, CardConfig(speed=None), events=[(5.0, lambda j, c: j.resume())], run_user_m=run_user_m
    )
    assert r.completed and r.card.position.tolist() == [8000, 0, 0]
    assert [w[2] for w in r.waits] == ["M6 at line 4: load tool 2 (not in the tool table)"]
    assert r.waits[0][1] == 5.0  # until the operator's continue
    assert ran == [
        ("M101", 5, ("/m/M101", "1", "2"), "M101 at line 5"),
        ("M102", 7, ("/m/M102", "3", "4"), "M102 at line 7"),
    ]
