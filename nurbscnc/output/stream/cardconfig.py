"""What a simulated card is (axes, buffer, pulse limit, period, speed, start position) and the
faults injected between it and the wire."""

from __future__ import annotations

from dataclasses import dataclass, field

from nurbscnc.errors import ConfigError
from nurbscnc.output.stream.axes import AXIS_NAMES, LINEAR_AXES, mask_of


@dataclass(frozen=True)
class Faults:
    """Injected faults. Rates are probabilities per frame, in each direction."""

    drop_rate: float = 0.0  #: a frame vanishes
    corrupt_rate: float = 0.0  #: one random bit of a frame is flipped
    delay_s: float = 0.0  #: every reply leaves this much later [s]
    reset_after_frames: int | None = None  #: the card resets once after this many frames in
    stall_after_frames: int | None = None  #: the card goes silent after this many frames in

    def __post_init__(self) -> None:
        for name in ("drop_rate", "corrupt_rate"):
            v = getattr(self, name)
            if not 0.0 <= v < 1.0:
                raise ConfigError(f"--{name.replace('_', '-')} must be in [0, 1), got {v}")
        if self.drop_rate + self.corrupt_rate >= 1.0:
            raise ConfigError("--drop-rate + --corrupt-rate must be < 1")
        if self.delay_s < 0.0:
            raise ConfigError(f"--delay-ms must be >= 0, got {self.delay_s * 1e3}")


@dataclass(frozen=True)
class CardConfig:
    """What the simulated card is: axes, buffer, pulse limit, period, speed, start position.

    ``speed`` None executes every period as soon as it is accepted (as fast as possible);
    otherwise periods run every ``period_s / speed`` seconds of wall time. The card starts
    executing when ``start_fill_periods`` are buffered (default: half the buffer) or END has
    arrived, and pushes a STATUS every ``status_every_periods`` executed periods.
    ``gap_s``: the receiver's limit on a stalled partial frame (see :class:`FrameDecoder`).
    ``axis_names``: the axes it drives, e.g. "xyza" (sets ``axes``; empty: the first
    ``axes`` of X Y Z A B C); ``version``: the protocol it speaks, 3 (X Y Z only, no axis
    mask) or 4 (0: 4 when it drives a rotary axis, else 3); ``position_steps`` empty: zeros.
    """

    axes: int = 3
    buffer_periods: int = 256
    max_pulses_per_period: int = 127
    period_s: float = 1e-3
    speed: float | None = 1.0
    start_fill_periods: int | None = None
    status_every_periods: int = 16
    position_steps: tuple[int, ...] = ()
    faults: Faults = field(default_factory=Faults)
    #: an incomplete frame whose bytes stop arriving this long is abandoned [s]; 10 ms is
    #: about 115 byte times at 115200 baud, far more than a UART leaves between bytes
    gap_s: float = 0.01
    axis_names: str = ""
    version: int = 0

    def __post_init__(self) -> None:
        self._set_axes()
        if not 1 <= self.axes <= 15:
            raise ConfigError(f"axes must be 1..15, got {self.axes}")
        if not 1 <= self.buffer_periods <= 0xFFFF:
            raise ConfigError(f"--buffer must be 1..65535 periods, got {self.buffer_periods}")
        if not 1 <= self.max_pulses_per_period <= 32767:
            raise ConfigError(f"--max-pulses must be 1..32767, got {self.max_pulses_per_period}")
        if not self.period_s > 0.0:
            raise ConfigError(f"--period-ms must be > 0, got {self.period_s * 1e3}")
        if self.speed is not None and not self.speed > 0.0:
            raise ConfigError(f"--speed must be > 0, got {self.speed}")
        if len(self.position_steps) != self.axes:
            raise ConfigError(f"the start position needs {self.axes} values")

    def _set_axes(self) -> None:
        """Axis names, count, start position and version from what was given."""
        names = self.axis_names.lower()
        if names:
            try:
                mask_of(names)
            except ValueError as exc:
                raise ConfigError(f"--axes: {exc}") from None
            if len(set(names)) != len(names) or names != "".join(
                a for a in AXIS_NAMES if a in names
            ):
                raise ConfigError(f"--axes {names.upper()}: each axis once, in the order XYZABC")
            object.__setattr__(self, "axes", len(names))
        if not names and self.axes <= len(AXIS_NAMES):
            object.__setattr__(self, "axis_names", AXIS_NAMES[: self.axes])
        if not self.position_steps:
            object.__setattr__(self, "position_steps", (0,) * self.axes)
        if not self.version:
            rotary = any(a not in LINEAR_AXES for a in self.axis_names)
            object.__setattr__(self, "version", 4 if rotary else 3)
        if self.version not in (3, 4):
            raise ConfigError(f"--protocol must be 3 or 4, got {self.version}")
        if self.version == 4 and not self.axis_names:
            raise ConfigError(f"a card speaking protocol 4 drives at most 6 axes, not {self.axes}")
        if self.version == 3 and any(a not in LINEAR_AXES for a in self.axis_names):
            raise ConfigError(
                f"a card speaking protocol 3 drives X Y Z, not {' '.join(self.axis_names.upper())}"
            )

    @property
    def start_fill(self) -> int:
        """Buffered periods that start execution."""
        if self.start_fill_periods is not None:
            return max(1, min(self.start_fill_periods, self.buffer_periods))
        return max(1, self.buffer_periods // 2)
