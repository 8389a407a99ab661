/* The nozzle joint's RK4, compiled: the operations of nozzle_joint.rk4_floats (one nozzle) and
 * nozzle_joint.rk4_arrays (a batch), in their order, with the power of joint_power.py.
 *
 * Every result is a chain of IEEE additions, multiplications, divisions, copysign, fabs,
 * comparisons and exact bit moves: built with -ffp-contract=off (no fused multiply-add) and
 * without -ffast-math, the scalar code and each SIMD width give the same bits as the Python
 * reference. The package checks that at import (nozzle_joint._kernel) and the tests check it
 * bit for bit; a build that differs is not used.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "_joint_arithmetic.h"

static int check_tables(void)
{
    if (!tables_set)
        PyErr_SetString(PyExc_RuntimeError, "set_tables first");
    return tables_set ? 0 : -1;
}

/* A number, or a contiguous float64 vector of length n: its values into col (length len from
 * offset start) */
typedef struct {
    double value;
    Py_buffer view;
    int is_view;
} Column;

static int column_open(PyObject *obj, Py_ssize_t n, Column *col, const char *name)
{
    col->is_view = 0;
    if (PyFloat_Check(obj) || PyLong_Check(obj)) {
        col->value = PyFloat_AsDouble(obj);
        return (col->value == -1.0 && PyErr_Occurred()) ? -1 : 0;
    }
    if (PyObject_GetBuffer(obj, &col->view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s: a number or a contiguous float64 vector", name);
        return -1;
    }
    col->is_view = 1;
    if (col->view.ndim == 0 && strcmp(col->view.format, "d") == 0) {
        col->value = *(double *)col->view.buf;
        PyBuffer_Release(&col->view);
        col->is_view = 0;
        return 0;
    }
    if (col->view.ndim != 1 || col->view.shape[0] != n || strcmp(col->view.format, "d") != 0) {
        PyBuffer_Release(&col->view);
        col->is_view = 0;
        PyErr_Format(PyExc_TypeError, "%s: a number or a float64 vector of length %zd", name, n);
        return -1;
    }
    return 0;
}

static void column_fill(const Column *col, double *dst, Py_ssize_t start, Py_ssize_t len)
{
    if (col->is_view)
        memcpy(dst, (const double *)col->view.buf + start, (size_t)len * sizeof(double));
    else
        for (Py_ssize_t i = 0; i < len; i++)
            dst[i] = col->value;
}

/* Lanes a caller discards (a vector env's restarting envs), left out of a block's RK4: the others
 * are packed into whole vectors (AVX-512's compress), stepped, and put back (expand). Each lane's
 * operations are its own, so the bits of the others are the same. Elsewhere every lane is
 * stepped. */
enum { MAX_PACKED = 3 + 9 }; /* rows packed: a nozzle's three, tau and a per-nozzle joint's eight */

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#include <immintrin.h>
#define PACKS 1
/* The lanes of a block that skip does not name, one mask per vector of 8 lanes (lanes at or past
 * len are not kept, so the loads and stores below touch none past a row's end); their count */
static Py_ssize_t kept_masks(const char *skip, Py_ssize_t len, unsigned char *masks)
{
    Py_ssize_t kept = 0;
    for (Py_ssize_t i = 0; i < len; i += 8) {
        unsigned keep = 0;
        for (Py_ssize_t b = 0; b < 8 && i + b < len; b++)
            keep |= (unsigned)(skip[i + b] == 0) << b;
        masks[i / 8] = (unsigned char)keep;
        kept += __builtin_popcount(keep);
    }
    return kept;
}

/* The kept lanes of the `count` rows src[r][0, len) packed into dst[r] (STRIDE wide), padded to
 * whole vectors with the last of them (at least one is kept); the padded count. */
__attribute__((target("avx512f"))) static Py_ssize_t pack_lanes(const unsigned char *masks, double *const *src,
                                                                  double (*dst)[STRIDE], int count,
                                                                  Py_ssize_t len)
{
    Py_ssize_t m = 0;
    for (Py_ssize_t i = 0; i < len; i += 8) {
        const __mmask8 keep = masks[i / 8];
        for (int r = 0; r < count; r++)
            _mm512_storeu_pd(dst[r] + m, _mm512_maskz_compress_pd(keep, _mm512_maskz_loadu_pd(keep, src[r] + i)));
        m += __builtin_popcount(keep);
    }
    Py_ssize_t padded = (m + 7) / 8 * 8;
    for (int r = 0; r < count; r++)
        for (Py_ssize_t j = m; j < padded; j++)
            dst[r][j] = dst[r][m - 1];
    return padded;
}

/* pack_lanes undone for the `count` rows: the packed lanes back into their places in dst */
__attribute__((target("avx512f"))) static void unpack_lanes(const unsigned char *masks, double (*src)[STRIDE],
                                                             double *const *dst, int count, Py_ssize_t len)
{
    Py_ssize_t m = 0;
    for (Py_ssize_t i = 0; i < len; i += 8) {
        const __mmask8 keep = masks[i / 8];
        for (int r = 0; r < count; r++)
            _mm512_mask_storeu_pd(dst[r] + i, keep, _mm512_maskz_expandloadu_pd(keep, src[r] + m));
        m += __builtin_popcount(keep);
    }
}
#else
#define PACKS 0
#endif

/* the joint of eight numbers (inv_j ... w_floor) where none of its columns is a vector: into *one,
 * returned; NULL where any is */
static const Joint *shared_joint(const Column *joint, Joint *one)
{
    for (int c = 0; c < 8; c++)
        if (joint[c].is_view)
            return NULL;
    *one = (Joint){joint[0].value, joint[1].value, joint[2].value, joint[3].value,
                   joint[4].value, joint[5].value, joint[6].value, joint[7].value};
    return one;
}

static int read_joint(PyObject *p, PyObject **items, int *hys)
{
    if (!PyTuple_Check(p) || PyTuple_GET_SIZE(p) != 9) {
        PyErr_SetString(PyExc_TypeError, "p: the nine RK4Parameters");
        return -1;
    }
    for (int i = 0; i < 8; i++)
        items[i] = PyTuple_GET_ITEM(p, i);
    *hys = PyObject_IsTrue(PyTuple_GET_ITEM(p, 8));
    return *hys < 0 ? -1 : 0;
}

static double number(PyObject *obj, int *err)
{
    double value = PyFloat_AsDouble(obj);
    if (value == -1.0 && PyErr_Occurred())
        *err = 1;
    return value;
}

/* the call's argument count, and the power's tables set */
static int check_call(Py_ssize_t nargs, Py_ssize_t expected, const char *usage)
{
    if (nargs != expected) {
        PyErr_SetString(PyExc_TypeError, usage);
        return -1;
    }
    return check_tables();
}

/* the joint's eight numbers (read_joint's items) into p */
static int joint_numbers(PyObject **items, Joint *p)
{
    int err = 0;
    double *fields[8] = {&p->inv_j, &p->b_j, &p->k_el_j, &p->k_hys_j, &p->beta, &p->gamma, &p->n, &p->floor};
    for (int i = 0; i < 8; i++)
        *fields[i] = number(items[i], &err);
    return err ? -1 : 0;
}

/* `steps` RK4 steps of one nozzle under the torque held (accel0 = tau / J) */
static inline void rk4_steps(double *x, double *v, double *w, double accel0, double h, long steps, int hys,
                             const Joint *p)
{
    if (hys)
        for (long s = 0; s < steps; s++)
            rk4_step_hysteretic(x, v, w, accel0, h, p);
    else
        for (long s = 0; s < steps; s++)
            rk4_step_linear(x, v, w, accel0, h, p);
}

/* a writable C-contiguous float64 (3, N) array: the nozzles' state */
static int open_state(PyObject *obj, Py_buffer *view)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0) {
        PyErr_Clear();
        PyErr_SetString(PyExc_TypeError, "state: a writable C-contiguous float64 (3, N) array");
        return -1;
    }
    if (view->ndim != 2 || view->shape[0] != 3 || strcmp(view->format, "d") != 0) {
        PyBuffer_Release(view);
        PyErr_SetString(PyExc_TypeError, "state: a writable C-contiguous float64 (3, N) array");
        return -1;
    }
    return 0;
}

