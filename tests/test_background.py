"""The output written while its windows are made (nurbscnc/output/background.py)."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

from nurbscnc.output.background import DEPTH, write_while_making


def _worker_gone(timeout_s: float = 5.0) -> bool:
    """Whether the making thread has ended (it is told to stop, not joined)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if not any(t.name == "nurbscnc-making" for t in threading.enumerate()):
            return True
        time.sleep(0.01)
    return False


def test_windows_arrive_in_order_and_after_runs_in_the_worker():
    made, seen = [], []
    main = threading.get_ident()

    def windows():
        for i in range(50):
            made.append(threading.get_ident())
            yield np.full(3, i)

    def write(items):
        for w in items:
            seen.append(int(w[0]))

    def after():
        return ("done", threading.get_ident(), len(seen) <= 50)

    word, where, _ = write_while_making(write, windows(), after)
    assert seen == list(range(50))
    assert word == "done"
    assert where != main and set(made) == {where}  # both made in the worker
    assert write_while_making(write, iter([np.zeros(1)])) is None  # no ``after``: None


def test_the_maker_stays_at_most_depth_windows_ahead():
    """Memory: a slow writer holds the maker back (one window being written, DEPTH queued,
    one being offered)."""
    made = written = 0
    lead = []

    def windows():
        nonlocal made
        for i in range(30):
            made += 1
            lead.append(made - written)
            yield i

    def write(items):
        nonlocal written
        for _ in items:
            time.sleep(0.002)
            written += 1

    write_while_making(write, windows())
    assert written == 30
    assert max(lead) <= DEPTH + 2


def test_an_error_of_the_making_unwinds_the_writer_and_reaches_the_caller():
    unwound = []
    error = ValueError("point outside the soft limits")

    def windows():
        yield 1
        yield 2
        raise error

    def write(items):
        try:
            for _ in items:
                pass
        finally:
            unwound.append(True)

    with pytest.raises(ValueError) as caught:
        write_while_making(write, windows())
    assert caught.value is error
    assert unwound == [True]
    assert _worker_gone()


def test_an_error_of_the_writer_stops_the_worker():
    def windows():
        yield from range(10_000)  # far more than DEPTH: the worker must not wait forever

    def write(items):
        for i in items:
            if i == 3:
                raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left"):
        write_while_making(write, windows(), lambda: pytest.fail("after ran"))
    assert _worker_gone()


def test_after_failing_is_raised_once_the_output_is_complete(tmp_path):
    from nurbscnc.output.files import write_table_windows

    out = tmp_path / "t.npz"
    cols = [(np.arange(5.0), np.arange(5.0) * 2)] * 3

    def write(items):
        write_table_windows(str(out), ("a", "b"), items, 15, ["%g", "%g"])

    def after():
        raise KeyError("summary")

    with pytest.raises(KeyError, match="summary"):
        write_while_making(write, iter(cols), after)
    with np.load(out) as back:
        np.testing.assert_array_equal(back["b"], np.tile(np.arange(5.0) * 2, 3))


def test_a_writer_that_returns_early_is_an_error_not_a_hang():
    def write(items):
        next(iter(items))

    with pytest.raises(RuntimeError, match="before the last window"):
        write_while_making(write, iter(range(100)))
    assert _worker_gone()


def test_a_failed_making_leaves_no_file(tmp_path):
    """The atomic writer, unwound by the making's error, removes its temporary file."""
    from nurbscnc.output.files import write_table_windows

    out = tmp_path / "o"
    out.mkdir()

    def windows():
        yield (np.arange(4.0), np.arange(4.0))
        raise RuntimeError("stop")

    def write(items):
        write_table_windows(str(out / "t.npz"), ("a", "b"), items, 8, ["%g", "%g"])

    with pytest.raises(RuntimeError, match="stop"):
        write_while_making(write, windows())
    assert os.listdir(out) == []


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="needs pthread_sigmask")
def test_the_worker_threads_leave_the_operators_signals_to_the_main_thread():
    """The kernel hands a process's SIGTERM, SIGHUP, SIGINT (and the stream's SIGUSR1/2) to
    any thread not blocking it, and Python runs the handler only when the main thread next
    executes: a writer waiting for the next window would not stop until the maker put one.
    The making thread, the stream's planner thread and the key reader block them."""
    from nurbscnc.controller.feed import WindowFeed

    wanted = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGUSR1, signal.SIGUSR2}
    masks = {}

    def windows(name):
        masks[name] = signal.pthread_sigmask(signal.SIG_BLOCK, [])
        yield np.zeros(3)

    write_while_making(lambda items: list(items), windows("making"))
    feed = WindowFeed(windows("planner"))
    feed._thread.join(5.0)
    feed.close()
    assert wanted <= masks["making"] and wanted <= masks["planner"]
    assert not wanted & signal.pthread_sigmask(signal.SIG_BLOCK, [])  # the main thread's


class _Signalled(Exception):
    pass


def test_a_signal_another_thread_takes_still_stops_the_waiting_writer():
    """A thread started before the workers (as a BLAS pool is, at numpy's import) does not
    block signals, so the kernel may hand it a signal meant for the process. The writer,
    waiting for the worker's next window, must still handle it at once, not when that
    window comes: here the window never comes before the signal is handled."""
    bystander_done = threading.Event()
    bystander = threading.Thread(target=bystander_done.wait, args=(10.0,), daemon=True)
    bystander.start()
    gate = threading.Event()
    second_made = []

    def windows():
        yield 1
        gate.wait(10.0)
        second_made.append(True)
        yield 2

    def write(items):
        for item in items:
            if item == 1:  # once this thread waits: the signal goes to the bystander
                threading.Timer(0.3, signal.pthread_kill, (bystander.ident, signal.SIGUSR1)).start()

    def raise_signalled(signum, frame):
        raise _Signalled

    previous = signal.signal(signal.SIGUSR1, raise_signalled)
    try:
        with pytest.raises(_Signalled):
            write_while_making(write, windows())
        assert not second_made  # handled while the worker still held its next window back
    finally:
        gate.set()
        bystander_done.set()
        signal.signal(signal.SIGUSR1, previous)
    assert _worker_gone()
