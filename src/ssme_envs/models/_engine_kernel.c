/* One SSME engine's step on floats, compiled: the operations of engine_step.valves_pair_floats
 * and dynamics_pair_floats (the point model) or dynamics_pair_offset_floats (the linked model),
 * in their order.
 *
 * Every result is a chain of IEEE additions, subtractions, multiplications, fabs and comparisons:
 * built with -ffp-contract=off (no fused multiply-add) and without -ffast-math it gives the bits
 * of the Python reference. The package checks that at import (engine_step's kernel) and the
 * tests check it bit for bit; a build that differs is not used.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "_buffers.h"
#include "_clones.h"

static double number(PyObject *obj, int *err)
{
    double value = PyFloat_AsDouble(obj);
    if (value == -1.0 && PyErr_Occurred())
        *err = 1;
    return value;
}

/* a pair (a tuple or list of two numbers) into a, b */
static int pair(PyObject *obj, double *a, double *b, const char *name)
{
    int err = 0;
    if (!(PyTuple_Check(obj) || PyList_Check(obj)) || PySequence_Fast_GET_SIZE(obj) != 2) {
        PyErr_Format(PyExc_TypeError, "%s: a tuple of two floats", name);
        return -1;
    }
    *a = number(PySequence_Fast_GET_ITEM(obj, 0), &err);
    *b = number(PySequence_Fast_GET_ITEM(obj, 1), &err);
    return err ? -1 : 0;
}

#include "_engine_arithmetic.h"

/* pair_step(x, linkage, valve, c0, c1, n0, n1, half, stick, table, width, step)
 *     -> (x, linkage, valve)
 *
 * x: the n states (a list of floats); linkage, valve: two floats each; c0, c1: the valve
 * commands; n0, n1: the nominal valve positions the asymmetric gains act about (0 for the point
 * model); half: half the backlash; stick: the stiction band. table: float64 bytes, per step
 * [lambda0 - 1, lambda1 - 1, then per state (source, K_i0, K_i1, B_i0, B_i1[, offset_i])]
 * (width 5, or 6 with the linked model's offsets, added last); step: which step's rows.
 * (step last: a task passes the fixed arguments as one tuple.) */
static PyObject *pair_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 12) {
        PyErr_SetString(PyExc_TypeError, "pair_step(x, linkage, valve, c0, c1, n0, n1, half, stick, table, width, step)");
        return NULL;
    }
    PyObject *xs = args[0], *table = args[9];
    if (!PyList_Check(xs) || !PyBytes_Check(table)) {
        PyErr_SetString(PyExc_TypeError, "pair_step: x a list of floats, table bytes");
        return NULL;
    }
    Py_ssize_t n = PyList_GET_SIZE(xs), width = PyLong_AsSsize_t(args[10]), step = PyLong_AsSsize_t(args[11]);
    if (PyErr_Occurred())
        return NULL;
    Py_ssize_t per_step = 2 + n * width, table_doubles = PyBytes_GET_SIZE(table) / (Py_ssize_t)sizeof(double);
    if (n < 2 || (width != 5 && width != 6) || step < 0 || step >= table_doubles / per_step) {
        PyErr_SetString(PyExc_ValueError, "pair_step: 2 or more states, width 5 or 6, a step inside the table");
        return NULL;
    }
    const double *rows = (const double *)PyBytes_AS_STRING(table) + step * per_step;
    for (Py_ssize_t i = 0; i < n; i++)
        if (rows[2 + i * width] >= (double)n) {
            PyErr_SetString(PyExc_ValueError, "pair_step: a shift source beyond the states");
            return NULL;
        }
    double l0, l1, v0, v1;
    int err = 0;
    if (pair(args[1], &l0, &l1, "linkage") < 0 || pair(args[2], &v0, &v1, "valve") < 0)
        return NULL;
    double c0 = number(args[3], &err), c1 = number(args[4], &err), n0 = number(args[5], &err);
    double n1 = number(args[6], &err), half = number(args[7], &err), stick = number(args[8], &err);
    if (err)
        return NULL;
    /* the old states, read before the list is built: on the stack for the SSME's few */
    double stack[64], stack_next[64], *x = n <= 64 ? stack : PyMem_Malloc(n * sizeof(double));
    if (x == NULL)
        return PyErr_NoMemory();
    for (Py_ssize_t i = 0; i < n; i++)
        x[i] = number(PyList_GET_ITEM(xs, i), &err);
    PyObject *out = err ? NULL : PyList_New(n);
    if (out == NULL)
        goto done;

    double valves[4] = {l0, l1, v0, v1};
    double *next = n <= 64 ? stack_next : PyMem_Malloc(n * sizeof(double));
    if (next == NULL) {
        Py_CLEAR(out);
        PyErr_NoMemory();
        goto done;
    }
    engine_one(x, 1, next, 1, n, valves, c0, c1, n0, n1, half, stick, rows, width);
    l0 = valves[0], l1 = valves[1], v0 = valves[2], v1 = valves[3];
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *item = PyFloat_FromDouble(next[i]);
        if (item == NULL) {
            Py_CLEAR(out);
            break;
        }
        PyList_SET_ITEM(out, i, item);
    }
    if (next != stack_next)
        PyMem_Free(next);