/* rk4_float(x, v, w, tau, h, steps, p) -> (x, v, w) */
static PyObject *rk4_float(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    PyObject *items[8];
    int hys, err = 0;
    Joint p;
    if (check_call(nargs, 7, "rk4_float(x, v, w, tau, h, steps, p)") < 0 || read_joint(args[6], items, &hys) < 0 ||
        joint_numbers(items, &p) < 0)
        return NULL;
    double x = number(args[0], &err), v = number(args[1], &err), w = number(args[2], &err);
    double tau = number(args[3], &err), h = number(args[4], &err);
    long steps = PyLong_AsLong(args[5]);
    if (err || (steps == -1 && PyErr_Occurred()))
        return NULL;
    rk4_steps(&x, &v, &w, tau * p.inv_j, h, steps, hys, &p);
    return Py_BuildValue("(ddd)", x, v, w);
}

/* A C-contiguous vector of length n and format code `format` (a `kind` vector: "writable
 * float64", "bool"), writable where asked */
static int open_vector(PyObject *obj, Py_ssize_t n, Py_buffer *view, int writable, const char *format,
                       const char *name, const char *kind)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s: a contiguous %s vector", name, kind);
        return -1;
    }
    if (view->ndim != 1 || view->shape[0] != n || strcmp(view->format, format) != 0) {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_TypeError, "%s: a %s vector of length %zd", name, kind, n);
        return -1;
    }
    return 0;
}

