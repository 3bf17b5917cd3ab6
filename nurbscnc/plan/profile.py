"""Jerk-limited feed profile over a sequence of pieces, with bidirectional look-ahead.

SPEC §7 (bidirectional scan, S-curve per piece) and §10. Pure 1-D kinematics along the arc
length ``s`` [mm]: a piece is only its length, its cruise cap and the caps at its two ends.

Planning (Python per piece, O(k)):

1. Junction caps: each junction's cap is lowered to the caps of the pieces on both sides
   (the speed is continuous there). The first and last junctions are 0: rest.
2. Backward scan from the program end at rest: ``w_i = min(cap_i, R(w_{i+1}, L_i))``, with
   ``R(v, L)`` the largest speed an S-curve reaches from ``v`` within ``L``
   (:func:`~nurbscnc.plan.feedrate.max_reachable_speed`; the jerk-limited counterpart of
   the ``v² = v0² + 2·A·L`` rule in Klipper's look-ahead over squared velocities).
3. Optional bounded look-ahead of ``N`` pieces: a controller that sees only ``N`` pieces
   ahead must be able to stop at the end of what it sees, so junction ``i`` is also capped by
   the backward scan started at rest at junction ``i + N``; a second backward scan makes the
   lowered caps consistent again.
4. Forward scan from the start at rest: ``v_{i+1} = min(w_{i+1}, R(v_i, L_i))``.
5. Per piece: S-curve up from ``v_i`` to the peak ``v_p`` (the piece cap, or the bisection
   peak of SPEC §7 when the piece is too short to reach it), cruise at ``v_p``, S-curve down
   to ``v_{i+1}``.

Why the scans give a feasible result although ``R`` is *not* monotone in its start speed:
with zero acceleration at both ends, ``D(v0 → v0 + Δv)`` grows with ``v0`` at fixed ``Δv``
(the same jerk ramps, at a higher speed), so a faster start can end slower within the same
length (``dR/dv0 = (2v0 − Δv)/(2v0 + 3Δv)`` while A is not reached); likewise slowing from
``x`` to a full stop can take less distance than slowing to ``x/3``. What the scans need is
only that ``D(lo → hi)`` grows with the *upper* speed ``hi``: a piece of the forward scan
either ends at ``R(v_i)`` (fits by definition), or ends at ``w_{i+1}`` above ``v_i`` (below
``R(v_i)``: fits), or below ``v_i`` with ``v_i ≤ w_i ≤ R(w_{i+1})`` (fits). Every junction is
locally maximal: ``v_i ≥ min(cap_i, R(v_{i−1}, L_{i−1}), R(v_{i+1}, L_i))``, i.e. it cannot be
raised alone. (A lower speed somewhere could, through the non-monotone ``R``, allow a higher
one further on; the scans do not search for that: the result stays safe, not globally
time-optimal.) A float guard in ``R`` and a final repair pass make ``D(v_i → v_{i+1}) ≤ L_i``
hold in floating point too, so every piece has a cruise length ≥ 0.

Planning units (issue 13, :func:`plan_profile`). The scans above run over *planning units*,
not programmed pieces: every S-curve starts and ends at zero acceleration, so a junction of
units is a single speed number and the joints are trivially continuous in ``v`` and ``a``;
but a chain of short pieces planned one by one pays the ``A/J`` jerk ramps at every junction
and never carries acceleration across one (on the 9 mm airfoil, 76 cells of 0.25 mm: 27 ms
of its 0.489 s). So pieces are grouped into units between *planning junctions* — stops,
junction caps below both neighbours' cruise caps (corners), the two ends of each valley of
the cap staircase, and joints whose limits differ by more than :data:`LIMIT_MERGE_RATIO` —
and each unit is planned as one piece with the largest of its pieces' caps and the smallest
of their limits. Between planning junctions the caps rise and fall once, so a unit's speed
(up, cruise, down) can only exceed the cap of a piece on its rising or falling flank; such a
piece is made the end (rising flank) or the start (falling flank) of a unit and the plan is
made again (a few rounds at most in practice; each round adds planning junctions, so it
ends). A piece of a unit thus sees the unit's single S-curve, which passes it below its cap
with non-zero acceleration: the descent into an airfoil's nose is one S-curve from the
cruise down to the nose's cap, ending at the nose with ``a = 0`` (the time-optimal way to
meet a constant cap), instead of a step per cell.

Gated flanks (issue 13). A unit's single S-curve down to its end speed may cross the caps of
a falling staircase (an airfoil's nose fitted in 16 corner cells, 32.5 → 10.5 mm/s; the
cells whose feed the contour check lowered): splitting the unit there ends the deceleration
(a = 0) at every cell it crosses, and the speed sinks below the next caps. Before splitting,
such a flank is planned under *gates* instead (:func:`_gated_rise`): the descent, time
reversed, is a rise from the unit's end speed that must be at or below each piece's cap
where that piece starts (the speed falls monotonically, so that is the piece's largest),
taking the largest jerk of +J, 0, −J that can still brake its acceleration to 0 under every
gate ahead, switch instants solved to 1e-12 s; likewise a rise over a rising staircase
(gates at the piece ends). The unit keeps its end speeds and cruise peak; only its cruise
shortens. A gated flank can lose a few 0.1 µs per gate against an exact S-curve; where it
does not fit its unit, the unit is split as before. On a 58 → 10 mm/s staircase of 16 cells
of 0.1 mm it is 12 ms faster than the split and within 1 ms of the relaxation without the
staircase (tests/test_profile_gated.py).

Per-piece limits (planner v2). Each piece has its own acceleration and jerk limits, and may
have separate ones for its descent (the S-curve from its peak down to its end speed: the
contour check softens the deceleration into a stop without touching the rise). A unit uses
the smallest rise and descent limits of its pieces, so a transition obeys the limits of
every piece it crosses; at a planning junction the acceleration is zero and only the jerk's
sign may change, so both neighbours' limits hold there. The backward scan uses each unit's
descent limits, the forward scan its rise limits, the peak bisection both. The feasibility
argument above is unchanged (it is per unit). Decision: the smallest limit of a unit can be
a little slower than a piece's own larger one where the transition does not cross the
smaller-limit piece; limits that differ by more than a factor 2 keep their junction.

The result, :class:`Profile`, holds the motion exactly: a list of phases of constant jerk,
so ``s(t)`` is a cubic on each; :meth:`Profile.sample` evaluates it for any array of times.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from nurbscnc.errors import ConfigError, PlanningError
from nurbscnc.plan.compiled import kernels as _kernels  # None: the Python loops
from nurbscnc.plan.feedrate import (
    check_limit_arrays,
    check_limits,
    max_reachable_speed,
    max_reachable_speed_scalar,
    peak_speed_unchecked,
    reach_unchecked,
    scurve_distance_mm,
    scurve_timing,
)

__all__ = ["Profile", "ProfileInput", "plan_profile", "plan_profile_pieces"]


def _frozen(values, dtype=float) -> np.ndarray:
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
        number for every piece, or (k,) arrays, one limit per piece (planner v2: the path
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
        length = _frozen(self.length_mm)
        k = length.size
        a, j = _piece_limits(self.a_max_mm_s2, self.j_max_mm_s3, k)
        a_dn = a if self.a_decel_mm_s2 is None else None
        j_dn = j if self.j_decel_mm_s3 is None else None
        if a_dn is None or j_dn is None:
            a_dn, j_dn = _piece_limits(self.a_max_mm_s2 if self.a_decel_mm_s2 is None
                                       else self.a_decel_mm_s2,
                                       self.j_max_mm_s3 if self.j_decel_mm_s3 is None
                                       else self.j_decel_mm_s3, k)  # fmt: skip
        v_max = _frozen(self.v_max_mm_s)
        v_junction = _frozen(self.v_junction_max_mm_s)
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
        return tuple(np.broadcast_to(np.asarray(x, dtype=float), (k,))
                     for x in (self.a_max_mm_s2, self.j_max_mm_s3, self.a_decel_mm_s2,
                               self.j_decel_mm_s3))  # fmt: skip

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
            raise PlanningError(f"{name} must be a number or one per piece ({k},), got "
                                f"shape {x.shape}")  # fmt: skip
    return (_frozen(np.broadcast_to(a, (k,))), _frozen(np.broadcast_to(j, (k,))))


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
_PHASE_COLUMNS = ("phase_duration_s", "phase_s0_mm", "phase_v0_mm_s", "phase_a0_mm_s2",
                  "phase_jerk_mm_s3")  # fmt: skip


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
        t = min(t, float(old.phase_start_time_s[first])
                + float(min(old.phase_duration_s[first], new.phase_duration_s[first])))
        cut = first + 1
    for prof in (old, new):
        if cut < prof.phase_start_time_s.size:
            t = min(t, float(prof.phase_start_time_s[cut]))
    moved = np.flatnonzero(old.piece_start_time_s != new.piece_start_time_s)
    if moved.size:
        p = int(moved[0])
        t = min(t, float(old.piece_start_time_s[p]), float(new.piece_start_time_s[p]))
    return t


def _window_caps(
    cap: np.ndarray, length: np.ndarray, w_back: np.ndarray, n: int, a: np.ndarray,
    j: np.ndarray,
) -> np.ndarray:
    """Stop-within-the-window caps of an ``n``-piece look-ahead, (k+1,) [mm/s].

    Junction ``i`` gets the value at ``i`` of the backward scan started at rest at junction
    ``i + n`` (``inf`` where the window reaches the program end: the full scan covers it).
    All chains step back together, vectorised over ``i``. A chain that becomes *equal* to the
    full backward scan ``w_back`` at some junction (typically both hit the same cap or exact
    stop) runs through the same recurrence from there on, so its answer is ``w_back[i]`` and
    it is dropped early.
    """
    k = length.size
    out = np.full(k + 1, np.inf)
    i = np.arange(1, k - n)  # junctions whose window ends inside the program (i + n < k)
    m = i + n
    w = np.zeros(i.size)
    for _ in range(n):
        if i.size == 0:
            break
        m = m - 1
        w = np.minimum(cap[m], max_reachable_speed(w, length[m], a[m], j[m]))
        same = w == w_back[m]
        if same.any():
            out[i[same]] = w_back[i[same]]
            live = ~same
            i, m, w = i[live], m[live], w[live]
    out[i] = w
    return out


#: Below this many live chains :func:`_chain_scan` finishes each one in plain floats (a numpy
#: step costs tens of µs whatever its size; the scalar closed form about 1 µs a piece).
CHAIN_SCALAR = 24


def _chain_scan(bound: np.ndarray, length: np.ndarray, a: np.ndarray,
                j: np.ndarray) -> np.ndarray:  # fmt: skip
    """The speeds (k+1,) [mm/s] of the recurrence ``y_0 = 0``,
    ``y_{n+1} = min(bound_{n+1}, R(y_n, L_n))`` (``R`` the reach of
    :func:`~nurbscnc.plan.feedrate.max_reachable_speed` with piece n's limits ``a_n, j_n``;
    ``bound_0`` unused): the look-ahead's forward scan, and, on reversed arrays, its
    backward scan.

    Solved by relaxation instead of a Python loop over the pieces: start from ``y = bound``
    and recompute, all at once, every ``y_{n+1}`` whose predecessor changed, until nothing
    changes. After round r the first r speeds are final (induction), so this ends; at the
    end every equation holds, and the recurrence has one solution, so it is the scan's.
    The rounds number the longest run of pieces on one S-curve (a few dozen on CAM
    chords); the last few chains run in plain floats (:data:`CHAIN_SCALAR`).
    """
    k = length.size
    y = np.array(bound, dtype=float)
    y[0] = 0.0
    live = np.arange(k)  # n: y_{n+1} to recompute from y_n
    while live.size > CHAIN_SCALAR:
        new = np.minimum(bound[live + 1], reach_unchecked(y[live], length[live], a[live],
                                                          j[live]))  # fmt: skip
        changed = new != y[live + 1]
        moved = live[changed] + 1
        y[moved] = new[changed]
        live = moved[moved < k]
    if live.size:
        reach = max_reachable_speed_scalar
        yl, bl, ll, al, jl = (x.tolist() for x in (y, bound, length, a, j))
        for n in live.tolist():
            w = yl[n]
            while n < k:
                w = reach(w, ll[n], al[n], jl[n])
                if bl[n + 1] < w:
                    w = bl[n + 1]
                if w == yl[n + 1]:
                    break
                yl[n + 1] = w
                n += 1
        y = np.array(yl)
    return y


def _backward_scan(cap: np.ndarray, length: np.ndarray, a: np.ndarray,
                   j: np.ndarray) -> np.ndarray:  # fmt: skip
    """``w_i = min(cap_i, R(w_{i+1}, L_i))`` from ``w_k = 0``, ``R`` with piece i's descent
    limits ``a[i], j[i]`` (:func:`_chain_scan` on the reversed pieces)."""
    return _chain_scan(cap[::-1], length[::-1], a[::-1], j[::-1])[::-1]


def _transition_distance_mm(v_a, v_b, a, j, a_dn=None, j_dn=None):
    """``D(v_a → v_b)`` [mm] with the rising limits ``a, j`` where ``v_b > v_a``, else the
    descending ones (default: the same)."""
    if a_dn is None:
        return scurve_distance_mm(v_a, v_b, a, j)
    up = v_b > v_a
    return scurve_distance_mm(v_a, v_b, np.where(up, a, a_dn), np.where(up, j, j_dn))


def _repair_junctions(v: np.ndarray, length: np.ndarray, a, j, a_dn=None,
                      j_dn=None) -> np.ndarray:  # fmt: skip
    """Make ``D(v_i → v_{i+1}) ≤ L_i`` hold in floats for every piece (in place; returned).

    The scans satisfy it mathematically and, with the float guard of the reach function,
    almost always in floats too; a rounding step at the A²/J branch switch of ``D`` can leave
    a piece an ulp short. Such a piece gets the higher of its end speeds lowered by a
    doubling number of ulps; a lowered junction re-checks its other piece. ``a, j`` (and
    ``a_dn, j_dn`` for descents, default the same): scalars or (k,) per piece.
    """
    k = length.size
    lims = [np.broadcast_to(np.asarray(x, dtype=float), (k,))
            for x in (a, j, a if a_dn is None else a_dn, j if j_dn is None else j_dn)]
    bad = np.flatnonzero(_transition_distance_mm(v[:-1], v[1:], *lims) > length)
    work = [int(x) for x in bad]
    while work:
        i = work.pop()
        step = 1.0
        li = [float(x[i]) for x in lims]
        while _transition_distance_mm(v[i], v[i + 1], *li) > length[i]:
            hi, lo = (i, i + 1) if v[i] > v[i + 1] else (i + 1, i)
            v[hi] = max(v[lo], v[hi] - step * math.ulp(v[hi]))
            step *= 2.0
            other = i - 1 if hi == i else i + 1  # the other piece that touches junction hi
            if 0 <= other < k:
                work.append(other)
    return v


#: A junction between two pieces whose acceleration or jerk limits differ by more than this
#: ratio (smaller / larger) stays a planning junction; below it the pieces may share one
#: planning unit, planned with the smaller limits (see :func:`plan_profile`).
LIMIT_MERGE_RATIO = 0.5
#: Rounds of :func:`plan_profile` that split one offending piece per unit and flank (the
#: least restrictive choice) before every offender is split at once.
SPLIT_ONE_ROUNDS = 3


def _key_junctions(inp: ProfileInput) -> np.ndarray:
    """(k+1,) bool: the junctions that stay planning junctions (zero acceleration there).

    Both ends; every junction whose own cap is below both neighbouring cruise caps (an exact
    stop, a corner); where the limits of the two pieces differ by more than
    :data:`LIMIT_MERGE_RATIO`; and both ends of every *valley*: a run of equal-cap pieces
    whose neighbouring runs (across junctions that are not already planning junctions) both
    have higher caps. Between two planning junctions the caps then rise and fall once
    (unimodal staircase), so a unit's single S-curve up and single S-curve down meet the
    caps or are split by :func:`_cap_violations`.
    """
    k = inp.piece_count
    c = np.asarray(inp.v_max_mm_s)
    jcap = np.asarray(inp.v_junction_max_mm_s)
    key = np.ones(k + 1, dtype=bool)
    left, right = c[:-1], c[1:]
    inner = jcap[1:-1] >= np.minimum(left, right)
    for x in inp.piece_limits():
        lo, hi = np.minimum(x[:-1], x[1:]), np.maximum(x[:-1], x[1:])
        inner &= lo >= LIMIT_MERGE_RATIO * hi
    key[1:-1] = ~inner
    # Runs of equal caps between planning junctions; a run's neighbour across a planning
    # junction counts as −inf (a run next to a stop is not a valley: the stop's own
    # junction is already a planning junction, and a staircase rising from it is one unit).
    step = key[1:-1] | (left != right)  # junction i+1 separates two runs
    bounds = np.flatnonzero(np.concatenate(([True], step, [True])))  # run boundaries
    run_cap = c[bounds[:-1]]
    n = run_cap.size
    if n < 3:
        return key
    left_cap = np.full(n, -np.inf)
    right_cap = np.full(n, -np.inf)
    soft = ~key[bounds[1:-1]]  # between run r and r+1 with no planning junction
    left_cap[1:] = np.where(soft, run_cap[:-1], -np.inf)
    right_cap[:-1] = np.where(soft, run_cap[1:], -np.inf)
    valley = (left_cap > run_cap) & (right_cap > run_cap)
    key[bounds[:-1][valley]] = True
    key[bounds[1:][valley]] = True
    return key


def plan_profile(inp: ProfileInput) -> Profile:
    """Plan the jerk-limited feed profile of ``inp`` (SPEC §7; see the module docstring).

    Acceleration is carried across the junctions where the path is smooth: pieces are
    grouped into *planning units* between planning junctions (:func:`_key_junctions`:
    stops, corner caps, valleys of the cap staircase, large changes of the limits), each
    unit planned as one piece (S-curve up, cruise, S-curve down; limits the smallest of its
    pieces'; cruise cap the largest of its pieces' caps). A unit whose speed then exceeds
    the cap of one of its pieces gets gated flanks (:func:`_gated_rise`, module docstring)
    where they fit; else it is split at that piece (:func:`_splits`) and the
    whole plan is made again, until every piece's cap holds; each round adds a planning
    junction, so this ends (at worst with every junction one, :func:`plan_profile_pieces`).
    A run of equal caps is one unit from the start, as is an airfoil's descent from its
    cruise into the nose where the S-curve meets the staircase of the nose cells' caps.
    The result is reported per original piece (start times found by inverting s(t) at the
    piece boundaries), so callers never see the grouping.
    """
    k = inp.piece_count
    if k < 2 or inp.lookahead_pieces is not None:
        # A bounded look-ahead counts programmed pieces (a controller's block buffer): keep
        # every piece a planning unit then.
        return plan_profile_pieces(inp)
    key = _key_junctions(inp)
    rounds = 0
    while not key.all():
        profile, split = _plan_units(inp, key, every=rounds >= SPLIT_ONE_ROUNDS)
        if profile is not None:
            return profile
        key |= split
        rounds += 1
    return plan_profile_pieces(inp)


def _plan_units(inp: ProfileInput, key: np.ndarray, every: bool = False,
                gate: bool = True) -> tuple[Profile | None, np.ndarray]:  # fmt: skip
    """The profile with the planning units between the junctions ``key`` (k+1,), reported
    per piece, and the junctions (k+1, bool) that must become planning junctions because a
    unit's speed exceeds one of its pieces' caps (then the profile is None: not valid);
    ``every``: split at every offending piece, not one per unit and flank
    (:func:`_splits`)."""
    k = inp.piece_count
    c = np.asarray(inp.v_max_mm_s)
    jcap = np.asarray(inp.v_junction_max_mm_s)
    first = np.flatnonzero(key[:-1])  # the first piece of each unit
    bounds = np.append(first, k)
    cum = np.concatenate(([0.0], np.cumsum(inp.length_mm)))
    unit_cap = np.maximum.reduceat(c, first)
    jcap_unit = jcap[bounds].copy()
    inner = bounds[1:-1]
    jcap_unit[1:-1] = np.minimum(jcap_unit[1:-1], np.minimum(c[inner - 1], c[inner]))
    if inp.uniform_limits:
        a_up = a_dn = inp.a_max_mm_s2
        j_up = j_dn = inp.j_max_mm_s3
    else:
        a_up, j_up, a_dn, j_dn = (np.minimum.reduceat(x, first) for x in inp.piece_limits())
    unit = plan_profile_pieces(ProfileInput(cum[bounds[1:]] - cum[bounds[:-1]], unit_cap,
                                            jcap_unit, a_up, j_up, a_decel_mm_s2=a_dn,
                                            j_decel_mm_s3=j_dn))  # fmt: skip
    lims = (a_up, j_up, a_dn, j_dn)
    unit_of = np.repeat(np.arange(first.size), np.diff(bounds))
    # Within a unit the speed rises to its peak v_p, cruises over [cruise_from, cruise_to]
    # and falls, so the largest speed on a piece is v_p where the piece touches the cruise,
    # else the larger of its end speeds. Only pieces below their unit's cap can exceed it.
    v_p = unit.piece_peak_speed_mm_s
    d_up = scurve_distance_mm(unit.junction_speeds_mm_s[:-1], v_p, a_up, j_up)
    d_dn = scurve_distance_mm(v_p, unit.junction_speeds_mm_s[1:], a_dn, j_dn)
    low = np.flatnonzero(c < unit_cap[unit_of])
    # Times at which the units' profile reaches every piece boundary (k+1), once per
    # version of it: the offenders read their pieces' ends, the result every piece start
    # (elementwise: the same numbers as asking for each subset).
    at_bounds: list = [None, None]  # (unit profile, its times)

    def bound_times(unit: Profile) -> np.ndarray:
        if at_bounds[0] is not unit:
            at_bounds[:] = [unit, time_at_length(unit, cum)]
        return at_bounds[1]

    def offenders(unit: Profile, d_up: np.ndarray, d_dn: np.ndarray):
        """The pieces whose cap the unit's speed exceeds, and piece_max of the module."""
        cruise_from = cum[bounds[:-1]] + d_up
        cruise_to = cum[bounds[1:]] - d_dn
        lo = np.minimum(cruise_from, cruise_to)
        hi = np.maximum(cruise_from, cruise_to)

        def piece_max(idx: np.ndarray, v_start: np.ndarray, v_end: np.ndarray) -> np.ndarray:
            u = unit_of[idx]
            at_peak = (cum[idx] <= hi[u]) & (cum[idx + 1] >= lo[u])
            return np.where(at_peak, v_p[u], np.maximum(v_start, v_end))

        if not low.size:
            return low, piece_max
        t = bound_times(unit)
        v_ends = unit.sample(np.concatenate((t[low], t[low + 1])))[1]
        over = low[piece_max(low, v_ends[:low.size], v_ends[low.size:])
                   > c[low] * (1.0 + 1e-12)]  # fmt: skip
        return over, piece_max

    over, piece_max = offenders(unit, d_up, d_dn)
    if over.size and gate:
        # Flanks over a staircase of caps follow it (gated flanks) where the unit has room.
        unit, d_up, d_dn = _gate_units(unit, over, c, cum, first, bounds, unit_of, unit_cap,
                                       lims, d_up.copy(), d_dn.copy())  # fmt: skip
        over, piece_max = offenders(unit, d_up, d_dn)
    if over.size:
        return None, _splits(over, c, unit_cap, unit_of, first, k, every)
    piece_start = cum[:-1]
    # Times at which the path reaches each piece start (exact within a unit).
    t_start = bound_times(unit)[:-1].copy()
    t_start[first] = unit.piece_start_time_s
    t_start = np.maximum.accumulate(t_start)
    v_junction = np.empty(k + 1)
    v_junction[:-1] = unit.sample(t_start)[1]
    v_junction[bounds] = unit.junction_speeds_mm_s
    v_piece = piece_max(np.arange(k), v_junction[:-1], v_junction[1:])
    profile = Profile(
        total_length_mm=unit.total_length_mm,
        duration_s=unit.duration_s,
        junction_speeds_mm_s=_frozen(v_junction),
        piece_peak_speed_mm_s=_frozen(np.minimum(v_piece, c)),
        piece_start_mm=_frozen(piece_start),
        piece_start_time_s=_frozen(t_start),
        phase_start_time_s=unit.phase_start_time_s,
        phase_duration_s=unit.phase_duration_s,
        phase_s0_mm=unit.phase_s0_mm,
        phase_v0_mm_s=unit.phase_v0_mm_s,
        phase_a0_mm_s2=unit.phase_a0_mm_s2,
        phase_jerk_mm_s3=unit.phase_jerk_mm_s3,
        phase_piece_index=_frozen(first[unit.phase_piece_index], dtype=np.int64),
    )
    return profile, np.zeros(k + 1, dtype=bool)


