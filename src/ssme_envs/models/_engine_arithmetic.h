/* The SSME engine's arithmetic, compiled: one engine's valves and dynamics (engine_one) and the
 * stages of the batch step (the plant, commands, measurements, references, observations and
 * errors of a chunk of envs), with no Python in them. Included by _engine_kernel.c alone (after
 * Python.h, math.h, string.h and _clones.h), which reads and checks the arguments; its notes on
 * the bits hold here, at every width the clones run (plant_chunk's and task_chunks'). */
#ifndef SSME_ENVS_ENGINE_ARITHMETIC_H
#define SSME_ENVS_ENGINE_ARITHMETIC_H

/* One engine's valves and dynamics: backlash, min(max(l, c - h), c + h) as the builtins decide,
 * then stiction; the gains u* = v + (lambda - 1)|v - n|; x_i <- (x_src(i) + (K_i0 y0 + K_i1 y1))
 * + (B_i0 u0 + B_i1 u1) [+ offset_i]. x: the n old states (stride xs), next: the new (stride ns,
 * not x); valves: linkage 0, 1 and valve 0, 1, updated; rows: one step's rows of the table. */
static void engine_one(const double *x, Py_ssize_t xs, double *next, Py_ssize_t ns, Py_ssize_t n,
                       double *valves, double c0, double c1, double n0, double n1, double half,
                       double stick, const double *rows, Py_ssize_t width)
{
    double l0 = valves[0], l1 = valves[1], v0 = valves[2], v1 = valves[3];
    if (half != 0.0) {
        double lo = c0 - half, hi = c0 + half;
        l0 = lo > l0 ? lo : l0;
        l0 = hi < l0 ? hi : l0;
        lo = c1 - half, hi = c1 + half;
        l1 = lo > l1 ? lo : l1;
        l1 = hi < l1 ? hi : l1;
    } else {
        l0 = c0, l1 = c1;
    }
    if (stick != 0.0) {
        v0 = fabs(l0 - v0) > stick ? l0 : v0;
        v1 = fabs(l1 - v1) > stick ? l1 : v1;
    } else {
        v0 = l0, v1 = l1;
    }
    double u0 = v0 + rows[0] * fabs(v0 - n0), u1 = v1 + rows[1] * fabs(v1 - n1);
    double y0 = x[(n - 2) * xs], y1 = x[(n - 1) * xs];
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *r = rows + 2 + i * width;
        double ky = r[1] * y0 + r[2] * y1;
        long source = (long)r[0];
        double value = (source >= 0 ? x[source * xs] + ky : ky) + (r[3] * u0 + r[4] * u1);
        next[i * ns] = width == 6 ? value + r[5] : value;
    }
    valves[0] = l0, valves[1] = l1, valves[2] = v0, valves[3] = v1;
}

/* The batch forms: N engines as the vector envs hold them, state-major ((n, N) and (2, N) float64
 * arrays, C-contiguous), stepped in place CHUNK envs at a time. Each stage is a loop over a
 * chunk's envs (which the compiler turns into SIMD operations), and each env gets the operations
 * of engine_one and the float step in their order: its bits. Every argument is checked before
 * any state is written, so a refused call leaves the state as it was. */

#define CHUNK 256

/* the config array's entries */
enum { SCALE, S0, S1, DT, LIMIT, ERROR_WEIGHT, RATE_WEIGHT, ENVELOPE, COST_BOUND, HORIZON, FAULT_KIND,
       FAULT_INDEX, MAGNITUDE, FAULT_STEP, HALF, STICK, WIDTH, SCHEDULED, CONFIG_SIZE };
enum { NO_FAULT, STUCK_VALVE, GAIN_LOSS, SENSOR_BIAS };

typedef struct {
    const double *table, *offsets;
    Py_ssize_t n, width, per_step, steps, offset_rows;
    int scheduled;
    double half, stick;
} Plant;

static const double *rows_at(const Plant *p, long long t)
{
    return p->table + (p->scheduled ? (Py_ssize_t)(t - 1) : 0) * p->per_step;
}

/* the plant of envs [j0, j0 + b) under the commands c0, c1, the gains about g0, g1 (chunk
 * arrays), in place; scratch: n CHUNK doubles. Envs at one step share its rows and go stage by
 * stage; a chunk of envs at different steps (of a scheduled plant) goes env by env. */
