/* Episode draws from numpy's PCG64 generators, compiled: any uniform of an episode's draw, and
 * the generator moved past the whole draw, without drawing what the episode never reaches.
 *
 * An env draws an episode as `rng.random(count, dtype=float32)`: `count` float32 numbers, each
 * (u >> 8) / 2^24 of the generator's next 32-bit output u. PCG64 makes 64-bit outputs: a 128-bit
 * LCG step s <- a s + inc, then the XSL-RR output of s; a 32-bit draw takes the low half of a new
 * output and keeps the high half for the next one (has_uint32, uinteger). The LCG jumps n steps
 * at once: s_n = a^n s + (a^(n-1) + ... + 1) inc, with a^n and the sum found in log2 n squarings.
 *
 * `start` records each env's generator state as its episode's origin and moves the generator to
 * where drawing `count` numbers leaves it (buffer included). `rows` gives numbers [lo, hi) of the
 * episodes from their origins. Together they give the bits of drawing the whole episode at once;
 * the package checks that against numpy at import (ssme_envs.envs.episode_draws) and uses the
 * kernel only where it holds. Where the compiler has no 128-bit integers the module has no
 * functions and the package draws with numpy.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#include "_buffers.h"

#if defined(__SIZEOF_INT128__)

typedef unsigned __int128 u128;

/* numpy's PCG64 state where its compiler has 128-bit integers: numpy/random/src/pcg64 */
typedef struct {
    u128 state, inc;
} Lcg;
typedef struct {
    Lcg *lcg;
    int has_uint32;
    uint32_t uinteger;
} Pcg64;
typedef struct {
    void *state; /* numpy's bitgen_t begins with its state */
} BitGen;

#define MULTIPLIER (((u128)2549297995355413924ULL << 64) + 4865540595714422341ULL)

#if defined(__GNUC__) || defined(__clang__)
#define PREFETCH(address) __builtin_prefetch(address)
#else
#define PREFETCH(address) ((void)(address))
#endif

/* an origin's words: state low, high; inc low, high; has_uint32; uinteger. STREAM_CHUNK: the envs
 * a streams call sorts at a time */
enum { ORIGIN = 6, TILE = 16, STREAM_CHUNK = 512 };

/* the jump of n LCG steps: s_n = mult s + sum inc */
static void jump_of(uint64_t n, u128 *mult, u128 *sum)
{
    u128 acc_mult = 1, acc_sum = 0, cur_mult = MULTIPLIER, cur_sum = 1;
    while (n) {
        if (n & 1) {
            acc_mult *= cur_mult;
            acc_sum = acc_sum * cur_mult + cur_sum;
        }
        cur_sum *= cur_mult + 1;
        cur_mult *= cur_mult;
        n >>= 1;
    }
    *mult = acc_mult;
    *sum = acc_sum;
}

static inline uint64_t output(u128 s)
{
    uint64_t x = (uint64_t)(s >> 64) ^ (uint64_t)s;
    unsigned r = (unsigned)(s >> 122);
    return (x >> r) | (x << ((64u - r) & 63u));
}

static inline float uniform(uint32_t u) { return (float)(u >> 8) * (1.0f / 16777216.0f); }

static inline u128 join(uint64_t lo, uint64_t hi) { return ((u128)hi << 64) | lo; }

/* the env indices, each checked within [0, n) */
static const int64_t *env_indices(Views *v, PyObject *obj, Py_ssize_t n, Py_ssize_t *k)
{
    const int64_t *envs = take(v, obj, 8, "qlL", -1, 0, "envs", k);
    if (envs == NULL)
        return NULL;
    for (Py_ssize_t j = 0; j < *k; j++)
        if (envs[j] < 0 || envs[j] >= n) {
            PyErr_Format(PyExc_ValueError, "envs: index %lld outside 0..%zd", (long long)envs[j], n - 1);
            return NULL;
        }
    return envs;
}

/* the episodes' origins, ORIGIN words each, their count into *n; NULL with an error otherwise */
static const uint64_t *take_origins(Views *v, PyObject *obj, const char *caller, Py_ssize_t *n)
{
    Py_ssize_t words;
    const uint64_t *origins = take(v, obj, 8, "QLK", -1, 0, "origins", &words);
    if (origins != NULL && words % ORIGIN != 0) {
        PyErr_Format(PyExc_ValueError, "%s: origins of %d words each expected", caller, ORIGIN);
        return NULL;
    }
    *n = words / ORIGIN;
    return origins;
}