def _splits(over: np.ndarray, c: np.ndarray, unit_cap: np.ndarray, unit_of: np.ndarray,
            first: np.ndarray, k: int, every: bool = False) -> np.ndarray:  # fmt: skip
    """The junctions (k+1, bool) that become planning junctions for the pieces ``over``
    whose cap their unit's speed exceeds.

    A piece before its unit's first piece at the unit's cap (on the rise) ends its unit
    there (v ≤ its cap at that junction, a = 0); a piece after the last one (on the
    descent) starts a unit. Either way it then lies in a unit whose caps are all ≤ its own
    (the unit's caps rise, then fall). One split per unit and side per round, the one
    nearest the end that side approaches (the rise's first offender, the descent's last):
    its planning junction often clears the other offenders of that side. With ``every``
    (after :data:`SPLIT_ONE_ROUNDS` rounds: a long smooth staircase would otherwise take a
    round per step) every offender is split at once.
    """
    idx = np.arange(k)
    is_top = c == unit_cap[unit_of]
    top_first = np.minimum.reduceat(np.where(is_top, idx, k), first)[unit_of]
    top_last = np.maximum.reduceat(np.where(is_top, idx, -1), first)[unit_of]
    rise = over[over < top_first[over]]
    fall = over[over > top_last[over]][::-1]
    if not every:
        rise = rise[np.unique(unit_of[rise], return_index=True)[1]]
        fall = fall[np.unique(unit_of[fall], return_index=True)[1]]
    if not (rise.size or fall.size):
        raise PlanningError("feed profile: a piece at its unit's cap exceeds it (rounding)")
    split = np.zeros(k + 1, dtype=bool)
    split[rise + 1] = True
    split[fall] = True
    return split


