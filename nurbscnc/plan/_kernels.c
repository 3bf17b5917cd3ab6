/* Compiled kernels of the plan stage: the loops numpy cannot vectorise (or only through
 * large temporaries), ported operation for operation from their Python reference
 * implementations — profile.py's _gated_rise_py and _time_at_length_py, feedrate.py's
 * _peak_speed_py — which remain the specification,
 * and the fallback where this module was not built (setup.py: optional).
 *
 * Every result is bit for bit the Python one: IEEE double arithmetic in the same order,
 * each expression as Python or numpy evaluates it (left to right, no reassociation), built
 * with -ffp-contract=off (no fused multiply-add) and without -ffast-math; sqrt and ceil
 * are correctly rounded / exact. tests/test_plan_kernels.py compares the two on random
 * and captured inputs.
 *
 *   gated_rise(v0, v_top, gate_d, gate_c, a_max, j_max, dt, min_step, gallop, max_steps)
 *       -> (durations list, jerks list, distance) or None       [profile._gated_rise_py]
 *   gated_rise_merged(the same) -> (rise durations, rise jerks, descent durations,
 *       descent jerks, distance) or None          [profile._gated_rise_memo's merging]
 *   time_at_length(s0, v0, a0, jerk, duration, start, s, out, rel, newton, halvings, whole)
 *       -> None (out filled)                                     [profile._time_at_length_py]
 *   peak_speeds(v_s, v_e, length, v_cap, a, j, a_dn, j_dn, out, newton, rel)
 *       -> None (out filled)                                        [feedrate._peak_speed_py]
 *
 * The arrays are C-contiguous float64 (lo, hi: int64) buffers (the caller makes them so).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>

/* ------------------------------------------------------------------ gated rise */

typedef struct {
    const double *gd, *gc; /* gates: distances [mm] (increasing), caps [mm/s] */
    Py_ssize_t n;
    double j, big_a, min_step;
    Py_ssize_t first; /* the first gate beyond x */
    int braking;
    double x, v, a; /* the state */
} Rise;

/* Python's min(p, q) and max(p, q) of two floats: the first unless the second is
 * strictly smaller (larger). */
static inline double py_min(double p, double q) { return (q < p) ? q : p; }
static inline double py_max(double p, double q) { return (q > p) ? q : p; }

/* _brake_ok */
static int brake_ok(const Rise *r, double x, double v, double a, Py_ssize_t first)
{
    double j = r->j;
    double v_end = v + a * a / (2.0 * j);
    for (Py_ssize_t m = first; m < r->n; m++) {
        double c = r->gc[m];
        if (c >= v_end)
            continue;
        if (v > c)
            return 0;
        double t_c = (a - sqrt(py_max(a * a - 2.0 * j * (c - v), 0.0))) / j;
        if (x + t_c * (v + t_c * (0.5 * a - t_c * j / 6.0)) < r->gd[m])
            return 0;
    }
    return 1;
}

/* advance(tau, jk) from (x, v, a) */
static inline void advance(double x, double v, double a, double tau, double jk,
                           double *x1, double *v1, double *a1)
{
    *x1 = x + tau * (v + tau * (0.5 * a + tau * jk / 6.0));
    *v1 = v + tau * (a + 0.5 * tau * jk);
    *a1 = a + tau * jk;
}

/* passes(x1, v1, a1) */
static int passes(const Rise *r, double x1, double v1, double a1)
{
    Py_ssize_t m = r->first;
    while (m < r->n && r->gd[m] <= x1) {
        if (v1 > r->gc[m] * (1.0 + 1e-12))
            return 0;
        m++;
    }
    return brake_ok(r, x1, v1, a1, m);
}

/* ok(t) of longest(jk, ·): passes(*advance(t, jk)) */
static int step_ok(const Rise *r, double jk, double t)
{
    double x1, v1, a1;
    advance(r->x, r->v, r->a, t, jk, &x1, &v1, &a1);
    return passes(r, x1, v1, a1);
}