done:
    if (x != stack)
        PyMem_Free(x);
    if (out == NULL)
        return NULL;
    return Py_BuildValue("(N(dd)(dd))", out, l0, l1, v0, v1);
}

/* the table, offsets and config of a batch call, and the steps of every t, checked: the rows of
 * step t - 1 (scheduled) or 0 in the table and, where offsets are given, a row t - 1 of them */
static int plant_of(Plant *p, Views *v, PyObject *table, PyObject *offsets, const double *config,
                    Py_ssize_t n, const long long *t, Py_ssize_t N)
{
    if (!PyBytes_Check(table)) {
        PyErr_SetString(PyExc_TypeError, "table: bytes (engine_step.pair_table's)");
        return -1;
    }
    p->n = n, p->width = (Py_ssize_t)config[WIDTH], p->scheduled = config[SCHEDULED] != 0.0;
    p->half = config[HALF], p->stick = config[STICK];
    p->table = (const double *)PyBytes_AS_STRING(table);
    p->per_step = 2 + n * p->width;
    p->steps = PyBytes_GET_SIZE(table) / (Py_ssize_t)sizeof(double) / p->per_step;
    Py_ssize_t count;
    p->offsets = take(v, offsets, sizeof(double), "d", -1, 0, "offsets", &count);
    if (p->offsets == NULL)
        return -1;
    p->offset_rows = count / 2;
    if (n < 2 || (p->width != 5 && p->width != 6) || p->steps < 1) {
        PyErr_SetString(PyExc_ValueError, "batch step: 2 or more states, width 5 or 6, a table of a step or more");
        return -1;
    }
    long long lo = t[0], hi = t[0];
    for (Py_ssize_t j = 1; j < N; j++) {
        lo = t[j] < lo ? t[j] : lo;
        hi = t[j] > hi ? t[j] : hi;
    }
    if ((p->offset_rows > 0 || p->scheduled) && (lo < 1 || hi > p->offset_rows)) {
        PyErr_SetString(PyExc_ValueError, "batch step: a step outside the nominal valves");
        return -1;
    }
    Py_ssize_t first = p->scheduled ? (Py_ssize_t)(lo - 1) : 0, last = p->scheduled ? (Py_ssize_t)(hi - 1) : 0;
    if (last >= p->steps) {
        PyErr_SetString(PyExc_ValueError, "batch step: a step outside the table");
        return -1;
    }
    for (Py_ssize_t step = first; step <= last; step++)
        for (Py_ssize_t i = 0; i < n; i++)
            if (p->table[step * p->per_step + 2 + i * p->width] >= (double)n) {
                PyErr_SetString(PyExc_ValueError, "batch step: a shift source beyond the states");
                return -1;
            }
    return 0;
}