#: Time step [s] of the gated flanks' jerk choice (:func:`_gated_rise`): 0.1 ms, a tenth
#: of a servo period; the loss against the continuous optimum is of that order per gate.
GATE_STEP_S = 1e-4
#: Shortest switch step [s] of a gated flank (:func:`_longest`).
GATE_MIN_STEP_S = 1e-7
#: Most steps of one gated flank (a rise of 10 s at 0.1 ms); beyond it the unit is split.
GATE_MAX_STEPS = 100_000
#: Most :data:`GATE_STEP_S` steps of +J taken as one (:func:`_gated_rise`'s galloping).
GATE_GALLOP = 64


def _brake_ok(x: float, v: float, a: float, j: float, gate_d: list, gate_c: list,
              first: int) -> bool:  # fmt: skip
    """Whether braking the acceleration ``a`` ≥ 0 at once (jerk −j until a = 0, then
    cruising) from position ``x`` [mm] at speed ``v`` passes every gate from ``first`` on:
    v(gate_d[m]) ≤ gate_c[m]. During the brake v = v + a t − j t²/2 rises to
    v + a²/(2j); a gate of cap c with v ≤ c < v + a²/(2j) is passed in time if the brake
    reaches speed c, at t_c = (a − √(a² − 2j(c − v)))/j, no earlier than the gate:
    x(t_c) ≥ d."""
    v_end = v + a * a / (2.0 * j)
    for m in range(first, len(gate_d)):
        c = gate_c[m]
        if c >= v_end:
            continue
        if v > c:
            return False
        t_c = (a - math.sqrt(max(a * a - 2.0 * j * (c - v), 0.0))) / j
        if x + t_c * (v + t_c * (0.5 * a - t_c * j / 6.0)) < gate_d[m]:
            return False
    return True


