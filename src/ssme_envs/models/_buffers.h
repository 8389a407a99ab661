/* Buffer arguments of the compiled kernels: each taken C-contiguous and checked, all released
 * at once. Included by _engine_kernel.c and _draw_kernel.c (after Python.h and string.h). */
#ifndef SSME_ENVS_BUFFERS_H
#define SSME_ENVS_BUFFERS_H

enum { MAX_VIEWS = 24 };
typedef struct {
    Py_buffer views[MAX_VIEWS];
    int count;
} Views;

static void release(Views *v)
{
    for (int i = 0; i < v->count; i++)
        PyBuffer_Release(&v->views[i]);
    v->count = 0;
}

/* a C-contiguous buffer of `count` items (count < 0: any number, into *items) of `itemsize`
 * bytes and one of the format codes `codes`; NULL with an error otherwise */
static void *take(Views *v, PyObject *obj, Py_ssize_t itemsize, const char *codes, Py_ssize_t count,
                  int writable, const char *name, Py_ssize_t *items)
{
    Py_buffer *view = &v->views[v->count];
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (v->count >= MAX_VIEWS) {
        PyErr_SetString(PyExc_RuntimeError, "too many buffer arguments");
        return NULL;
    }
    if (PyObject_GetBuffer(obj, view, flags) < 0) { /* numpy's own message names no argument */
        PyObject *kind = PyErr_Occurred();
        const int not_buffer = kind != NULL && PyErr_GivenExceptionMatches(kind, PyExc_TypeError);
        PyErr_Clear();
        if (not_buffer)
            PyErr_Format(PyExc_TypeError, "%s: an array expected, got %.100s", name, Py_TYPE(obj)->tp_name);
        else
            PyErr_Format(PyExc_ValueError, "%s: a C-contiguous%s array expected", name, writable ? " writable" : "");
        return NULL;
    }
    v->count++;
    const char *format = view->format == NULL ? "B" : view->format;
    char code = format[0] == '<' || format[0] == '=' || format[0] == '@' ? format[1] : format[0];
    if (view->itemsize != itemsize || code == '\0' || strchr(codes, code) == NULL
        || (count >= 0 && view->len != count * itemsize)) {
        if (count >= 0)
            PyErr_Format(PyExc_ValueError, "%s: a C-contiguous array of %zd items of type '%s' expected", name,
                         count, codes);
        else
            PyErr_Format(PyExc_ValueError, "%s: a C-contiguous array of type '%s' expected", name, codes);
        return NULL;
    }
    if (items != NULL)
        *items = view->len / itemsize;
    return view->buf;
}

#endif
