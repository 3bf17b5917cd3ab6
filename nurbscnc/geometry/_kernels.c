/* The compiled kernels of the geometry stage: the point-to-segments distance of
 * distance.py's _segment_distances_py and the bookkeeping of one safeguarded Newton step of
 * ph.py's bracketed_newton (_newton_step_py) and the B-spline basis derivatives of bspline.py
 * (_basis_derivatives_py), each ported operation for operation from its
 * Python reference implementation, which remains the specification and the fallback where
 * this module was not built (setup.py: optional). Without the numpy temporaries.
 *
 * Every result is bit for bit the Python one: IEEE double arithmetic in the same order,
 * each expression as numpy evaluates it (left to right, no reassociation), built with
 * -ffp-contract=off (no fused multiply-add) and without -ffast-math; sqrt is correctly
 * rounded. tests/test_plan_kernels.py compares the two on random inputs.
 *
 *   segment_distances(q, a, d, lo, hi, out)
 *       -> None (out filled)                                   [distance._segment_distances_py]
 *   basis_derivatives(knots, spans, u, degree, n_ders, out)
 *       -> None (out (n_ders + 1, degree + 1, m) filled)       [bspline._basis_derivatives_py]
 *   nurbs_derivatives(knots, spans, u, degree, order, pw, out)
 *       -> None (out (order + 1, m, 3) filled)          [nurbs.NurbsCurve._derivatives_py]
 *   nurbs_derivatives_at(knots, u, u_lo, u_hi, degree, order, pw, out)
 *       -> None (the same, u clipped and spans found here)          [NurbsCurve.derivatives]
 *   powerform_speed(coeffs, centers, u, spans, degree, out)
 *       -> None (out: |C'(u)|)                              [powerform.PowerForm._speed_py]
 *   newton_step(f, df, xa, a, b, idx, x, ftol)
 *       -> the number still going (xa, a, b, idx compacted; x of the finished set)
 *                                                                        [ph._newton_step_py]
 *   ph_closest(cp_re, cp_im, w_re, w_im, xs, q_re, q_im, max_steps, out)
 *       -> None (out: the foot parameters)                [ph._closest_param_py]
 *   spiral_t(r0, r1, dtheta, h, length, s, max_iter, out)
 *       -> None (out: fractions t of one arc at arc lengths s)  [segments._spiral_t_arrays]
 *
 * The arrays are C-contiguous float64 (lo, hi, idx: int64) buffers (the caller makes them so).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

/* numpy's minimum and clip of two floats: NaN-propagating. */
static inline double np_minimum(double a, double b) { return (a <= b || isnan(a)) ? a : b; }
static inline double np_clip(double x, double lo, double hi)
{
    double m = isnan(x) ? x : ((x > lo) ? x : lo);
    return isnan(m) ? m : ((m < hi) ? m : hi);
}

/* ------------------------------------------------------------------ contour distance */

/* distance._segment_distances_py: for each point q_i (m, 3), the smallest distance to the
 * segments a_k + t d_k (t in [0, 1]) for k in [lo_i, hi_i) (inf when empty). Dot products
 * as (x0 y0 + x1 y1) + x2 y2; t = (qa.d) / |d|^2 clipped to [0, 1] (0 where |d|^2 = 0); the
 * minimum NaN-propagating as numpy's. */
