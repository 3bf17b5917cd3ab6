/* The CPython glue of the plan stage's compiled kernels: argument parsing, buffer checks,
 * result objects and the module definition. The numerics are in _kernels_math.h (ported
 * from their Python reference implementations, which remain the specification and the
 * fallback where this module was not built: setup.py, optional).
 *
 *   gated_rise(v0, v_top, gate_d, gate_c, a_max, j_max, dt, min_step, gallop, max_steps)
 *       -> (durations list, jerks list, distance) or None          [gated.gated_rise_py]
 *   gated_rise_merged(the same) -> (rise durations, rise jerks, descent durations,
 *       descent jerks, distance) or None               [gated._gated_rise_memo's merging]
 *   time_at_length(s0, v0, a0, jerk, duration, start, s, out, rel, newton, halvings, whole)
 *       -> None (out filled)                                     [profile._time_at_length_py]
 *   peak_speeds(v_s, v_e, length, v_cap, a, j, a_dn, j_dn, out, newton, rel)
 *       -> None (out filled)                                        [feedrate._peak_speed_py]
 *
 * The arrays are C-contiguous float64 buffers (the caller makes them so).
 * tests/test_plan_kernels.py compares every kernel with its Python reference.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "_kernels_math.h"

static int float64_buffer(Py_buffer *b, const char *what)
{
    /* The bytes of C-contiguous float64 arrays: the Python side makes them so. */
    if (b->len % (Py_ssize_t)sizeof(double)) {
        PyErr_Format(PyExc_TypeError, "%s: a contiguous float64 buffer is needed", what);
        return -1;
    }
    return 0;
}

static PyObject *list_of(const double *x, Py_ssize_t n)
{
    PyObject *list = PyList_New(n);
    if (!list)
        return NULL;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *f = PyFloat_FromDouble(x[i]);
        if (!f) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, i, f);
    }
    return list;
}

static PyObject *gated_rise(PyObject *self, PyObject *args)
{
    double v0, v_top, a_max, j_max, dt, min_step;
    long long gallop, max_steps;
    Py_buffer bd, bc;
    if (!PyArg_ParseTuple(args, "ddy*y*ddddLL", &v0, &v_top, &bd, &bc, &a_max, &j_max, &dt,
                          &min_step, &gallop, &max_steps))
        return NULL;
    PyObject *result = NULL;
    Phases out = {NULL, NULL, 0, 0};
    if (float64_buffer(&bd, "gate_d") < 0 || float64_buffer(&bc, "gate_c") < 0)
        goto done;
    if (bd.len != bc.len) {
        PyErr_SetString(PyExc_ValueError, "gate_d and gate_c differ in length");
        goto done;
    }
    Rise r = {(const double *)bd.buf, (const double *)bc.buf, bd.len / (Py_ssize_t)sizeof(double),
              j_max, a_max, min_step, 0, 0, 0.0, v0, 0.0};
    int status;
    Py_BEGIN_ALLOW_THREADS
    status = rise_loop(&r, v_top, dt, gallop, max_steps, &out);
    Py_END_ALLOW_THREADS
    if (status < 0) {
        PyErr_NoMemory();
        goto done;
    }
    if (status == 0) {
        result = Py_NewRef(Py_None);
        goto done;
    }
    PyObject *durs = list_of(out.d, out.n);
    PyObject *jerks = durs ? list_of(out.j, out.n) : NULL;
    if (durs && jerks)
        result = Py_BuildValue("(NNd)", durs, jerks, r.x);
    else {
        Py_XDECREF(durs);
        Py_XDECREF(jerks);
    }
done:
    free(out.d);
    free(out.j);
    PyBuffer_Release(&bd);
    PyBuffer_Release(&bc);
    return result;
}

/* gated_rise_merged(...): gated_rise's flank merged as gated._gated_rise_memo merges it:
 * (rise durations, rise jerks, descent durations, descent jerks, distance) or None — the
 * descent the reversed steps merged in their own order. */