/* skip: None (NULL) or a C-contiguous bool vector of length n */
static int open_mask(PyObject *obj, Py_ssize_t n, Py_buffer *view, const char **mask, const char *name)
{
    *mask = NULL;
    if (obj == Py_None)
        return 0;
    if (open_vector(obj, n, view, 0, "?", name, "bool") < 0)
        return -1;
    *mask = (const char *)view->buf;
    return 0;
}

/* rk4_batch(state, tau, h, steps, p[, skip]): state a C-contiguous float64 (3, N) array, in
 * place; skip None or a bool (N,) row of nozzles whose state the caller discards, which a block
 * may leave as they were (where AVX-512 packs the others) */
static PyObject *rk4_batch(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    PyObject *items[8];
    int hys, err = 0;
    if (check_call(nargs == 5 ? 6 : nargs, 6, "rk4_batch(state, tau, h, steps, p[, skip])") < 0 ||
        read_joint(args[4], items, &hys) < 0)
        return NULL;
    double h = number(args[2], &err);
    long steps = PyLong_AsLong(args[3]);
    if (err || (steps == -1 && PyErr_Occurred()))
        return NULL;
    Py_buffer state, skip_view;
    if (open_state(args[0], &state) < 0)
        return NULL;
    Py_ssize_t n = state.shape[1];
    const char *skip;
    if (open_mask(nargs == 6 ? args[5] : Py_None, n, &skip_view, &skip, "skip") < 0) {
        PyBuffer_Release(&state);
        return NULL;
    }
    Column cols[9];
    int opened = 0;
    static const char *names[9] = {"tau", "inv_j", "b_j", "k_el_j", "k_hys_j", "beta", "gamma", "n", "w_floor"};
    for (; opened < 9; opened++)
        if (column_open(opened == 0 ? args[1] : items[opened - 1], n, &cols[opened], names[opened]) < 0)
            break;
    if (opened == 9) {
        double *rows = (double *)state.buf;
        double block[9][STRIDE];
        Joint one;
        const Joint *shared = shared_joint(cols + 1, &one);
        const int filled = shared != NULL ? 1 : 9; /* a shared joint is read from `one` */
#if PACKS
        const int packs = skip != NULL && __builtin_cpu_supports("avx512f");
        double packed[MAX_PACKED][STRIDE];
        unsigned char masks[BLOCK / 8];
#endif
        for (Py_ssize_t start = 0; start < n; start += BLOCK) {
            Py_ssize_t len = n - start < BLOCK ? n - start : BLOCK;
            for (int c = 0; c < filled; c++)
                column_fill(&cols[c], block[c], start, len);
            double *at[MAX_PACKED] = {rows + start, rows + n + start, rows + 2 * n + start};
#if PACKS
            Py_ssize_t kept = packs ? kept_masks(skip + start, len, masks) : len;
            if ((kept + 7) / 8 * 8 < len) { /* a whole vector or more left out: the others packed */
                for (int c = 0; c < filled; c++)
                    at[3 + c] = block[c];
                if (kept > 0) {
                    Py_ssize_t m = pack_lanes(masks, at, packed, 3 + filled, len);
                    rk4_block(packed[0], packed[1], packed[2], packed + 3, m, h, steps, hys, shared);
                    unpack_lanes(masks, packed, at, 3, len);
                }
                continue;
            }
#endif
            rk4_block(at[0], at[1], at[2], block, len, h, steps, hys, shared);
        }
    }
    for (int c = 0; c < opened; c++)
        if (cols[c].is_view)
            PyBuffer_Release(&cols[c].view);
    if (skip != NULL)
        PyBuffer_Release(&skip_view);
    PyBuffer_Release(&state);
    if (opened != 9)
        return NULL;
    Py_RETURN_NONE;
}

/* the servo's (feedforward, k_p, k_d) and the body's eight numbers into servo_body[0..2], [3..10]:
 * (k_p, k_d, lim) then the body */