static PyObject *segment_distances(PyObject *self, PyObject *args)
{
    Py_buffer bq, ba, bd, blo, bhi, bout;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*w*", &bq, &ba, &bd, &blo, &bhi, &bout))
        return NULL;
    PyObject *result = NULL;
    Py_ssize_t m = bq.len / (Py_ssize_t)(3 * sizeof(double));
    Py_ssize_t n = ba.len / (Py_ssize_t)(3 * sizeof(double));
    if (bq.len != m * (Py_ssize_t)(3 * sizeof(double)) || ba.len != bd.len ||
        ba.len != n * (Py_ssize_t)(3 * sizeof(double)) ||
        blo.len != m * (Py_ssize_t)sizeof(long long) || bhi.len != blo.len ||
        bout.len != m * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "segment_distances: inconsistent buffers");
        goto done;
    }
    const double *q = bq.buf, *a = ba.buf, *d = bd.buf;
    const long long *lo = blo.buf, *hi = bhi.buf;
    double *out = bout.buf;
    for (Py_ssize_t i = 0; i < m; i++)
        if (lo[i] < 0 || hi[i] > n) {
            PyErr_SetString(PyExc_IndexError, "segment_distances: a range outside the segments");
            goto done;
        }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m; i++) {
        const double q0 = q[3 * i], q1 = q[3 * i + 1], q2 = q[3 * i + 2];
        double best = INFINITY;
        int any = 0;
        for (long long k = lo[i]; k < hi[i]; k++) {
            const double *ak = a + 3 * k, *dk = d + 3 * k;
            double e0 = q0 - ak[0], e1 = q1 - ak[1], e2 = q2 - ak[2];
            double len2 = (dk[0] * dk[0] + dk[1] * dk[1]) + dk[2] * dk[2];
            double t = ((e0 * dk[0] + e1 * dk[1]) + e2 * dk[2]) / (len2 > 0.0 ? len2 : 1.0);
            t = np_clip(len2 > 0.0 ? t : 0.0, 0.0, 1.0);
            e0 = e0 - t * dk[0];
            e1 = e1 - t * dk[1];
            e2 = e2 - t * dk[2];
            double dist = sqrt((e0 * e0 + e1 * e1) + e2 * e2);
            best = any ? np_minimum(best, dist) : dist;
            any = 1;
        }
        out[i] = best;
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&bq);
    PyBuffer_Release(&ba);
    PyBuffer_Release(&bd);
    PyBuffer_Release(&blo);
    PyBuffer_Release(&bhi);
    PyBuffer_Release(&bout);
    return result;
}

/* ------------------------------------------------------------------ B-spline basis */

/* Largest degree the compiled basis takes (its per-sample tables live on the stack); the
 * caller runs the Python loops above it. */
#define BASIS_MAX_DEGREE 15

/* P&T A2.3 at one parameter us in knot span span: ders[k][r] = d^k N_{span-p+r, p}/du^k
 * for k <= n_top, unscaled (the callers multiply row k by p!/(p-k)!): ndu (knot differences
 * below the diagonal, basis functions of rising degree on and above it), then the a-table
 * recurrence, each expression in bspline._basis_derivatives_py's order. */
static void ders_one(const double *knots, long long span, int p, double us, int n_top,
                     double ders[][BASIS_MAX_DEGREE + 1])
{
    double ndu[BASIS_MAX_DEGREE + 1][BASIS_MAX_DEGREE + 1];
    double left[BASIS_MAX_DEGREE + 1], right[BASIS_MAX_DEGREE + 1];
    double a[2][BASIS_MAX_DEGREE + 1];
    ndu[0][0] = 1.0;
    for (int j = 1; j <= p; j++) {
        left[j] = us - knots[span + 1 - j];
        right[j] = knots[span + j] - us;
        double saved = 0.0;
        for (int r = 0; r < j; r++) {
            ndu[j][r] = right[r + 1] + left[j - r];
            const double temp = ndu[r][j - 1] / ndu[j][r];
            ndu[r][j] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        ndu[j][j] = saved;
    }
    for (int r = 0; r <= p; r++)
        ders[0][r] = ndu[r][p];
    for (int r = 0; r <= p; r++) {
        int s1 = 0, s2 = 1;
        a[0][0] = 1.0;
        for (int k = 1; k <= n_top; k++) {
            double d = 0.0;
            const int rk = r - k, pk = p - k;
            if (r >= k) {
                a[s2][0] = a[s1][0] / ndu[pk + 1][rk];
                d = a[s2][0] * ndu[rk][pk];
            }
            const int j1 = rk >= -1 ? 1 : -rk;
            const int j2 = r - 1 <= pk ? k - 1 : p - r;
            for (int j = j1; j <= j2; j++) {
                a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][rk + j];
                d += a[s2][j] * ndu[rk + j][pk];
            }
            if (r <= pk) {
                a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r];
                d += a[s2][k] * ndu[r][pk];
            }
            ders[k][r] = d;
            const int t = s1;
            s1 = s2;
            s2 = t;
        }
    }
}

/* bspline._basis_derivatives_py (Piegl & Tiller A2.3) for each parameter u[s] in its knot
 * span spans[s]: ndu (knot differences below the diagonal, basis functions of rising degree
 * on and above it), then the derivatives by the a-table recurrence, each expression in the
 * reference's order; out[k][r][s] = d^k N_{span-p+r, p}/du^k, times p!/(p-k)! as the
 * reference scales them (k > min(n_ders, p): zero). */