/* a batch call's steps t (N,), states x (n, N, written in place) and config, checked: -1 with
 * an error otherwise */
static int batch_head(Views *v, PyObject *t_obj, PyObject *x_obj, PyObject *config_obj, const char *name,
                      const long long **t, double **x, const double **config, Py_ssize_t *N, Py_ssize_t *n)
{
    Py_ssize_t nN;
    *t = take(v, t_obj, 8, "lq", -1, 0, "t", N);
    *x = *t ? take(v, x_obj, 8, "d", -1, 1, "x", &nN) : NULL;
    *config = *x ? take(v, config_obj, 8, "d", CONFIG_SIZE, 0, "config", NULL) : NULL;
    if (*config == NULL)
        return -1;
    if (*N < 1 || nN % *N != 0) {
        PyErr_Format(PyExc_ValueError, "%s: x of (n, N), t of (N,)", name);
        return -1;
    }
    *n = nN / *N;
    return 0;
}

/* plant_batch(x, linkage, valve, command, t, config, table, offsets) -> None
 *
 * N engines' valves and dynamics under the commands (2, N) of step t - 1 -> t, in place: the
 * task's advance on arrays. config: the float64 config of engine_step.BATCH_CONFIG (half,
 * stick, width and scheduled are read); offsets: the nominal valves per step ((T + 1, 2); the
 * gains act about row t - 1 when scheduled). */
static PyObject *plant_batch(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError, "plant_batch(x, linkage, valve, command, t, config, table, offsets)");
        return NULL;
    }
    Views v = {.count = 0};
    Plant p;
    PyObject *result = NULL;
    double *scratch = NULL;
    Py_ssize_t N, n;
    const long long *t;
    double *x;
    const double *config;
    if (batch_head(&v, args[4], args[0], args[5], "plant_batch", &t, &x, &config, &N, &n) < 0)
        goto done;
    double *linkage = take(&v, args[1], 8, "d", 2 * N, 1, "linkage", NULL);
    double *valve = linkage ? take(&v, args[2], 8, "d", 2 * N, 1, "valve", NULL) : NULL;
    const double *command = valve ? take(&v, args[3], 8, "d", 2 * N, 0, "command", NULL) : NULL;
    if (command == NULL || plant_of(&p, &v, args[6], args[7], config, n, t, N) < 0)
        goto done;
    if ((scratch = PyMem_Malloc((size_t)p.n * CHUNK * sizeof(double))) == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    double g0[CHUNK], g1[CHUNK];
    for (Py_ssize_t j0 = 0; j0 < N; j0 += CHUNK) {
        Py_ssize_t b = N - j0 < CHUNK ? N - j0 : CHUNK;
        for (Py_ssize_t k = 0; k < b; k++) {
            const double *nominal = p.scheduled ? p.offsets + 2 * (t[j0 + k] - 1) : NULL;
            g0[k] = nominal ? nominal[0] : 0.0, g1[k] = nominal ? nominal[1] : 0.0;
        }
        plant_chunk(&p, x, linkage, valve, N, j0, b, t, command + j0, command + N + j0, g0, g1, scratch);
    }
    result = Py_NewRef(Py_None);
done:
    PyMem_Free(scratch);
    release(&v);
    return result;
}

/* the arrays of a task_batch call, checked */
typedef struct {
    double *x, *linkage, *valve, *integral0, *integral1, *held;
    const double *prev0, *prev1, *action;
    const long long *t;
    const double *r0, *r1;
    const float *z0, *z1;
    float *values;
    double *reward;
    char *terminated;
    int each0, each1;
    Py_ssize_t N;
} Steps;

/* task_batch's steps, CHUNK envs at a time; every loop but a scheduled plant's mixed chunk has
 * no branch, so that the clones run them as vectors */
