/* The spiral arcs' arc-length inversion of nurbscnc.geometry._kernels (included by
 * _kernels.c after its numpy helpers): segments._spiral_t_arrays for one arc, sample by
 * sample, ported operation for operation (the same bits; built with _kernels.c's flags:
 * -ffp-contract=off, no -ffast-math; sqrt, asinh and hypot from libm as numpy's on this
 * build). tests/test_paths.py compares the two.
 */
/* ------------------------------------------------------------------ spiral arc length */

/* numpy's clip of a float between scalar bounds (a value below lo or above hi replaced by
 * it, one equal to a bound kept, NaN propagated); -0.0 is kept with a scalar lower bound
 * but replaced with an array one (numpy's two loops), so the callers pass none. */
static inline double np_clip_keep(double x, double lo, double hi)
{
    double m = isnan(x) ? x : ((x < lo) ? lo : x);
    return isnan(m) ? m : ((m > hi) ? hi : m);
}

/* segments._spiral_length_at at one fraction t: s(t) (returned) and w(t) = dtheta r(t). */
static inline double spiral_length_at(double r0, double dr, double dtheta, double a2, double w0,
                                      double s0, double circle, double t, double *w_out)
{
    const double w1 = dtheta * (r0 + t * dr);
    const double s1 = sqrt(a2 + w1 * w1);
    const double ssum = s0 + s1, wsum = w0 + w1;
    const double cross = w1 * s0 + w0 * s1;
    double mean_speed = 0.25 * ssum + ((ssum > 0.0) ? wsum * wsum / (4.0 * ssum) : 0.0);
    if (cross != 0.0) {
        const double d = (w1 - w0) * wsum / cross;
        const double ratio = (d == 0.0) ? 1.0 : asinh(d) / d;
        mean_speed = mean_speed + 0.5 * a2 * ratio * wsum / cross;
    } else {
        mean_speed = mean_speed + 0.5 * sqrt(a2);
    }
    *w_out = w1;
    return t * ((dr == 0.0) ? circle : mean_speed);
}

/* segments._spiral_t_arrays for one arc (r0, r1, dtheta, h, its length big; all finite) and
 * the arc lengths s_in (m,), finite, none negative or -0.0: per sample the array code's
 * Newton, t <- clip(t - f/|C'|, 0, 1)
 * from t = s/big, stopped when |f| <= max(1e-12, 8 eps s) (t kept) or |t_new - t| <= 2 eps,
 * at most max_iter steps; samples at or beyond the ends keep t = s/big (0 when big = 0). */
static PyObject *spiral_t(PyObject *self, PyObject *args)
{
    double r0, r1, dtheta, h, big;
    Py_buffer bs, bout;
    int max_iter;
    if (!PyArg_ParseTuple(args, "dddddy*iw*", &r0, &r1, &dtheta, &h, &big, &bs, &max_iter, &bout))
        return NULL;
    PyObject *result = NULL;
    if (bout.len != bs.len) {
        PyErr_SetString(PyExc_ValueError, "spiral_t: inconsistent buffers");
        goto done;
    }
    const double eps = 2.220446049250313e-16;
    const double *s_in = bs.buf;
    double *out = bout.buf;
    const Py_ssize_t m = bs.len / (Py_ssize_t)sizeof(double);
    const double dr = r1 - r0;
    const double a2 = dr * dr + h * h;
    const double w0 = dtheta * r0;
    const double s0 = sqrt(a2 + w0 * w0);
    const double circle = hypot(w0, h);
    for (Py_ssize_t i = 0; i < m; i++) {
        /* the caller passes no s < 0 and no -0.0 (see np_clip_keep), so only s > big is
         * clipped */
        const double s = np_clip_keep(s_in[i], 0.0, big);
        double t = (big > 0.0) ? s / big : 0.0;
        if (s > 0.0 && s < big) {
            const double tol = np_maximum(1e-12, 8.0 * eps * s);
            for (int it = 0; it < max_iter; it++) {
                double w;
                const double f = spiral_length_at(r0, dr, dtheta, a2, w0, s0, circle, t, &w) - s;
                const int settled = fabs(f) <= tol;
                const double new_t = np_clip_keep(t - f / sqrt(a2 + w * w), 0.0, 1.0);
                const int finished = settled || fabs(new_t - t) <= 2.0 * eps;
                if (!settled)
                    t = new_t;
                if (finished)
                    break;
            }
        }
        out[i] = t;
    }
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&bs);
    PyBuffer_Release(&bout);
    return result;
}