/* start(bitgens, envs, count, origins): for each env i of envs, origins[i] <- the state of the
 * generator whose numpy capsule is bitgens[i], which then moves on as drawing `count` float32
 * numbers moves it. Every argument is checked before a generator moves. */
static PyObject *start(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "start(bitgens, envs, count, origins)");
        return NULL;
    }
    PyObject *bitgens = args[0];
    long long count = PyLong_AsLongLong(args[2]);
    if (count == -1 && PyErr_Occurred())
        return NULL;
    if (!PyList_Check(bitgens) || count < 0) {
        PyErr_SetString(PyExc_ValueError, "start: a list of capsules and a count >= 0 expected");
        return NULL;
    }
    Views v = {.count = 0};
    PyObject *result = NULL;
    void **link = NULL;
    Py_ssize_t k, words, n = PyList_GET_SIZE(bitgens);
    uint64_t *origins = take(&v, args[3], 8, "QLK", -1, 1, "origins", &words);
    const int64_t *envs = origins == NULL ? NULL : env_indices(&v, args[1], n, &k);
    if (envs == NULL)
        goto done;
    if (words != ORIGIN * n) {
        PyErr_Format(PyExc_ValueError, "origins: %d words per generator expected", ORIGIN);
        goto done;
    }
    /* Each env's state lies at the end of a chain of scattered objects (capsule, bitgen,
     * PCG64 state, LCG), cold in cache when hundreds of envs restart. The chains are followed
     * one link per pass over every env, each link's loads prefetched by the pass before, so that
     * the misses of many envs overlap instead of one env waiting on four in turn. */
    link = k == 0 ? NULL : PyMem_Malloc((size_t)k * sizeof(void *));
    if (k > 0 && link == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t j = 0; j < k; j++) {
        link[j] = PyList_GET_ITEM(bitgens, envs[j]);
        PREFETCH(link[j]);
    }
    for (Py_ssize_t j = 0; j < k; j++) { /* every capsule checked before a generator moves */
        if (!PyCapsule_IsValid(link[j], "BitGenerator")) {
            PyErr_SetString(PyExc_TypeError, "start: bitgens holds a non-BitGenerator capsule");
            goto done;
        }
        link[j] = PyCapsule_GetPointer(link[j], "BitGenerator");
        PREFETCH(link[j]);
    }
    for (Py_ssize_t j = 0; j < k; j++) {
        link[j] = ((BitGen *)link[j])->state;
        PREFETCH(link[j]);
    }
    for (Py_ssize_t j = 0; j < k; j++) {
        PREFETCH(((Pcg64 *)link[j])->lcg);
        PREFETCH(origins + ORIGIN * envs[j]);
    }
    /* the outputs a draw takes: all `count` from new outputs, or the first from the buffer */
    uint64_t fresh[2] = {(uint64_t)count, count > 0 ? (uint64_t)count - 1 : 0};
    u128 mult[2], sum[2];
    for (int h = 0; h < 2; h++)
        jump_of((fresh[h] + 1) / 2, &mult[h], &sum[h]);
    for (Py_ssize_t j = 0; j < k; j++) {
        Pcg64 *g = link[j];
        uint64_t *o = origins + ORIGIN * envs[j];
        const int h = g->has_uint32 != 0;
        o[0] = (uint64_t)g->lcg->state;
        o[1] = (uint64_t)(g->lcg->state >> 64);
        o[2] = (uint64_t)g->lcg->inc;
        o[3] = (uint64_t)(g->lcg->inc >> 64);
        o[4] = (uint64_t)h;
        o[5] = g->uinteger;
        if (count == 0)
            continue;
        if (fresh[h] == 0) { /* the one number came from the buffer */
            g->has_uint32 = 0;
            continue;
        }
        g->lcg->state = mult[h] * g->lcg->state + sum[h] * g->lcg->inc;
        g->uinteger = (uint32_t)(output(g->lcg->state) >> 32);
        g->has_uint32 = (int)(fresh[h] & 1); /* an odd count of new halves leaves one kept */
    }
    result = Py_NewRef(Py_None);