def _longest(ok, tau: float) -> float:
    """The longest step in [0, ``tau``] [s] that ``ok`` accepts: ``tau`` itself, else found
    by bisection (to 1e-12 s; feasibility falls with the step), 0 when even
    :data:`GATE_MIN_STEP_S` fails (no endless creeping along a gate's boundary).
    An exact switch inside a step makes a flank touch its gates instead of turning a step
    early (a staircase 58 → 12 mm/s then met within 1e-9 s of the exact S-curve)."""
    if ok(tau):
        return tau
    if not ok(GATE_MIN_STEP_S):
        return 0.0
    lo, hi = GATE_MIN_STEP_S, tau
    while hi - lo > 1e-12:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def _gated_rise(v0: float, v_top: float, gate_d, gate_c, a_max: float, j_max: float,
                dt: float = GATE_STEP_S):  # fmt: skip
    """:func:`_gated_rise_py`, compiled where :mod:`nurbscnc.plan._kernels` was built (the
    same numbers bit for bit; a flank of a few hundred steps in ~10 µs instead of ~1 ms)."""
    if _kernels is None:
        return _gated_rise_py(v0, v_top, gate_d, gate_c, a_max, j_max, dt)
    return _kernels.gated_rise(float(v0), float(v_top), _float64(gate_d), _float64(gate_c),
                               float(a_max), float(j_max), float(dt), GATE_MIN_STEP_S,
                               GATE_GALLOP, GATE_MAX_STEPS)  # fmt: skip


