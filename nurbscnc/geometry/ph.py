"""Planar Pythagorean-hodograph (PH) quintics in complex form (SPEC §4).

A PH quintic is r(ξ) = p0 + ∫ w(t)² dt, ξ ∈ [0, 1], with the quadratic complex preimage
w(ξ) = w0(1−ξ)² + 2w1(1−ξ)ξ + w2ξ² (Farouki; Moon, Farouki & Choi 2001). Its parametric speed
σ = |r′| = |w|² is a polynomial, so the arc length s(ξ) is a polynomial too (Bernstein degree 5)
and the arc-length parametrisation is found exactly by Newton's method.

The curve lives in a plane of 3-D space: the complex point x + iy maps to
``origin_mm + x e1 + y e2`` (``e1``, ``e2`` orthonormal). :func:`plane_frame` picks such a frame
for a planar set of 3-D points.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nurbscnc.errors import GeometryError
from nurbscnc.geometry import phfoot
from nurbscnc.geometry.compiled import kernels as _kernels
from nurbscnc.geometry.segments import PLANE_AXES, frozen_array, vec3

_EPS = np.finfo(float).eps


def _binomials(n: int) -> np.ndarray:
    """Binomial coefficients C(n, k), k = 0..n, as floats."""
    row = [1.0]
    for k in range(n):
        row.append(row[-1] * (n - k) / (k + 1))
    return np.array(row)


_BINOM = {4: frozen_array(_binomials(4)), 5: frozen_array(_binomials(5))}
#: The exponents k and n − k of the Bernstein basis of degree n (made once: the basis is
#: evaluated at every Newton step of the foot-point searches).
_POWERS = {n: (frozen_array(np.arange(n + 1)), frozen_array(n - np.arange(n + 1))) for n in (4, 5)}
#: 64-point Gauss–Legendre rule on [0, 1] (nodes, weights), for the bending energy.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)
_GL_X = frozen_array(0.5 * (_GL_X + 1.0))
_GL_W = frozen_array(0.5 * _GL_W)


def _bernstein(xi: np.ndarray, n: int) -> np.ndarray:
    """Bernstein basis B_k^n(ξ), k = 0..n; shape ``xi.shape + (n + 1,)``."""
    x = xi[..., None]
    k, n_k = _POWERS[n]
    return _BINOM[n] * x**k * (1.0 - x) ** n_k


def _as_xi(xi) -> np.ndarray:
    return np.asarray(xi, dtype=float)


def bracketed_newton(fun, lo, hi, x0, ftol: float = 0.0, max_iter: int = 200) -> np.ndarray:
    """Solve f(x) = 0 elementwise by Newton's method safeguarded by bisection.

    ``fun(x, idx) -> (f, df)`` evaluates f and f′ at ``x`` for the elements ``idx``; f must be
    ≤ 0 at ``lo`` and ≥ 0 at ``hi`` (one sign change in the bracket). A Newton step that leaves
    the current bracket (or f′ ≤ 0) is replaced by the bisection of the bracket, so convergence
    never depends on the starting values ``x0``. An element stops when |f| ≤ ``ftol``, when the
    Newton step is at rounding level, or when the bracket has collapsed (the step's
    bookkeeping: :func:`_newton_step_py`, compiled where the geometry's kernels were built).
    """
    lo = np.array(lo, dtype=float)
    hi = np.array(hi, dtype=float)
    x = np.clip(np.array(x0, dtype=float), lo, hi)
    # The active elements (their first ``n`` entries): x, bracket and index, compacted as
    # elements finish (each element's arithmetic is the same whichever others are active).
    xa, a, b = x.copy(), np.ascontiguousarray(lo), np.ascontiguousarray(hi)
    idx = np.arange(x.size, dtype=np.int64)
    step = _newton_step_py if _kernels is None else _kernels.newton_step
    n = x.size
    for _ in range(max_iter):
        if n == 0:
            break
        f, df = fun(xa[:n], idx[:n])
        f = np.ascontiguousarray(f, dtype=np.float64)
        df = np.ascontiguousarray(df, dtype=np.float64)
        n = step(f, df, xa, a, b, idx, x, float(ftol))
    x[idx[:n]] = xa[:n]
    return x


def _newton_step_py(f, df, xa, a, b, idx, x, ftol: float) -> int:
    """One step of :func:`bracketed_newton` for its ``f.size`` active elements (values ``f``,
    ``df`` at ``xa``, brackets ``a``, ``b``): the bracket's side of f's sign moves to xa, the
    Newton point xa − f/f′ is taken if strictly inside with f′ > 0, else the bracket's middle;
    an element is done at |f| ≤ ``ftol``, at a Newton step of rounding level
    (2 ε max(1, |xa|)) or a collapsed bracket (4 ε max(1, |xa|)). Every element takes its
    step (but where |f| ≤ ``ftol``); the finished ones are written to ``x[idx]``, the others
    moved to the front of ``xa``, ``a``, ``b``, ``idx`` in order. Returns their number."""
    n = f.size
    xs, lo, hi = xa[:n], a[:n], b[:n]
    neg = f < 0.0
    lo = np.where(neg, xs, lo)
    hi = np.where(neg, hi, xs)
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = xs - f / df
    inside = (xn > lo) & (xn < hi) & (df > 0.0)
    xn = np.where(inside, xn, 0.5 * (lo + hi))
    scale = np.maximum(1.0, np.abs(xs))
    small = np.abs(f) <= ftol
    done = (
        small | (inside & (np.abs(xn - xs) <= 2.0 * _EPS * scale)) | (hi - lo <= 4.0 * _EPS * scale)
    )
    # A Newton step at rounding level is still taken (it is the better value).
    xn = np.where(small, xs, xn)
    x[idx[:n][done]] = xn[done]
    going = ~done
    m = int(np.count_nonzero(going))
    idx[:m] = idx[:n][going]
    xa[:m], a[:m], b[:m] = xn[going], lo[going], hi[going]
    return m


#: Newton steps at most per foot point (:func:`bracketed_newton`'s default).
FOOT_STEPS = 200


def _closest_param_py(coeffs, xs, q_re, q_im) -> np.ndarray:
    """:meth:`PHQuintic.closest_param` in numpy (the reference of the compiled
    ``ph_closest``): ``coeffs`` the control points' and preimage's real and imaginary parts,
    ``xs`` the dense samples, ``q_re``, ``q_im`` the points."""
    n_dense = xs.size
    rx, ry = phfoot.point_xy(coeffs[0], coeffs[1], xs)
    nearest = np.empty(q_re.size, dtype=np.int64)
    chunk = max(1, 2_000_000 // n_dense)
    for start in range(0, q_re.size, chunk):  # bounded memory; not a per-sample loop
        dx = rx[None, :] - q_re[start : start + chunk, None]
        dy = ry[None, :] - q_im[start : start + chunk, None]
        nearest[start : start + chunk] = np.argmin(dx * dx + dy * dy, axis=1)
    x_mid = xs[nearest]
    x_lo = xs[np.maximum(nearest - 1, 0)]
    x_hi = xs[np.minimum(nearest + 1, n_dense - 1)]
    g_lo, _ = phfoot.g_terms(*coeffs, x_lo, q_re, q_im)
    g_mid, _ = phfoot.g_terms(*coeffs, x_mid, q_re, q_im)
    g_hi, _ = phfoot.g_terms(*coeffs, x_hi, q_re, q_im)
    left = (g_lo <= 0.0) & (g_mid >= 0.0)
    right = ~left & (g_mid <= 0.0) & (g_hi >= 0.0)
    a = np.where(left, x_lo, x_mid)
    b = np.where(left, x_mid, np.where(right, x_hi, x_mid))
    xi = x_mid.copy()
    sel = np.flatnonzero((left | right) & (b > a))
    if sel.size:
        qr, qi = q_re[sel], q_im[sel]

        def g(x, idx):
            return phfoot.g_terms(*coeffs, x, qr[idx], qi[idx])

        xi[sel] = bracketed_newton(g, a[sel], b[sel], x_mid[sel], max_iter=FOOT_STEPS)
    return xi


@dataclass(frozen=True, eq=False)
class PHQuintic:
    """A planar PH quintic r(ξ) = p0 + ∫₀^ξ w² (SPEC §4), embedded in 3-D.

    ``w`` (3,) complex preimage coefficients (w0, w1, w2) [√mm]; ``p0`` complex start point in
    plane coordinates [mm]; ``origin_mm``, ``e1``, ``e2`` the plane embedding (x + iy ↦
    origin + x e1 + y e2). Derived once: ``control_points`` (6,) complex [mm],
    ``sigma_coeffs`` (5,) Bernstein coefficients of σ = |r′| [mm], ``s_coeffs`` (6,) Bernstein
    coefficients of s(ξ) [mm], ``length_mm``.
    """

    w: np.ndarray
    p0: complex
    origin_mm: np.ndarray = field(default_factory=lambda: vec3((0.0, 0.0, 0.0)))
    e1: np.ndarray = field(default_factory=lambda: vec3((1.0, 0.0, 0.0)))
    e2: np.ndarray = field(default_factory=lambda: vec3((0.0, 1.0, 0.0)))
    control_points: np.ndarray = field(init=False, repr=False)
    sigma_coeffs: np.ndarray = field(init=False, repr=False)
    s_coeffs: np.ndarray = field(init=False, repr=False)
    length_mm: float = field(init=False)

    def __post_init__(self):
        w = np.array(self.w, dtype=complex).reshape(3)
        w.setflags(write=False)
        w0, w1, w2 = w
        p0 = complex(self.p0)
        set_ = object.__setattr__
        set_(self, "w", w)
        set_(self, "p0", p0)
        set_(self, "origin_mm", vec3(self.origin_mm))
        set_(self, "e1", vec3(self.e1))
        set_(self, "e2", vec3(self.e2))
        # Control points (SPEC §4): p_{k+1} − p_k = (Bernstein coefficients of w²) / 5.
        steps = np.array([w0 * w0, w0 * w1, (2.0 * w1 * w1 + w0 * w2) / 3.0, w1 * w2, w2 * w2])
        points = p0 + np.concatenate(([0.0], np.cumsum(steps / 5.0)))
        set_(self, "control_points", frozen_array(points, dtype=complex))
        # σ = |w|² in Bernstein form, degree 4.
        sigma = np.array(
            [
                abs(w0) ** 2,
                (w0 * w1.conjugate()).real,
                (2.0 * abs(w1) ** 2 + (w0 * w2.conjugate()).real) / 3.0,
                (w1 * w2.conjugate()).real,
                abs(w2) ** 2,
            ]
        )
        set_(self, "sigma_coeffs", frozen_array(sigma))
        # s = ∫σ: s_0 = 0, s_k = s_{k−1} + σ_{k−1}/5; L = Σσ_k/5.
        set_(self, "s_coeffs", frozen_array(np.concatenate(([0.0], np.cumsum(sigma / 5.0)))))
        set_(self, "length_mm", float(self.s_coeffs[-1]))

    # --- the preimage w and its derivatives --------------------------------------------------

    def preimage(self, xi) -> np.ndarray:
        """w(ξ) (complex, same shape as ``xi``)."""
        x = _as_xi(xi)
        w0, w1, w2 = self.w
        return w0 * (1.0 - x) ** 2 + 2.0 * w1 * (1.0 - x) * x + w2 * x**2

    def preimage_derivative(self, xi) -> np.ndarray:
        """w′(ξ) = 2[(w1 − w0)(1 − ξ) + (w2 − w1)ξ] (complex)."""
        x = _as_xi(xi)
        w0, w1, w2 = self.w
        return 2.0 * ((w1 - w0) * (1.0 - x) + (w2 - w1) * x)

    @property
    def preimage_second_derivative(self) -> complex:
        """w″ = 2(w0 − 2w1 + w2) (constant)."""
        w0, w1, w2 = self.w
        return complex(2.0 * (w0 - 2.0 * w1 + w2))

    # --- the curve in plane coordinates (complex) --------------------------------------------

    def point(self, xi) -> np.ndarray:
        """r(ξ) in plane coordinates [mm] (complex, same shape as ``xi``); Bernstein degree 5."""
        return _bernstein(_as_xi(xi), 5) @ self.control_points

    def hodograph(self, xi) -> np.ndarray:
        """r′(ξ) = w² [mm] (complex)."""
        return self.preimage(xi) ** 2

    def second_derivative(self, xi) -> np.ndarray:
        """r″(ξ) = 2 w w′ [mm] (complex)."""
        return 2.0 * self.preimage(xi) * self.preimage_derivative(xi)

    def third_derivative(self, xi) -> np.ndarray:
        """r‴(ξ) = 2(w′² + w w″) [mm] (complex)."""
        w = self.preimage(xi)
        dw = self.preimage_derivative(xi)
        return 2.0 * (dw * dw + w * self.preimage_second_derivative)

    def sigma(self, xi) -> np.ndarray:
        """Parametric speed σ(ξ) = |r′| = |w|² [mm] (Bernstein degree 4, SPEC §4)."""
        return _bernstein(_as_xi(xi), 4) @ self.sigma_coeffs

    def arc_length(self, xi) -> np.ndarray:
        """Arc length s(ξ) = ∫₀^ξ σ [mm] (Bernstein degree 5, SPEC §4)."""
        return _bernstein(_as_xi(xi), 5) @ self.s_coeffs

    def curvature(self, xi) -> np.ndarray:
        """Signed curvature κ(ξ) = 2 Im(w̄ w′)/|w|⁴ [1/mm] (positive: turning left, SPEC §4)."""
        w = self.preimage(xi)
        return 2.0 * (np.conj(w) * self.preimage_derivative(xi)).imag / np.abs(w) ** 4

    def turning_angle_rad(self) -> float:
        """Total turning of the tangent ∫κ ds [rad], exactly.

        The tangent angle is 2 arg w. Write w = c2(ξ − z1)(ξ − z2) (power basis
        c0 + c1ξ + c2ξ²); along ξ ∈ [0, 1] the continuous change of arg(ξ − z) is the principal
        Arg((1 − z)/(−z)) = Arg(1 − 1/z), since a straight segment not through 0 subtends less
        than π. With the stable roots z1 = q/c2, z2 = c0/q (q = −(c1 ± √(c1² − 4c0c2))/2,
        |q| maximal) the two terms are Arg(1 − c2/q) and Arg(1 − q/c0), which stay finite as
        c2 → 0 (w linear). A root on [0, 1] (a cusp, σ = 0) is not a regular curve.
        """
        return turning_angle_rad(self.w)

    def rotation_index(self) -> float:
        """Rotation index: total tangent turning / 2π (not rounded)."""
        return self.turning_angle_rad() / (2.0 * np.pi)

    def bending_energy(self) -> float:
        """∫κ² ds = ∫₀¹ κ² σ dξ [1/mm], by 64-point Gauss–Legendre quadrature."""
        return float(_GL_W @ (self.curvature(_GL_X) ** 2 * self.sigma(_GL_X)))

    def param_at_length(self, s_mm, xi_guess=None) -> np.ndarray:
        """ξ with s(ξ) = ``s_mm`` [mm], elementwise, to 1e-12 mm (SPEC §4, eq. 10–12).

        Newton ξ ← ξ − (s(ξ) − s)/σ(ξ), safeguarded by bisection on a bracket in [0, 1]
        (σ > 0, so the root is unique). Starting values: ``xi_guess`` if given (e.g. the
        previous servo period's ξ), else linear interpolation in a 33-point s(ξ) table; the
        result does not depend on them. Targets within 1e-9 mm of [0, L] are clamped to it.
        """
        s = np.asarray(s_mm, dtype=float)
        shape = s.shape
        s = s.ravel()
        total = self.length_mm
        slack = 1e-9 * max(1.0, total)
        if np.any(~np.isfinite(s)) or np.any(s < -slack) or np.any(s > total + slack):
            raise GeometryError(
                f"arc length outside the PH curve's [0, {total:.9g}] mm: "
                f"{s.min():.9g} .. {s.max():.9g} mm"
            )
        s = np.clip(s, 0.0, total)
        if xi_guess is None:
            table_xi = np.linspace(0.0, 1.0, 33)
            x0 = np.interp(s, self.arc_length(table_xi), table_xi)
        else:
            x0 = np.broadcast_to(np.asarray(xi_guess, dtype=float), shape).ravel()

        def fun(x, idx):
            return self.arc_length(x) - s[idx], self.sigma(x)

        # Below 1e-12 mm with margin, or a few ulps of L for very long curves (the rounding
        # floor of s(ξ)).
        ftol = max(1e-13, 8.0 * _EPS * total)
        xi = bracketed_newton(fun, np.zeros(s.size), np.ones(s.size), x0, ftol=ftol)
        return xi.reshape(shape)

    def closest_param(self, q, n_dense: int = 512) -> np.ndarray:
        """ξ of the closest curve point to each complex point ``q`` (plane coordinates, mm).

        The nearest of ``n_dense`` uniform samples gives a bracket [ξ_{i−1}, ξ_i] or
        [ξ_i, ξ_{i+1}] where g(ξ) = Re(conj(r − q) r′) = ½ d|r − q|²/dξ changes sign; the
        foot point is then refined by safeguarded Newton (g′ = |r′|² + Re(conj(r − q) r″)).
        Without a sign change the minimum is at the end sample (ξ = 0 or 1). The arithmetic is
        :mod:`~nurbscnc.geometry.phfoot`'s; compiled (``ph_closest``) where the geometry's
        kernels were built, the same bits.
        """
        q = np.asarray(q, dtype=complex)
        shape = q.shape
        q_re = np.ascontiguousarray(q.real, dtype=np.float64).ravel()
        q_im = np.ascontiguousarray(q.imag, dtype=np.float64).ravel()
        cp, w = self.control_points, self.w
        coeffs = (cp.real.copy(), cp.imag.copy(), w.real.copy(), w.imag.copy())
        xs = np.linspace(0.0, 1.0, n_dense)
        if _kernels is not None:
            out = np.empty(q_re.size)
            _kernels.ph_closest(*coeffs, xs, q_re, q_im, FOOT_STEPS, out)
            return out.reshape(shape)
        return _closest_param_py(coeffs, xs, q_re, q_im).reshape(shape)

    # --- 3-D embedding -----------------------------------------------------------------------

    def to_mm(self, z, translate: bool = True) -> np.ndarray:
        """Map complex plane coordinates to 3-D, (m, 3) [mm]; ``translate=False`` for vectors."""
        z = np.asarray(z, dtype=complex).ravel()
        out = z.real[:, None] * self.e1 + z.imag[:, None] * self.e2
        return out + self.origin_mm if translate else out

    @property
    def normal(self) -> np.ndarray:
        """Unit normal e1 × e2 (positive curvature turns counter-clockwise about it)."""
        return np.cross(self.e1, self.e2)

    @property
    def control_points_mm(self) -> np.ndarray:
        """Control points p0..p5 in 3-D, (6, 3) [mm]."""
        return self.to_mm(self.control_points)

    def point_mm(self, xi) -> np.ndarray:
        """r(ξ) in 3-D, (m, 3) [mm] for m = ``np.size(xi)``."""
        return self.to_mm(self.point(np.ravel(_as_xi(xi))))

    def derivatives_mm(self, xi, order: int) -> np.ndarray:
        """r and its ξ-derivatives up to ``order`` in 3-D, shape (order + 1, m, 3) [mm].

        r′ = w², r″ = 2ww′, r‴ = 2(w′² + ww″), r⁗ = 6w′w″, r⁽⁵⁾ = 6w″², higher ones vanish.
        Same layout as a NURBS curve's ``derivatives``, so a PH piece can stand in for one.
        """
        x = np.ravel(_as_xi(xi))
        w = self.preimage(x)
        dw = self.preimage_derivative(x)
        ddw = self.preimage_second_derivative
        complex_derivs = [
            lambda: self.point(x),
            lambda: w * w,
            lambda: 2.0 * w * dw,
            lambda: 2.0 * (dw * dw + w * ddw),
            lambda: 6.0 * dw * ddw,
            lambda: np.full(x.shape, 6.0 * ddw * ddw),
        ]
        out = np.zeros((order + 1, x.size, 3))
        for k in range(min(order, 5) + 1):
            out[k] = self.to_mm(complex_derivs[k](), translate=(k == 0))
        return out

    def derivatives(self, xi, order: int) -> np.ndarray:
        """Alias of :meth:`derivatives_mm` (the NURBS curve interface)."""
        return self.derivatives_mm(xi, order)


def _hermite_preimages(p0, p5, d0, d1) -> list[np.ndarray]:
    """The preimages w (3,) of :func:`hermite_solutions`' four curves, in its order."""
    p0, p5, d0, d1 = complex(p0), complex(p5), complex(d0), complex(d1)
    values = np.array([p0, p5, d0, d1])
    if not np.all(np.isfinite(values)):
        raise GeometryError("PH Hermite data must be finite")
    if d0 == 0 or d1 == 0:
        raise GeometryError("PH Hermite interpolation needs nonzero end derivatives")
    w0 = np.sqrt(d0)
    out = []
    for sign2 in (1.0, -1.0):
        w2 = sign2 * np.sqrt(d1)
        root = np.sqrt(120.0 * (p5 - p0) - 15.0 * w0 * w0 - 15.0 * w2 * w2 + 10.0 * w0 * w2)
        for sign1 in (1.0, -1.0):
            w1 = -0.75 * (w0 + w2) + sign1 * 0.25 * root
            out.append(np.array([w0, w1, w2]))
    return out


def hermite_solutions(
    p0, p5, d0, d1, origin_mm=(0.0, 0.0, 0.0), e1=(1.0, 0.0, 0.0), e2=(0.0, 1.0, 0.0)
) -> list[PHQuintic]:
    """The four PH quintics with r(0) = p0, r(1) = p5, r′(0) = d0, r′(1) = d1 (SPEC §4, eq. 21).

    All arguments complex plane coordinates [mm]; the frame is passed to each curve.
    w0 = √d0 (the overall sign of w does not change the curve), w2 = ±√d1 and
    w1 = −¾(w0 + w2) ± ¼√(120(p5 − p0) − 15w0² − 15w2² + 10w0w2). Taking both signs of both
    square roots covers all solutions whatever branch the principal √ picks.
    """
    p0 = complex(p0)
    return [PHQuintic(w, p0, origin_mm, e1, e2) for w in _hermite_preimages(p0, p5, d0, d1)]


def hermite_ph(
    p0, p5, d0, d1, origin_mm=(0.0, 0.0, 0.0), e1=(1.0, 0.0, 0.0), e2=(0.0, 1.0, 0.0)
) -> PHQuintic:
    """The "good" PH quintic Hermite interpolant (SPEC §4): of the four solutions the one with
    the least absolute rotation index; ties (within 1e-9) go to the least bending energy.
    The index is a function of w alone: only the curves in the running are built."""
    ws = _hermite_preimages(p0, p5, d0, d1)
    rot = np.array([abs(turning_angle_rad(w) / (2.0 * np.pi)) for w in ws])
    p0 = complex(p0)
    tied = [PHQuintic(w, p0, origin_mm, e1, e2) for w, r in zip(ws, rot) if r <= rot.min() + 1e-9]
    if len(tied) == 1:
        return tied[0]
    return min(tied, key=lambda c: c.bending_energy())


def turning_angle_rad(w) -> float:
    """Total turning ∫κ ds [rad] of the PH quintic with preimage ``w`` (3,) complex: see
    :meth:`PHQuintic.turning_angle_rad` (a function of w alone, so the Hermite solutions are
    ranked before any curve is built)."""
    w0, w1, w2 = np.array(w, dtype=complex).reshape(3)
    c0, c1, c2 = w0, 2.0 * (w1 - w0), w0 - 2.0 * w1 + w2
    if c1 == 0 and c2 == 0:
        return 0.0
    root = np.sqrt(c1 * c1 - 4.0 * c0 * c2)
    qa, qb = -0.5 * (c1 + root), -0.5 * (c1 - root)
    q = qa if abs(qa) >= abs(qb) else qb
    darg_w = np.angle(1.0 - c2 / q) + np.angle(1.0 - q / c0)
    return float(2.0 * darg_w)


def plane_frame(points_mm, tol_mm: float = 1e-6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A plane frame (origin_mm, e1, e2) containing the 3-D points ``points_mm`` (k, 3) [mm].

    Points in a coordinate plane (spread along its normal ≤ ``tol_mm``) get that plane's axes
    exactly, in RS274/NGC order (XY: x, y; ZX: z, x; YZ: y, z), so the mapping adds no
    rounding and positive curvature means counter-clockwise about the G17/G18/G19 normal.
    Otherwise the best-fit plane by SVD (normal oriented with its largest component positive).
    The origin is the centroid (in-plane coordinate). Raises :class:`GeometryError` if the
    points deviate from their best-fit plane by more than ``tol_mm``.
    """
    pts = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    if pts.shape[0] == 0 or not np.all(np.isfinite(pts)):
        raise GeometryError("plane_frame needs finite points")
    scale = max(1.0, float(np.abs(pts).max()))
    origin = pts.mean(axis=0)
    spread = np.ptp(pts, axis=0)
    for plane in ("XY", "ZX", "YZ"):
        i, j = PLANE_AXES[plane]
        normal_axis = 3 - i - j
        if spread[normal_axis] <= tol_mm:
            e1, e2 = np.zeros(3), np.zeros(3)
            e1[i], e2[j] = 1.0, 1.0
            origin[normal_axis] = pts[0, normal_axis]
            return vec3(origin), vec3(e1), vec3(e2)
    _, sv, vh = np.linalg.svd(pts - origin)
    if sv.size < 2 or sv[1] <= 1e-12 * scale * np.sqrt(pts.shape[0]):
        # Collinear: any plane through the line; take the one containing the axis least
        # aligned with the line direction.
        direction = vh[0]
        normal = np.cross(direction, np.eye(3)[np.argmin(np.abs(direction))])
    else:
        normal = vh[2] if vh.shape[0] > 2 else np.cross(vh[0], vh[1])
    normal = normal / np.linalg.norm(normal)
    if normal[np.argmax(np.abs(normal))] < 0:
        normal = -normal
    off_plane = np.abs((pts - origin) @ normal).max()
    if off_plane > tol_mm:
        raise GeometryError(
            f"points are not planar (off-plane deviation {off_plane:.3g} mm); "
            "PH quintics need a planar curve"
        )
    e1 = vh[0] - (vh[0] @ normal) * normal
    e1 = e1 / np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    return vec3(origin), vec3(e1), vec3(e2)
