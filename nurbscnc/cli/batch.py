"""``nurbscnc run --output-dir``: a batch of programs planned and written by worker
processes, a table (or JSON) of the results, and the workers stopped with the command."""

from __future__ import annotations

import json
import os
import sys

import click

from nurbscnc.app.load import display_name
from nurbscnc.app.output import batch_targets, write_output
from nurbscnc.cli.common import make_plan
from nurbscnc.cli.console import err, format_error, out
from nurbscnc.cli.handle import Failed, Terminated
from nurbscnc.errors import EXIT_INTERNAL, EXIT_INTERRUPTED, NurbsCncError, OutputError


def _batch_one(args):
    """Worker: plan one program and write its output; returns a result row (never raises)."""
    program, target, settings = args

    try:
        prog, mach, run = make_plan(program, **settings)
        samples = write_output(
            target,
            "halstreamer" if target.endswith(".hs") else "",
            run,
            mach,
            prog.name,
            lambda stats: stats.count,
        )
        return {
            "program": program,
            "ok": True,
            "output": target,
            "cycle_time_s": run.cycle_time_s,
            "samples": samples,
        }
    except NurbsCncError as exc:
        return {
            "program": program,
            "ok": False,
            "error": format_error(exc, display_name(program)),
            "exit_code": exc.exit_code,
        }
    except Exception as exc:  # a bug: report it as such, keep the batch going
        return {
            "program": program,
            "ok": False,
            "exit_code": EXIT_INTERNAL,
            "error": f"{program}: internal error: {type(exc).__name__}: {exc}",
        }


#: After SIGTERM, SIGHUP or Ctrl-C, a batch's parent is gone within this time [s].
BATCH_STOP_S = 10


def _stop_batch(exc: BaseException) -> None:
    """A batch interrupted by a signal: each worker is told now (it removes its temporary
    file and exits), and the parent ends within :data:`BATCH_STOP_S` whatever the pool's
    own shutdown does next: it can wait for ever on a queue lock a dying worker held. Exit
    code as for the signal."""
    import multiprocessing
    import signal

    for worker in multiprocessing.active_children():
        worker.terminate()
    code = 128 + exc.signum if isinstance(exc, Terminated) else EXIT_INTERRUPTED
    signal.signal(signal.SIGALRM, lambda *_: os._exit(code))
    signal.alarm(BATCH_STOP_S)


#: After SIGTERM, SIGHUP or Ctrl-C, a batch worker is gone within this time [s].
WORKER_STOP_S = 3


def _worker_exit(signum, _frame):
    """SystemExit unwinds the worker (atomic_output: no temporary file stays); should the
    unwinding hang (a lock of the pool's queues that a worker killed beside it held, as the
    parent's can: :func:`_stop_batch`), an alarm ends the worker within
    :data:`WORKER_STOP_S` all the same."""
    import signal

    signal.signal(signal.SIGALRM, lambda *_: os._exit(128 + signum))
    signal.alarm(WORKER_STOP_S)
    sys.exit(128 + signum)


def _worker_init(parent_pid: int) -> None:
    """A batch worker ends quietly on SIGTERM/SIGHUP/SIGINT (the parent reports), and is
    sent SIGTERM when the process that started it ends (Linux: ``PR_SET_PDEATHSIG``). The
    pool replaces a worker that ends while tasks are pending, so a replacement can be
    started between :func:`_stop_batch`'s terminations and the pool's own shutdown; the
    parent's death then ends it instead of leaving it waiting on the task queue for ever."""
    import signal

    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, _worker_exit)
    if sys.platform.startswith("linux"):
        import ctypes

        pr_set_pdeathsig = 1
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGTERM))
    if os.getppid() != parent_pid:  # the parent ended before the request above took hold
        _worker_exit(int(signal.SIGTERM), None)


def run_batch(programs, output_dir, jobs, fmt, quiet, as_json, settings) -> None:
    """Plan every program of a batch and write its points into ``output_dir`` (``jobs``
    worker processes at most); then the results (a table, or JSON), and Failed with the
    worst exit code when any program failed."""
    targets = batch_targets(programs, output_dir, fmt)
    try:
        os.makedirs(output_dir, exist_ok=True)
    except OSError as exc:
        raise OutputError(
            f"cannot create the output folder {output_dir}: {exc.strerror or exc}"
        ) from None
    tasks = [(program, target, settings) for program, target in zip(programs, targets)]
    results = _run_tasks(tasks, min(jobs or os.cpu_count() or 1, len(tasks)))
    failed = [r for r in results if not r["ok"]]
    if as_json:
        click.echo(json.dumps({"ok": not failed, "results": results}))
    else:
        _print_results(results, failed, quiet)
    if failed:
        raise Failed(max(r["exit_code"] for r in failed))


def _run_tasks(tasks: list, workers: int) -> list[dict]:
    """The result rows of the batch's tasks, in order, made by ``workers`` processes (in
    this one when 1)."""
    import multiprocessing

    if workers == 1:
        return [_batch_one(t) for t in tasks]
    # Leaving the block for any reason (a signal, Ctrl-C) terminates the workers: each
    # removes its temporary file and exits; none goes on writing after we are gone.
    with multiprocessing.Pool(workers, initializer=_worker_init, initargs=(os.getpid(),)) as pool:
        try:
            return pool.map(_batch_one, tasks, chunksize=1)
        except (Terminated, KeyboardInterrupt) as exc:
            _stop_batch(exc)
            raise


def _print_results(results: list[dict], failed: list[dict], quiet: bool) -> None:
    """The batch's table (on stderr when ``quiet``), then the failures' messages."""
    from rich.table import Table

    table = Table(title=f"batch: {len(results)} programs, {len(failed)} failed", show_edge=False)
    for col in ("program", "result", "cycle time [s]", "points"):
        table.add_column(col)
    for r in results:
        table.add_row(
            r["program"],
            "ok" if r["ok"] else "FAILED",
            f"{r['cycle_time_s']:.4f}" if r["ok"] else "",
            str(r["samples"]) if r["ok"] else "",
        )
    (err if quiet else out).print(table)
    for r in failed:
        err.print(r["error"], markup=False)