static PyObject *basis_derivatives(PyObject *self, PyObject *args)
{
    Py_buffer bk, bsp, bu, bout;
    int p, n_ders;
    if (!PyArg_ParseTuple(args, "y*y*y*iiw*", &bk, &bsp, &bu, &p, &n_ders, &bout))
        return NULL;
    PyObject *result = NULL;
    const Py_ssize_t nk = bk.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t m = bu.len / (Py_ssize_t)sizeof(double);
    if (p < 0 || p > BASIS_MAX_DEGREE || n_ders < 0 ||
        bu.len != m * (Py_ssize_t)sizeof(double) ||
        bsp.len != m * (Py_ssize_t)sizeof(long long) ||
        bout.len != (Py_ssize_t)(n_ders + 1) * (p + 1) * m * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "basis_derivatives: inconsistent buffers");
        goto done;
    }
    const double *knots = bk.buf, *u = bu.buf;
    const long long *spans = bsp.buf;
    double *out = bout.buf;
    for (Py_ssize_t s = 0; s < m; s++)
        if (spans[s] + 1 - p < 0 || spans[s] + p >= nk) {
            PyErr_SetString(PyExc_IndexError, "basis_derivatives: a span outside the knots");
            goto done;
        }
    const int n_top = n_ders < p ? n_ders : p;
    const Py_ssize_t plane = (Py_ssize_t)(p + 1) * m; /* one derivative order */
    for (Py_ssize_t i = 0; i < (Py_ssize_t)(n_ders + 1) * plane; i++)
        out[i] = 0.0;
    double ders[BASIS_MAX_DEGREE + 1][BASIS_MAX_DEGREE + 1];
    for (Py_ssize_t s = 0; s < m; s++) {
        ders_one(knots, spans[s], p, u[s], n_top, ders);
        for (int k = 0; k <= n_top; k++)
            for (int r = 0; r <= p; r++)
                out[k * plane + (Py_ssize_t)r * m + s] = ders[k][r];
    }
    double factor = (double)p;
    for (int k = 1; k <= n_top; k++) {
        for (Py_ssize_t i = 0; i < plane; i++)
            out[k * plane + i] *= factor;
        factor *= (double)(p - k);
    }
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&bk);
    PyBuffer_Release(&bsp);
    PyBuffer_Release(&bu);
    PyBuffer_Release(&bout);
    return result;
}

/* ------------------------------------------------------------------ NURBS derivatives */