def _float64(x) -> np.ndarray:
    """``x`` as a C-contiguous float64 array (the compiled kernels read its bytes)."""
    return np.ascontiguousarray(x, dtype=np.float64)


def _gated_rise_py(v0: float, v_top: float, gate_d, gate_c, a_max: float, j_max: float,
                   dt: float = GATE_STEP_S):  # fmt: skip
    """A rise from (``v0``, a = 0) to (``v_top``, a = 0) under *gates*: at distance
    ``gate_d[m]`` [mm] from the start (increasing) the speed must be ≤ ``gate_c[m]`` [mm/s],
    with |a| ≤ ``a_max``, |j| ≤ ``j_max``, the speed never falling (a ≥ 0).

    This is the flank of a planning unit over a staircase of caps (issue 13): a rising
    staircase read forwards, or a falling one read backwards (the descent into an airfoil's
    nose, time reversed: jerk keeps its sign, acceleration flips). The speed is non-decreasing,
    so on each piece it is largest at the piece's far end, the gate: a rise that meets every
    gate stays under every cap, without ending its acceleration at each of them (the unit
    split does: a = 0 at every cell).

    Greedy in time steps of ``dt`` (the jerk is piecewise constant, so every step is exact):
    the largest jerk of +J, 0, −J whose new state can still brake its acceleration to 0
    without exceeding ``v_top`` (v + a²/(2J) ≤ v_top) or any gate ahead (:func:`_brake_ok`);
    the target is met exactly by solving for the switch time inside the last step.

    Two shortcuts take the same steps (up to rounding), as feasibility falls with the step
    (the premise of :func:`_longest`). Galloping: after a full +J step, n = 2, 4, … up to
    :data:`GATE_GALLOP` steps of +J are tried as one while none of them could be the last
    rise (a₁ = √(J(v_top − v) + a²/2) is constant under +J, so the step whose end would
    start it is known) nor pass A; if the n-step passes, each of its steps would have.
    While braking, the +J and hold tries test their shortest step first: it fails as long
    as the brake goes on, and then so would the full step.

    Returns (durations, jerks, distance) — lists of the constant-jerk phases [s], [mm/s³]
    and the distance covered [mm] — or None when no such rise exists (a gate below ``v0``,
    or too many steps).
    """
    j, big_a = j_max, a_max
    gate_d, gate_c = [float(d) for d in gate_d], [float(c) for c in gate_c]
    x, v, a = 0.0, float(v0), 0.0
    durs: list = []
    jerks: list = []
    first = 0
    tol = v_top * 1e-12

    def advance(tau, jk):
        return (x + tau * (v + tau * (0.5 * a + tau * jk / 6.0)),
                v + tau * (a + 0.5 * tau * jk), a + tau * jk)  # fmt: skip

    def passes(x1, v1, a1):
        """The state after a step: the gates crossed in it (v non-decreasing: v1 is the
        largest), then the brake from it."""
        m = first
        while m < len(gate_d) and gate_d[m] <= x1:
            if v1 > gate_c[m] * (1.0 + 1e-12):
                return False
            m += 1
        return _brake_ok(x1, v1, a1, j, gate_d, gate_c, m)

    def finish(phases):
        """Try ending with ``phases`` [(τ, jerk), …] (the last brakes a to 0 at v_top)."""
        xs, vs, as_ = x, v, a
        for tau, jk in phases[:-1]:
            xs, vs, as_ = (xs + tau * (vs + tau * (0.5 * as_ + tau * jk / 6.0)),
                           vs + tau * (as_ + 0.5 * tau * jk), as_ + tau * jk)  # fmt: skip
        return passes(xs, vs, as_)

    def longest(jk, tau):
        """:func:`_longest` of the step with jerk ``jk``; while braking, the shortest step
        first (class doc)."""
        ok = lambda t: passes(*advance(t, jk))  # noqa: E731
        if braking and not ok(GATE_MIN_STEP_S):
            return 0.0
        return _longest(ok, tau)

    steps, streak, braking = 0, 0, False  # streak: dt steps of the last +J step, if full
    while steps < GATE_MAX_STEPS:
        steps += 1
        while first < len(gate_d) and gate_d[first] <= x:
            first += 1
        if a <= 0.0 and v >= v_top - tol:
            return durs, jerks, x
        done = None
        if a < big_a:  # +J, possibly the last rise before the brake into v_top
            a1 = math.sqrt(j * max(v_top - v, 0.0) + 0.5 * a * a)
            if a1 <= min(a + j * dt, big_a):
                phases = [((a1 - a) / j, j), (a1 / j, -j)]
                if finish(phases):
                    done = phases
            else:
                # Galloping: n steps, none of whose ends starts the last rise (that of step
                # k does once a + (k + 1) J dt ≥ a₁; one step of margin) or passes A.
                n = min(2 * streak, GATE_GALLOP, int((big_a - a) / (j * dt)),
                        math.ceil((a1 - a) / (j * dt)) - 2 if a1 <= big_a else GATE_GALLOP,
                        GATE_MAX_STEPS - steps + 1)  # fmt: skip
                if n >= 2 and passes(*advance(n * dt, j)):
                    tau, steps = n * dt, steps + n - 1
                else:
                    n, tau = 1, longest(j, min(dt, (big_a - a) / j))
                if tau > 0.0:
                    streak, braking = (n if tau == n * dt else 0), False
                    durs.append(tau)
                    jerks.append(j)
                    x, v, a = advance(tau, j)
                    continue
        streak = 0
        if done is None and a > 0.0:  # hold a, possibly until the brake into v_top
            t0 = (v_top - v - a * a / (2.0 * j)) / a
            if t0 <= dt:
                phases = [(max(t0, 0.0), 0.0), (a / j, -j)]
                if finish(phases):
                    done = phases
            else:
                tau = longest(0.0, dt)
                if tau > 0.0:
                    braking = False
                    durs.append(tau)
                    jerks.append(0.0)
                    x, v, a = advance(tau, 0.0)
                    continue
        if done is not None:
            for tau, jk in done:
                if tau > 0.0:
                    durs.append(tau)
                    jerks.append(jk)
                    x, v, a = advance(tau, jk)
            return durs, jerks, x
        if a > 0.0:  # brake: feasible since the last step's check
            braking = True
            t_b = a / j
            tau = min(dt, t_b)
            x, v, a = advance(tau, -j)
            if tau >= t_b or a < 1e-12 * big_a:
                a = 0.0
            durs.append(tau)
            jerks.append(-j)
            continue
        # a = 0 and a gate ahead at the speed v: cruise at v just past it (riding its cap).
        if first >= len(gate_d) or v <= 0.0 or v > gate_c[first] * (1.0 + 1e-12):
            return None
        tau = (gate_d[first] - x) / v * (1.0 + 1e-12) + 1e-15
        durs.append(tau)
        jerks.append(0.0)
        x, v, a = advance(tau, 0.0)
    return None