static void CLONES task_chunks(const Plant *p, const Steps *a, const double *config, double *scratch)
{
    const Py_ssize_t N = a->N, n = p->n;
    const long long *t = a->t;
    const double *action = a->action;
    double *x = a->x, *held = a->held, *integral0 = a->integral0, *integral1 = a->integral1;
    const double s0 = config[S0], s1 = config[S1], dt = config[DT], lim = config[LIMIT];
    const double ew = config[ERROR_WEIGHT], rw = config[RATE_WEIGHT], envelope = config[ENVELOPE];
    const double magnitude = config[MAGNITUDE], cost = config[COST_BOUND];
    const long long fault_step = (long long)config[FAULT_STEP], horizon = (long long)config[HORIZON];
    const int kind = (int)config[FAULT_KIND], index = (int)config[FAULT_INDEX] != 0;
    double c0[CHUNK], c1[CHUNK], g0[CHUNK], g1[CHUNK], ref0[CHUNK], ref1[CHUNK];
    double m0[CHUNK], m1[CHUNK], e0[CHUNK], e1[CHUNK];
    for (Py_ssize_t j0 = 0; j0 < N; j0 += CHUNK) {
        const Py_ssize_t b = N - j0 < CHUNK ? N - j0 : CHUNK;
        const long long *restrict tc = t + j0;
        commands(p, action, N, j0, b, t, config[SCALE], c0, c1, g0, g1);
        double *ci = index ? c1 : c0;
        if (kind == STUCK_VALVE) {
            for (Py_ssize_t k = 0; k < b; k++) {
                double h = tc[k] == fault_step + 1 ? ci[k] : held[j0 + k];
                ci[k] = tc[k] > fault_step ? h : ci[k];
                held[j0 + k] = h;
            }
        } else if (kind == GAIN_LOSS) {
            for (Py_ssize_t k = 0; k < b; k++)
                ci[k] = tc[k] > fault_step ? ci[k] * magnitude : ci[k];
        }
        plant_chunk(p, x, a->linkage, a->valve, N, j0, b, t, c0, c1, g0, g1, scratch);
        references(b, a->each0 ? a->r0 + j0 : a->r0, a->each0, ref0);
        references(b, a->each1 ? a->r1 + j0 : a->r1, a->each1, ref1);
        const double *restrict y0 = x + (n - 2) * N + j0, *restrict y1 = x + (n - 1) * N + j0;
        measure(b, y0, y1, a->z0 + j0, a->z1 + j0, s0, s1, m0, m1);
        if (kind == SENSOR_BIAS) {
            double *mi = index ? m1 : m0;
            for (Py_ssize_t k = 0; k < b; k++)
                mi[k] = tc[k] >= fault_step ? mi[k] + magnitude : mi[k];
        }
        double *restrict rew = a->reward + j0;
        char *restrict ended = a->terminated + j0;
        errors(b, ref0, ref1, m0, m1, integral0 + j0, integral1 + j0, action + j0, action + N + j0, a->prev0 + j0,
               a->prev1 + j0, e0, e1, rew, dt, lim, ew, rw);
        for (Py_ssize_t k = 0; k < b; k++) { /* termination, its penalty selected per env */
            const int out = (fabs(y0[k] - ref0[k]) > envelope) | (fabs(y1[k] - ref1[k]) > envelope);
            const double penalty = cost * (double)(horizon - tc[k] + 1);
            ended[k] = (char)out;
            rew[k] = out ? rew[k] - penalty : rew[k];
        }
        observations(b, a->values + j0, N, m0, m1, ref0, ref1, e0, e1, integral0 + j0, integral1 + j0,
                     action + j0, action + N + j0);
    }
}

/* task_batch(x, linkage, valve, integral0, integral1, held, prev0, prev1, action, t, r0, r1,
 *            z0, z1, values, reward, terminated, config, table, offsets) -> None
 *
 * One step of N engine tracking episodes, EngineTask.step's operations in its order: the valve
 * commands (action * scale, the nominal valves added), the fault, the plant, the measurements
 * (outputs plus the float32 unit noise z times its scale), errors, integrals (clipped), reward
 * and termination (with its penalty). x, linkage, valve, integral0, integral1 and held are
 * stepped in place; values (10, N) float32 (the observation values, rounded), reward and
 * terminated are written. r0, r1: the references, N of them or one for all. */