static void CLONES plant_chunk(const Plant *p, double *x, double *linkage, double *valve, Py_ssize_t N,
                        Py_ssize_t j0, Py_ssize_t b, const long long *t, const double *c0,
                        const double *c1, const double *g0, const double *g1, double *scratch)
{
    const Py_ssize_t n = p->n, width = p->width;
    int same = 1;
    for (Py_ssize_t k = 1; k < b && p->scheduled; k++)
        same &= t[j0 + k] == t[j0];
    if (!same) {
        for (Py_ssize_t k = 0; k < b; k++) {
            Py_ssize_t j = j0 + k;
            for (Py_ssize_t i = 0; i < n; i++)
                scratch[i] = x[i * N + j];
            double valves[4] = {linkage[j], linkage[N + j], valve[j], valve[N + j]};
            engine_one(scratch, 1, x + j, N, n, valves, c0[k], c1[k], g0[k], g1[k], p->half, p->stick,
                       rows_at(p, t[j]), width);
            linkage[j] = valves[0], linkage[N + j] = valves[1], valve[j] = valves[2], valve[N + j] = valves[3];
        }
        return;
    }
    const double *rows = rows_at(p, t[j0]);
    double *restrict L0 = linkage + j0, *restrict L1 = linkage + N + j0;
    double *restrict V0 = valve + j0, *restrict V1 = valve + N + j0;
    const double half = p->half, stick = p->stick, lam0 = rows[0], lam1 = rows[1];
    if (half != 0.0) {
        for (Py_ssize_t k = 0; k < b; k++) {
            double lo = c0[k] - half, hi = c0[k] + half, l = L0[k];
            l = lo > l ? lo : l;
            L0[k] = hi < l ? hi : l;
            lo = c1[k] - half, hi = c1[k] + half, l = L1[k];
            l = lo > l ? lo : l;
            L1[k] = hi < l ? hi : l;
        }
    } else {
        for (Py_ssize_t k = 0; k < b; k++)
            L0[k] = c0[k], L1[k] = c1[k];
    }
    if (stick != 0.0) {
        for (Py_ssize_t k = 0; k < b; k++) {
            V0[k] = fabs(L0[k] - V0[k]) > stick ? L0[k] : V0[k];
            V1[k] = fabs(L1[k] - V1[k]) > stick ? L1[k] : V1[k];
        }
    } else {
        for (Py_ssize_t k = 0; k < b; k++)
            V0[k] = L0[k], V1[k] = L1[k];
    }
    double u0[CHUNK], u1[CHUNK];
    for (Py_ssize_t k = 0; k < b; k++) {
        u0[k] = V0[k] + lam0 * fabs(V0[k] - g0[k]);
        u1[k] = V1[k] + lam1 * fabs(V1[k] - g1[k]);
    }
    /* the new states into scratch (the old are read throughout), then over the old */
    const double *restrict y0 = x + (n - 2) * N + j0, *restrict y1 = x + (n - 1) * N + j0;
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *r = rows + 2 + i * width;
        const double k0 = r[1], k1 = r[2], b0 = r[3], b1 = r[4];
        const long source = (long)r[0];
        double *restrict out = scratch + i * CHUNK;
        if (source >= 0) {
            const double *restrict xs = x + source * N + j0;
            for (Py_ssize_t k = 0; k < b; k++)
                out[k] = (xs[k] + (k0 * y0[k] + k1 * y1[k])) + (b0 * u0[k] + b1 * u1[k]);
        } else {
            for (Py_ssize_t k = 0; k < b; k++)
                out[k] = (k0 * y0[k] + k1 * y1[k]) + (b0 * u0[k] + b1 * u1[k]);
        }
        if (width == 6) {
            const double offset = r[5];
            for (Py_ssize_t k = 0; k < b; k++)
                out[k] = out[k] + offset;
        }
    }
    for (Py_ssize_t i = 0; i < n; i++)
        memcpy(x + i * N + j0, scratch + i * CHUNK, (size_t)b * sizeof(double));
}

/* the commands of envs [j0, j0 + b) (action * scale, the nominal valves added) and the gains'
 * centres (the nominal valves when scheduled, else 0) */