done:
    PyMem_Free(link);
    release(&v);
    return result;
}

#include "_draw_streams.h"

/* rows(origins, envs, lo, hi, out): out[r, j] <- number lo + r of the episode drawn from
 * origins[envs[j]], for r in [0, hi - lo); out is float32 (hi - lo, len(envs)). */
static PyObject *rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "rows(origins, envs, lo, hi, out)");
        return NULL;
    }
    long long lo = PyLong_AsLongLong(args[2]), hi = PyLong_AsLongLong(args[3]);
    if ((lo == -1 || hi == -1) && PyErr_Occurred())
        return NULL;
    if (lo < 0 || hi < lo) {
        PyErr_SetString(PyExc_ValueError, "rows: 0 <= lo <= hi expected");
        return NULL;
    }
    Views v = {.count = 0};
    PyObject *result = NULL;
    Py_ssize_t k, n, items;
    const uint64_t *origins = take_origins(&v, args[0], "rows", &n);
    const int64_t *envs = origins == NULL ? NULL : env_indices(&v, args[1], n, &k);
    float *out = envs == NULL ? NULL : take(&v, args[4], 4, "f", -1, 1, "out", &items);
    if (out == NULL)
        goto done;
    if (items != (Py_ssize_t)(hi - lo) * k) {
        PyErr_SetString(PyExc_ValueError, "rows: out of (hi - lo, len(envs)) numbers expected");
        goto done;
    }
    /* TILE envs at a time, each env's numbers into a scratch row, then written out a step at a
     * time: a row of TILE floats is a cache line, where writing down one column at a time
     * would touch a line (and a page) per number */
    const Py_ssize_t r = (Py_ssize_t)(hi - lo);
    Jumps jumps = {.used = 0};
    float *scratch = r == 0 ? NULL : PyMem_Malloc((size_t)(TILE * r) * sizeof(float));
    if (r > 0 && scratch == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t j0 = 0; j0 < k && r > 0; j0 += TILE) {
        const Py_ssize_t b = k - j0 < TILE ? k - j0 : TILE;
        for (Py_ssize_t t = 0; t < b; t++) { /* the streams' cursor, from number lo on */
            const uint64_t *o = origins + ORIGIN * envs[j0 + t];
            float *col = scratch + t * r;
            fill(seek(o, (uint64_t)lo, &jumps), o, join(o[2], o[3]), col, col + r);
        }
        for (Py_ssize_t q = 0; q < r; q++)
            for (Py_ssize_t t = 0; t < b; t++)
                out[q * k + j0 + t] = scratch[t * r + q];
    }
    PyMem_Free(scratch);
    result = Py_NewRef(Py_None);
done:
    release(&v);
    return result;
}

/* streams(origins, envs, t, cursors, layout, amplitude, fresh, refs, radius, angle): for each env
 * e = envs[j] at step t[j] >= 0, refs[j] <- its random_steps reference, radius[j] and angle[j] <-
 * the uniforms of its Box-Muller noise (_draw_streams.h), reading and moving its cursor words
 * (cursors: (STREAM_WORDS, N), a row per word; fresh: sought from the origin, as after a
 * restart). layout = (half, refs_at, holds, shortest, longest). Returns how many t[j] >= half
 * (their noise is a sine). */
