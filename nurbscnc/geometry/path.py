"""The path model: every piece of a toolpath in one column table.

One kind enum (:class:`Kind`) and one table (:class:`PathTable`, one row a piece, numpy
columns) own the geometry of the planned path: lines, circular arcs and helices, spiral arcs
(radius changing along the arc), PH quintics (corner fits and G64 blends, SPEC §4) and NURBS
spans (SPEC §2). Everything that samples the path — the planner's pieces and dynamics check,
the interpolator, the lower bound, the plots — asks this table, many arc lengths at once:

- :meth:`PathTable.points` — points [mm] and parameters at arc lengths from the piece starts;
- :meth:`PathTable.points_at_fraction` — points at fractions of the parameter range;
- :meth:`PathTable.params` — arc length → own parameter;
- :meth:`PathTable.tangents`, :meth:`PathTable.curvature` — unit tangents and κ [1/mm].

Everything at the interface is real-valued 3-D: a PH quintic, complex in its plane
(:class:`~nurbscnc.geometry.ph.PHQuintic`), enters the table as the power coefficients of its
plane coordinates x(ξ), y(ξ) and of its arc length s(ξ), with its plane frame (origin, e1, e2).

Parameters: lines, circular arcs and helices use u = s (closed forms); PH pieces ξ ∈ [0, 1]
found by Newton on the polynomial arc length (SPEC §4, eq. 10–12); NURBS pieces the curve
parameter u via the curve's quintic Hermite inversion table (SPEC §10); spiral arcs by Newton
on their closed-form arc length (paths.py). Per-sample work is whole-array numpy over all rows
of one kind at once; the Python loops run over kinds, curves and cache-sized blocks of samples.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from functools import cached_property
from math import comb

import numpy as np
from numpy.polynomial import polynomial as npoly

from nurbscnc.geometry import segments
from nurbscnc.geometry.distinct import distinct
from nurbscnc.geometry.powerform import BLOCK

#: Program segment kinds that do not move X Y Z: the tool stops at rest there (a dwell holds
#: for its ``seconds``; a pause, M0/M1/M60, is a stop of zero duration that the operator ends;
#: a rotate holds while the rotary axes turn, for the time the planner gives it).
STOP_KINDS = ("dwell", "pause", "rotate")


def stop_seconds(segment) -> float:
    """How long a stop segment holds [s] (0 for a pause, or any segment without ``seconds``)."""
    return float(getattr(segment, "seconds", 0.0))


class Kind(IntEnum):
    """The kind of a piece of path (the one numbering; ``PathTable.kind`` holds these)."""

    LINE = 0
    ARC = 1  # circular arc or helix (constant radius): closed form, u = s
    SPIRAL = 2  # arc whose radius changes along it: closed-form arc length, Newton inverse
    PH = 3  # planar PH quintic in 3-D (SPEC §4)
    NURBS = 4  # a span [u_a, u_b] of a NURBS curve (SPEC §2)


# ---------------------------------------------------------------------------------------------
# Polynomial helpers (PH pieces): Bernstein → centred power basis, Horner per row
# ---------------------------------------------------------------------------------------------


def centred_bernstein_matrix(n: int) -> np.ndarray:
    """M (n+1, n+1) with B_i^n(½ + x) = Σ_k M[i, k] x^k: Bernstein → power basis about ξ = ½.

    The entries are dyadic rationals, exact in floating point. Centred monomials on
    x ∈ [−½, ½] keep the PH polynomials' power coefficients small (well conditioned)."""
    m = np.zeros((n + 1, n + 1))
    for i in range(n + 1):
        poly = npoly.polymul(npoly.polypow([0.5, 1.0], i), npoly.polypow([0.5, -1.0], n - i))
        m[i, : poly.size] = comb(n, i) * poly
    m.setflags(write=False)
    return m


#: Bernstein → centred power basis for degree 4 (σ) and 5 (points, s) of a PH quintic.
BERNSTEIN4, BERNSTEIN5 = centred_bernstein_matrix(4), centred_bernstein_matrix(5)


