"""The cut windows of a plan handed to the stream as they are planned.

:func:`~nurbscnc.plan.lookahead.plan_windows` yields a program's cut windows in order, each
final when yielded (the junction after it is a rest: what comes after cannot change it). A
feed hands them to the :class:`~.job.Job` while the card already runs the first ones:

- :class:`WindowFeed` plans on a thread of its own (the planner is pure; the thread only
  moves finished windows through a queue), so the sender keeps the card fed meanwhile;
- :class:`ScheduledFeed` releases windows planned beforehand at given (virtual) times: the
  simulator's stand-in for a planner of known speed (a slow planner, in tests).

Both: :meth:`first` (the first window; blocks), :meth:`poll` (the windows ready since the
last call, with the time each became ready; never blocks; raises the planner's error once
every window before it was handed over), :meth:`next_ready_s` (blocks until the next window
is ready: for the simulator's waits), ``clock`` (the time base of the reports [s]),
``first_s`` and ``planned_s`` (time from the start to the first and to the last window [s];
None while planning), :meth:`close` (the stream is over: stop planning).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterable

from nurbscnc.output.background import STOP_WAIT_S, signals_to_main_thread, waited

_END = object()


class WindowFeed:
    """Plan ``windows`` (an iterable of windows, e.g. a generator around
    :func:`~nurbscnc.plan.lookahead.plan_windows`) on a daemon thread; ``clock`` [s]."""

    def __init__(self, windows: Iterable, clock: Callable[[], float] = time.monotonic):
        self.clock = clock
        self.start_s = clock()
        self.first_s: float | None = None
        self.planned_s: float | None = None
        self.done = False
        self._queue: queue.Queue = queue.Queue()
        self._waited = None  #: an item :meth:`next_ready_s` took off the queue
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self._plan, args=(iter(windows),), name="nurbscnc-planner", daemon=True
        )
        self._thread.start()

    def _plan(self, windows) -> None:
        signals_to_main_thread()  # the operator's hold and stop reach the stream at once
        try:
            for w in windows:
                if self._stop.is_set():
                    return
                self._queue.put((w, self.clock()))
            self._queue.put((_END, self.clock()))
        except BaseException as exc:  # noqa: BLE001 - handed to the stream, raised there
            self._queue.put((exc, self.clock()))

    def _take(self, item) -> list:
        w, t = item
        if w is _END:
            self.done = True
            self.planned_s = t - self.start_s
            return []
        if isinstance(w, BaseException):
            self.done = True
            raise w
        if self.first_s is None:
            self.first_s = t - self.start_s
        return [(w, t)]

    def close(self, wait_s: float = STOP_WAIT_S) -> None:
        """Stop planning after the window being planned, and wait for that (at most
        ``wait_s`` [s]): the stream is over (done, failed or aborted). The process must not
        exit while the planner is inside numpy: a daemon thread stopped there at exit can
        abort the interpreter."""
        self._stop.set()
        self._thread.join(wait_s)

    def first(self):
        """The first window (blocks until it is planned; raises the planner's error)."""
        out = self._take(waited(self._queue))
        if not out:
            raise ValueError("the planner yielded no window")
        return out[0][0]

    def poll(self) -> list:
        """The windows planned since the last call, (window, time ready) each."""
        out: list = []
        while not self.done:
            if self._waited is not None:
                item, self._waited = self._waited, None
            else:
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    break
            out += self._take(item)
        return out

    def next_ready_s(self, now_s: float) -> float:
        """Block until the next window (or the end, or an error) is ready; returns
        ``now_s`` (real time passes, not the simulator's)."""
        if not self.done and self._waited is None:
            self._waited = waited(self._queue)
        return now_s


class ScheduledFeed:
    """Windows planned beforehand, released at the (virtual) times ``ready_s`` [s] (one
    per window, the first at the start); ``now_s`` is the simulator's time."""

    def __init__(self, windows: list, ready_s: list[float]):
        self.windows, self.ready_s = list(windows), list(ready_s)
        self.now_s = 0.0
        self.clock = lambda: self.now_s
        self.first_s = self.ready_s[0]
        self.planned_s = self.ready_s[-1]
        self.given = 0

    @property
    def done(self) -> bool:
        return self.given >= len(self.windows)

    def close(self, wait_s: float = STOP_WAIT_S) -> None:
        """Nothing to stop: the windows were planned beforehand."""

    def first(self):
        self.given = 1
        return self.windows[0]

    def poll(self) -> list:
        out = []
        while not self.done and self.ready_s[self.given] <= self.now_s:
            out.append((self.windows[self.given], self.ready_s[self.given]))
            self.given += 1
        return out

    def next_ready_s(self, now_s: float) -> float:
        return max(now_s, self.ready_s[self.given]) if not self.done else now_s