/* bspline.basis_functions (P&T A2.2) at one parameter us in knot span span: n[0..p]. */
static inline void basis_one(const double *knots, long long span, int p, double us, double *n)
{
    double left[BASIS_MAX_DEGREE + 1], right[BASIS_MAX_DEGREE + 1];
    n[0] = 1.0;
    for (int j = 1; j <= p; j++) {
        left[j] = us - knots[span + 1 - j];
        right[j] = knots[span + j] - us;
        double saved = 0.0;
        for (int r = 0; r < j; r++) {
            const double temp = n[r] / (right[r + 1] + left[j - r]);
            n[r] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        n[j] = saved;
    }
}

/* bspline.find_span of a clipped parameter: the last i with knots[i] <= u (numpy's
 * searchsorted side="right", minus one; NaN sorts last), clipped to [p, n_ctrl - 1]. */
static inline long long span_of(const double *knots, Py_ssize_t nk, int p, double u)
{
    const long long n_ctrl = (long long)nk - p - 1;
    long long i;
    if (isnan(u)) {
        i = (long long)nk - 1;
    } else {
        Py_ssize_t lo = 0, hi = nk; /* the first index with knots[index] > u */
        while (lo < hi) {
            const Py_ssize_t mid = lo + (hi - lo) / 2;
            if (knots[mid] <= u)
                lo = mid + 1;
            else
                hi = mid;
        }
        i = (long long)lo - 1;
    }
    return i < p ? p : (i > n_ctrl - 1 ? n_ctrl - 1 : i);
}

/* NurbsCurve.derivatives without its numpy set-up: each u clipped to [u_lo, u_hi] as
 * np.clip, its span by span_of, then nurbs_derivatives' arithmetic. */
static PyObject *nurbs_derivatives(PyObject *self, PyObject *args);
static PyObject *nurbs_derivatives_at(PyObject *self, PyObject *args)
{
    Py_buffer bk, bu;
    double u_lo, u_hi;
    int p, order;
    PyObject *pw, *out;
    if (!PyArg_ParseTuple(args, "y*y*ddiiOO", &bk, &bu, &u_lo, &u_hi, &p, &order, &pw, &out))
        return NULL;
    PyObject *result = NULL, *uc = NULL, *sp = NULL;
    const Py_ssize_t nk = bk.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t m = bu.len / (Py_ssize_t)sizeof(double);
    if (p < 0 || p > BASIS_MAX_DEGREE || nk < 2 * (Py_ssize_t)p + 2) {
        PyErr_SetString(PyExc_ValueError, "nurbs_derivatives_at: inconsistent knots");
        goto done;
    }
    uc = PyBytes_FromStringAndSize(NULL, m * (Py_ssize_t)sizeof(double));
    sp = PyBytes_FromStringAndSize(NULL, m * (Py_ssize_t)sizeof(long long));
    if (uc == NULL || sp == NULL)
        goto done;
    double *ucv = (double *)PyBytes_AS_STRING(uc);
    long long *spv = (long long *)PyBytes_AS_STRING(sp);
    const double *knots = bk.buf, *u = bu.buf;
    for (Py_ssize_t s = 0; s < m; s++) {
        ucv[s] = np_clip(u[s], u_lo, u_hi);
        spv[s] = span_of(knots, nk, p, ucv[s]);
    }
    PyObject *inner = Py_BuildValue("OOOiiOO", PyTuple_GET_ITEM(args, 0), sp, uc, p, order, pw, out);
    if (inner == NULL)
        goto done;
    result = nurbs_derivatives(self, inner);
    Py_DECREF(inner);
done:
    Py_XDECREF(uc);
    Py_XDECREF(sp);
    PyBuffer_Release(&bk);
    PyBuffer_Release(&bu);
    return result;
}

/* nurbs.NurbsCurve._derivatives_py: C and its derivatives up to order at each u[s] (already
 * clipped; spans[s] its knot span) from the homogeneous control points pw (4, n), components
 * first. Order 0: the A2.2 basis, acc = sum_j N_j pw[:, first + j] left to right, C = acc / w.
 * Order >= 1: the A2.3 derivatives (basis_derivatives' arithmetic, as it scales them), the
 * homogeneous derivatives hom[k] = 0 + sum_j ders[k][j] pw[:, first + j] (zero above p), then
 * the quotient rule of bspline.rational_derivatives. out (order + 1, m, 3). */
static PyObject *nurbs_derivatives(PyObject *self, PyObject *args)
{
    Py_buffer bk, bsp, bu, bpw, bout;
    int p, order;
    if (!PyArg_ParseTuple(args, "y*y*y*iiy*w*", &bk, &bsp, &bu, &p, &order, &bpw, &bout))
        return NULL;
    PyObject *result = NULL;
    const Py_ssize_t nk = bk.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t m = bu.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t n_ctrl = bpw.len / (4 * (Py_ssize_t)sizeof(double));
    if (p < 0 || p > BASIS_MAX_DEGREE || order < 0 || order > 2 * BASIS_MAX_DEGREE ||
        bu.len != m * (Py_ssize_t)sizeof(double) ||
        bsp.len != m * (Py_ssize_t)sizeof(long long) ||
        bpw.len != 4 * n_ctrl * (Py_ssize_t)sizeof(double) ||
        bout.len != (Py_ssize_t)(order + 1) * m * 3 * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "nurbs_derivatives: inconsistent buffers");
        goto done;
    }
    const double *knots = bk.buf, *u = bu.buf, *pw = bpw.buf;
    const long long *spans = bsp.buf;
    double *out = bout.buf;
    for (Py_ssize_t s = 0; s < m; s++)
        if (spans[s] + 1 - p < 0 || spans[s] + p >= nk || spans[s] - p < 0 ||
            spans[s] >= n_ctrl) {
            PyErr_SetString(PyExc_IndexError, "nurbs_derivatives: a span outside the knots");
            goto done;
        }
    const int n_top = order < p ? order : p;
    double ders[BASIS_MAX_DEGREE + 1][BASIS_MAX_DEGREE + 1]; /* [k][r], k <= n_top */
    double hom[2 * BASIS_MAX_DEGREE + 1][4];
    double cw[2 * BASIS_MAX_DEGREE + 1][3];
    for (Py_ssize_t s = 0; s < m; s++) {
        const double us = u[s];
        const long long span = spans[s], first = span - p;
        if (order == 0) {
            double n[BASIS_MAX_DEGREE + 1];
            basis_one(knots, span, p, us, n);
            double acc[4];
            for (int c = 0; c < 4; c++)
                acc[c] = n[0] * pw[c * n_ctrl + first];
            for (int j = 1; j <= p; j++)
                for (int c = 0; c < 4; c++)
                    acc[c] += n[j] * pw[c * n_ctrl + first + j];
            for (int c = 0; c < 3; c++)
                out[s * 3 + c] = acc[c] / acc[3];
            continue;
        }
        ders_one(knots, span, p, us, n_top, ders); /* basis_derivatives' arithmetic */
        double factor = (double)p;
        for (int k = 1; k <= n_top; k++) {
            for (int r = 0; r <= p; r++)
                ders[k][r] *= factor;
            factor *= (double)(p - k);
        }
        /* the homogeneous derivatives, then the quotient rule */
        for (int k = 0; k <= order; k++)
            for (int c = 0; c < 4; c++)
                hom[k][c] = 0.0;
        for (int j = 0; j <= p; j++)
            for (int k = 0; k <= n_top; k++)
                for (int c = 0; c < 4; c++)
                    hom[k][c] += ders[k][j] * pw[c * n_ctrl + first + j];
        for (int k = 0; k <= order; k++) {
            double binom = 1.0; /* C(k, i), exact in doubles for these k */
            double v[3] = {hom[k][0], hom[k][1], hom[k][2]};
            for (int i = 1; i <= k; i++) {
                binom = binom * (double)(k - i + 1) / (double)i;
                const double bw = binom * hom[i][3];
                for (int c = 0; c < 3; c++)
                    v[c] -= bw * cw[k - i][c];
            }
            for (int c = 0; c < 3; c++) {
                cw[k][c] = v[c] / hom[0][3];
                out[((Py_ssize_t)k * m + s) * 3 + c] = cw[k][c];
            }
        }
    }
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&bk);
    PyBuffer_Release(&bsp);
    PyBuffer_Release(&bu);
    PyBuffer_Release(&bpw);
    PyBuffer_Release(&bout);
    return result;
}

