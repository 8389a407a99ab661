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
    const double std = config[NOISE_STD], bias = config[BIAS], dt = config[DT], lim = config[LIMIT];
    const double low = -lim, ew = -config[ERROR_WEIGHT], rw = config[RATE_WEIGHT];
    const double envelope = config[ENVELOPE], cost = config[COST_BOUND], deg = config[DEGREES];
    const double rate_scale = config[RATE_SCALE];
    const long long horizon = (long long)config[HORIZON], bias_step = (long long)config[BIAS_STEP];
    const int has_bias = config[HAS_BIAS] != 0.0, measured = config[RATE_MEASURED] != 0.0;
    float *row_m = values, *row_rate = values + N, *row_ref = values + 2 * N, *row_e = values + 3 * N;
    float *row_int = values + 4 * N, *row_extra = values + 5 * N, *row_a = values + (rows - 1) * N;
    for (Py_ssize_t k = 0; k < N; k++) {
        if (restarting != NULL && restarting[k]) { /* initial_observation's operations */
            double m = 0.0 + noise[k] * std;
            if (has_bias && 0 >= bias_step)
                m = m + bias;
            row_m[k] = (float)(m * deg);
            row_ref[k] = (float)(ref[k] * deg);
            row_e[k] = (float)((ref[k] - m) * deg);
            row_rate[k] = row_int[k] = row_a[k] = 0.0f;
            if (has_extra)
                row_extra[k] = 0.0f;
            reward[k] = 0.0;
            terminated[k] = 0;
            continue;
        }
        double m = x[k] + noise[k] * std;
        if (has_bias && t[k] >= bias_step)
            m = m + bias;
        const double e = (ref[k] - m) * deg;
        double i = integral[k] + e * dt;
        i = low > i ? low : i; /* numpy's clip: NaN kept */
        i = lim < i ? lim : i;
        const double d = a[k] - prev[k];
        double r = ew * (e * e) - rw * (d * d);
        const int ended = fabs(x[k]) > envelope;
        if (ended)
            r = r - cost * (double)(horizon - t[k] + 1);
        double rate_value;
        if (measured) {
            rate_value = (m - rate[k]) * rate_scale;
            rate[k] = m;
        } else {
            rate_value = rate[k] * rate_scale;
        }
        integral[k] = i;
        prev[k] = a[k];
        reward[k] = r;
        terminated[k] = (char)ended;
        row_m[k] = (float)(m * deg);
        row_rate[k] = (float)rate_value;
        row_ref[k] = (float)(ref[k] * deg);
        row_e[k] = (float)e;
        row_int[k] = (float)i;
        if (has_extra)
            row_extra[k] = (float)(extra[k] * deg);
        row_a[k] = (float)a[k];
    }
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
