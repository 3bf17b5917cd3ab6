/* The numerics of the plan stage's compiled kernels (_kernels.c is their CPython glue: it
 * parses the arguments, checks the buffers and builds the results). Each function is ported
 * operation for operation from its Python reference implementation — gated.py's
 * gated_rise_py and merged_phases, profile.py's _time_at_length_py, feedrate.py's
 * _peak_speed_py — which remain the specification.
 *
 * Every result is bit for bit the Python one: IEEE double arithmetic in the same order,
 * each expression as Python or numpy evaluates it (left to right, no reassociation), built
 * with -ffp-contract=off (no fused multiply-add) and without -ffast-math (setup.py); sqrt
 * and ceil are correctly rounded / exact. tests/test_plan_kernels.py compares the two.
 *
 * Plain C (no Python API), static functions included by _kernels.c alone: one translation
 * unit, so the compiler inlines across the glue as before.
 */
#ifndef NURBSCNC_KERNELS_MATH_H
#define NURBSCNC_KERNELS_MATH_H

#include <math.h>
#include <stddef.h>
#include <stdlib.h>

/* ------------------------------------------------------------------ gated rise */

typedef struct {
    const double *gd, *gc; /* gates: distances [mm] (increasing), caps [mm/s] */
    ptrdiff_t n;
    double j, big_a, min_step;
    ptrdiff_t first; /* the first gate beyond x */
    int braking;
    double x, v, a; /* the state */
} Rise;

/* Python's min(p, q) and max(p, q) of two floats: the first unless the second is
 * strictly smaller (larger). */
static inline double py_min(double p, double q) { return (q < p) ? q : p; }
static inline double py_max(double p, double q) { return (q > p) ? q : p; }

/* gated._brake_ok */
static int brake_ok(const Rise *r, double x, double v, double a, ptrdiff_t first)
{
    double j = r->j;
    double v_end = v + a * a / (2.0 * j);
    for (ptrdiff_t m = first; m < r->n; m++) {
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
    ptrdiff_t m = r->first;
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
    ptrdiff_t n, cap;
} Phases;

static int push(Phases *p, double d, double j)
{
    if (p->n == p->cap) {
        ptrdiff_t cap = p->cap ? 2 * p->cap : 256;
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

/* The loop of gated_rise_py. Returns 1 (done: phases, r->x), 0 (None) or -1 (no memory). */
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

/* gated.merged_phases: consecutive phases of equal jerk as one (in order, or reversed). */
static int merge_phases(const Phases *in, int reverse, Phases *out)
{
    for (ptrdiff_t k = 0; k < in->n; k++) {
        ptrdiff_t i = reverse ? in->n - 1 - k : k;
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


/* _time_at_length_py for the m queries s of a profile of n phases (columns s0 … start):
 * each query's phase by searchsorted, then TAL_BATCH queries at a time (time_at_batch);
 * out[q] the phase's start time + the time in it [s]. */
static void time_at_lengths(ptrdiff_t n, const double *s0, const double *v0, const double *a0,
                            const double *jerk, const double *dur, const double *start,
                            ptrdiff_t m, const double *s, double rel, int newton, int halvings,
                            int whole, double *out)
{
    for (ptrdiff_t q0 = 0; q0 < m; q0 += TAL_BATCH) {
        int count = (int)(m - q0 < TAL_BATCH ? m - q0 : TAL_BATCH);
        double ph[6][TAL_BATCH], t[TAL_BATCH];
        for (int q = 0; q < count; q++) {
            /* searchsorted(s0, s, side="right") - 1, clipped to [0, n - 1] */
            ptrdiff_t lo = 0, hi = n;
            double x = s[q0 + q];
            while (lo < hi) {
                ptrdiff_t mid = lo + (hi - lo) / 2;
                if (x < s0[mid]) /* numpy: first index whose value is > x (NaN sorts last) */
                    hi = mid;
                else
                    lo = mid + 1;
            }
            ptrdiff_t k = lo - 1;
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

/* peak_one for each of n pieces. */
static void peak_speeds_all(ptrdiff_t n, const double *v_s, const double *v_e, const double *len,
                            const double *cap, const double *a, const double *j,
                            const double *a_dn, const double *j_dn, int newton, double rel,
                            double *out)
{
    for (ptrdiff_t i = 0; i < n; i++)
        out[i] = peak_one(v_s[i], v_e[i], len[i], cap[i], a[i], j[i], a_dn[i], j_dn[i], newton,
                          rel);
}

#endif /* NURBSCNC_KERNELS_MATH_H */