static PyObject *task_batch(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 20) {
        PyErr_SetString(PyExc_TypeError, "task_batch takes 20 arguments (engine_compiled.task_step's)");
        return NULL;
    }
    Views v = {.count = 0};
    Plant p;
    PyObject *result = NULL;
    double *scratch = NULL;
    Py_ssize_t N, n, nr0, nr1;
    const long long *t;
    double *x;
    const double *config;
    if (batch_head(&v, args[9], args[0], args[17], "task_batch", &t, &x, &config, &N, &n) < 0)
        goto done;
    double *io[5];
    const char *io_names[5] = {"linkage", "valve", "integral0", "integral1", "held"};
    Py_ssize_t io_counts[5] = {2 * N, 2 * N, N, N, N};
    for (int k = 0; k < 5; k++)
        if ((io[k] = take(&v, args[1 + k], 8, "d", io_counts[k], 1, io_names[k], NULL)) == NULL)
            goto done;
    const double *prev0 = take(&v, args[6], 8, "d", N, 0, "prev0", NULL);
    const double *prev1 = prev0 ? take(&v, args[7], 8, "d", N, 0, "prev1", NULL) : NULL;
    const double *action = prev1 ? take(&v, args[8], 8, "d", 2 * N, 0, "action", NULL) : NULL;
    const double *r0 = action ? take(&v, args[10], 8, "d", -1, 0, "r0", &nr0) : NULL;
    const double *r1 = r0 ? take(&v, args[11], 8, "d", -1, 0, "r1", &nr1) : NULL;
    const float *z0 = r1 ? take(&v, args[12], 4, "f", N, 0, "z0", NULL) : NULL;
    const float *z1 = z0 ? take(&v, args[13], 4, "f", N, 0, "z1", NULL) : NULL;
    float *values = z1 ? take(&v, args[14], 4, "f", 10 * N, 1, "values", NULL) : NULL;
    double *reward = values ? take(&v, args[15], 8, "d", N, 1, "reward", NULL) : NULL;
    char *terminated = reward ? take(&v, args[16], 1, "?", N, 1, "terminated", NULL) : NULL;
    if (terminated == NULL || plant_of(&p, &v, args[18], args[19], config, n, t, N) < 0)
        goto done;
    if ((nr0 != N && nr0 != 1) || (nr1 != N && nr1 != 1)) {
        PyErr_SetString(PyExc_ValueError, "task_batch: references of N envs or one for all");
        goto done;
    }
    if ((scratch = PyMem_Malloc((size_t)p.n * CHUNK * sizeof(double))) == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    const Steps steps = {.x = x, .linkage = io[0], .valve = io[1], .integral0 = io[2], .integral1 = io[3],
                         .held = io[4], .prev0 = prev0, .prev1 = prev1, .action = action, .t = t, .r0 = r0,
                         .r1 = r1, .z0 = z0, .z1 = z1, .values = values, .reward = reward,
                         .terminated = terminated, .each0 = nr0 == N, .each1 = nr1 == N, .N = N};
    task_chunks(&p, &steps, config, scratch);
    result = Py_NewRef(Py_None);
done:
    PyMem_Free(scratch);
    release(&v);
    return result;
}

static PyMethodDef methods[] = {
    {"pair_step", (PyCFunction)(void (*)(void))pair_step, METH_FASTCALL, "One engine's valves and dynamics."},
    {"plant_batch", (PyCFunction)(void (*)(void))plant_batch, METH_FASTCALL, "N engines' valves and dynamics."},
    {"task_batch", (PyCFunction)(void (*)(void))task_batch, METH_FASTCALL, "One step of N engine tracking episodes."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_engine_kernel", "The SSME engine's float step.", -1, methods};

PyMODINIT_FUNC PyInit__engine_kernel(void) { return PyModule_Create(&module); }