static PyObject *gated_rise_merged(PyObject *self, PyObject *args)
{
    PyObject *flank = gated_rise(self, args);
    if (flank == NULL || flank == Py_None)
        return flank;
    PyObject *durs = PyTuple_GET_ITEM(flank, 0), *jerks = PyTuple_GET_ITEM(flank, 1);
    Py_ssize_t n = PyList_GET_SIZE(durs);
    Phases in = {NULL, NULL, 0, 0}, up = {NULL, NULL, 0, 0}, down = {NULL, NULL, 0, 0};
    PyObject *result = NULL;
    for (Py_ssize_t i = 0; i < n; i++)
        if (push(&in, PyFloat_AS_DOUBLE(PyList_GET_ITEM(durs, i)),
                 PyFloat_AS_DOUBLE(PyList_GET_ITEM(jerks, i))) < 0) {
            PyErr_NoMemory();
            goto done;
        }
    if (merge_phases(&in, 0, &up) < 0 || merge_phases(&in, 1, &down) < 0) {
        PyErr_NoMemory();
        goto done;
    }
    PyObject *parts[4] = {list_of(up.d, up.n), list_of(up.j, up.n), list_of(down.d, down.n),
                          list_of(down.j, down.n)};
    if (parts[0] && parts[1] && parts[2] && parts[3])
        result = Py_BuildValue("(NNNNO)", parts[0], parts[1], parts[2], parts[3],
                               PyTuple_GET_ITEM(flank, 2));
    else
        for (int i = 0; i < 4; i++)
            Py_XDECREF(parts[i]);
done:
    Py_DECREF(flank);
    free(in.d), free(in.j), free(up.d), free(up.j), free(down.d), free(down.j);
    return result;
}

static PyObject *time_at_length(PyObject *self, PyObject *args)
{
    Py_buffer b[8];
    double rel;
    int newton, halvings, whole;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*w*diii", &b[0], &b[1], &b[2], &b[3], &b[4], &b[5],
                          &b[6], &b[7], &rel, &newton, &halvings, &whole))
        return NULL;
    PyObject *result = NULL;
    static const char *names[8] = {"s0", "v0", "a0", "jerk", "duration", "start", "s", "out"};
    for (int i = 0; i < 8; i++)
        if (float64_buffer(&b[i], names[i]) < 0)
            goto done;
    Py_ssize_t n = b[0].len / (Py_ssize_t)sizeof(double);
    Py_ssize_t m = b[6].len / (Py_ssize_t)sizeof(double);
    for (int i = 1; i < 6; i++)
        if (b[i].len != b[0].len) {
            PyErr_SetString(PyExc_ValueError, "the phase columns differ in length");
            goto done;
        }
    if (b[7].len != b[6].len || n == 0) {
        PyErr_SetString(PyExc_ValueError, "time_at_length: no phases, or out not as long as s");
        goto done;
    }
    const double *s0 = b[0].buf, *v0 = b[1].buf, *a0 = b[2].buf, *jerk = b[3].buf,
                 *dur = b[4].buf, *start = b[5].buf, *s = b[6].buf;
    double *out = b[7].buf;
    Py_BEGIN_ALLOW_THREADS
    time_at_lengths(n, s0, v0, a0, jerk, dur, start, m, s, rel, newton, halvings, whole, out);
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    for (int i = 0; i < 8; i++)
        PyBuffer_Release(&b[i]);
    return result;
}

static PyObject *peak_speeds(PyObject *self, PyObject *args)
{
    Py_buffer b[9];
    int newton;
    double rel;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*y*w*id", &b[0], &b[1], &b[2], &b[3], &b[4], &b[5],
                          &b[6], &b[7], &b[8], &newton, &rel))
        return NULL;
    PyObject *result = NULL;
    for (int i = 1; i < 9; i++)
        if (b[i].len != b[0].len || b[i].len % (Py_ssize_t)sizeof(double)) {
            PyErr_SetString(PyExc_ValueError, "peak_speeds: the columns differ in length");
            goto done;
        }
    Py_ssize_t n = b[0].len / (Py_ssize_t)sizeof(double);
    const double *v_s = b[0].buf, *v_e = b[1].buf, *len = b[2].buf, *cap = b[3].buf,
                 *a = b[4].buf, *j = b[5].buf, *a_dn = b[6].buf, *j_dn = b[7].buf;
    double *out = b[8].buf;
    Py_BEGIN_ALLOW_THREADS
    peak_speeds_all(n, v_s, v_e, len, cap, a, j, a_dn, j_dn, newton, rel, out);
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    for (int i = 0; i < 9; i++)
        PyBuffer_Release(&b[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"peak_speeds", peak_speeds, METH_VARARGS, "feedrate._peak_speed_py, compiled."},
    {"gated_rise", gated_rise, METH_VARARGS, "gated.gated_rise_py, compiled."},
    {"gated_rise_merged", gated_rise_merged, METH_VARARGS,
     "gated.gated_rise_py, compiled, its phases merged (gated.merged_phases)."},
    {"time_at_length", time_at_length, METH_VARARGS, "profile._time_at_length_py, compiled."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernels",
    "Compiled kernels of the plan stage (gated.py, profile.py, feedrate.py).", -1, methods,
};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
