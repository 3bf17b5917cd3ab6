"""The feed profile's types: what it is planned from (:class:`ProfileInput`), the planned
motion (:class:`Profile`: phases of constant jerk along the arc length ``s`` [mm], so
``s(t)`` is a cubic on each; :meth:`Profile.sample` evaluates it for any array of times),
its inverse (:func:`time_at_length`) and where two profiles start to differ
(:func:`same_until_s`). Planning is :func:`nurbscnc.plan.profile_plan.plan_profile` (SPEC §7).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.plan.compiled import as_float64
from nurbscnc.plan.compiled import kernels as _kernels  # None: the Python loops
from nurbscnc.plan.feedrate import check_limit_arrays, check_limits


def frozen_array(values, dtype=float) -> np.ndarray:
    a = np.array(values, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class ProfileInput:
    """What the feed profile needs to know about ``k`` pieces (SPEC §7).

    Attributes
    ----------
    length_mm : (k,) arc length of each piece, finite ≥ 0 [mm].
    v_max_mm_s : (k,) cruise cap within each piece, finite > 0 [mm/s].
    v_junction_max_mm_s : (k+1,) cap at each junction (piece starts, then the program end),
        ≥ 0, may be ``inf`` [mm/s]. The first and last must be 0 (start and end at rest); a 0
        inside is an exact stop.
    a_max_mm_s2, j_max_mm_s3 : tangential acceleration [mm/s²] and jerk [mm/s³] limits: one
        number for every piece, or (k,) arrays, one limit per piece (the path
        limits of the axes on that piece, lowered by the contour check's shaping).
    lookahead_pieces : ``None`` (see the whole program) or how many pieces ahead the planner
        sees (≥ 1); it then keeps the ability to stop within them.
    a_decel_mm_s2, j_decel_mm_s3 : ``None`` (the same as ``a_max_mm_s2``, ``j_max_mm_s3``) or
        separate limits (scalar or (k,)) for the *deceleration* within each piece (its
        S-curve down from the peak to the end speed); the others then limit its rise.

    Where the limits apply: every speed transition lies inside one planning unit and obeys
    the smallest limits of the unit's pieces (see the module docstring); at a planning
    junction the acceleration is zero and only the jerk's sign may change.
    """

    length_mm: np.ndarray
    v_max_mm_s: np.ndarray
    v_junction_max_mm_s: np.ndarray
    a_max_mm_s2: float | np.ndarray
    j_max_mm_s3: float | np.ndarray
    lookahead_pieces: int | None = None
    a_decel_mm_s2: float | np.ndarray | None = None
    j_decel_mm_s3: float | np.ndarray | None = None

    def __post_init__(self):
        length = frozen_array(self.length_mm)
        k = length.size
        a, j = _piece_limits(self.a_max_mm_s2, self.j_max_mm_s3, k)
        a_dn = a if self.a_decel_mm_s2 is None else None
        j_dn = j if self.j_decel_mm_s3 is None else None
        if a_dn is None or j_dn is None:
            a_dn, j_dn = _piece_limits(
                self.a_max_mm_s2 if self.a_decel_mm_s2 is None else self.a_decel_mm_s2,
                self.j_max_mm_s3 if self.j_decel_mm_s3 is None else self.j_decel_mm_s3,
                k,
            )
        v_max = frozen_array(self.v_max_mm_s)
        v_junction = frozen_array(self.v_junction_max_mm_s)
        if length.ndim != 1 or length.size < 1:
            raise PlanningError("length_mm must be a 1-D array of at least one piece")
        if v_max.shape != (k,) or v_junction.shape != (k + 1,):
            raise PlanningError(
                f"shapes: length_mm {length.shape}, v_max_mm_s {v_max.shape} (need ({k},)), "
                f"v_junction_max_mm_s {v_junction.shape} (need ({k + 1},))"
            )
        if not np.all(np.isfinite(length)) or np.any(length < 0.0):
            raise PlanningError("length_mm must be finite and >= 0")
        if not np.all(np.isfinite(v_max)) or np.any(v_max <= 0.0):
            raise PlanningError("v_max_mm_s must be finite and > 0")
        if np.any(np.isnan(v_junction)) or np.any(v_junction < 0.0):
            raise PlanningError("v_junction_max_mm_s must be >= 0 (inf allowed)")
        if v_junction[0] != 0.0 or v_junction[-1] != 0.0:
            raise PlanningError("the first and last junction caps must be 0 (rest)")
        n = self.lookahead_pieces
        if n is not None:
            if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
                raise ConfigError(f"lookahead_pieces must be None or an integer >= 1, got {n!r}")
            n = int(n)
        for name, value in (
            ("length_mm", length),
            ("v_max_mm_s", v_max),
            ("v_junction_max_mm_s", v_junction),
            ("a_max_mm_s2", a),
            ("j_max_mm_s3", j),
            ("lookahead_pieces", n),
            ("a_decel_mm_s2", a_dn),
            ("j_decel_mm_s3", j_dn),
        ):
            object.__setattr__(self, name, value)

    @property
    def piece_count(self) -> int:
        return int(self.length_mm.size)

    def piece_limits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(k,) arrays ``(a_up, j_up, a_down, j_down)``: each piece's limits for its rise
        and its descent [mm/s², mm/s³]."""
        k = self.piece_count
        return tuple(
            np.broadcast_to(np.asarray(x, dtype=float), (k,))
            for x in (self.a_max_mm_s2, self.j_max_mm_s3, self.a_decel_mm_s2, self.j_decel_mm_s3)
        )

    @property
    def uniform_limits(self) -> bool:
        """Whether every piece has the same limits, rising and falling."""
        lims = (self.a_max_mm_s2, self.j_max_mm_s3, self.a_decel_mm_s2, self.j_decel_mm_s3)
        return all(np.ndim(x) == 0 for x in lims) and lims[0] == lims[2] and lims[1] == lims[3]


def _piece_limits(a_max, j_max, k: int):
    """Validated limits: floats, or read-only (k,) arrays when either is per piece."""
    if np.ndim(a_max) == 0 and np.ndim(j_max) == 0:
        return check_limits(a_max, j_max)
    a, j = check_limit_arrays(a_max, j_max)
    for name, x in (("a_max_mm_s2", a), ("j_max_mm_s3", j)):
        if x.ndim not in (0, 1) or (x.ndim == 1 and x.shape != (k,)):
            raise PlanningError(
                f"{name} must be a number or one per piece ({k},), got shape {x.shape}"
            )
    return (frozen_array(np.broadcast_to(a, (k,))), frozen_array(np.broadcast_to(j, (k,))))


@dataclass(frozen=True, eq=False)
class Profile:
    """A planned feed profile: piecewise constant jerk along the path, exactly.

    Phase ``p`` starts at ``phase_start_time_s[p]`` and lasts ``phase_duration_s[p]``; with
    ``τ = t − t_p`` its motion is ``s = s0 + v0·τ + a0·τ²/2 + jerk·τ³/6``. Phases of zero
    duration are omitted; ``phase_piece_index`` says which piece each belongs to. All arrays
    are read-only.

    Attributes
    ----------
    total_length_mm, duration_s : the whole path [mm] and its time [s].
    junction_speeds_mm_s : (k+1,) planned speed at each junction [mm/s].
    piece_peak_speed_mm_s : (k,) cruise (or peak) speed of each piece [mm/s].
    piece_start_mm : (k,) arc length at each piece start [mm] (cumulative lengths).
    piece_start_time_s : (k,) time at which each piece starts [s].
    """

    total_length_mm: float
    duration_s: float
    junction_speeds_mm_s: np.ndarray
    piece_peak_speed_mm_s: np.ndarray
    piece_start_mm: np.ndarray
    piece_start_time_s: np.ndarray
    phase_start_time_s: np.ndarray
    phase_duration_s: np.ndarray
    phase_s0_mm: np.ndarray
    phase_v0_mm_s: np.ndarray
    phase_a0_mm_s2: np.ndarray
    phase_jerk_mm_s3: np.ndarray
    phase_piece_index: np.ndarray

    @property
    def piece_count(self) -> int:
        return int(self.piece_start_mm.size)

    @property
    def piece_start_s(self) -> np.ndarray:
        """Arc length ``s`` [mm] at each piece start; the same array as ``piece_start_mm``."""
        return self.piece_start_mm

    @property
    def piece_duration_s(self) -> np.ndarray:
        """Time [s] the motion spends on each piece (k,), dwells not included."""
        return np.diff(np.append(self.piece_start_time_s, self.duration_s))

    def sample(self, t_s) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Evaluate the profile at times ``t_s`` [s] (any shape, any order).

        Returns ``(s_mm, v_mm_s, a_mm_s2, j_mm_s3, piece_index)`` of the same shape. Before 0
        the machine is at rest at ``s = 0``; from ``duration_s`` on it is at rest at exactly
        ``total_length_mm`` (in the last piece). ``v`` is clipped at 0 and ``s`` to
        ``[0, total_length_mm]`` (both only remove rounding: mathematically they hold).
        """
        t = np.asarray(t_s, dtype=float)
        shape = t.shape
        t = t.ravel()
        n = self.phase_start_time_s.size
        if n == 0:  # every piece has zero length: the machine never moves
            z = np.zeros(shape)
            return z, z.copy(), z.copy(), z.copy(), np.zeros(shape, dtype=np.int64)
        idx = np.searchsorted(self.phase_start_time_s, t, side="right") - 1
        np.clip(idx, 0, n - 1, out=idx)
        tau = np.clip(t - self.phase_start_time_s[idx], 0.0, self.phase_duration_s[idx])
        jerk = self.phase_jerk_mm_s3[idx]
        a0 = self.phase_a0_mm_s2[idx]
        v0 = self.phase_v0_mm_s[idx]
        s = self.phase_s0_mm[idx] + tau * (v0 + tau * (0.5 * a0 + tau * (jerk / 6.0)))
        v = v0 + tau * (a0 + (0.5 * tau) * jerk)
        a = a0 + tau * jerk
        # The piece is found from s (pieces may share phases: see plan_profile).
        piece = np.searchsorted(self.piece_start_mm, s, side="right") - 1
        np.clip(piece, 0, self.piece_count - 1, out=piece)
        before = t < 0.0
        after = t >= self.duration_s
        if before.any():
            s[before] = 0.0
            v[before] = a[before] = jerk[before] = 0.0
        if after.any():
            s[after] = self.total_length_mm
            v[after] = a[after] = jerk[after] = 0.0
            piece[after] = self.piece_count - 1
        np.maximum(v, 0.0, out=v)
        np.clip(s, 0.0, self.total_length_mm, out=s)
        return (
            s.reshape(shape),
            v.reshape(shape),
            a.reshape(shape),
            jerk.reshape(shape),
            piece.reshape(shape),
        )


#: The phase columns that :meth:`Profile.sample` reads (with ``phase_start_time_s``).
_PHASE_COLUMNS = (
    "phase_duration_s",
    "phase_s0_mm",
    "phase_v0_mm_s",
    "phase_a0_mm_s2",
    "phase_jerk_mm_s3",
)


def same_until_s(old: Profile, new: Profile) -> float:
    """The profile time [s] before which ``old`` and ``new`` sample alike, bit for bit
    (:meth:`Profile.sample` at any τ < it gives the same five numbers), and their pieces
    start at the same times (``piece_start_time_s``, which places dwells): a re-plan that
    changed the profile from some phase on changes nothing before it.

    :meth:`Profile.sample` at τ reads the phase found among the phase start times and that
    phase's columns, the piece start lengths and the duration. So: the earlier start of the
    first phase that differs in any column (or is missing from one profile) — where only
    its duration differs, its shorter end or the earlier start of the phase after it — the
    earlier start time of the first piece whose start time differs, and the shorter
    duration; 0 when the pieces' start lengths differ (another path)."""
    if not np.array_equal(old.piece_start_mm, new.piece_start_mm):
        return 0.0
    t = min(old.duration_s, new.duration_s)
    m = min(old.phase_start_time_s.size, new.phase_start_time_s.size)
    starts_apart = old.phase_start_time_s[:m] != new.phase_start_time_s[:m]  # or s, v, a, j
    for name in _PHASE_COLUMNS[1:]:
        starts_apart |= getattr(old, name)[:m] != getattr(new, name)[:m]
    differ = starts_apart | (old.phase_duration_s[:m] != new.phase_duration_s[:m])
    first = int(np.argmax(differ)) if differ.any() else m
    cut = first  # the phase whose start bounds the common samples
    if first < m and not starts_apart[first]:
        # The same motion cut short in one (a cruise that the braking now begins earlier
        # in): alike up to the shorter end, and before either profile's next phase.
        t = min(
            t,
            float(old.phase_start_time_s[first])
            + float(min(old.phase_duration_s[first], new.phase_duration_s[first])),
        )
        cut = first + 1
    for prof in (old, new):
        if cut < prof.phase_start_time_s.size:
            t = min(t, float(prof.phase_start_time_s[cut]))
    moved = np.flatnonzero(old.piece_start_time_s != new.piece_start_time_s)
    if moved.size:
        p = int(moved[0])
        t = min(t, float(old.piece_start_time_s[p]), float(new.piece_start_time_s[p]))
    return t


def _phase_s(t, s0, v0, c2, c3) -> np.ndarray:
    """s(t) [mm] in a phase, t [s] from its start: s0 + t (v0 + t (c2 + t c3)), c2 = a0/2,
    c3 = j/6."""
    return s0 + t * (v0 + t * (c2 + t * c3))


def _below(t, s0, v0, c2, c3, s) -> np.ndarray:
    """s(t) < s in a phase (:func:`_phase_s`)."""
    return _phase_s(t, s0, v0, c2, c3) < s


def _bisect(lo: np.ndarray, hi: np.ndarray, phase: tuple, count: int):
    """``count`` halvings of [lo, hi] [s] towards the first time s(t) ≥ s (``phase``:
    s0, v0, c2, c3, s as :func:`_below`); returns (lo, hi)."""
    for _ in range(count):
        mid = 0.5 * (lo + hi)
        below = _below(mid, *phase)
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return lo, hi


#: Newton steps of :func:`time_at_length`, the relative half-width of the bracket about their
#: result, and the halvings of that bracket (2^-26 · 2^-30: below a float's resolution).
TIME_NEWTON_STEPS = 5
TIME_BRACKET_REL = 2.0**-26
TIME_HALVINGS = 30


#: Halvings of the whole phase where the Newton result gives no bracket (time_at_length).
TIME_WHOLE_HALVINGS = 64


def time_at_length(profile: Profile, s_mm: np.ndarray) -> np.ndarray:
    """Times [s] at which the profile reaches arc lengths ``s_mm`` (first time, each sample
    on its own): :func:`_time_at_length_py`, compiled where :mod:`nurbscnc.plan._kernels`
    was built (the same numbers bit for bit; one loop over the queries instead of hundreds
    of numpy calls)."""
    if _kernels is None or profile.phase_s0_mm.size == 0:
        return _time_at_length_py(profile, s_mm)
    shape = np.shape(s_mm)
    s = as_float64(s_mm).reshape(-1)
    out = np.empty(s.size)
    _kernels.time_at_length(
        *(
            as_float64(c)
            for c in (
                profile.phase_s0_mm,
                profile.phase_v0_mm_s,
                profile.phase_a0_mm_s2,
                profile.phase_jerk_mm_s3,
                profile.phase_duration_s,
                profile.phase_start_time_s,
            )
        ),
        s,
        out,
        TIME_BRACKET_REL,
        TIME_NEWTON_STEPS,
        TIME_HALVINGS,
        TIME_WHOLE_HALVINGS,
    )
    return out.reshape(shape)


def _time_at_length_py(profile: Profile, s_mm: np.ndarray) -> np.ndarray:
    """Times [s] at which the profile reaches arc lengths ``s_mm`` (first time, each sample
    on its own).

    Inside its phase s(t) = s0 + v0 t + a0 t²/2 + j t³/6 is a monotone cubic. Newton steps
    from the phase's mean speed, kept inside a bracket that each step's sign narrows, come
    within rounding in a few steps; the root is then bisected in [t(1 − 2^-26), t(1 + 2^-26)]
    (30 halvings, as the plain bisection of the whole phase would from there) where s at the
    ends of that interval brackets it, else — a flat start or end of a stop, s at a phase
    start — in the whole phase, 64 halvings in all. Within rounding of a 64-halving
    bisection of the whole phase (the tests allow 1 ulp), in about half its time."""
    s = np.asarray(s_mm, dtype=float)
    n = profile.phase_s0_mm.size
    if n == 0:
        return np.zeros_like(s)
    idx = np.clip(np.searchsorted(profile.phase_s0_mm, s, side="right") - 1, 0, n - 1)
    s0 = profile.phase_s0_mm[idx]
    v0 = profile.phase_v0_mm_s[idx]
    c2 = 0.5 * profile.phase_a0_mm_s2[idx]
    c3 = profile.phase_jerk_mm_s3[idx] / 6.0
    dur = profile.phase_duration_s[idx]

    end = _phase_s(dur, 0.0, v0, c2, c3)  # the phase's length
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.where(end > 0.0, dur * ((s - s0) / end), 0.0), 0.0, dur)
    lo, hi = np.zeros_like(s), dur.copy()
    for _ in range(TIME_NEWTON_STEPS):
        f = _phase_s(t, s0, v0, c2, c3) - s
        below = f < 0.0
        lo, hi = np.where(below, t, lo), np.where(below, hi, t)
        speed = v0 + t * (2.0 * c2 + 3.0 * c3 * t)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = t - f / speed
        t = np.where((speed > 0.0) & (step >= lo) & (step <= hi), step, 0.5 * (lo + hi))
    near_lo = np.maximum(t * (1.0 - TIME_BRACKET_REL), 0.0)
    near_hi = np.minimum(t * (1.0 + TIME_BRACKET_REL), dur)
    near = (
        (near_hi > near_lo)
        & _below(near_lo, s0, v0, c2, c3, s)
        & ~_below(near_hi, s0, v0, c2, c3, s)
    )
    lo, hi = _bisect(
        np.where(near, near_lo, 0.0),
        np.where(near, near_hi, dur),
        (s0, v0, c2, c3, s),
        TIME_HALVINGS,
    )
    far = np.flatnonzero(~near)
    if far.size:
        hi[far] = _bisect(
            lo[far],
            hi[far],
            tuple(c[far] for c in (s0, v0, c2, c3, s)),
            TIME_WHOLE_HALVINGS - TIME_HALVINGS,
        )[1]
    return profile.phase_start_time_s[idx] + hi
