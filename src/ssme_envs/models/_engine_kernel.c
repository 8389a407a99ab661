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
    double stack[64], *x = n <= 64 ? stack : PyMem_Malloc(n * sizeof(double));
    if (x == NULL)
        return PyErr_NoMemory();
    for (Py_ssize_t i = 0; i < n; i++)
        x[i] = number(PyList_GET_ITEM(xs, i), &err);
    PyObject *out = err ? NULL : PyList_New(n);
    if (out == NULL)
        goto done;

    /* backlash: min(max(l, c - h), c + h) as the builtins decide; then stiction */
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
    double y0 = x[n - 2], y1 = x[n - 1];
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *r = rows + 2 + i * width;
        double ky = r[1] * y0 + r[2] * y1;
        long source = (long)r[0];
        double value = (source >= 0 ? x[source] + ky : ky) + (r[3] * u0 + r[4] * u1);
        if (width == 6)
            value = value + r[5];
        PyObject *item = PyFloat_FromDouble(value);
        if (item == NULL) {
            Py_CLEAR(out);
            goto done;
        }
        PyList_SET_ITEM(out, i, item);
    }
done:
    if (x != stack)
        PyMem_Free(x);
    if (out == NULL)
        return NULL;
    return Py_BuildValue("(N(dd)(dd))", out, l0, l1, v0, v1);
}

static PyMethodDef methods[] = {
    {"pair_step", (PyCFunction)(void (*)(void))pair_step, METH_FASTCALL, "One engine's valves and dynamics."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_engine_kernel", "The SSME engine's float step.", -1, methods};

PyMODINIT_FUNC PyInit__engine_kernel(void) { return PyModule_Create(&module); }
