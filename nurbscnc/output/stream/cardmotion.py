"""The simulated card's motion: it starts executing once enough periods are buffered, runs the
periods due in (scaled) real time or all at once, moves and logs, finishes on END, and raises
alarms (underrun, END mismatch)."""

from __future__ import annotations

import numpy as np

from nurbscnc.output.stream import protocol as p


class Execution:
    """The card's execution of its buffer (a mixin of :class:`~.card.CardSim`: it provides
    ``config``, ``state``, the buffer and counters, ``status`` and ``_send``)."""

    def _run_fast(self, now: float) -> None:
        """As fast as possible: every buffered period runs at once (unless held)."""
        if self._period_wall_s is None and self.state is p.CardState.RUNNING:
            self._execute(self.fill, now)

    def _maybe_start(self, now: float) -> None:
        fast = self._period_wall_s is None
        if self.state is p.CardState.FILLING and (
            self.fill >= self.config.start_fill or self._end is not None or (fast and self.fill)
        ):
            self.state = p.CardState.RUNNING
            self._started = True
            self._next_due = now
            self._send(self.status(), now)

    def advance(self, now: float) -> None:
        """Execute every period due by ``now`` [s] (real time / speed); abandon a stalled frame."""
        if not self.stalled and self._wire.pending_bytes:
            self._from_wire(self._wire.expire(now), now)
        if self.stalled or self.state is not p.CardState.RUNNING or self._period_wall_s is None:
            return
        due = int((now - self._next_due) // self._period_wall_s) + 1
        if due <= 0:
            return
        n = min(due, self.fill)
        self._execute(n, now)
        self._next_due += n * self._period_wall_s
        if self.fill == 0 and self._end is not None:
            self._maybe_finish(now)
        elif due > n:
            self._raise_alarm(
                p.AlarmCode.UNDERRUN,
                f"buffer underrun: period {self.stream_executed + 1} was due and the buffer "
                "was empty",
                now,
            )

    def _execute(self, n: int, now: float) -> None:
        """Run the next ``n`` buffered periods: move, log, push a STATUS now and then."""
        if n <= 0:
            return
        taken = []
        left = n
        while left:
            head = self._buffer[0]
            if len(head) <= left:
                taken.append(self._buffer.popleft())
                left -= len(head)
            else:
                taken.append(head[:left])
                self._buffer[0] = head[left:]
                left = 0
        block = np.vstack(taken) if len(taken) > 1 else taken[0]
        self.position += block.sum(axis=0)
        self._log.append(block)
        self.fill -= n
        self.executed_periods += n
        self.stream_executed += n
        self._since_status += n
        if self._since_status >= self.config.status_every_periods:
            self._since_status = 0
            self._send(self.status(), now)

    def _maybe_finish(self, now: float) -> None:
        if self._end is None or self.fill or self.state is not p.CardState.RUNNING:
            return
        pos = tuple(int(v) for v in self.position)
        if self._end.periods != self.stream_executed or tuple(self._end.position_steps) != pos:
            self._raise_alarm(
                p.AlarmCode.END_MISMATCH,
                f"END says {self._end.periods} periods to "
                f"{list(self._end.position_steps)}, executed "
                f"{self.stream_executed} to {list(pos)}",
                now,
            )
            return
        self.state = p.CardState.DONE
        self._send(self.status(), now)

    def _raise_alarm(self, code: int, text: str, now: float) -> None:
        self.state = p.CardState.ALARM
        self.alarm, self.alarm_text = p.AlarmCode(code), text
        self._buffer.clear()
        self._early.clear()
        self.fill = self._early_periods = 0
        self._send(p.Alarm(int(code), text), now)
        self._send(self.status(), now)
