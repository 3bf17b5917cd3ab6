"""Writing an output while its windows are made (long programs).

``run -o`` makes the reference points window by window and writes each as it comes. The
writing is mostly work that does not hold Python's interpreter lock — deflating NPZ members
(zlib), their checksums, the file writes — and the making (sampling the plan, the summary)
mostly work that does. Done one after the other they add up; done in two threads they
overlap. The NPZ writer also finishes with a tail: it copies six spooled columns into their
zip members (on the 200,000-line spiral 0.15 s, mostly deflate), which now overlaps the
summary.

:func:`write_while_making` runs the *making* in a worker thread and the *writing* in the
calling thread. The writer stays in the calling thread because that is where signals arrive:
SIGTERM, SIGHUP or Ctrl-C raise there and unwind the writer's own ``with`` blocks at once,
so an atomic output leaves no file even when the writer is stuck on a slow disk or pipe.
The worker only computes; when the writer stops early (a signal, a full disk, a closed
pipe) it is told to stop, and the error waits for it to stop at its next window (at most
:data:`STOP_WAIT_S`) before it goes on: a process that exits while the worker is inside
numpy can abort.
An exception of the making (a point outside the soft limits, found as it is made) is raised
in the writer where the next window would have come, so it unwinds the writer too (no
file), and then reaches the caller unchanged.
"""

from __future__ import annotations

import queue
import signal
import threading

#: Windows made ahead of the writer at most (each one window of points: 65,536 rows ×
#: 7 columns, 3.7 MB): the worker waits when it is this far ahead.
DEPTH = 2
#: Seconds between the worker's checks that the writer still wants windows while it waits.
POLL_S = 0.05
#: Seconds the writer's error waits for the worker to stop (at its next window: one
#: window's sampling, or the summary; the stream's planner thread likewise,
#: :meth:`~nurbscnc.controller.feed.WindowFeed.close`). The process must not end while
#: a worker is inside numpy: a daemon thread stopped there at exit can abort the
#: interpreter ("terminate called without an active exception"). A worker stuck longer
#: (a bug) is left behind.
STOP_WAIT_S = 2.0


#: The signals the main thread handles (stop, hang-up, Ctrl-C; the stream's hold and resume).
OPERATOR_SIGNALS = frozenset(
    getattr(signal, name)
    for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGUSR1", "SIGUSR2")
    if hasattr(signal, name)
)


def signals_to_main_thread() -> None:
    """Block :data:`OPERATOR_SIGNALS` in the calling (worker) thread. The kernel hands a
    process's signal to any thread that does not block it; Python runs the handler only in
    the main thread, and only when that thread next executes: one blocked in a queue's
    ``get`` would not wake until the worker put something there, a whole window's work
    later. Blocked in the workers, the signal interrupts the main thread's wait at once."""
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, OPERATOR_SIGNALS)


def waited(items: queue.Queue):
    """The next item of ``items``, waited for in steps of :data:`POLL_S`. A signal is
    handled by the main thread only when it runs Python again; an untimed wait wakes for it
    only if the kernel handed the signal to this very thread, while threads started before
    the workers blocked theirs (a BLAS library's pool, started when numpy is imported) may
    take it instead. A timed wait returns to the interpreter at least every POLL_S."""
    while True:
        try:
            return items.get(timeout=POLL_S)
        except queue.Empty:
            continue


class _Stopped(Exception):
    """The writer stopped: unwinds the worker."""


class _End:
    """The end of the windows."""


class _Failed:
    """The making's exception, carried to the writer."""

    def __init__(self, error: BaseException):
        self.error = error


def write_while_making(write, windows, after=None):
    """``write(iterable)`` in this thread on the items of ``windows``, which are made in a
    worker thread (``windows`` is iterated there), at most :data:`DEPTH` ahead; then, in
    the worker, ``after()`` while the writer finishes. Returns ``after()``'s result (None
    without it) once both are done. An exception of ``windows`` or ``after`` is raised
    here, after the writer has unwound; the writer's own exceptions (and signals) propagate
    at once, the worker told to stop."""
    items: queue.Queue = queue.Queue(maxsize=DEPTH)
    stop = threading.Event()
    outcome: dict = {}

    def offer(item) -> None:
        while not stop.is_set():
            try:
                items.put(item, timeout=POLL_S)
                return
            except queue.Full:
                continue
        raise _Stopped

    def work() -> None:
        signals_to_main_thread()
        try:
            try:
                for window in windows:
                    offer(window)
            except _Stopped:
                raise
            except BaseException as exc:  # the making failed: the writer unwinds with it
                offer(_Failed(exc))
                return
            offer(_End())
            if after is not None:
                outcome["result"] = after()
        except _Stopped:
            pass
        except BaseException as exc:  # ``after`` failed: raised in the caller
            outcome["error"] = exc

    ended = []

    def received():
        while True:
            item = waited(items)
            if isinstance(item, _End):
                ended.append(True)
                return
            if isinstance(item, _Failed):
                raise item.error
            yield item

    def halt() -> None:  # the worker stopped at its next window before we go on
        stop.set()
        worker.join(STOP_WAIT_S)

    worker = threading.Thread(target=work, name="nurbscnc-making", daemon=True)
    worker.start()
    try:
        write(received())
    except BaseException:
        halt()
        raise
    if not ended:  # the writer returned before the last window: a bug, not a hang
        halt()
        raise RuntimeError("the output writer returned before the last window")
    worker.join()
    if "error" in outcome:
        raise outcome["error"]
    return outcome.get("result")
