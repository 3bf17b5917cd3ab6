"""Fault injection of the simulated card: frames from the wire dropped or with one bit
flipped before the card's decoder (and replies the same way after its encoder), a power cycle
or a stall after a number of frames."""

from __future__ import annotations

from nurbscnc.output.stream import protocol as p


class FaultInjection:
    """The card's faults between the wire and its decoder (a mixin of :class:`~.card.CardSim`:
    it provides ``config``, ``_rng``, ``_wire``, ``_decoder``, the counters, ``_handle``,
    ``_open_stream``, ``caps`` and ``_send``)."""

    def _from_wire(self, items, now: float) -> None:
        """Frames split from the wire: faults, resets and stalls, then the card's decoder."""
        faults = self.config.faults
        for item in items:
            self.frames_received += 1
            if (
                faults.reset_after_frames is not None
                and self.resets == 0
                and self.frames_received >= faults.reset_after_frames
            ):
                self._reset(now)
                continue
            if (
                faults.stall_after_frames is not None
                and self.frames_received > faults.stall_after_frames
            ):
                self.stalled = True
                return
            if isinstance(item, p.BadFrame):  # damaged on the wire already
                self._handle(item, now)
                continue
            raw = self._inject(p.encode_frame(item.type, item.payload, item.seq), "in")
            if raw is None:
                continue
            for ev in self._decoder.feed(raw):
                self._handle(ev, now)

    def _inject(self, raw: bytes, direction: str) -> bytes | None:
        """Apply drop/corrupt to one frame; None when it is dropped."""
        faults = self.config.faults
        if faults.drop_rate == 0.0 and faults.corrupt_rate == 0.0:
            return raw
        r = self._rng.random()
        if r < faults.drop_rate:
            setattr(self, f"dropped_{direction}", getattr(self, f"dropped_{direction}") + 1)
            return None
        if r < faults.drop_rate + faults.corrupt_rate:
            setattr(self, f"corrupted_{direction}", getattr(self, f"corrupted_{direction}") + 1)
            bit = self._rng.randrange(8 * len(raw))
            b = bytearray(raw)
            b[bit // 8] ^= 1 << (bit % 8)
            return bytes(b)
        return raw

    def _reset(self, now: float) -> None:
        """Power cycle: new session, position lost, buffer gone; announce with a CAPS."""
        self.resets += 1
        old = self.session_id
        while self.session_id == old:
            self.session_id = self._rng.getrandbits(32)
        self.position[:] = 0
        self._decoder = p.FrameDecoder()
        self._open_stream(now)
        self.state = p.CardState.IDLE
        self._send(self.caps(), now)