def _merged(durs: list, jerks: list) -> tuple[list, list]:
    """Consecutive phases of equal jerk as one (the cubic continues: exact)."""
    out_d: list = []
    out_j: list = []
    for d, jk in zip(durs, jerks, strict=True):
        if d <= 0.0:
            continue
        if out_j and out_j[-1] == jk:
            out_d[-1] += d
        else:
            out_d.append(d)
            out_j.append(jk)
    return out_d, out_j


def _scurve_phases(tj: float, tc: float, rising: bool, j: float) -> tuple[list, list]:
    """The constant-jerk phases (durations [s], jerks [mm/s³]) of an S-curve (SPEC §7) with
    jerk phases ``tj`` [s] and constant acceleration ``tc`` [s] (:func:`scurve_timing`, for
    all units at once), read from rest of acceleration to rest of acceleration."""
    sign = 1.0 if rising else -1.0
    return _merged([tj, tc, tj], [sign * j, 0.0, -sign * j])


def _rows(durs: list, jerks: list, s0: float, v0: float) -> tuple[np.ndarray, float]:
    """(n, 5) rows (duration, jerk, a0, v0, s0) of phases started at rest of acceleration
    at ``s0`` [mm], ``v0`` [mm/s], integrated exactly (cubics), and the end position [mm]
    (the flank's distance is taken from this very sum, so the unit's phases meet to the
    last ulp: a position jump of 1e-12 mm shows as 10 mm/s³ in a 50 µs finite difference)."""
    rows = np.empty((len(durs), 5))
    s, v, a = s0, v0, 0.0
    a_scale = 0.0
    for i, (d, jk) in enumerate(zip(durs, jerks, strict=True)):
        rows[i] = (d, jk, a, v, s)
        s, v, a = (s + d * (v + d * (0.5 * a + d * jk / 6.0)), v + d * (a + 0.5 * d * jk),
                   a + d * jk)  # fmt: skip
        # A braked acceleration is 0, not the rounding of Σ jerk·duration (2e-12 mm/s²
        # held over a 500 s cruise would raise the speed by 1e-9 mm/s).
        a_scale = max(a_scale, abs(a))
        if abs(a) <= 1e-9 * a_scale:
            a = 0.0
    return rows, s


#: Fewest gates (capped pieces on a flank) for a gated flank (:func:`_gated_rise`, a Python
#: loop in 0.1 ms steps, ~1 ms a flank): a staircase. A flank under one lower cap keeps the
#: split at that piece (a = 0 there), as before gating: on a 200k-line G1 spiral every one
#: of its 160k flanks had one gate, and gating them tripled the run time for no measurable
#: gain; the nose of the 9 mm airfoil has 8–13 gates per flank.
MIN_GATES = 2


def _gated_rise_of(v0: float, v1: float, gates_mm: np.ndarray, caps_mm_s: np.ndarray,
                   a: float, j: float):
    """:func:`_gated_rise`, remembered: the check re-plans the profile 5–10 times and each
    plan splits its units several times, asking for the same flanks again (a 20k-line CAM
    spiral: 26 flanks asked 1052 times). A pure function of its numbers, so the memo changes
    no result; bounded (:data:`GATED_MEMO`). Returns (phases as a rise, phases read
    backwards for a descent, distance [mm]), each phase list merged (:func:`_merged`; a
    gated flank has hundreds of 0.1 ms steps: merging them at every ask cost 2 s of a 20 s
    `run`), or None."""
    return _gated_rise_memo(float(v0), float(v1), np.ascontiguousarray(gates_mm, float).tobytes(),
                            np.ascontiguousarray(caps_mm_s, float).tobytes(), float(a), float(j))


#: Flanks remembered by :func:`_gated_rise_of` (each a few kB).
GATED_MEMO = 4096


@functools.lru_cache(maxsize=GATED_MEMO)
def _gated_rise_memo(v0, v1, gates_b: bytes, caps_b: bytes, a, j):
    if _kernels is not None:  # the flank and its merging compiled (the same floats)
        got = _kernels.gated_rise_merged(float(v0), float(v1), gates_b, caps_b, float(a),
                                         float(j), GATE_STEP_S, GATE_MIN_STEP_S, GATE_GALLOP,
                                         GATE_MAX_STEPS)  # fmt: skip
        if got is None:
            return None
        return (tuple(got[0]), tuple(got[1])), (tuple(got[2]), tuple(got[3])), got[4]
    result = _gated_rise(v0, v1, np.frombuffer(gates_b), np.frombuffer(caps_b), a, j)
    if result is None:
        return None
    durs, jerks, distance = result
    # Shared by every caller: immutable. The descent merges the reversed steps (its own
    # sums, in its own order: the same bits as merging at the caller).
    rise = tuple(map(tuple, _merged(durs, jerks)))
    fall = tuple(map(tuple, _merged(durs[::-1], jerks[::-1])))
    return rise, fall, distance


