/* The compiled kernel of the geometry stage: the point-to-segments distance of
 * distance.py's _segment_distances_py, ported operation for operation from that Python
 * reference implementation, which remains the specification and the fallback where this
 * module was not built (setup.py: optional). Without its (pairs, 3) temporaries.
 *
 * Every result is bit for bit the Python one: IEEE double arithmetic in the same order,
 * each expression as numpy evaluates it (left to right, no reassociation), built with
 * -ffp-contract=off (no fused multiply-add) and without -ffast-math; sqrt is correctly
 * rounded. tests/test_plan_kernels.py compares the two on random inputs.
 *
 *   segment_distances(q, a, d, lo, hi, out)
 *       -> None (out filled)                                   [distance._segment_distances_py]
 *
 * The arrays are C-contiguous float64 (lo, hi: int64) buffers (the caller makes them so).
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

static PyMethodDef methods[] = {
    {"segment_distances", segment_distances, METH_VARARGS,
     "distance._segment_distances_py, compiled."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernels", "Compiled kernel of the geometry stage (distance.py).",
    -1, methods,
};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
