"""The sender's retransmission timeout from round-trip samples (RFC 6298)."""

from __future__ import annotations

from nurbscnc.output.stream.linkstate import SenderOptions


class RoundTrip:
    """Retransmission timeout from round-trip samples (RFC 6298, α = 1/8, β = 1/4, K = 4)."""

    def __init__(self, opt: SenderOptions):
        self._opt = opt
        self._srtt: float | None = None
        self._rttvar = 0.0
        self._backoff = 1.0

    def sample(self, r_s: float) -> None:
        """A round trip of a frame sent once: update the estimate."""
        if self._srtt is None:
            self._srtt, self._rttvar = r_s, r_s / 2.0
        else:
            self._rttvar = 0.75 * self._rttvar + 0.25 * abs(self._srtt - r_s)
            self._srtt = 0.875 * self._srtt + 0.125 * r_s

    def back_off(self) -> None:
        self._backoff *= 2.0

    def progress(self) -> None:
        """The card acknowledged something new: the line works, end the back-off."""
        self._backoff = 1.0

    @property
    def stale_s(self) -> float:
        """Time after which a frame's missing acknowledgement means it was lost."""
        srtt = self._opt.rto_s if self._srtt is None else self._srtt
        return max(2.0 * srtt + 4.0 * self._rttvar, self._opt.rto_min_s / 2.0)

    @property
    def rto(self) -> float:
        opt = self._opt
        base = opt.rto_s if self._srtt is None else self._srtt + 4.0 * self._rttvar
        return min(opt.rto_max_s, max(opt.rto_min_s, base) * self._backoff)