def _per_unit(unit: np.ndarray, values: np.ndarray, reduce) -> tuple[np.ndarray, np.ndarray]:
    """The distinct ``unit`` numbers (sorted) and ``reduce`` (a ufunc: np.minimum, …) of the
    ``values`` of each."""
    order = np.argsort(unit, kind="stable")
    u = unit[order]
    starts = np.flatnonzero(np.r_[True, u[1:] != u[:-1]])
    return u[starts], reduce.reduceat(values[order], starts)


def _gate_units(unit: Profile, over: np.ndarray, c: np.ndarray, cum: np.ndarray,
                first: np.ndarray, bounds: np.ndarray, unit_of: np.ndarray,
                unit_cap: np.ndarray, lims, d_up: np.ndarray,
                d_dn: np.ndarray) -> tuple[Profile, np.ndarray, np.ndarray]:  # fmt: skip
    """The unit profile with *gated flanks* (:func:`_gated_rise`) in the units whose speed
    exceeds the caps ``c`` of the pieces ``over``: a rising flank under the caps of the
    pieces before the unit's first piece at its cap (each a gate at the piece's end), a
    falling flank under those after its last one (gates at the piece starts, planned time
    reversed). The unit keeps its end speeds and peak; it is gated only if both flanks fit
    in its length (else its offenders stay for :func:`_splits`). ``d_up``, ``d_dn``
    (units,): the units' rise and descent distances [mm], updated in place where gated.
    Returns the profile (per unit) and those distances."""
    a_up, j_up, a_dn, j_dn = (np.broadcast_to(np.asarray(x, dtype=float), (first.size,))
                              for x in lims)  # fmt: skip
    v_s, v_e = unit.junction_speeds_mm_s[:-1], unit.junction_speeds_mm_s[1:]
    v_p = unit.piece_peak_speed_mm_s
    # Every unit's S-curve phase times at once (elementwise IEEE operations: the same bits as
    # one unit at a time, without a numpy call per unit and flank).
    tj_up, tc_up, _ = scurve_timing(v_s, v_p, a_up, j_up)
    tj_dn, tc_dn, _ = scurve_timing(v_p, v_e, a_dn, j_dn)
    idx = np.arange(c.size)
    is_top = c == unit_cap[unit_of]
    top_first = np.minimum.reduceat(np.where(is_top, idx, c.size), first)
    top_last = np.maximum.reduceat(np.where(is_top, idx, -1), first)
    phase_rows = {}
    # The offenders' first and last piece per unit (one pass; not a scan of ``over`` per unit).
    units, o_min = _per_unit(unit_of[over], over, np.minimum)
    _, o_max = _per_unit(unit_of[over], over, np.maximum)
    for u, lo_over, hi_over in zip(units.tolist(), o_min.tolist(), o_max.tolist(), strict=True):
        lo, hi = int(bounds[u]), int(bounds[u + 1])  # pieces lo … hi − 1
        n_pre = min(int(top_first[u]), hi) - lo
        n_post = hi - max(int(top_last[u]) + 1, lo)
        gate_pre = lo_over < top_first[u] and n_pre >= MIN_GATES
        gate_post = hi_over > top_last[u] and n_post >= MIN_GATES
        if not (gate_pre or gate_post):  # nothing to gate: the unit is split as before
            continue
        s_a, s_b = cum[lo], cum[hi]
        vs, vp, ve = float(v_s[u]), float(v_p[u]), float(v_e[u])
        rise = _scurve_phases(float(tj_up[u]), float(tc_up[u]), vp >= vs, j_up[u])
        fall = _scurve_phases(float(tj_dn[u]), float(tc_dn[u]), ve >= vp, j_dn[u])
        du, dd = float(d_up[u]), float(d_dn[u])
        pre = np.arange(lo, lo + n_pre)
        post = np.arange(hi - n_post, hi)[::-1]
        ok = True
        if gate_pre:
            g = _gated_rise_of(vs, vp, cum[pre + 1] - s_a, c[pre], a_up[u], j_up[u])
            ok = g is not None
            if ok:
                rise, du = g[0], g[2]
        if ok and gate_post:
            g = _gated_rise_of(ve, vp, s_b - cum[post], c[post], a_dn[u], j_dn[u])
            ok = g is not None
            if ok:
                fall, dd = g[1], g[2]
        if not ok or du + dd > (s_b - s_a) * (1.0 + 1e-12):
            continue
        up_rows, up_end = _rows(*rise, s_a, vs)
        dn_rows, dd = _rows(*fall, 0.0, vp)
        du = up_end - s_a
        if du + dd > (s_b - s_a) * (1.0 + 1e-12):
            continue
        cruise = max(s_b - s_a - du - dd, 0.0)
        dn_rows[:, 4] += s_b - dd
        mid = np.array([[cruise / vp if vp > 0 else 0.0, 0.0, 0.0, vp, s_a + du]])
        rows = np.concatenate((up_rows, mid if cruise > 0.0 else mid[:0], dn_rows))
        phase_rows[u] = rows
        d_up[u], d_dn[u] = du, dd
    if not phase_rows:
        return unit, d_up, d_dn
    # Every unit's phases, the gated ones replaced; times re-accumulated.
    pu = unit.phase_piece_index
    old = np.column_stack((unit.phase_duration_s, unit.phase_jerk_mm_s3, unit.phase_a0_mm_s2,
                           unit.phase_v0_mm_s, unit.phase_s0_mm))  # fmt: skip
    parts, owner = [], []
    for u in range(first.size):
        rows = phase_rows.get(u)
        if rows is None:
            rows = old[pu == u]
        parts.append(rows)
        owner.append(np.full(rows.shape[0], u, dtype=np.int64))
    rows = np.concatenate(parts)
    owner = np.concatenate(owner)
    t0 = np.concatenate(([0.0], np.cumsum(rows[:, 0])))
    unit_t = t0[np.searchsorted(owner, np.arange(first.size), side="left")]
    gated = Profile(
        total_length_mm=unit.total_length_mm, duration_s=float(t0[-1]),
        junction_speeds_mm_s=unit.junction_speeds_mm_s,
        piece_peak_speed_mm_s=unit.piece_peak_speed_mm_s,
        piece_start_mm=unit.piece_start_mm, piece_start_time_s=_frozen(unit_t),
        phase_start_time_s=_frozen(t0[:-1]), phase_duration_s=_frozen(rows[:, 0]),
        phase_s0_mm=_frozen(rows[:, 4]), phase_v0_mm_s=_frozen(rows[:, 3]),
        phase_a0_mm_s2=_frozen(rows[:, 2]), phase_jerk_mm_s3=_frozen(rows[:, 1]),
        phase_piece_index=_frozen(owner, dtype=np.int64))  # fmt: skip
    return gated, d_up, d_dn


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
    was built (the same numbers bit for bit, one loop over the queries instead of ~400
    numpy calls: 0.4 ms → 0.03 ms for an airfoil's 500 piece boundaries)."""
    if _kernels is None or profile.phase_s0_mm.size == 0:
        return _time_at_length_py(profile, s_mm)
    shape = np.shape(s_mm)
    s = _float64(s_mm).reshape(-1)
    out = np.empty(s.size)
    _kernels.time_at_length(*(_float64(c) for c in (
        profile.phase_s0_mm, profile.phase_v0_mm_s, profile.phase_a0_mm_s2,
        profile.phase_jerk_mm_s3, profile.phase_duration_s, profile.phase_start_time_s)),
        s, out, TIME_BRACKET_REL, TIME_NEWTON_STEPS, TIME_HALVINGS,
        TIME_WHOLE_HALVINGS)  # fmt: skip
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
    bisection of the whole phase (on 240,000 random queries the same floats; the tests allow
    1 ulp), in half its time (the 200,000-line spiral's 240,000 piece starts: 0.19 →
    0.10 s)."""
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
    near = ((near_hi > near_lo) & _below(near_lo, s0, v0, c2, c3, s)
            & ~_below(near_hi, s0, v0, c2, c3, s))  # fmt: skip
    lo, hi = _bisect(np.where(near, near_lo, 0.0), np.where(near, near_hi, dur),
                     (s0, v0, c2, c3, s), TIME_HALVINGS)  # fmt: skip
    far = np.flatnonzero(~near)
    if far.size:
        hi[far] = _bisect(lo[far], hi[far], tuple(c[far] for c in (s0, v0, c2, c3, s)),
                          TIME_WHOLE_HALVINGS - TIME_HALVINGS)[1]  # fmt: skip
    return profile.phase_start_time_s[idx] + hi


def plan_profile_pieces(inp: ProfileInput) -> Profile:
    """Plan with every piece boundary a junction of zero acceleration (the scans below).

    Cost O(k) Python steps for the two scans plus vectorised numpy for the peaks (bisection)
    and the phases; a bounded look-ahead adds O(k·N) vectorised work at worst.
    """
    a, j, a_dn, j_dn = inp.piece_limits()  # (k,) each: rise and descent limits per piece
    length = np.array(inp.length_mm)
    v_max = np.array(inp.v_max_mm_s)
    k = length.size

    # 1. Junction caps, lowered to the neighbouring pieces' cruise caps.
    cap = np.array(inp.v_junction_max_mm_s)
    cap[:-1] = np.minimum(cap[:-1], v_max)
    cap[1:] = np.minimum(cap[1:], v_max)

    # 2. Backward scan from the end at rest.
    w_back = _backward_scan(cap, length, a_dn, j_dn)

    # 3. Bounded look-ahead: cap by the stop-within-the-window speeds, then rescan so that
    #    the caps are backward-consistent again (w_i ≤ R(w_{i+1}, L_i)), which is what makes
    #    the forward scan's result feasible (R is not monotone in its start speed: module doc).
    n = inp.lookahead_pieces
    if n is not None and n < k:
        cap = np.minimum(cap, _window_caps(cap, length, w_back, n, a_dn, j_dn))
        w_back = _backward_scan(cap, length, a_dn, j_dn)

    # 4. Forward scan from the start at rest.
    v = _repair_junctions(_chain_scan(w_back, length, a, j), length, a, j, a_dn, j_dn)

    # 5. Per piece: peak speed, then the seven phases.
    v_s, v_e = v[:-1], v[1:]
    v_p = peak_speed_unchecked(v_s, v_e, length, v_max, a, j, a_dn, j_dn)
    tj1, tc1, ap1 = scurve_timing(v_s, v_p, a, j)
    tj2, tc2, ap2 = scurve_timing(v_p, v_e, a_dn, j_dn)
    d_acc = scurve_distance_mm(v_s, v_p, a, j)
    d_dec = scurve_distance_mm(v_p, v_e, a_dn, j_dn)
    cruise = np.maximum(length - d_acc - d_dec, 0.0)  # ≥ 0 up to an ulp, by the bisection
    if np.any((cruise > 0.0) & (v_p <= 0.0)):
        raise PlanningError("a piece has length but no reachable speed (length underflow)")
    with np.errstate(divide="ignore", invalid="ignore"):
        t_cr = np.where(cruise > 0.0, cruise / v_p, 0.0)

    bounds = np.concatenate(([0.0], np.cumsum(length)))
    start, end = bounds[:-1], bounds[1:]
    half_j1 = 0.5 * j * tj1 * tj1
    half_j2 = 0.5 * j_dn * tj2 * tj2
    sixth_j1 = j * tj1**3 / 6.0
    sixth_j2 = j_dn * tj2**3 / 6.0
    zero = np.zeros(k)
    dur = np.stack([tj1, tc1, tj1, t_cr, tj2, tc2, tj2], axis=1)
    jerk = np.stack([j, zero, -j, zero, -j_dn, zero, j_dn], axis=1)
    a0 = np.stack([zero, ap1, ap1, zero, zero, -ap2, -ap2], axis=1)
    v0 = np.stack([v_s, v_s + half_j1, v_p - half_j1, v_p, v_p, v_p - half_j2, v_e + half_j2], 1)
    # Positions are anchored at both ends of the piece (the S-curves' closed-form distances),
    # not accumulated, so each piece ends exactly where the next begins. Phase distances:
    # jerk ramp up from v_s: v_s·t + J·t³/6; ramp down into v_p: v_p·t − J·t³/6 (and the
    # mirror images for the deceleration).
    s0 = np.stack(
        [
            start,
            start + (v_s * tj1 + sixth_j1),
            start + d_acc - (v_p * tj1 - sixth_j1),
            start + d_acc,
            end - d_dec,
            end - d_dec + (v_p * tj2 - sixth_j2),
            end - (v_e * tj2 + sixth_j2),
        ],
        axis=1,
    )
    # Times: cumulative sums, so phase starts never decrease (a piece's last phase start is
    # ≤ its end because the row cumsum only adds non-negative durations).
    t_in_piece = np.cumsum(dur, axis=1)
    piece_dur = t_in_piece[:, -1]
    piece_end_time = np.cumsum(piece_dur)
    piece_start_time = np.concatenate(([0.0], piece_end_time[:-1]))
    offsets = np.concatenate((np.zeros((k, 1)), t_in_piece[:, :-1]), axis=1)
    t0 = piece_start_time[:, None] + offsets

    keep = (dur > 0.0).ravel()
    piece_idx = np.repeat(np.arange(k, dtype=np.int64), 7)
    return Profile(
        total_length_mm=float(bounds[-1]),
        duration_s=float(piece_end_time[-1]),
        junction_speeds_mm_s=_frozen(v),
        piece_peak_speed_mm_s=_frozen(v_p),
        piece_start_mm=_frozen(start),
        piece_start_time_s=_frozen(piece_start_time),
        phase_start_time_s=_frozen(t0.ravel()[keep]),
        phase_duration_s=_frozen(dur.ravel()[keep]),
        phase_s0_mm=_frozen(s0.ravel()[keep]),
        phase_v0_mm_s=_frozen(v0.ravel()[keep]),
        phase_a0_mm_s2=_frozen(a0.ravel()[keep]),
        phase_jerk_mm_s3=_frozen(jerk.ravel()[keep]),
        phase_piece_index=_frozen(piece_idx[keep], dtype=np.int64),
    )