def horner_rows(coeffs: np.ndarray, i: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Σ_k coeffs[k, i] x^k (coeffs (K, rows), gathered per sample)."""
    acc = np.take(coeffs[-1], i)
    for k in range(coeffs.shape[0] - 2, -1, -1):
        acc *= x
        acc += np.take(coeffs[k], i)
    return acc


def _horner(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Σ_k c[k] x^k (c (K, n) coefficients already gathered per sample): the arithmetic of
    :func:`horner_rows`, operation for operation (the same bits)."""
    acc = c[-1] * x
    acc += c[-2]
    for k in range(c.shape[0] - 3, -1, -1):
        acc *= x
        acc += c[k]
    return acc


def horner_rows_derivative(coeffs: np.ndarray, i: np.ndarray, x: np.ndarray) -> np.ndarray:
    """d/dx Σ_k coeffs[k, i] x^k (coeffs (K, rows), gathered per sample)."""
    acc = np.take(coeffs[-1], i) * (coeffs.shape[0] - 1)
    for k in range(coeffs.shape[0] - 2, 0, -1):
        acc *= x
        acc += k * np.take(coeffs[k], i)
    return acc


def ph_power_rows(s_bern: np.ndarray, sigma_bern: np.ndarray, points: np.ndarray):
    """Centred power coefficients (columns: one a piece) of PH quintics given in Bernstein form:
    ``s_bern`` (m, 6) arc length [mm], ``sigma_bern`` (m, 5) parametric speed [mm], ``points``
    (m, 6) complex control points [mm]. Returns (s (6, m), σ (5, m), x (6, m), y (6, m))."""
    return (
        (s_bern @ BERNSTEIN5).T,
        (sigma_bern @ BERNSTEIN4).T,
        (points.real @ BERNSTEIN5).T,
        (points.imag @ BERNSTEIN5).T,
    )


def _blocks(n: int, size: int = BLOCK):
    """Slices covering range(n) in blocks of ``size``."""
    return (slice(i, min(i + size, n)) for i in range(0, n, size))


def equal_runs(keys: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of the runs of equal consecutive values of ``keys``."""
    if keys.size == 0:
        return []
    cuts = np.flatnonzero(keys[1:] != keys[:-1]) + 1
    edges = np.concatenate(([0], cuts, [keys.size]))
    return list(zip(edges[:-1].tolist(), edges[1:].tolist()))


def whole_row(geom, line: int = 0) -> tuple:
    """The :meth:`PathTable.of` row of one whole geometry object (a LineGeometry,
    ArcGeometry, NurbsCurve or PHQuintic, over its full parameter range)."""
    from nurbscnc.geometry.nurbs import NurbsCurve
    from nurbscnc.geometry.paths import ArcGeometry, LineGeometry
    from nurbscnc.geometry.ph import PHQuintic

    for cls, kind in (
        (LineGeometry, Kind.LINE),
        (ArcGeometry, Kind.ARC),
        (NurbsCurve, Kind.NURBS),
        (PHQuintic, Kind.PH),
    ):
        if isinstance(geom, cls):
            u_a, u_b = (0.0, 1.0) if kind == Kind.PH else (geom.u_start, geom.u_end)
            return (kind, geom, float(geom.length_mm), float(u_a), float(u_b), 0.0, line)
    raise TypeError(f"no path-model row for a {type(geom).__name__}")


#: Newton iterations on PH pieces before the bracketed fallback (3–4 are typical).
PH_MAX_NEWTON = 12


@dataclass(frozen=True, eq=False)
class PathTable:
    """The pieces of a path as columns, one row a piece (module doc).

    ``kind`` (k,) :class:`Kind` codes; ``length_mm`` (k,) arc length [mm]; ``line`` (k,) source
    lines. Lines: ``start_mm``/``end_mm`` (3, k). Arcs and helices: ``origin_mm``, ``e1``,
    ``e2``, ``normal`` (3, k), ``radius_mm``, ``angle_rad``, ``helix_mm`` (k,):
    C = O + r (cos θ e1 + sin θ e2) + t H n, θ = t Δθ, t = s/L. PH pieces: ``ph_s``,
    ``ph_sigma``, ``ph_x``, ``ph_y`` power coefficients in ξ − ½ of s(ξ), σ(ξ) and the plane
    point (x, y) [mm] ((6|5, m), one column per PH row: row r's is column ``ph_slot[r]``,
    −1 on other rows; a CAM program's line rows need none), with the plane frame in
    ``origin_mm``, ``e1``, ``e2``.
    NURBS and spiral rows: ``obj_id`` (k,) index into ``objects`` (their geometry, −1 on other
    rows), ``u_a``/``u_b`` (k,) their parameter range and ``s_a_mm`` (k,) the arc length of
    the object at ``u_a`` [mm]. Columns no row needs may be broadcast zeros (no memory).
    """

    kind: np.ndarray
    length_mm: np.ndarray
    line: np.ndarray
    start_mm: np.ndarray
    end_mm: np.ndarray
    origin_mm: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    normal: np.ndarray
    radius_mm: np.ndarray
    angle_rad: np.ndarray
    helix_mm: np.ndarray
    ph_s: np.ndarray
    ph_sigma: np.ndarray
    ph_x: np.ndarray
    ph_y: np.ndarray
    ph_slot: np.ndarray
    obj_id: np.ndarray
    objects: tuple
    u_a: np.ndarray
    u_b: np.ndarray
    s_a_mm: np.ndarray

    @property
    def size(self) -> int:
        return int(self.kind.size)

    # -- building ---------------------------------------------------------------------------
    @classmethod
    def of(cls, rows, bulk: bool = True) -> PathTable:
        """A table from ``rows``: (kind, geometry, length_mm, u_a, u_b, s_a_mm, line) per
        piece, geometry a LineGeometry, ArcGeometry, PHQuintic or NurbsCurve (one pass).
        ``bulk``: rows that are all NURBS cells gathered whole (:meth:`_of_curves`; False:
        row by row, what the tests compare it with)."""
        k = len(rows)
        if bulk and k and all(int(r[0]) == Kind.NURBS for r in rows):
            return cls._of_curves(rows)
        kind = np.empty(k, dtype=np.int8)
        length = np.empty(k)
        line = np.zeros(k, dtype=np.int64)
        vec = {name: np.zeros((k, 3)) for name in ("start", "end", "origin", "e1", "e2", "n")}
        radius, angle, helix = np.zeros(k), np.zeros(k), np.zeros(k)
        u_a, u_b, s_a = np.zeros(k), np.zeros(k), np.zeros(k)
        obj_id = np.full(k, -1, dtype=np.intp)
        ph_rows: list[int] = []
        ph_s, ph_sigma, ph_pts = [], [], []
        ids: dict[int, int] = {}
        objects: list = []
        # Plain int codes in the loop (an enum per row was half of it on 4,950 NURBS rows).
        c_line, c_arc, c_ph, c_spiral = (
            int(Kind.LINE),
            int(Kind.ARC),
            int(Kind.PH),
            int(Kind.SPIRAL),
        )
        for i, (code, g, length_i, ua, ub, sa, ln) in enumerate(rows):
            code = int(code)
            if code == c_arc and g.is_spiral:
                code = c_spiral
            length[i], line[i] = length_i, ln
            if code == c_line:
                vec["start"][i], vec["end"][i] = g.start_mm, g.end_mm
            elif code == c_arc:
                vec["origin"][i], vec["e1"][i], vec["e2"][i] = g.origin_mm, g.e1, g.e2
                vec["n"][i] = g.normal
                radius[i], angle[i], helix[i] = g.radius_start_mm, g.angle_rad, g.helix_mm
            elif code == c_ph:
                vec["origin"][i], vec["e1"][i], vec["e2"][i] = g.origin_mm, g.e1, g.e2
                ph_rows.append(i)
                ph_s.append(g.s_coeffs)
                ph_sigma.append(g.sigma_coeffs)
                ph_pts.append(g.control_points)
            else:  # NURBS, SPIRAL: evaluated by their geometry object
                obj_id[i] = ids.setdefault(id(g), len(objects))
                if obj_id[i] == len(objects):
                    objects.append(g)
                u_a[i], u_b[i], s_a[i] = ua, ub, sa
            kind[i] = code
        m = len(ph_rows)
        ph = (np.zeros((6, m)), np.zeros((5, m)), np.zeros((6, m)), np.zeros((6, m)))
        ph_slot = np.full(k, -1, dtype=np.intp)
        if ph_rows:
            ph_slot[np.array(ph_rows)] = np.arange(m)
            ph = tuple(
                map(
                    np.ascontiguousarray,
                    ph_power_rows(np.array(ph_s), np.array(ph_sigma), np.array(ph_pts)),
                )
            )
        t = {name: np.ascontiguousarray(v.T) for name, v in vec.items()}
        table = cls(
            kind,
            length,
            line,
            t["start"],
            t["end"],
            t["origin"],
            t["e1"],
            t["e2"],
            t["n"],
            radius,
            angle,
            helix,
            *ph,
            ph_slot,
            obj_id,
            tuple(objects),
            u_a,
            u_b,
            s_a,
        )
        return table.frozen()

    @classmethod
    def _of_curves(cls, rows) -> PathTable:
        """:meth:`of` for rows that are all NURBS cells (a G6.2 program's): the same table,
        its columns gathered whole instead of row by row (0.9 µs a row: an airfoil's 495
        cells cost 0.45 ms)."""
        k = len(rows)
        ids: dict[int, int] = {}  # curve → its index, in order of first use
        obj_id = np.fromiter(
            (ids.setdefault(id(r[1]), len(ids)) for r in rows), dtype=np.intp, count=k
        )
        objects = tuple({id(r[1]): r[1] for r in rows}.values())
        length, u_a, u_b, s_a = (np.array([r[c] for r in rows], dtype=float) for c in (2, 3, 4, 5))
        line = np.array([r[6] for r in rows], dtype=np.int64)
        zeros3 = [np.zeros((3, k)) for _ in range(6)]  # start, end, origin, e1, e2, n
        ph = (np.zeros((6, 0)), np.zeros((5, 0)), np.zeros((6, 0)), np.zeros((6, 0)))
        table = cls(
            np.full(k, int(Kind.NURBS), dtype=np.int8),
            length,
            line,
            *zeros3,
            np.zeros(k),
            np.zeros(k),
            np.zeros(k),
            *ph,
            np.full(k, -1, dtype=np.intp),
            obj_id,
            objects,
            u_a,
            u_b,
            s_a,
        )
        return table.frozen()

    def frozen(self) -> PathTable:
        """Make every column read-only (returns self)."""
        for name in self.__dataclass_fields__:
            a = getattr(self, name)
            if isinstance(a, np.ndarray) and a.flags.writeable:
                a.setflags(write=False)
        return self

    # -- sampling ---------------------------------------------------------------------------
    def points(self, idx, s_local_mm) -> tuple[np.ndarray, np.ndarray]:
        """Exact points (N, 3) [mm] and parameters (N,) at arc lengths ``s_local_mm`` (N,)
        from the starts of pieces ``idx`` (N,), clipped to [0, L] (see the module doc for the
        parameters). NURBS runs are long when ``idx`` is sorted."""
        idx = np.asarray(idx, dtype=np.intp)
        n = idx.size
        out = np.empty((n, 3))
        param = np.empty(n)
        if n == 0:
            return out, param
        loc = np.clip(np.asarray(s_local_mm, dtype=float), 0.0, np.take(self.length_mm, idx))
        for code, sel, i, ls in self._by_kind(idx, loc):
            o, prm = np.empty((i.size, 3)), np.empty(i.size)
            if code == Kind.LINE:
                self._place_lines(i, ls, o, prm)
            elif code == Kind.ARC:
                self._place_arcs(i, ls, o, prm)
            elif code == Kind.PH:
                self._place_ph(i, ls, o, prm)
            elif code == Kind.NURBS:
                oid = np.take(self.obj_id, i)
                s_curve = np.take(self.s_a_mm, i) + ls
                for a, z in equal_runs(oid):
                    o[a:z], prm[a:z] = self.objects[int(oid[a])].points_at_length(s_curve[a:z])
            else:  # spiral arcs: Newton on their closed-form arc length, all rows at once
                prm = self._spiral_params(i, ls)
                o = self._spiral_at(i, prm)
            if sel is None:
                return o, prm
            out[sel], param[sel] = o, prm
        return out, param

    def _by_kind(self, idx, *columns):
        """(kind, selection, idx[sel], *columns[sel]) per kind present; selection None when
        one kind only (no gather/scatter)."""
        kind = np.take(self.kind, idx)
        present = distinct(kind)
        for code in present.tolist():
            if present.size == 1:
                yield (Kind(code), None, idx, *columns)
                return
            sel = np.flatnonzero(kind == code)
            yield (Kind(code), sel, idx[sel], *(c[sel] for c in columns))

    def _col3(self, name: str, i: np.ndarray) -> np.ndarray:
        return np.take(getattr(self, name), i, axis=1)

    def _place_lines(self, idx, loc, out, param) -> None:
        """C = start (1 − f) + end f, f = s/L: exact at both ends."""
        for b in _blocks(idx.size):
            i = idx[b]
            length = np.take(self.length_mm, i)
            with np.errstate(invalid="ignore", divide="ignore"):
                f = np.where(length > 0.0, loc[b] / length, 0.0)
            out[b] = (self._col3("start_mm", i) * (1.0 - f) + self._col3("end_mm", i) * f).T
            param[b] = loc[b]

    def _place_arcs(self, idx, loc, out, param) -> None:
        """Constant-radius arcs and helices, u = s: C = O + r (cos θ e1 + sin θ e2) + t H n with
        t = s/L, θ = t Δθ (the same formula as :class:`~nurbscnc.geometry.paths.ArcGeometry`)."""
        for b in _blocks(idx.size):
            i = idx[b]
            length = np.take(self.length_mm, i)
            with np.errstate(invalid="ignore", divide="ignore"):
                t = np.where(length > 0.0, loc[b] / length, 0.0)
            out[b] = self._arc_at(i, t).T
            param[b] = loc[b]

    def _arc_at(self, i, t) -> np.ndarray:
        """Arc points (3, m) at fractions ``t`` of the arcs ``i``."""
        theta = t * np.take(self.angle_rad, i)
        r = np.take(self.radius_mm, i)
        return (
            self._col3("origin_mm", i)
            + (r * np.cos(theta)) * self._col3("e1", i)
            + (r * np.sin(theta)) * self._col3("e2", i)
            + (t * np.take(self.helix_mm, i)) * self._col3("normal", i)
        )

    def _ph_at(self, i, xi) -> np.ndarray:
        """PH points (3, m) at ξ on pieces ``i``: origin + x(ξ) e1 + y(ξ) e2."""
        x = xi - 0.5
        j = np.take(self.ph_slot, i)
        px, py = horner_rows(self.ph_x, j, x), horner_rows(self.ph_y, j, x)
        return self._col3("origin_mm", i) + px * self._col3("e1", i) + py * self._col3("e2", i)

    def _ph_params(self, i, s) -> np.ndarray:
        """ξ at arc lengths ``s`` on PH pieces ``i``: Newton on the closed-form arc length
        (SPEC §4, eq. 10–12) ξ ← ξ − (s(ξ) − s)/σ(ξ) from ξ = s/L, to |s(ξ) − s| ≤
        max(1e-13 mm, 8 ulp L); samples not there after :data:`PH_MAX_NEWTON` steps (never
        seen) by bisection on the monotone s(ξ)."""
        eps = np.finfo(float).eps
        length = np.take(self.length_mm, i)
        tol = np.maximum(1e-13, 8.0 * eps * length)
        with np.errstate(invalid="ignore", divide="ignore"):
            xi = np.where(length > 0.0, s / length, 0.0)
        # Each sample stops at its own tolerance (not when all have converged), so its ξ does
        # not depend on the others in the call: a window of samples gives the same bits as
        # the whole reference (the chunked output). The coefficients are gathered
        # once; the working set is compacted only when less than half of it still moves
        # (the others keep their ξ: the same arithmetic per sample, the same bits).
        slot = np.take(self.ph_slot, i)
        cs, cg = np.take(self.ph_s, slot, axis=1), np.take(self.ph_sigma, slot, axis=1)
        at, xa, sa, ta = np.arange(xi.size), xi.copy(), s, tol
        for _ in range(PH_MAX_NEWTON):
            x = xa - 0.5
            f = _horner(cs, x) - sa
            going = np.abs(f) > ta
            n_going = int(np.count_nonzero(going))
            if n_going == 0:
                xi[at] = xa
                return xi
            if 2 * n_going < xa.size:  # compact (the settled samples keep their ξ)
                xi[at[~going]] = xa[~going]
                at, xa, sa, ta, x, f = (
                    at[going],
                    xa[going],
                    sa[going],
                    ta[going],
                    x[going],
                    f[going],
                )
                cs, cg = cs[:, going], cg[:, going]
                xa = np.clip(xa - f / _horner(cg, x), 0.0, 1.0)
            else:
                with np.errstate(divide="ignore", invalid="ignore"):
                    step = np.clip(xa - f / _horner(cg, x), 0.0, 1.0)
                xa = np.where(going, step, xa)
        xi[at] = xa
        bad = np.flatnonzero(np.abs(horner_rows(self.ph_s, slot, xi - 0.5) - s) > tol)
        if bad.size:
            lo, hi = np.zeros(bad.size), np.ones(bad.size)
            for _ in range(60):  # 2^-60 of the parameter range
                mid = 0.5 * (lo + hi)
                below = horner_rows(self.ph_s, slot[bad], mid - 0.5) < s[bad]
                lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
            xi[bad] = 0.5 * (lo + hi)
        return xi

    def _place_ph(self, idx, loc, out, param) -> None:
        """PH pieces, all at once (:meth:`_ph_params`, then the power form of the point)."""
        for b in _blocks(idx.size):
            i = idx[b]
            xi = self._ph_params(i, loc[b])
            out[b] = self._ph_at(i, xi).T
            param[b] = xi

    def _object_params(self, code: Kind, i: np.ndarray, ls: np.ndarray) -> np.ndarray:
        """Own parameters u at arc lengths ``ls`` (clipped) on the NURBS or spiral rows ``i``
        (all of kind ``code``), without the points (:meth:`points` uses the same u)."""
        u = np.empty(i.size)
        if code == Kind.NURBS:
            oid = np.take(self.obj_id, i)
            s_curve = np.take(self.s_a_mm, i) + ls
            for a, z in equal_runs(oid):
                u[a:z] = self.objects[int(oid[a])].param_at_length_fast(s_curve[a:z])
        else:
            u = self._spiral_params(i, ls)
        return u

    @cached_property
    def _spiral_columns(self) -> dict:
        """Per geometry object (``objects``): the spiral-arc constants of
        :class:`~nurbscnc.geometry.paths.ArcGeometry` as columns (zeros on NURBS objects):
        r0, r1, Δθ, H, L [mm, rad] (n_obj,) and origin, e1, e2, n (n_obj, 3)."""
        n = len(self.objects)
        col = {name: np.zeros(n) for name in ("r0", "r1", "angle", "helix", "length")}
        for name in ("origin", "e1", "e2", "normal"):
            col[name] = np.zeros((n, 3))
        for o, g in enumerate(self.objects):
            if hasattr(g, "radius_end_mm"):
                col["r0"][o], col["r1"][o] = g.radius_start_mm, g.radius_end_mm
                col["angle"][o], col["helix"][o] = g.angle_rad, g.helix_mm
                col["length"][o] = g.length_mm
                col["origin"][o], col["e1"][o] = g.origin_mm, g.e1
                col["e2"][o], col["normal"][o] = g.e2, g.normal
        return col

    def _spiral_params(self, i: np.ndarray, ls: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """u = t L at arc lengths ``ls`` on spiral rows ``i``: 0 and L at the ends exactly,
        inside Newton on the closed-form arc length (segments.spiral_arc_length_mm) from
        t = s/L, t ← t − (s(t) − s)/√(a² + w(t)²), each sample to |s(t) − s| ≤ max(1e-12 mm,
        8 ulps of s) or an ulp of t — the arithmetic of ArcGeometry.param_at_length, over
        all rows at once (the same numbers)."""
        col = self._spiral_columns
        o = np.take(self.obj_id, i)
        length = col["length"][o]
        u = np.where(ls > 0.0, length, 0.0)
        inside = np.flatnonzero((ls > 0.0) & (ls < np.take(self.length_mm, i)))
        if inside.size == 0:
            return u
        oi = o[inside]
        big = length[inside]
        t = segments.spiral_t_at_length(
            col["r0"][oi],
            col["r1"][oi],
            col["angle"][oi],
            col["helix"][oi],
            ls[inside],
            big,
            max_iter,
        )
        u[inside] = np.where(big > 0.0, big, 1.0) * t
        return u

    def _spiral_at(self, i: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Points (m, 3) [mm] of spiral rows ``i`` at their parameters ``u`` (ArcGeometry's
        C = r(t) (cos θ e1 + sin θ e2) + (O + t H n), t = u/L, θ = t Δθ, r = r0 + t Δr)."""
        col = self._spiral_columns
        o = np.take(self.obj_id, i)
        big = col["length"][o]
        t = np.clip(u / np.where(big > 0.0, big, 1.0), 0.0, 1.0)
        r0 = col["r0"][o]
        radius = r0 + t * (col["r1"][o] - r0)
        theta = t * col["angle"][o]
        c, sn = np.cos(theta), np.sin(theta)
        ring = radius[:, None] * (c[:, None] * col["e1"][o] + sn[:, None] * col["e2"][o])
        return ring + (col["origin"][o] + (t * col["helix"][o])[:, None] * col["normal"][o])

    def params(self, idx, s_local_mm) -> np.ndarray:
        """Own parameters (N,) at arc lengths ``s_local_mm`` from the starts of pieces ``idx``."""
        return self.points(idx, s_local_mm)[1]

    def points_at_fraction(self, idx, frac) -> np.ndarray:
        """Points (m, 3) [mm] at fraction ``frac`` (m,) ∈ [0, 1] of the *parameter* range of
        pieces ``idx`` (m,): no arc-length inversion (a polyline does not need its points
        evenly spaced in length). Lines, arcs and PH pieces in closed form; spiral arcs and
        NURBS by their geometry objects, one call per piece or curve."""
        idx = np.asarray(idx, dtype=np.intp)
        frac = np.asarray(frac, dtype=float)
        out = np.empty((idx.size, 3))
        for code, sel, i, f in self._by_kind(idx, frac):
            if code == Kind.LINE:
                a, b = self._col3("start_mm", i).T, self._col3("end_mm", i).T
                fc = f[:, None]
                o = np.where(fc == 1.0, b, a + fc * (b - a))
            elif code == Kind.ARC:
                o = self._arc_at(i, f).T
            elif code == Kind.PH:
                o = self._ph_at(i, f).T
            elif code == Kind.SPIRAL:  # u = 0 + f (L − 0), as ArcGeometry's point
                o = self._spiral_at(
                    i, f * np.take(self._spiral_columns["length"], np.take(self.obj_id, i))
                )
            else:
                o = np.empty((i.size, 3))
                # Rows grouped by piece (a stable sort: O(m log m), not one scan per piece).
                by_piece = np.argsort(i, kind="stable")
                for a, z in equal_runs(i[by_piece]):
                    rows = by_piece[a:z]
                    j = int(i[rows[0]])
                    g = self.objects[int(self.obj_id[j])]
                    ua, ub = float(self.u_a[j]), float(self.u_b[j])
                    if code == Kind.SPIRAL:
                        ua, ub = float(g.u_start), float(g.u_end)
                    o[rows] = g.point(ua + f[rows] * (ub - ua))
            if sel is None:
                return o
            out[sel] = o
        return out

    def derivatives(self, idx, s_local_mm) -> tuple[np.ndarray, np.ndarray]:
        """First and second derivatives (N, 3) of the points with respect to each piece's own
        parameter at arc lengths ``s_local_mm`` (N,) from the piece starts (lines and arcs:
        with respect to t = s/L; PH: ξ; NURBS and spirals: their u)."""
        idx = np.asarray(idx, dtype=np.intp)
        loc = np.clip(np.asarray(s_local_mm, dtype=float), 0.0, np.take(self.length_mm, idx))
        d1, d2 = np.zeros((idx.size, 3)), np.zeros((idx.size, 3))
        for code, sel, i, ls in self._by_kind(idx, loc):
            sel = slice(None) if sel is None else sel
            if code == Kind.LINE:
                d1[sel] = (self._col3("end_mm", i) - self._col3("start_mm", i)).T
            elif code == Kind.ARC:
                length = np.take(self.length_mm, i)
                with np.errstate(invalid="ignore", divide="ignore"):
                    t = np.where(length > 0.0, ls / length, 0.0)
                dth = np.take(self.angle_rad, i)
                r = np.take(self.radius_mm, i)
                c, s = np.cos(t * dth), np.sin(t * dth)
                e1, e2 = self._col3("e1", i), self._col3("e2", i)
                d1[sel] = (
                    r * dth * (c * e2 - s * e1)
                    + np.take(self.helix_mm, i) * self._col3("normal", i)
                ).T
                d2[sel] = (-r * dth * dth * (c * e1 + s * e2)).T
            elif code == Kind.PH:
                xi = self._ph_params(i, ls)
                x = xi - 0.5
                e1, e2 = self._col3("e1", i), self._col3("e2", i)
                j = np.take(self.ph_slot, i)
                dx, dy = (
                    horner_rows_derivative(self.ph_x, j, x),
                    horner_rows_derivative(self.ph_y, j, x),
                )
                d1[sel] = (dx * e1 + dy * e2).T
                ddx = _second_derivative_rows(self.ph_x, j, x)
                ddy = _second_derivative_rows(self.ph_y, j, x)
                d2[sel] = (ddx * e1 + ddy * e2).T
            else:
                u = self._object_params(code, i, ls)
                oid = np.take(self.obj_id, i)
                a1, a2 = np.empty((i.size, 3)), np.empty((i.size, 3))
                for a, z in equal_runs(oid):
                    d = self.objects[int(oid[a])].derivatives(u[a:z], 2)
                    a1[a:z], a2[a:z] = d[1], d[2]
                d1[sel], d2[sel] = a1, a2
        return d1, d2

    def tangents(self, idx, s_local_mm) -> np.ndarray:
        """Unit tangents (N, 3) at arc lengths ``s_local_mm`` on pieces ``idx`` (zero where the
        derivative vanishes: a cusp)."""
        d1, _ = self.derivatives(idx, s_local_mm)
        n = np.sqrt(np.einsum("ij,ij->i", d1, d1))
        return d1 / np.where(n > 0.0, n, 1.0)[:, None]

    def curvature(self, idx, s_local_mm) -> np.ndarray:
        """Curvature κ = |C′ × C″| / |C′|³ [1/mm] (N,) at arc lengths ``s_local_mm`` on pieces
        ``idx`` (inf at a cusp)."""
        d1, d2 = self.derivatives(idx, s_local_mm)
        cross = np.cross(d1, d2)
        speed = np.sqrt(np.einsum("ij,ij->i", d1, d1))
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.sqrt(np.einsum("ij,ij->i", cross, cross)) / speed**3
        return np.where(speed > 0.0, k, np.inf)

    def place(self, piece_start_mm: np.ndarray, s_mm, idx) -> tuple[np.ndarray, np.ndarray]:
        """Points and parameters at path lengths ``s_mm`` on pieces ``idx``, the pieces
        starting at path lengths ``piece_start_mm`` (k,) [mm]."""
        idx = np.asarray(idx, dtype=np.intp)
        s = np.asarray(s_mm, dtype=float)
        return self.points(idx, s - np.take(piece_start_mm, idx))


def _second_derivative_rows(coeffs: np.ndarray, i: np.ndarray, x: np.ndarray) -> np.ndarray:
    """d²/dx² Σ_k coeffs[k, i] x^k."""
    top = coeffs.shape[0] - 1
    acc = np.take(coeffs[top], i) * (top * (top - 1))
    for k in range(top - 1, 1, -1):
        acc *= x
        acc += k * (k - 1) * np.take(coeffs[k], i)
    return acc
