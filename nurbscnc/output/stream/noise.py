"""A noisy serial line for the simulated streams: errors per byte, both kinds a real line
has (lost characters, flipped bits), so a longer frame is hit more often than a short one;
:class:`~.simlink.Relay` damages whole frames instead. Pass one as ``to_card`` or
``to_host`` of :func:`~.simlink.simulate`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ByteRelay:
    """A noisy line on one direction: every byte is lost with probability ``drop_rate``, else
    gets one random bit flipped with probability ``corrupt_rate`` (a serial line's noise, or a
    USB adapter dropping characters: errors per byte, so a longer frame is hit more often than
    a short one, unlike :class:`~.simlink.Relay`'s per-frame faults). Counters: ``bytes``,
    ``dropped``, ``corrupted``."""

    drop_rate: float = 0.0
    corrupt_rate: float = 0.0
    seed: int = 0
    bytes: int = 0
    dropped: int = 0
    corrupted: int = 0
    rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    def __call__(self, frame: bytes) -> bytes:
        n = len(frame)
        self.bytes += n
        if n == 0:
            return frame
        r = self.rng.random(n)
        lost = r < self.drop_rate
        hit = ~lost & (r < self.drop_rate + self.corrupt_rate)
        if not (lost.any() or hit.any()):
            return frame
        data = np.frombuffer(frame, dtype=np.uint8).copy()
        data[hit] ^= (1 << self.rng.integers(0, 8, int(hit.sum()))).astype(np.uint8)
        self.dropped += int(lost.sum())
        self.corrupted += int(hit.sum())
        return data[~lost].tobytes()
