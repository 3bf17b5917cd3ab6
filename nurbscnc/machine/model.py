"""The machine in the program's internal units (mm, s): limits, servo models, steps, soft
limits and per-axis limits (SPEC §7-§9), and the feed formulas of :mod:`nurbscnc.machine.caps`
with its own parameters filled in."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nurbscnc.machine import caps
from nurbscnc.machine.discovery import FOUND_BY_DEFAULT
from nurbscnc.machine.schema import AXES, DEFAULT_MAX_POINTS

# ---------------------------------------------------------------------------------------------
# Derived feed formulas: defined in nurbscnc.machine.caps (SPEC §5 and §7).


def _as_result(values: np.ndarray):
    """A float for a 0-d result, else the array itself."""
    return float(values) if values.ndim == 0 else values


# ---------------------------------------------------------------------------------------------
# The profile, in internal units.


@dataclass(frozen=True)
class Limits:
    """Kinematic limits and tolerances (SPEC §7, Table 3), in mm and s."""

    v_max_mm_s: float  #: feed ceiling V_max
    rapid_mm_s: float  #: G0 traverse rate (defaults to V_max)
    a_max_mm_s2: float  #: acceleration limit A_max
    j_max_mm_s3: float  #: jerk limit J_max
    chord_tolerance_mm: float  #: δ, eq. 23
    kappa_ref_per_mm: float  #: κ̄, eq. 24
    contour_tolerance_mm: float  #: ε_max, SPEC §8
    ph_tolerance_mm: float  #: e, SPEC §6
    #: Most reference points a program may make (one per servo period): checked before
    #: anything is sampled, so a program whose motion takes days fails at its line, quickly.
    max_points: int = DEFAULT_MAX_POINTS
    #: The machine's path tolerance [mm]: how far G64 without P may blend a corner away from
    #: the programmed path (LinuxCNC's G64 "best speed", bounded here). None: ε_max.
    path_tolerance_mm: float | None = None

    def __post_init__(self):
        if self.path_tolerance_mm is None:
            object.__setattr__(self, "path_tolerance_mm", self.contour_tolerance_mm)


def natural_frequency_rad_s(bandwidth_hz: float, damping: float) -> float:
    """ω_n [rad/s] of G(s) = ω_n²/(s² + 2ζω_n s + ω_n²) whose −3 dB bandwidth is ``bandwidth_hz``.

    |G(jω)|² = 1/((1 − u²)² + 4ζ²u²) with u = ω/ω_n equals 1/2 where
    u⁴ + (4ζ² − 2)u² − 1 = 0, whose one positive root is u² = 1 − 2ζ² + √(4ζ⁴ − 4ζ² + 2).
    So ω_n = 2π f_bw / √(1 − 2ζ² + √(4ζ⁴ − 4ζ² + 2)); for ζ = 1/√2, ω_n = 2π f_bw.
    """
    c = 1.0 - 2.0 * damping * damping
    r = math.sqrt(c * c + 1.0)  # = √(4ζ⁴ − 4ζ² + 2)
    # c + r without cancellation: for c < 0 use the product of the roots, (c + r)(r − c) = 1.
    u2 = c + r if c >= 0.0 else 1.0 / (r - c)
    return 2.0 * math.pi * bandwidth_hz / math.sqrt(u2)


@dataclass(frozen=True)
class AxisServo:
    """One axis's closed-loop position model (SPEC eq. 25, Table 2).

    G(s) = (b2 s² + b1 s + b0) / (a4 s⁴ + a3 s³ + a2 s² + a1 s + a0), s in 1/s.

    The simple form (:meth:`second_order`) sets ``bandwidth_hz`` and ``damping`` and holds the
    same 2nd-order model in these eq.-25 coefficients, so every consumer of eq. 25 (planner,
    simulation) uses it unchanged; ``poles()`` then gives the model's own two poles.
    """

    a0: float
    a1: float
    a2: float
    a3: float
    a4: float
    b0: float
    b1: float
    b2: float
    bandwidth_hz: float | None = None  #: −3 dB bandwidth of the simple form, else None
    damping: float | None = None  #: damping ratio ζ of the simple form, else None

    @classmethod
    def second_order(cls, bandwidth_hz: float, damping: float) -> AxisServo:
        """G(s) = ω_n²/(s² + 2ζω_n s + ω_n²), ω_n from :func:`natural_frequency_rad_s`.

        Written in eq.-25 form by multiplying numerator and denominator by (s + p)² with
        p = 10 ω_n: G = ω_n²(s + p)² / ((s² + 2ζω_n s + ω_n²)(s + p)²), the same transfer
        function (the pair at −p cancels exactly; it is never a pole of the 2nd-order part for
        ζ ≤ MAX_DAMPING, whose poles lie within ω_n(ζ + √(ζ² − 1)) < 4 ω_n of the origin).
        """
        wn = natural_frequency_rad_s(bandwidth_hz, damping)
        p = 10.0 * wn
        d2, d1, d0 = 1.0, 2.0 * damping * wn, wn * wn  # s² + 2ζω_n s + ω_n²
        q2, q1, q0 = 1.0, 2.0 * p, p * p  # (s + p)²
        return cls(
            a4=d2 * q2,
            a3=d2 * q1 + d1 * q2,
            a2=d2 * q0 + d1 * q1 + d0 * q2,
            a1=d1 * q0 + d0 * q1,
            a0=d0 * q0,
            b2=d0 * q2,
            b1=d0 * q1,
            b0=d0 * q0,
            bandwidth_hz=float(bandwidth_hz),
            damping=float(damping),
        )

    @property
    def simple(self) -> bool:
        """True for the bandwidth/damping form."""
        return self.bandwidth_hz is not None

    @property
    def natural_frequency_rad_s(self) -> float | None:
        """ω_n [rad/s] of the simple form, else None."""
        if not self.simple:
            return None
        return natural_frequency_rad_s(self.bandwidth_hz, self.damping)

    @property
    def numerator(self) -> tuple[float, float, float]:
        """Numerator coefficients, highest power first (scipy.signal order)."""
        return (self.b2, self.b1, self.b0)

    @property
    def denominator(self) -> tuple[float, float, float, float, float]:
        """Denominator coefficients, highest power first (scipy.signal order)."""
        return (self.a4, self.a3, self.a2, self.a1, self.a0)

    def poles(self) -> np.ndarray:
        """The closed-loop poles [1/s]: roots of the denominator, or of s² + 2ζω_n s + ω_n²
        for the simple form (without the cancelled pair of :meth:`second_order`)."""
        if self.simple:
            wn = self.natural_frequency_rad_s
            return np.roots([1.0, 2.0 * self.damping * wn, wn * wn])
        return np.roots(self.denominator)

    @property
    def dc_gain(self) -> float:
        """G(0) = b0/a0 (1 for a servo with integral action)."""
        return self.b0 / self.a0


@dataclass(frozen=True)
class Servo:
    """Servo period and per-axis models; an axis model None means that axis follows its
    reference exactly (no lag). With no model at all (``modelled`` False) the contour check
    is off."""

    period_s: float  #: T_s, one reference point per period
    x: AxisServo | None = None
    y: AxisServo | None = None
    z: AxisServo | None = None

    def axis(self, name: str) -> AxisServo | None:
        """The model of axis ``name`` ("x", "y", "z"); None means an ideal axis."""
        return getattr(self, name)

    @property
    def modelled(self) -> bool:
        """True when at least one axis has a model: the contour check can run."""
        return any(self.axis(a) is not None for a in AXES)


@dataclass(frozen=True)
class AxisLimits:
    """Per-axis limits (x, y, z), each axis on its own [mm, s]; ``inf`` where the profile sets
    none (that axis is then bounded by the path limits alone). The planner turns them into
    path limits per piece (:func:`nurbscnc.plan.axes.piece_limits`)."""

    v_max_mm_s: tuple[float, float, float] = (math.inf,) * 3  #: axis velocity limit
    a_max_mm_s2: tuple[float, float, float] = (math.inf,) * 3  #: axis acceleration limit
    j_max_mm_s3: tuple[float, float, float] = (math.inf,) * 3  #: axis jerk limit

    @property
    def any(self) -> bool:
        """True when some axis has some limit (False: the path limits alone apply)."""
        return any(
            math.isfinite(x) for x in (*self.v_max_mm_s, *self.a_max_mm_s2, *self.j_max_mm_s3)
        )

    def as_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(3,) arrays of the velocity [mm/s], acceleration [mm/s²], jerk [mm/s³] limits."""
        return (
            np.array(self.v_max_mm_s, dtype=float),
            np.array(self.a_max_mm_s2, dtype=float),
            np.array(self.j_max_mm_s3, dtype=float),
        )