static int read_servo(PyObject *servo, PyObject *lim, PyObject *body, double *out)
{
    int err = 0;
    if (!PyTuple_Check(servo) || PyTuple_GET_SIZE(servo) != 3 || !PyTuple_Check(body) || PyTuple_GET_SIZE(body) != 8) {
        PyErr_SetString(PyExc_TypeError, "servo: (feedforward, k_p, k_d); body: eight numbers");
        return -1;
    }
    out[0] = number(PyTuple_GET_ITEM(servo, 1), &err);
    out[1] = number(PyTuple_GET_ITEM(servo, 2), &err);
    out[2] = number(lim, &err);
    for (int i = 0; i < 8; i++)
        out[3 + i] = number(PyTuple_GET_ITEM(body, i), &err);
    return err ? -1 : 0;
}

/* servo_float(x, v, w, theta, q, drive, gain, servo, lim, body, h, steps, samples, p)
 * -> (x, v, w, theta, q): launcher_servo.servo_floats without its integrator argument */
static PyObject *servo_float(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    PyObject *items[8];
    int hys, err = 0;
    double sb[11];
    Joint p;
    if (check_call(nargs, 14, "servo_float(x, v, w, theta, q, drive, gain, servo, lim, body, h, steps, samples, p)") < 0 ||
        read_joint(args[13], items, &hys) < 0 || joint_numbers(items, &p) < 0 ||
        read_servo(args[7], args[8], args[9], sb) < 0)
        return NULL;
    double x = number(args[0], &err), v = number(args[1], &err), w = number(args[2], &err);
    double theta = number(args[3], &err), q = number(args[4], &err), drive = number(args[5], &err);
    int has_gain = args[6] != Py_None;
    double gain = has_gain ? number(args[6], &err) : 1.0;
    double h = number(args[10], &err);
    long steps = PyLong_AsLong(args[11]), samples = PyLong_AsLong(args[12]);
    if (err || ((steps == -1 || samples == -1) && PyErr_Occurred()))
        return NULL;
    const double k_p = sb[0], k_d = sb[1], lim = sb[2], low = -lim;
    const double *body = sb + 3;
    for (long s = 0; s < samples; s++) {
        double torque = drive - k_p * x - k_d * v;
        torque = low > torque ? low : torque;
        torque = lim < torque ? lim : torque;
        if (has_gain)
            torque = torque * gain;
        double theta_next = body[0] * theta + body[1] * q + body[4] * x;
        double q_next = body[2] * theta + body[3] * q + body[5] * x;
        rk4_steps(&x, &v, &w, torque * p.inv_j, h, steps, hys, &p);
        theta = theta_next + body[6] * x;
        q = q_next + body[7] * x;
    }
    return Py_BuildValue("(ddddd)", x, v, w, theta, q);
}

/* servo_batch(state, theta, q, drive, gain, servo, lim, body, h, steps, samples, p): N launchers in
 * place, state (3, N), theta and q (N,); drive and gain (None: no fault) numbers or (N,) */
static PyObject *servo_batch(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    PyObject *items[8];
    int hys, err = 0;
    double sb[11];
    if (check_call(nargs, 12, "servo_batch(state, theta, q, drive, gain, servo, lim, body, h, steps, samples, p)") < 0 ||
        read_joint(args[11], items, &hys) < 0 || read_servo(args[5], args[6], args[7], sb) < 0)
        return NULL;
    double h = number(args[8], &err);
    long steps = PyLong_AsLong(args[9]), samples = PyLong_AsLong(args[10]);
    if (err || ((steps == -1 || samples == -1) && PyErr_Occurred()))
        return NULL;
    Py_buffer state, rows[2];
    if (open_state(args[0], &state) < 0)
        return NULL;
    Py_ssize_t n = state.shape[1];
    int ok = 0, rows_open = 0, opened = 0;
    Column cols[10]; /* drive, gain, the joint's eight */
    static const char *names[8] = {"inv_j", "b_j", "k_el_j", "k_hys_j", "beta", "gamma", "n", "w_floor"};
    int has_gain = args[4] != Py_None;
    if (open_vector(args[1], n, &rows[0], 1, "d", "theta", "writable float64") == 0) {
        rows_open = 1;
        if (open_vector(args[2], n, &rows[1], 1, "d", "q", "writable float64") == 0) {
            rows_open = 2;
            if (column_open(args[3], n, &cols[0], "drive") == 0) {
                opened = 1;
                if (!has_gain || column_open(args[4], n, &cols[1], "gain") == 0) {
                    opened = 2;
                    for (; opened < 10; opened++)
                        if (column_open(items[opened - 2], n, &cols[opened], names[opened - 2]) < 0)
                            break;
                    ok = opened == 10;
                }
            }
        }
    }
    if (ok) {
        double *x = (double *)state.buf, *theta = (double *)rows[0].buf, *q = (double *)rows[1].buf;
        double block[9][STRIDE], drive[BLOCK], gain[BLOCK];
        Joint one;
        const Joint *shared = shared_joint(cols + 2, &one);
        for (Py_ssize_t start = 0; start < n; start += BLOCK) {
            Py_ssize_t len = n - start < BLOCK ? n - start : BLOCK;
            column_fill(&cols[0], drive, start, len);
            if (has_gain)
                column_fill(&cols[1], gain, start, len);
            for (int c = 0; c < (shared != NULL ? 0 : 8); c++)
                column_fill(&cols[2 + c], block[1 + c], start, len);
            servo_block(x + start, x + n + start, x + 2 * n + start, theta + start, q + start, drive,
                        has_gain ? gain : NULL, sb, sb + 3, block, len, h, steps, samples, hys, shared);
        }
    }
    for (int c = 0; c < opened; c++)
        if ((c != 1 || has_gain) && cols[c].is_view)
            PyBuffer_Release(&cols[c].view);
    for (int r = 0; r < rows_open; r++)
        PyBuffer_Release(&rows[r]);
    PyBuffer_Release(&state);
    if (!ok)
        return NULL;
    Py_RETURN_NONE;
}