/* _longest(ok, tau) */
static double longest_of(const Rise *r, double jk, double tau)
{
    if (step_ok(r, jk, tau))
        return tau;
    if (!step_ok(r, jk, r->min_step))
        return 0.0;
    double lo = r->min_step, hi = tau;
    while (hi - lo > 1e-12) {
        double mid = 0.5 * (lo + hi);
        if (step_ok(r, jk, mid))
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

/* longest(jk, tau): while braking, the shortest step first */
static double longest(const Rise *r, double jk, double tau)
{
    if (r->braking && !step_ok(r, jk, r->min_step))
        return 0.0;
    return longest_of(r, jk, tau);
}

/* finish(phases): the state after every phase but the last, then passes */
static int finish(const Rise *r, const double *taus, const double *jks, int count)
{
    double xs = r->x, vs = r->v, as_ = r->a;
    for (int i = 0; i < count - 1; i++) {
        double tau = taus[i], jk = jks[i];
        double x1 = xs + tau * (vs + tau * (0.5 * as_ + tau * jk / 6.0));
        double v1 = vs + tau * (as_ + 0.5 * tau * jk);
        double a1 = as_ + tau * jk;
        xs = x1;
        vs = v1;
        as_ = a1;
    }
    return passes(r, xs, vs, as_);
}

/* Growable list of phases. */
typedef struct {
    double *d, *j;
    Py_ssize_t n, cap;
} Phases;

static int push(Phases *p, double d, double j)
{
    if (p->n == p->cap) {
        Py_ssize_t cap = p->cap ? 2 * p->cap : 256;
        double *nd = realloc(p->d, (size_t)cap * sizeof(double));
        if (!nd)
            return -1;
        p->d = nd;
        double *nj = realloc(p->j, (size_t)cap * sizeof(double));
        if (!nj)
            return -1;
        p->j = nj;
        p->cap = cap;
    }
    p->d[p->n] = d;
    p->j[p->n] = j;
    p->n++;
    return 0;
}

/* Python's int(x) of a finite float as a long long, clamped far beyond any count used. */
static long long trunc_ll(double x)
{
    if (!(x < 4e18))
        return (long long)4e18;
    if (!(x > -4e18))
        return -(long long)4e18;
    return (long long)x; /* truncation towards zero, as int() */
}

static long long min_ll(long long p, long long q) { return (q < p) ? q : p; }

/* The loop of _gated_rise_py. Returns 1 (done: phases, r->x), 0 (None) or -1 (no memory). */
static int rise_loop(Rise *r, double v_top, double dt, long long gallop, long long max_steps,
                     Phases *out)
{
    const double j = r->j, big_a = r->big_a;
    const double tol = v_top * 1e-12;
    long long steps = 0, streak = 0;
    r->braking = 0;
    while (steps < max_steps) {
        steps += 1;
        while (r->first < r->n && r->gd[r->first] <= r->x)
            r->first++;
        if (r->a <= 0.0 && r->v >= v_top - tol)
            return 1;
        int done = 0;
        double done_d[2], done_j[2];
        if (r->a < big_a) {
            double a = r->a;
            double a1 = sqrt(j * py_max(v_top - r->v, 0.0) + 0.5 * a * a);
            if (a1 <= py_min(a + j * dt, big_a)) {
                double pd[2] = {(a1 - a) / j, a1 / j}, pj[2] = {j, -j};
                if (finish(r, pd, pj, 2)) {
                    done = 1;
                    done_d[0] = pd[0], done_d[1] = pd[1], done_j[0] = pj[0], done_j[1] = pj[1];
                }
            }
            else {
                long long n = min_ll(2 * streak, gallop);
                n = min_ll(n, trunc_ll((big_a - a) / (j * dt)));
                n = min_ll(n, a1 <= big_a ? trunc_ll(ceil((a1 - a) / (j * dt))) - 2 : gallop);
                n = min_ll(n, max_steps - steps + 1);
                double tau;
                double x1, v1, a1s;
                advance(r->x, r->v, r->a, (double)n * dt, j, &x1, &v1, &a1s);
                if (n >= 2 && passes(r, x1, v1, a1s)) {
                    tau = (double)n * dt;
                    steps = steps + n - 1;
                }
                else {
                    n = 1;
                    tau = longest(r, j, py_min(dt, (big_a - a) / j));
                }
                if (tau > 0.0) {
                    streak = (tau == (double)n * dt) ? n : 0;
                    r->braking = 0;
                    if (push(out, tau, j) < 0)
                        return -1;
                    advance(r->x, r->v, r->a, tau, j, &r->x, &r->v, &r->a);
                    continue;
                }
            }
        }
        streak = 0;
        if (!done && r->a > 0.0) {
            double a = r->a;
            double t0 = (v_top - r->v - a * a / (2.0 * j)) / a;
            if (t0 <= dt) {
                double pd[2] = {py_max(t0, 0.0), a / j}, pj[2] = {0.0, -j};
                if (finish(r, pd, pj, 2)) {
                    done = 1;
                    done_d[0] = pd[0], done_d[1] = pd[1], done_j[0] = pj[0], done_j[1] = pj[1];
                }
            }
            else {
                double tau = longest(r, 0.0, dt);
                if (tau > 0.0) {
                    r->braking = 0;
                    if (push(out, tau, 0.0) < 0)
                        return -1;
                    advance(r->x, r->v, r->a, tau, 0.0, &r->x, &r->v, &r->a);
                    continue;
                }
            }
        }
        if (done) {
            for (int i = 0; i < 2; i++) {
                if (done_d[i] > 0.0) {
                    if (push(out, done_d[i], done_j[i]) < 0)
                        return -1;
                    advance(r->x, r->v, r->a, done_d[i], done_j[i], &r->x, &r->v, &r->a);
                }
            }
            return 1;
        }
        if (r->a > 0.0) { /* brake */
            r->braking = 1;
            double t_b = r->a / j;
            double tau = py_min(dt, t_b);
            advance(r->x, r->v, r->a, tau, -j, &r->x, &r->v, &r->a);
            if (tau >= t_b || r->a < 1e-12 * big_a)
                r->a = 0.0;
            if (push(out, tau, -j) < 0)
                return -1;
            continue;
        }
        /* a = 0 and a gate ahead at the speed v: cruise just past it */
        if (r->first >= r->n || r->v <= 0.0 || r->v > r->gc[r->first] * (1.0 + 1e-12))
            return 0;
        double tau = (r->gd[r->first] - r->x) / r->v * (1.0 + 1e-12) + 1e-15;
        if (push(out, tau, 0.0) < 0)
            return -1;
        advance(r->x, r->v, r->a, tau, 0.0, &r->x, &r->v, &r->a);
    }
    return 0;
}

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

/* profile._merged: consecutive phases of equal jerk as one (in order, or reversed). */
static int merge_phases(const Phases *in, int reverse, Phases *out)
{
    for (Py_ssize_t k = 0; k < in->n; k++) {
        Py_ssize_t i = reverse ? in->n - 1 - k : k;
        double d = in->d[i], jk = in->j[i];
        if (d <= 0.0)
            continue;
        if (out->n && out->j[out->n - 1] == jk)
            out->d[out->n - 1] += d;
        else if (push(out, d, jk) < 0)
            return -1;
    }
    return 0;
}

/* gated_rise_merged(...): gated_rise's flank merged as profile._gated_rise_memo merges it:
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

/* ------------------------------------------------------------------ time at length */

/* numpy's maximum/minimum of two floats (NaN propagating) and clip's (x, lo, hi) */
static inline double np_maximum(double a, double b) { return (a >= b || isnan(a)) ? a : b; }
static inline double np_minimum(double a, double b) { return (a <= b || isnan(a)) ? a : b; }
static inline double np_clip(double x, double lo, double hi)
{
    double m = isnan(x) ? x : ((x > lo) ? x : lo);
    return isnan(m) ? m : ((m < hi) ? m : hi);
}

static inline double phase_s(double t, double s0, double v0, double c2, double c3)
{
    return s0 + t * (v0 + t * (c2 + t * c3));
}

/* _time_at_length_py for TAL_BATCH queries at a time, in lockstep: each query's Newton steps
 * and halvings are a chain of dependent operations, so the queries of a batch are stepped
 * together (their chains overlap in the processor; the selections are branch-free) — the
 * same operations per query as one at a time. s0 … dur: each query's phase. */
#define TAL_BATCH 8

static void time_at_batch(int m, const double *s, const double *s0, const double *v0,
                          const double *a0, const double *jerk, const double *dur, double rel,
                          int newton, int halvings, int whole, double *out)
{
    double c2[TAL_BATCH], c3[TAL_BATCH], t[TAL_BATCH], lo[TAL_BATCH], hi[TAL_BATCH];
    int count[TAL_BATCH], most = 0;
    for (int q = 0; q < m; q++) {
        c2[q] = 0.5 * a0[q];
        c3[q] = jerk[q] / 6.0;
        double end = phase_s(dur[q], 0.0, v0[q], c2[q], c3[q]);
        t[q] = np_clip((end > 0.0) ? dur[q] * ((s[q] - s0[q]) / end) : 0.0, 0.0, dur[q]);
        lo[q] = 0.0;
        hi[q] = dur[q];
    }
    for (int i = 0; i < newton; i++)
        for (int q = 0; q < m; q++) {
            double tq = t[q];
            double f = phase_s(tq, s0[q], v0[q], c2[q], c3[q]) - s[q];
            int below = f < 0.0;
            lo[q] = below ? tq : lo[q];
            hi[q] = below ? hi[q] : tq;
            double speed = v0[q] + tq * (2.0 * c2[q] + 3.0 * c3[q] * tq);
            double step = tq - f / speed;
            t[q] = (speed > 0.0 && step >= lo[q] && step <= hi[q]) ? step : 0.5 * (lo[q] + hi[q]);
        }
    for (int q = 0; q < m; q++) {
        double near_lo = np_maximum(t[q] * (1.0 - rel), 0.0);
        double near_hi = np_minimum(t[q] * (1.0 + rel), dur[q]);
        int near = (near_hi > near_lo) && (phase_s(near_lo, s0[q], v0[q], c2[q], c3[q]) < s[q]) &&
                   !(phase_s(near_hi, s0[q], v0[q], c2[q], c3[q]) < s[q]);
        lo[q] = near ? near_lo : 0.0;
        hi[q] = near ? near_hi : dur[q];
        count[q] = near ? halvings : whole;
        most = count[q] > most ? count[q] : most;
    }
    for (int i = 0; i < most; i++)
        for (int q = 0; q < m; q++) {
            double mid = 0.5 * (lo[q] + hi[q]);
            int live = i < count[q];
            int below = phase_s(mid, s0[q], v0[q], c2[q], c3[q]) < s[q];
            lo[q] = (live && below) ? mid : lo[q];
            hi[q] = (live && !below) ? mid : hi[q];
        }
    for (int q = 0; q < m; q++)
        out[q] = hi[q];
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
    for (Py_ssize_t q0 = 0; q0 < m; q0 += TAL_BATCH) {
        int count = (int)(m - q0 < TAL_BATCH ? m - q0 : TAL_BATCH);
        double ph[6][TAL_BATCH], t[TAL_BATCH];
        for (int q = 0; q < count; q++) {
            /* searchsorted(s0, s, side="right") - 1, clipped to [0, n - 1] */
            Py_ssize_t lo = 0, hi = n;
            double x = s[q0 + q];
            while (lo < hi) {
                Py_ssize_t mid = lo + (hi - lo) / 2;
                if (x < s0[mid]) /* numpy: first index whose value is > x (NaN sorts last) */
                    hi = mid;
                else
                    lo = mid + 1;
            }
            Py_ssize_t k = lo - 1;
            if (k < 0)
                k = 0;
            if (k > n - 1)
                k = n - 1;
            ph[0][q] = s0[k], ph[1][q] = v0[k], ph[2][q] = a0[k], ph[3][q] = jerk[k];
            ph[4][q] = dur[k], ph[5][q] = start[k];
        }
        time_at_batch(count, s + q0, ph[0], ph[1], ph[2], ph[3], ph[4], rel, newton, halvings,
                      whole, t);
        for (int q = 0; q < count; q++)
            out[q0 + q] = ph[5][q] + t[q]; /* the phase's start time + the time in it */
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    for (int i = 0; i < 8; i++)
        PyBuffer_Release(&b[i]);
    return result;
}

/* ------------------------------------------------------------------ peak speed */

/* feedrate._distance_arr for one element: D(v_a -> v_b) of an S-curve with limits a, j */
static inline double distance(double v_a, double v_b, double a, double j)
{
    double dv = fabs(v_b - v_a);
    double t = (dv * j >= a * a) ? dv / a + a / j : 2.0 * sqrt(dv / j);
    return 0.5 * (v_a + v_b) * t;
}

/* feedrate._pair_distance_mm */
static inline double pair_distance(double v_s, double v_p, double v_e, double a, double j,
                                   double a_dn, double j_dn)
{
    return distance(v_s, v_p, a, j) + distance(v_p, v_e, a_dn, j_dn);
}

/* feedrate._distance_slope */
static inline double distance_slope(double v_a, double v_b, double a, double j)
{
    double dv = np_maximum(v_b - v_a, 0.0);
    int reached = dv * j >= a * a;
    double t = reached ? dv / a + a / j : 2.0 * sqrt(dv / j);
    double t_prime = reached ? 1.0 / a : 1.0 / sqrt(dv * j);
    return 0.5 * t + 0.5 * (v_a + v_b) * t_prime;
}

/* feedrate._peak_speed_py for one piece (its arrays broadcast by the caller). */
static double peak_one(double v_s, double v_e, double length, double v_cap, double a, double j,
                       double a_dn, double j_dn, int newton, double rel)
{
    double lo = np_maximum(v_s, v_e);
    double hi = np_maximum(v_cap, lo);
    if (length <= 0.0)
        return lo;
    if (!(pair_distance(v_s, hi, v_e, a, j, a_dn, j_dn) > length))
        return hi;
    double x = 0.5 * (lo + hi);
    for (int i = 0; i < newton; i++) {
        double f = pair_distance(v_s, x, v_e, a, j, a_dn, j_dn) - length;
        if (f <= 0.0)
            lo = x;
        else
            hi = x;
        double slope = distance_slope(v_s, x, a, j) + distance_slope(v_e, x, a_dn, j_dn);
        double step = x - f / slope;
        x = (isfinite(step) && step >= lo && step <= hi) ? step : 0.5 * (lo + hi);
    }
    double near_lo = np_maximum(x * (1.0 - rel), lo);
    double near_hi = np_minimum(x * (1.0 + rel), hi);
    if (pair_distance(v_s, near_lo, v_e, a, j, a_dn, j_dn) <= length)
        lo = near_lo;
    if (pair_distance(v_s, near_hi, v_e, a, j, a_dn, j_dn) > length)
        hi = near_hi;
    for (int i = 0; i < 1100; i++) {
        double mid = 0.5 * (lo + hi);
        if (!(mid > lo && mid < hi))
            break;
        if (pair_distance(v_s, mid, v_e, a, j, a_dn, j_dn) <= length)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
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
    for (Py_ssize_t i = 0; i < n; i++)
        out[i] = peak_one(v_s[i], v_e[i], len[i], cap[i], a[i], j[i], a_dn[i], j_dn[i], newton,
                          rel);
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    for (int i = 0; i < 9; i++)
        PyBuffer_Release(&b[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"peak_speeds", peak_speeds, METH_VARARGS, "feedrate._peak_speed_py, compiled."},
    {"gated_rise", gated_rise, METH_VARARGS, "profile._gated_rise_py, compiled."},
    {"gated_rise_merged", gated_rise_merged, METH_VARARGS,
     "profile._gated_rise_py, compiled, its phases merged (profile._merged)."},
    {"time_at_length", time_at_length, METH_VARARGS, "profile._time_at_length_py, compiled."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernels",
    "Compiled kernels of the plan stage (profile.py, feedrate.py).", -1, methods,
};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