@dataclass(frozen=True)
class RotaryAxis:
    """One rotary axis (A, B or C) of the profile's ``[axis_limits.<a|b|c>]`` table, in
    degrees and seconds: an independent joint moving in step with X Y Z (LinuxCNC's trivial
    kinematics). The table's presence declares the axis.

    ``name`` "a", "b" or "c"; ``v_max_deg_s`` velocity [deg/s] (the profile's
    ``v_max_deg_min`` / 60), ``a_max_deg_s2`` acceleration [deg/s²], ``j_max_deg_s3`` jerk
    [deg/s³]; ``min_deg`` / ``max_deg`` the soft limits [deg] (machine coordinates; ±inf when
    the profile sets none); ``wrapped``: LinuxCNC's ``WRAPPED_ROTARY`` (in G90 the word is a
    position in [0, 360) reached the short way, its sign a direction); ``steps_per_deg`` the
    card's steps per degree (0 where the profile gives none: the axis cannot be streamed).
    """

    name: str
    v_max_deg_s: float
    a_max_deg_s2: float
    j_max_deg_s3: float
    min_deg: float = -math.inf
    max_deg: float = math.inf
    wrapped: bool = False
    steps_per_deg: float = 0.0


@dataclass(frozen=True)
class Steps:
    """Step (pulse) resolution per axis (x, y, z) and the card's per-period pulse ceiling."""

    per_mm: tuple[float, float, float]  #: steps per mm
    max_pulses_per_period: int