static int fill(PyObject *seq, double *dst, Py_ssize_t n)
{
    PyObject *fast = PySequence_Fast(seq, "a sequence of floats");
    if (fast == NULL)
        return -1;
    int ok = PySequence_Fast_GET_SIZE(fast) == n;
    for (Py_ssize_t i = 0; ok && i < n; i++) {
        dst[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(fast, i));
        ok = !(dst[i] == -1.0 && PyErr_Occurred());
    }
    Py_DECREF(fast);
    if (!ok && !PyErr_Occurred())
        PyErr_Format(PyExc_ValueError, "a table of %zd floats", n);
    return ok ? 0 : -1;
}

/* set_tables(inv_c, log_c, exp2): joint_power.tables(), once; inv_c must be what the power
 * computes in its place, 1.0 / c for the cell centres c */
static PyObject *set_tables(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double inv[128], log[128], exp2[64];
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "set_tables(inv_c, log_c, exp2)");
        return NULL;
    }
    if (fill(args[0], inv, 128) < 0 || fill(args[1], log, 128) < 0 || fill(args[2], exp2, 64) < 0)
        return NULL;
    for (int i = 0; i < 128; i++)
        if (to_bits(inv[i]) != to_bits(1.0 / (1.0 + (i + 0.5) / 128.0))) {
            PyErr_Format(PyExc_ValueError, "inv_c[%d] is not 1.0 / c for the centre c of cell %d", i, i);
            return NULL;
        }
    memcpy(log_c, log, sizeof log);
    memcpy(exp2_table, exp2, sizeof exp2);
    tables_set = 1;
    Py_RETURN_NONE;
}

/* power(x, n): joint_power on one float, for the tests */
static PyObject *power(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    int err = 0;
    if (check_call(nargs, 2, "power(x, n)") < 0)
        return NULL;
    double x = number(args[0], &err), n = number(args[1], &err);
    if (!err && x < 0.0) {
        PyErr_Format(PyExc_ValueError, "the joint's power takes x >= 0, got %R", args[0]);
        return NULL;
    }
    return err ? NULL : PyFloat_FromDouble(joint_power(x, n));
}

static PyMethodDef methods[] = {
    {"rk4_float", (PyCFunction)(void (*)(void))rk4_float, METH_FASTCALL, "RK4 steps of one nozzle."},
    {"rk4_batch", (PyCFunction)(void (*)(void))rk4_batch, METH_FASTCALL, "RK4 steps of N nozzles, in place."},
    {"servo_float", (PyCFunction)(void (*)(void))servo_float, METH_FASTCALL, "Servo samples of one launcher."},
    {"servo_batch", (PyCFunction)(void (*)(void))servo_batch, METH_FASTCALL, "Servo samples of N launchers, in place."},
    {"set_tables", (PyCFunction)(void (*)(void))set_tables, METH_FASTCALL, "The power's tables."},
    {"power", (PyCFunction)(void (*)(void))power, METH_FASTCALL, "The joint's power on one float."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_joint_kernel", NULL, -1, methods};

PyMODINIT_FUNC PyInit__joint_kernel(void) { return PyModule_Create(&module); }