static PyObject *streams(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 10) {
        PyErr_SetString(PyExc_TypeError,
                        "streams(origins, envs, t, cursors, layout, amplitude, fresh, refs, radius, angle)");
        return NULL;
    }
    const double amplitude = PyFloat_AsDouble(args[5]);
    const int fresh = PyObject_IsTrue(args[6]);
    if ((amplitude == -1.0 && PyErr_Occurred()) || fresh < 0)
        return NULL;
    Views v = {.count = 0};
    PyObject *result = NULL;
    Py_ssize_t k, n, cursor_words;
    const uint64_t *origins = take_origins(&v, args[0], "streams", &n);
    const int64_t *envs = origins == NULL ? NULL : env_indices(&v, args[1], n, &k);
    const int64_t *t = envs == NULL ? NULL : take(&v, args[2], 8, "qlL", k, 0, "t", NULL);
    uint64_t *cursors = t == NULL ? NULL : take(&v, args[3], 8, "QLK", -1, 1, "cursors", &cursor_words);
    const int64_t *layout = cursors == NULL ? NULL : take(&v, args[4], 8, "qlL", 5, 0, "layout", NULL);
    double *refs = layout == NULL ? NULL : take(&v, args[7], 8, "d", k, 1, "refs", NULL);
    float *radius = refs == NULL ? NULL : take(&v, args[8], 4, "f", k, 1, "radius", NULL);
    float *angle = radius == NULL ? NULL : take(&v, args[9], 4, "f", k, 1, "angle", NULL);
    if (angle == NULL)
        goto done;
    if (cursor_words != STREAM_WORDS * n) {
        PyErr_Format(PyExc_ValueError, "streams: cursors of %d words per env expected", STREAM_WORDS);
        goto done;
    }
    const Layout l = {layout[0], layout[1], layout[2], layout[3], layout[4], amplitude};
    if (l.half < 1 || l.refs_at < 2 * l.half || l.holds < 1 || l.shortest < 1 || l.longest < l.shortest) {
        PyErr_SetString(PyExc_ValueError, "streams: layout (half, refs_at, holds, shortest, longest) out of range");
        goto done;
    }
    int synced = 1, ascending = 1, consecutive = 1, restart = 0;
    Py_ssize_t sines = 0;
    for (Py_ssize_t j = 0; j < k; j++) {
        if (t[j] < 0 || t[j] >= 2 * l.half) {
            PyErr_Format(PyExc_ValueError, "streams: step %lld outside 0..%lld", (long long)t[j],
                         (long long)(2 * l.half - 1));
            goto done;
        }
        synced &= t[j] == t[0];
        ascending &= j == 0 || envs[j] > envs[j - 1];
        consecutive &= envs[j] == envs[0] + j;
        restart |= t[j] == 0;
        sines += t[j] >= l.half;
    }
    /* the envs that step on first (step_on), then the others in their order (stream_step); where
     * an env may come twice (envs not ascending) or all restart, every env in its order */
#if WIDE
    const int wide = consecutive && k > 0 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq");
#endif
    Jumps jumps = {.used = 0};
    Py_ssize_t later[STREAM_CHUNK];
#if WIDE
    Restarts restarts;
    if (wide && restart) /* the restarts' jumps, where some env is at step 0 */
        restarts_of(&l, &jumps, &restarts);
#endif
    for (Py_ssize_t j0 = 0; j0 < k; j0 += STREAM_CHUNK) {
        const Py_ssize_t j1 = k - j0 < STREAM_CHUNK ? k : j0 + STREAM_CHUNK;
        Py_ssize_t m = 0;
        if (fresh || !ascending)
            for (Py_ssize_t j = j0; j < j1; j++)
                later[m++] = j;
#if WIDE
        else if (wide)
            m = step_on_wide(cursors, n, origins, envs[0], t, j0, j1, &l, &restarts, radius, angle, refs, later);
#endif
        else
            m = step_on(cursors, n, envs, t, j0, j1, l.half, synced, radius, angle, refs, later);
        for (Py_ssize_t i = 0; i < m; i++) {
            const Py_ssize_t j = later[i];
            stream_step(cursors + envs[j], n, origins + ORIGIN * envs[j], t[j], fresh, synced, &l, &jumps, radius + j,
                        angle + j, refs + j);
        }
    }
    result = PyLong_FromSsize_t(sines);
done:
    release(&v);
    return result;
}

static PyMethodDef methods[] = {
    {"start", (PyCFunction)(void (*)(void))start, METH_FASTCALL, "Record episodes' origins, move the generators on."},
    {"rows", (PyCFunction)(void (*)(void))rows, METH_FASTCALL, "Numbers [lo, hi) of episodes from their origins."},
    {"streams", (PyCFunction)(void (*)(void))streams, METH_FASTCALL, "One step's noise uniforms and references."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_draw_kernel", "Episode draws from PCG64 generators.",
                                    -1, methods};

PyMODINIT_FUNC PyInit__draw_kernel(void) { return PyModule_Create(&module); }

#else /* no 128-bit integers: no module, the package draws with numpy */

PyMODINIT_FUNC PyInit__draw_kernel(void)
{
    PyErr_SetString(PyExc_ImportError, "_draw_kernel needs a compiler with 128-bit integers");
    return NULL;
}

#endif
