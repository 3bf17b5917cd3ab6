"""A serial line's byte rate in virtual or wall time: bytes pushed at t arrive one every
10/baud s after t (the card simulator's and the simulated link's line)."""

from __future__ import annotations

import collections

from nurbscnc.output.stream import protocol as p


class Wire:
    """A serial line's byte rate: bytes pushed at t arrive one every 10/baud s after t."""

    def __init__(self, baud: int | None):
        self.byte_s = None if not baud else p.BITS_PER_BYTE_8N1 / baud
        self._queue: collections.deque[list] = collections.deque()  # [start_s, data, taken]
        self._free_at = 0.0

    def push(self, data: bytes, now: float) -> None:
        if data:
            start = max(now, self._free_at)
            self._free_at = start + (len(data) * self.byte_s if self.byte_s else 0.0)
            self._queue.append([start, data, 0])

    def pop(self, now: float) -> bytes:
        """The bytes that have arrived by ``now``."""
        if self.byte_s is None:
            out = b"".join(item[1] for item in self._queue)
            self._queue.clear()
            return out
        chunks = []
        while self._queue:
            start, data, taken = self._queue[0]
            arrived = min(len(data), int((now - start) / self.byte_s))
            if arrived > taken:
                chunks.append(data[taken:arrived])
                self._queue[0][2] = arrived
            if arrived < len(data):
                break
            self._queue.popleft()
        return b"".join(chunks)

    def next_s(self) -> float | None:
        if not self._queue:
            return None
        start, data, taken = self._queue[0]
        return start + (taken + 1) * self.byte_s if self.byte_s else start

    def done_s(self) -> float | None:
        """When the oldest chunk on the line has arrived whole (None: nothing on the line)."""
        if not self._queue:
            return None
        start, data, _ = self._queue[0]
        return start + len(data) * self.byte_s if self.byte_s else start

    def queued_bytes(self, now: float) -> int:
        """Bytes pushed and not yet arrived by ``now``."""
        if self.byte_s is None:
            return sum(len(item[1]) for item in self._queue)
        return max(0, round((self._free_at - now) / self.byte_s))

    def drop_unsent(self, now: float) -> None:
        """Forget the chunks not yet started by ``now`` (a port's output queue flushed)."""
        while self._queue and self._queue[-1][0] > now:
            self._queue.pop()
        if self._queue:
            start, data, _ = self._queue[-1]
            self._free_at = start + len(data) * (self.byte_s or 0.0)
        else:
            self._free_at = min(self._free_at, now)
