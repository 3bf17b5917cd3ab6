"""The section loop of a job: stream each section, and between sections do what the card
waits for at rest — the operator's continue (a program stop, a tool change, a feed hold), a
user M-code's executable, the next planned window.

No I/O here: :func:`run_job` drives a ``card`` (``output.stream.sender.Sender`` or a
stand-in) and calls what the command hands in: ``wait`` (block until the job no longer
waits; :meth:`~nurbscnc.output.stream.sender.Sender.wait_idle`) and ``run_user_m`` (run a
user M-code's executable; ``cli/stream.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from nurbscnc.controller.stops import Stop
from nurbscnc.errors import StreamError


@dataclass(frozen=True)
class UserMResult:
    """How a user M-code's executable ended: ``returncode`` (None: killed at its timeout
    ``timeout_s`` [s]) and its captured ``output`` (stdout and stderr, as text)."""

    returncode: int | None
    output: str = ""
    timeout_s: float = 0.0


def run_job(
    job,
    card,
    wait: Callable,
    *,
    zero: bool = False,
    run_user_m: Callable[[Stop], UserMResult] | None = None,
    positions_mm: Callable | None = None,
) -> list:
    """Stream the :class:`~nurbscnc.controller.job.Job` ``job`` section by section on
    ``card`` (``stream_section(program, session_id=, zero=, peak_pulses=, program_open=,
    hook=)`` → a report with ``session_id``, ``executed_periods``,
    ``final_position_steps``). Between sections: a user M-code's stop runs
    ``run_user_m(stop)`` at rest and continues when it exits 0 (else StreamError, exit 3,
    naming the code, its status and where the card stands; its output is the runner's to
    show); any other wait calls
    ``wait(job, reports)``, which returns once the job no longer waits (or raises).

    ``zero``: the first section declares the card's position to be the program's start.
    ``positions_mm(steps)``: the card's position in mm for the messages. Returns every
    section's report.
    """
    reports: list = []
    session = None
    while not job.finished:
        program = job.next_section()
        if program is None:
            if job.finished:
                break
            stop = job.at_stop
            if stop is not None and stop.user_m:
                _user_m(job, stop, run_user_m, reports, positions_mm)
            else:
                wait(job, reports)
            continue
        report = card.stream_section(
            program,
            session_id=session,
            zero=zero and not reports,
            peak_pulses=job.peak_pulses,
            program_open=job.section_open,
            hook=job.update,
        )
        reports.append(report)
        session = report.session_id
        job.section_done(report.executed_periods)
    return reports


def _user_m(job, stop: Stop, run_user_m, reports: list, positions_mm) -> None:
    """Run the user M-code of ``stop`` with the card at rest; continue the job when it exits
    0, else stop the stream (the card stays where it stands)."""
    if run_user_m is None or not stop.argv:
        raise StreamError(f"line {stop.line}: {stop.code}: no user M-code executable to run")
    result = run_user_m(stop)
    if result.returncode == 0:
        job.resume()
        return
    where = ""
    if reports:
        steps = list(reports[-1].final_position_steps)
        where = f"; the card stands at {steps} steps"
        if positions_mm is not None:
            where += f" ({_mm_text(positions_mm(steps))})"
    if result.returncode is None:
        why = f"did not end within {result.timeout_s:g} s and was killed"
    else:
        why = f"exited with status {result.returncode}"
    raise StreamError(
        f"line {stop.line}: {stop.code} ({stop.argv[0]}) {why}: the stream stops here{where}"
    )


def _mm_text(position_mm) -> str:
    return ", ".join(f"{v:.4f}" for v in position_mm) + " mm"
