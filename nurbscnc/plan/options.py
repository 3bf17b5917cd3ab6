"""Planning options: enums and validated frozen dataclasses, checked where they are built.

As Ruckig's ``InputParameter::validate``: an option object that exists is a valid one. A
string naming a choice is turned into its enum member on construction (so
``LookaheadOptions(dynamics="global")`` works), and anything else — a misspelt or
differently capitalised name (``"Global"``, ``"paek"``), a negative tolerance, a zero
look-ahead — raises :class:`~nurbscnc.errors.ConfigError` at once, never later in the
planner. Lengths are in mm inside the program (SI-style units with mm: the ``_mm`` suffix).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

from nurbscnc.errors import ConfigError


def parse_choice(enum_cls: type[StrEnum], value, what: str):
    """The member of ``enum_cls`` named ``value`` (a member or its exact string value);
    ConfigError naming ``what`` and the choices otherwise."""
    try:
        return enum_cls(value)
    except ValueError:
        names = ", ".join(m.value for m in enum_cls)
        raise ConfigError(f"{what} must be one of {names}, not {value!r}") from None


class Dynamics(StrEnum):
    """The dynamics check's re-plan rule (SPEC §8): lower the feed on the offending pieces
    (``local``, our default), for the whole program (``global``, the paper's rule), or do
    not check (``off``)."""

    LOCAL = "local"
    GLOBAL = "global"
    OFF = "off"


class CornerFeed(StrEnum):
    """How PH corner pieces are capped (SPEC §7): each by its own peak curvature
    (``piece``, our default) or the whole region at V_sp of its peak (``peak``, the paper)."""

    PIECE = "piece"
    PEAK = "peak"


def _positive_or_none(value, what: str, allow_zero: bool = False):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{what} must be a number, not {value!r}")
    ok = value >= 0.0 if allow_zero else value > 0.0
    if not (math.isfinite(value) and ok):
        raise ConfigError(
            f"{what} must be {'≥ 0' if allow_zero else '> 0'} and finite, not {value!r}"
        )
    return float(value)


@dataclass(frozen=True)
class PlanOptions:
    """Piece options (validated on construction).

    ``corner_feed``: :class:`CornerFeed`. ``ph``: replace corner regions by PH quintics
    (False: plan the NURBS as it is, capped by the same corner feed). ``tolerance_mm``: the
    PH fit tolerance e [mm] (None: the machine profile's). ``blend_tolerance_mm``: overrides
    every segment's G64 P [mm] (None: as programmed; 0: exact stop at every corner).
    ``smooth``: dense CAM polylines under G64 become cubic B-splines within half their
    tolerance (:mod:`nurbscnc.plan.smoothing`).
    """

    corner_feed: CornerFeed = CornerFeed.PIECE
    ph: bool = True
    tolerance_mm: float | None = None
    blend_tolerance_mm: float | None = None
    smooth: bool = True

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "corner_feed", parse_choice(CornerFeed, self.corner_feed, "corner_feed"))
        for name in ("ph", "smooth"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"{name} must be True or False, not {getattr(self, name)!r}")
        set_(self, "tolerance_mm", _positive_or_none(self.tolerance_mm, "tolerance_mm"))
        set_(
            self,
            "blend_tolerance_mm",
            _positive_or_none(self.blend_tolerance_mm, "blend_tolerance_mm", allow_zero=True),
        )


@dataclass(frozen=True)
class LookaheadOptions:
    """Look-ahead planner options (validated on construction).

    ``dynamics``: :class:`Dynamics`; ``max_iterations`` (≥ 0) of the re-plan loop;
    ``lookahead_pieces``: None (whole program) or a window of ≥ 1 pieces; ``plan``: the
    piece options (:class:`PlanOptions`); ``raise_corner_caps``: the local check may raise
    the caps that the corner heuristic V_cf (SPEC eq. 24) set, up to the machine's own
    caps, where the checked contour error has room (pre-compensation: the check simulates
    the compensated reference, whose error V_cf does not model)."""

    dynamics: Dynamics = Dynamics.LOCAL
    max_iterations: int = 40
    lookahead_pieces: int | None = None
    plan: PlanOptions = field(default_factory=PlanOptions)
    raise_corner_caps: bool = False

    def __post_init__(self):
        object.__setattr__(self, "dynamics", parse_choice(Dynamics, self.dynamics, "dynamics"))
        if (
            isinstance(self.max_iterations, bool)
            or not isinstance(self.max_iterations, int)
            or self.max_iterations < 0
        ):
            raise ConfigError(f"max_iterations must be an integer ≥ 0, not {self.max_iterations!r}")
        n = self.lookahead_pieces
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            raise ConfigError(f"lookahead_pieces must be None or an integer ≥ 1, not {n!r}")
        if not isinstance(self.plan, PlanOptions):
            raise ConfigError(f"plan must be PlanOptions, not {type(self.plan).__name__}")


class Interpolator(StrEnum):
    """How NURBS pieces are sampled: ``exact`` arc-length inversion (SPEC §10) or the
    paper's 2nd-order ``taylor`` recurrence (SPEC §3). Lines, arcs and PH pieces are exact
    either way."""

    EXACT = "exact"
    TAYLOR = "taylor"

    @classmethod
    def parse(cls, value) -> Interpolator:
        """The member for ``value`` (a member or its name); ConfigError otherwise."""
        try:
            return cls(value)
        except ValueError:
            names = tuple(m.value for m in cls)
            raise ConfigError(f"interpolator must be one of {names}, not {value!r}") from None


class Algorithm(StrEnum):
    """The look-ahead planner, or one of the paper's baselines (SPEC §9): adaptive
    (chord-error) feed or curvature feed, Taylor interpolation, no acceleration limit."""

    PH_LOOKAHEAD = "ph-lookahead"
    ADAPTIVE = "adaptive"
    CURVATURE = "curvature"
