/* The nozzle family's score and observation, compiled: what NozzleTask.score and the steps of
 * NozzleTask and LauncherTask do after the plant, on N envs in one pass.
 *
 * In numpy that is about twenty passes over (N,) rows and a float32 table filled row by row;
 * here each env's measurement, error, integral, reward, termination and observation columns are
 * made at once, with the float step's IEEE operations in its order (built with
 * -ffp-contract=off, no fast math), so the bits are the scalar env's. The package checks that
 * against the scalar step before it uses the kernel (ssme_envs.envs.nozzle_compiled).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "_buffers.h"
#include "_clones.h"

/* the float64 config of nozzle_compiled.score_config, in its order */
enum {
    NOISE_STD,
    HAS_BIAS,
    BIAS_STEP,
    BIAS,
    DT,
    LIMIT,
    ERROR_WEIGHT,
    RATE_WEIGHT,
    ENVELOPE,
    COST_BOUND,
    HORIZON,
    DEGREES,
    RATE_SCALE,
    RATE_MEASURED,
    CONFIG_SIZE
};

typedef struct {
    double std, bias, dt, lim, ew, rw, envelope, cost, deg, rate_scale;
    long long horizon, bias_step;
    int has_bias;
} Score;

/* The loop of score_batch over envs, with no branch in it: each env's float-step operations,
 * and for a restarting env (has_restarts and restarting[k]) initial_observation's, which are
 * the same measurement at x = 0 and step 0, its other outputs selected to 0 and its state kept.
 * (The arrays are restrict parameters: read from a struct, GCC does not vectorize the loop.) */
#define SCORE_PARAMS                                                                                                 \
    const Score *c, const double *restrict x, const double *restrict a, const long long *restrict t,                \
        const double *restrict ref, const double *restrict noise, const double *restrict extra,                     \
        double *restrict prev, double *restrict integral, double *restrict rate, float *restrict row_m,             \
        float *restrict row_rate, float *restrict row_ref, float *restrict row_e, float *restrict row_int,          \
        float *restrict row_extra, float *restrict row_a, double *restrict reward, char *restrict terminated,       \
        const char *restrict restarting, Py_ssize_t n
#define SCORE_ARGS                                                                                                   \
    c, x, a, t, ref, noise, extra, prev, integral, rate, row_m, row_rate, row_ref, row_e, row_int, row_extra, row_a, \
        reward, terminated, restarting, n

static inline __attribute__((always_inline)) void score_lanes(SCORE_PARAMS, const int measured, const int has_extra,
                                                              const int has_restarts)
{
    const double std = c->std, bias = c->bias, dt = c->dt, lim = c->lim, low = -lim, ew = c->ew, rw = c->rw;
    const double envelope = c->envelope, cost = c->cost, deg = c->deg, rate_scale = c->rate_scale;
    const long long horizon = c->horizon, bias_step = c->bias_step;
    const int has_bias = c->has_bias;
    for (Py_ssize_t k = 0; k < n; k++) {
        const int fresh = has_restarts ? restarting[k] != 0 : 0;
        const double xk = x[k];
        const long long tk = t[k];
        double m = (fresh ? 0.0 : xk) + noise[k] * std;
        const double biased = m + bias;
        m = has_bias && (fresh ? 0 : tk) >= bias_step ? biased : m;
        const double e = (ref[k] - m) * deg;
        double i = integral[k] + e * dt;
        i = low > i ? low : i; /* numpy's clip: NaN kept */
        i = lim < i ? lim : i;
        const double d = a[k] - prev[k];
        double r = ew * (e * e) - rw * (d * d);
        const int ended = fabs(xk) > envelope;
        const double penalty = r - cost * (double)(horizon - tk + 1);
        r = ended ? penalty : r;
        const double rk = rate[k], ik = integral[k], pk = prev[k], ak = a[k];
        const double rate_value = measured ? (m - rk) * rate_scale : rk * rate_scale;
        if (measured)
            rate[k] = fresh ? rk : m;
        integral[k] = fresh ? ik : i;
        prev[k] = fresh ? pk : ak;
        reward[k] = fresh ? 0.0 : r;
        terminated[k] = (char)(fresh ? 0 : ended);
        row_m[k] = (float)(m * deg);
        row_rate[k] = fresh ? 0.0f : (float)rate_value;
        row_ref[k] = (float)(ref[k] * deg);
        row_e[k] = (float)e;
        row_int[k] = fresh ? 0.0f : (float)i;
        if (has_extra)
            row_extra[k] = fresh ? 0.0f : (float)(extra[k] * deg);
        row_a[k] = fresh ? 0.0f : (float)ak;
    }
}

/* the nozzle's form: the rate measured, no extra column (restarting NULL or not: each
 * compiled on its own) */
static void CLONES score_measured(SCORE_PARAMS)
{
    if (restarting != NULL)
        score_lanes(SCORE_ARGS, 1, 0, 1);
    else
        score_lanes(SCORE_ARGS, 1, 0, 0);
}

/* the launcher's form: the rate given, the nozzle's deflection an extra column */
static void CLONES score_given(SCORE_PARAMS)
{
    if (restarting != NULL)
        score_lanes(SCORE_ARGS, 0, 1, 1);
    else
        score_lanes(SCORE_ARGS, 0, 1, 0);
}