/* ------------------------------------------------------------------ power-form speed */

/* powerform.PowerForm._speed_py: |C'(u)| = |A'w - Aw'| / w^2 at each u[s] on span spans[s],
 * A and A' by Horner's rule with one derivative row (acc1 = acc1 x + acc0, then
 * acc0 = acc0 x + c[k], from acc1 = 0), the squared norm summed over x, y, z in that order
 * (numpy's einsum order for two samples or more; the caller runs numpy for one). */
static PyObject *powerform_speed(PyObject *self, PyObject *args)
{
    Py_buffer bc, bctr, bu, bsp, bout;
    int p;
    if (!PyArg_ParseTuple(args, "y*y*y*y*iw*", &bc, &bctr, &bu, &bsp, &p, &bout))
        return NULL;
    PyObject *result = NULL;
    const Py_ssize_t n_spans = bctr.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t m = bu.len / (Py_ssize_t)sizeof(double);
    if (p < 0 || bc.len != (Py_ssize_t)(p + 1) * 4 * n_spans * (Py_ssize_t)sizeof(double) ||
        bsp.len != m * (Py_ssize_t)sizeof(long long) || bout.len != bu.len) {
        PyErr_SetString(PyExc_ValueError, "powerform_speed: inconsistent buffers");
        goto done;
    }
    const double *c = bc.buf, *centers = bctr.buf, *u = bu.buf;
    const long long *spans = bsp.buf;
    double *out = bout.buf;
    for (Py_ssize_t s = 0; s < m; s++)
        if (spans[s] < 0 || spans[s] >= n_spans) {
            PyErr_SetString(PyExc_IndexError, "powerform_speed: a span outside the table");
            goto done;
        }
    const Py_ssize_t row = 4 * n_spans; /* one power k: (4, n_spans) */
    for (Py_ssize_t s = 0; s < m; s++) {
        const long long j = spans[s];
        const double x = u[s] - centers[j];
        double a[4], da[4];
        for (int i = 0; i < 4; i++) {
            a[i] = c[(Py_ssize_t)p * row + i * n_spans + j];
            da[i] = 0.0;
        }
        for (int k = p - 1; k >= 0; k--)
            for (int i = 0; i < 4; i++) {
                da[i] = da[i] * x + a[i];
                a[i] = a[i] * x + c[(Py_ssize_t)k * row + i * n_spans + j];
            }
        double sum = 0.0;
        for (int i = 0; i < 3; i++) {
            const double num = da[i] * a[3] - a[i] * da[3];
            sum += num * num;
        }
        out[s] = sqrt(sum) / (a[3] * a[3]);
    }
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&bc);
    PyBuffer_Release(&bctr);
    PyBuffer_Release(&bu);
    PyBuffer_Release(&bsp);
    PyBuffer_Release(&bout);
    return result;
}