@dataclass(frozen=True)
class SoftLimits:
    """Travel box per axis (x, y, z) [mm]."""

    min_mm: tuple[float, float, float]
    max_mm: tuple[float, float, float]

    def inside(self, points_mm) -> np.ndarray:
        """Per point (rows of an (N, 3) array, or one 3-vector): inside the box, bounds included."""
        p = np.asarray(points_mm, dtype=float)
        return np.all((p >= self.min_mm) & (p <= self.max_mm), axis=-1)


@dataclass(frozen=True)
class Machine:
    """A validated machine profile in internal units (mm, s).

    ``source`` is the file it came from (``"<default machine>"`` for the bundled one),
    ``found_by`` how it was chosen (one of the ``FOUND_BY_*`` constants), ``settings`` the
    effective profile in the file's units (the TOML tables after overrides, optional keys
    filled in with their defaults, ``defaults`` the keys so filled), for ``profile show``.
    ``axis_limits`` the optional per-axis limits (none: the path limits of ``limits`` alone).
    """

    limits: Limits
    servo: Servo
    steps: Steps
    soft_limits: SoftLimits
    source: str = "<default>"
    found_by: str = FOUND_BY_DEFAULT
    settings: dict = field(default_factory=dict, compare=False, repr=False)
    axis_limits: AxisLimits = field(default_factory=AxisLimits)
    #: The dotted keys of ``settings`` the profile left out, filled with their defaults.
    defaults: frozenset = field(default_factory=frozenset, compare=False, repr=False)
    #: The rotary axes the machine has, by name ("a", "b", "c"): :class:`RotaryAxis`. Empty:
    #: a three-axis machine (a program that moves A B C is refused).
    rotary_axes: dict = field(default_factory=dict, compare=False)

    @property
    def contour_check(self) -> bool:
        """Whether the planner's contour (dynamics) check applies: some axis has a model."""
        return self.servo.modelled

    def describe(self) -> str:
        """ "<file> (<how it was found>)", for command summaries."""
        if self.found_by == FOUND_BY_DEFAULT:
            return "bundled default (the paper's machine, nurbscnc/data/default_machine.toml)"
        return f"{self.source} ({self.found_by})"

    def kappa_threshold_per_mm(self, feed_mm_s):
        """κ_th = A_max / F² [1/mm] at programmed feed ``feed_mm_s`` (SPEC §5)."""
        return caps.kappa_threshold_per_mm(feed_mm_s, self.limits.a_max_mm_s2)

    def chord_feed_mm_s(self, kappa_per_mm):
        """V_af at curvature ``kappa_per_mm`` with this machine's T_s and δ (SPEC eq. 23)."""
        return caps.chord_feed_mm_s(
            kappa_per_mm, self.servo.period_s, self.limits.chord_tolerance_mm
        )

    def curvature_feed_mm_s(self, kappa_per_mm, feed_mm_s: float | None = None):
        """V_cf with κ̄ of this machine (SPEC eq. 24); ``feed_mm_s`` defaults to V_max."""
        v = self.limits.v_max_mm_s if feed_mm_s is None else feed_mm_s
        return caps.curvature_feed_mm_s(kappa_per_mm, v, self.limits.kappa_ref_per_mm)

    def corner_feed_mm_s(self, kappa_per_mm, feed_mm_s: float | None = None):
        """V_sp = min(V_af, V_cf) at a corner of peak curvature ``kappa_per_mm`` (SPEC §7)."""
        return _as_result(
            np.minimum(
                np.asarray(self.chord_feed_mm_s(kappa_per_mm)),
                np.asarray(self.curvature_feed_mm_s(kappa_per_mm, feed_mm_s)),
            )
        )