/* any other config */
static void score_any(SCORE_PARAMS, int measured, int has_extra)
{
    score_lanes(SCORE_ARGS, measured, has_extra, restarting != NULL);
}

/* score_batch(x, a, prev, t, ref, noise, integral, rate, extra, values, reward, terminated, config
 *             [, restarting])
 *
 * x: the tracked output (rad), a: the actions, t: the steps, ref (rad), noise: the unit noise,
 * all (N,). prev, integral and rate are stepped in place: prev <- a, the error integral (deg s,
 * clipped), and where config says the rate is measured, rate <- m, the measurement, whose
 * difference over dt makes the rate column; else the rate column is rate (rad/s) in deg/s.
 * extra: None or (N,) in rad, a column in deg before the action's. values: (6 or 7, N) float32,
 * the observation columns (m, rate, ref, error, integral, [extra,] a) rounded; reward, terminated:
 * (N,), written. restarting: None or a bool (N,) row, the envs whose ref and noise are their new
 * episodes' step 0: their columns get the task's initial_observation (the measurement of a
 * nozzle at rest at step 0; rate, integral, extra and action columns 0), reward 0, not ended,
 * and their prev, integral and rate are left as they are (the caller resets them). */
static PyObject *score_batch(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 13 && nargs != 14) {
        PyErr_SetString(PyExc_TypeError, "score_batch(x, a, prev, t, ref, noise, integral, rate, extra, values, "
                                         "reward, terminated, config[, restarting])");
        return NULL;
    }
    Views v = {.count = 0};
    PyObject *result = NULL;
    Py_ssize_t N;
    const double *x = take(&v, args[0], 8, "d", -1, 0, "x", &N);
    const double *a = x ? take(&v, args[1], 8, "d", N, 0, "a", NULL) : NULL;
    double *prev = a ? take(&v, args[2], 8, "d", N, 1, "prev", NULL) : NULL;
    const long long *t = prev ? take(&v, args[3], 8, "lq", N, 0, "t", NULL) : NULL;
    const double *ref = t ? take(&v, args[4], 8, "d", N, 0, "ref", NULL) : NULL;
    const double *noise = ref ? take(&v, args[5], 8, "d", N, 0, "noise", NULL) : NULL;
    double *integral = noise ? take(&v, args[6], 8, "d", N, 1, "integral", NULL) : NULL;
    double *rate = integral ? take(&v, args[7], 8, "d", N, 1, "rate", NULL) : NULL;
    const int has_extra = args[8] != Py_None;
    const double *extra = rate && has_extra ? take(&v, args[8], 8, "d", N, 0, "extra", NULL) : NULL;
    const Py_ssize_t rows = 6 + has_extra;
    float *values = rate && (extra || !has_extra) ? take(&v, args[9], 4, "f", rows * N, 1, "values", NULL) : NULL;
    double *reward = values ? take(&v, args[10], 8, "d", N, 1, "reward", NULL) : NULL;
    char *terminated = reward ? take(&v, args[11], 1, "?", N, 1, "terminated", NULL) : NULL;
    const double *config = terminated ? take(&v, args[12], 8, "d", CONFIG_SIZE, 0, "config", NULL) : NULL;
    const int has_restarts = config != NULL && nargs == 14 && args[13] != Py_None;
    const char *restarting = has_restarts ? take(&v, args[13], 1, "?", N, 0, "restarting", NULL) : NULL;
    if (config == NULL || (has_restarts && restarting == NULL))
        goto done;
    const Score config_ = {
        .std = config[NOISE_STD], .bias = config[BIAS], .dt = config[DT], .lim = config[LIMIT],
        .ew = -config[ERROR_WEIGHT], .rw = config[RATE_WEIGHT], .envelope = config[ENVELOPE],
        .cost = config[COST_BOUND], .deg = config[DEGREES], .rate_scale = config[RATE_SCALE],
        .horizon = (long long)config[HORIZON], .bias_step = (long long)config[BIAS_STEP],
        .has_bias = config[HAS_BIAS] != 0.0,
    };
    const int measured = config[RATE_MEASURED] != 0.0;
    const Py_ssize_t n = N;
    float *row_m = values, *row_rate = values + N, *row_ref = values + 2 * N, *row_e = values + 3 * N;
    float *row_int = values + 4 * N, *row_extra = values + 5 * N, *row_a = values + (rows - 1) * N;
    const Score *c = &config_;
    /* each form compiled on its own, so that the loop over envs has no branch left to vectorize */
    if (measured && !has_extra)
        score_measured(SCORE_ARGS);
    else if (!measured && has_extra)
        score_given(SCORE_ARGS);
    else
        score_any(SCORE_ARGS, measured, has_extra);
    result = Py_NewRef(Py_None);
done:
    release(&v);
    return result;
}

static PyMethodDef methods[] = {
    {"score_batch", (PyCFunction)(void (*)(void))score_batch, METH_FASTCALL,
     "The score and observation of N nozzle-family envs."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_score_kernel",
                                    "The nozzle family's score and observation.", -1, methods};

PyMODINIT_FUNC PyInit__score_kernel(void) { return PyModule_Create(&module); }