/* ------------------------------------------------------------------ bracketed Newton */

/* numpy's maximum of two floats: NaN-propagating (the first argument wins ties). */
static inline double np_maximum(double a, double b) { return (a >= b || isnan(a)) ? a : b; }

/* ph._newton_step_py: one step of the safeguarded Newton iteration for the n active elements
 * (f, df their function values at xa; [a, b] their brackets). The bracket side of f's sign
 * moves to xa; the Newton point xa - f/df is kept if it lies strictly inside the bracket with
 * df > 0, else the bracket's middle; an element is done when |f| <= ftol, when the kept Newton
 * step is at rounding level (2 eps max(1, |xa|)) or when the bracket has collapsed
 * (4 eps max(1, |xa|)). Every element takes its step (but where |f| <= ftol); the finished
 * ones are written to x[idx], the others moved to the front of xa, a, b, idx in order. */
static PyObject *newton_step(PyObject *self, PyObject *args)
{
    Py_buffer bf, bdf, bxa, ba, bb, bidx, bx;
    double ftol;
    if (!PyArg_ParseTuple(args, "y*y*w*w*w*w*w*d", &bf, &bdf, &bxa, &ba, &bb, &bidx, &bx, &ftol))
        return NULL;
    PyObject *result = NULL;
    const Py_ssize_t n = bf.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t nx = bx.len / (Py_ssize_t)sizeof(double);
    if (bf.len != n * (Py_ssize_t)sizeof(double) || bdf.len != bf.len || bxa.len < bf.len ||
        ba.len < bf.len || bb.len < bf.len || bidx.len < n * (Py_ssize_t)sizeof(long long)) {
        PyErr_SetString(PyExc_ValueError, "newton_step: inconsistent buffers");
        goto done;
    }
    const double *f = bf.buf, *df = bdf.buf;
    double *xa = bxa.buf, *a = ba.buf, *b = bb.buf, *x = bx.buf;
    long long *idx = bidx.buf;
    for (Py_ssize_t i = 0; i < n; i++)
        if (idx[i] < 0 || idx[i] >= nx) {
            PyErr_SetString(PyExc_IndexError, "newton_step: an index outside x");
            goto done;
        }
    const double eps = 2.220446049250313e-16; /* np.finfo(float).eps */
    Py_ssize_t kept = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        const double xi = xa[i], fi = f[i], dfi = df[i];
        const int neg = fi < 0.0;
        const double ai = neg ? xi : a[i];
        const double bi = neg ? b[i] : xi;
        double xn = xi - fi / dfi;
        const int inside = (xn > ai) && (xn < bi) && (dfi > 0.0);
        if (!inside)
            xn = 0.5 * (ai + bi);
        const double scale = np_maximum(1.0, fabs(xi));
        const int small = fabs(fi) <= ftol;
        const int finished = small || (inside && fabs(xn - xi) <= (2.0 * eps) * scale) ||
                             (bi - ai <= (4.0 * eps) * scale);
        const double xnew = small ? xi : xn;
        if (finished) {
            x[idx[i]] = xnew;
        } else {
            xa[kept] = xnew;
            a[kept] = ai;
            b[kept] = bi;
            idx[kept] = idx[i];
            kept++;
        }
    }
    result = PyLong_FromSsize_t(kept);