static inline void commands(const Plant *p, const double *action, Py_ssize_t N, Py_ssize_t j0, Py_ssize_t b,
                     const long long *t, double scale, double *c0, double *c1, double *g0, double *g1)
{
    for (Py_ssize_t k = 0; k < b; k++) {
        c0[k] = action[j0 + k] * scale, c1[k] = action[N + j0 + k] * scale;
        g0[k] = 0.0, g1[k] = 0.0;
    }
    if (p->offset_rows == 0)
        return;
    for (Py_ssize_t k = 0; k < b; k++) {
        const double *nominal = p->offsets + 2 * (t[j0 + k] - 1);
        c0[k] = nominal[0] + c0[k], c1[k] = nominal[1] + c1[k];
    }
    for (Py_ssize_t k = 0; k < b && p->scheduled; k++) {
        const double *nominal = p->offsets + 2 * (t[j0 + k] - 1);
        g0[k] = nominal[0], g1[k] = nominal[1];
    }
}

/* the measurements m = y + z s of a chunk's envs (z float32 unit noise) */
static inline void measure(Py_ssize_t b, const double *restrict y0, const double *restrict y1, const float *restrict z0,
                    const float *restrict z1, double s0, double s1, double *restrict m0, double *restrict m1)
{
    for (Py_ssize_t k = 0; k < b; k++) {
        m0[k] = y0[k] + (double)z0[k] * s0;
        m1[k] = y1[k] + (double)z1[k] * s1;
    }
}

/* a chunk's references: its envs' own (each) or one for all */
static inline void references(Py_ssize_t b, const double *restrict r, int each, double *restrict out)
{
    if (each)
        memcpy(out, r, (size_t)b * sizeof(double));
    else
        for (Py_ssize_t k = 0; k < b; k++)
            out[k] = r[0];
}

/* a chunk's row of observation values, rounded to float32: in % (100 in), or as it is */
static inline void percent(Py_ssize_t b, float *restrict out, const double *restrict in)
{
    for (Py_ssize_t k = 0; k < b; k++)
        out[k] = (float)(100.0 * in[k]);
}

static inline void narrow(Py_ssize_t b, float *restrict out, const double *restrict in)
{
    for (Py_ssize_t k = 0; k < b; k++)
        out[k] = (float)in[k];
}

/* the observation values of a chunk's envs, rounded to float32 (as the envs hand them out):
 * measurements and references in %, errors, integrals, the action. A loop per row: the
 * compiler vectorizes none of one loop over all ten. */
static inline void observations(Py_ssize_t b, float *values, Py_ssize_t N, const double *m0, const double *m1,
                                const double *ref0, const double *ref1, const double *e0, const double *e1,
                                const double *i0, const double *i1, const double *a0, const double *a1)
{
    const double *rows[10] = {m0, m1, ref0, ref1, e0, e1, i0, i1, a0, a1};
    for (int q = 0; q < 4; q++)
        percent(b, values + q * N, rows[q]);
    for (int q = 4; q < 10; q++)
        narrow(b, values + q * N, rows[q]);
}

/* the errors e (in %), the integrals i (clipped as numpy's clip: min(max(x, lo), hi), NaN kept)
 * and the reward without the termination penalty, of a chunk's envs */
static inline void errors(Py_ssize_t b, const double *restrict ref0, const double *restrict ref1,
                   const double *restrict m0, const double *restrict m1, double *restrict i0,
                   double *restrict i1, const double *restrict a0, const double *restrict a1,
                   const double *restrict p0, const double *restrict p1, double *restrict e0,
                   double *restrict e1, double *restrict reward, double dt, double lim, double ew, double rw)
{
    for (Py_ssize_t k = 0; k < b; k++) {
        const double f0 = 100.0 * (ref0[k] - m0[k]), f1 = 100.0 * (ref1[k] - m1[k]);
        double q0 = i0[k] + f0 * dt, q1 = i1[k] + f1 * dt;
        q0 = -lim > q0 ? -lim : q0;
        q0 = lim < q0 ? lim : q0;
        q1 = -lim > q1 ? -lim : q1;
        q1 = lim < q1 ? lim : q1;
        const double d0 = a0[k] - p0[k], d1 = a1[k] - p1[k];
        reward[k] = -ew * (f0 * f0 + f1 * f1) - rw * (d0 * d0 + d1 * d1);
        e0[k] = f0, e1[k] = f1, i0[k] = q0, i1[k] = q1;
    }
}

#endif /* SSME_ENVS_ENGINE_ARITHMETIC_H */