done:
    PyBuffer_Release(&bf);
    PyBuffer_Release(&bdf);
    PyBuffer_Release(&bxa);
    PyBuffer_Release(&ba);
    PyBuffer_Release(&bb);
    PyBuffer_Release(&bidx);
    PyBuffer_Release(&bx);
    return result;
}

/* ------------------------------------------------------------------ PH foot points */

/* phfoot._point_xy: r(x) of the PH quintic with control points (cr, ci), the Bernstein sum
 * written out as there. */
static inline void ph_point(const double *cr, const double *ci, double x, double *re, double *im)
{
    const double t = 1.0 - x;
    const double t2 = t * t, t3 = t2 * t, t4 = t3 * t;
    const double x2 = x * x, x3 = x2 * x, x4 = x3 * x;
    const double bs[6] = {t4 * t, (5.0 * x) * t4, (10.0 * x2) * t3, (10.0 * x3) * t2,
                          (5.0 * x4) * t, x4 * x};
    double r = bs[0] * cr[0], i = bs[0] * ci[0];
    for (int k = 1; k < 6; k++) {
        r = r + bs[k] * cr[k];
        i = i + bs[k] * ci[k];
    }
    *re = r;
    *im = i;
}

/* phfoot._g_terms: g and g' at x for the point (qr, qi). */
static inline void ph_g(const double *cr, const double *ci, const double *wr_, const double *wi_,
                        double x, double qr, double qi, double *g, double *dg)
{
    const double t = 1.0 - x;
    const double a0 = t * t, a1 = 2.0 * (t * x), a2 = x * x;
    const double wr = (a0 * wr_[0] + a1 * wr_[1]) + a2 * wr_[2];
    const double wi = (a0 * wi_[0] + a1 * wi_[1]) + a2 * wi_[2];
    const double dwr = 2.0 * ((wr_[1] - wr_[0]) * t + (wr_[2] - wr_[1]) * x);
    const double dwi = 2.0 * ((wi_[1] - wi_[0]) * t + (wi_[2] - wi_[1]) * x);
    const double r1r = wr * wr - wi * wi, r1i = 2.0 * (wr * wi);
    const double r2r = 2.0 * (wr * dwr - wi * dwi), r2i = 2.0 * (wr * dwi + wi * dwr);
    double px, py;
    ph_point(cr, ci, x, &px, &py);
    const double dx = px - qr, dy = py - qi;
    *g = dx * r1r + dy * r1i;
    *dg = (r1r * r1r + r1i * r1i) + (dx * r2r + dy * r2i);
}

/* ph._closest_param_py: for each point q_j the nearest of the dense samples xs
 * (squared distance, the first of equal ones), the bracket where g changes sign, then the
 * safeguarded Newton of bracketed_newton (newton_step's arithmetic, ftol 0) to its end, at
 * most max_steps steps; without a bracket the nearest sample. */
static PyObject *ph_closest(PyObject *self, PyObject *args)
{
    Py_buffer bcr, bci, bwr, bwi, bxs, bqr, bqi, bout;
    int max_steps;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*iw*", &bcr, &bci, &bwr, &bwi, &bxs, &bqr, &bqi,
                          &max_steps, &bout))
        return NULL;
    PyObject *result = NULL;
    const Py_ssize_t nd = bxs.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t m = bqr.len / (Py_ssize_t)sizeof(double);
    double *rx = NULL, *ry = NULL;
    if (bcr.len != 6 * (Py_ssize_t)sizeof(double) || bci.len != bcr.len ||
        bwr.len != 3 * (Py_ssize_t)sizeof(double) || bwi.len != bwr.len || nd < 1 ||
        bqi.len != bqr.len || bout.len != bqr.len) {
        PyErr_SetString(PyExc_ValueError, "ph_closest: inconsistent buffers");
        goto done;
    }
    const double *cr = bcr.buf, *ci = bci.buf, *wr = bwr.buf, *wi = bwi.buf, *xs = bxs.buf;
    const double *qr = bqr.buf, *qi = bqi.buf;
    double *out = bout.buf;
    rx = PyMem_Malloc(2 * nd * sizeof(double));
    if (rx == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    ry = rx + nd;
    for (Py_ssize_t k = 0; k < nd; k++)
        ph_point(cr, ci, xs[k], &rx[k], &ry[k]);
    const double eps = 2.220446049250313e-16; /* np.finfo(float).eps */
    for (Py_ssize_t j = 0; j < m; j++) {
        Py_ssize_t near = 0;
        double best = 0.0;
        for (Py_ssize_t k = 0; k < nd; k++) {
            const double dx = rx[k] - qr[j], dy = ry[k] - qi[j];
            const double d2 = dx * dx + dy * dy;
            /* np.argmin: the first minimum; a NaN is the minimum at once. */
            if (k == 0 || d2 < best || (isnan(d2) && !isnan(best))) {
                best = d2;
                near = k;
            }
        }
        const double x_mid = xs[near];
        const double x_lo = xs[near > 0 ? near - 1 : 0];
        const double x_hi = xs[near + 1 < nd ? near + 1 : nd - 1];
        double g_lo, g_mid, g_hi, unused;
        ph_g(cr, ci, wr, wi, x_lo, qr[j], qi[j], &g_lo, &unused);
        ph_g(cr, ci, wr, wi, x_mid, qr[j], qi[j], &g_mid, &unused);
        ph_g(cr, ci, wr, wi, x_hi, qr[j], qi[j], &g_hi, &unused);
        const int left = (g_lo <= 0.0) && (g_mid >= 0.0);
        const int right = !left && (g_mid <= 0.0) && (g_hi >= 0.0);
        double a = left ? x_lo : x_mid;
        double b = left ? x_mid : (right ? x_hi : x_mid);
        if (!((left || right) && (b > a))) {
            out[j] = x_mid;
            continue;
        }
        double xa = np_clip(x_mid, a, b);
        int finished = 0;
        for (int it = 0; it < max_steps && !finished; it++) {
            double fi, dfi;
            ph_g(cr, ci, wr, wi, xa, qr[j], qi[j], &fi, &dfi);
            const int neg = fi < 0.0;
            const double ai = neg ? xa : a;
            const double bi = neg ? b : xa;
            double xn = xa - fi / dfi;
            const int inside = (xn > ai) && (xn < bi) && (dfi > 0.0);
            if (!inside)
                xn = 0.5 * (ai + bi);
            const double scale = np_maximum(1.0, fabs(xa));
            const int small = fabs(fi) <= 0.0;
            finished = small || (inside && fabs(xn - xa) <= (2.0 * eps) * scale) ||
                       (bi - ai <= (4.0 * eps) * scale);
            xa = small ? xa : xn;
            a = ai;
            b = bi;
        }
        out[j] = xa;
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    PyMem_Free(rx);
    PyBuffer_Release(&bcr);
    PyBuffer_Release(&bci);
    PyBuffer_Release(&bwr);
    PyBuffer_Release(&bwi);
    PyBuffer_Release(&bxs);
    PyBuffer_Release(&bqr);
    PyBuffer_Release(&bqi);
    PyBuffer_Release(&bout);
    return result;
}


#include "_kernels_spiral.h" /* spiral_t: needs np_maximum above */

static PyMethodDef methods[] = {
    {"segment_distances", segment_distances, METH_VARARGS,
     "distance._segment_distances_py, compiled."},
    {"basis_derivatives", basis_derivatives, METH_VARARGS,
     "bspline._basis_derivatives_py, compiled."},
    {"newton_step", newton_step, METH_VARARGS, "ph._newton_step_py, compiled."},
    {"ph_closest", ph_closest, METH_VARARGS, "ph._closest_param_py, compiled."},
    {"powerform_speed", powerform_speed, METH_VARARGS, "powerform.PowerForm._speed_py, compiled."},
    {"nurbs_derivatives", nurbs_derivatives, METH_VARARGS,
     "nurbs.NurbsCurve._derivatives_py, compiled."},
    {"nurbs_derivatives_at", nurbs_derivatives_at, METH_VARARGS,
     "nurbs.NurbsCurve.derivatives: clip, spans and nurbs_derivatives in one call."},
    {"spiral_t", spiral_t, METH_VARARGS, "segments._spiral_t_arrays for one arc, compiled."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernels", "Compiled kernels of the geometry stage (distance.py, bspline.py, ph.py, phfoot.py).",
    -1, methods,
};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
