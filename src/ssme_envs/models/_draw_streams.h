/* Cursors on an episode's draw, compiled: any number of the draw sought from its origin and moved
 * on one number at a time (read by `rows` for blocks of numbers), and the per-step streams of one
 * step's Box-Muller noise uniforms and random_steps reference, so that an episode costs what its
 * steps read. Included by _draw_kernel.c alone (after its PCG64 helpers: Lcg, join, output,
 * uniform, jump_of, MULTIPLIER); no Python calls here.
 *
 * The numbers are numpy's draw, and the reference that of envs/references.py's
 * random_steps: the package checks both against their numpy references at import
 * (ssme_envs.envs.episode_streams) and uses the kernel only where they agree. */
#ifndef SSME_ENVS_DRAW_STREAMS_H
#define SSME_ENVS_DRAW_STREAMS_H

#include <math.h>

/* the jumps of a call, found once each: a call seeks few distinct positions (0, half, the
 * reference's uniforms) for hundreds of envs */
enum { JUMPS = 16 };
typedef struct {
    uint64_t n[JUMPS];
    u128 mult[JUMPS], sum[JUMPS];
    int used;
} Jumps;

static void jump_cached(Jumps *c, uint64_t n, u128 *mult, u128 *sum)
{
    for (int i = 0; i < c->used; i++)
        if (c->n[i] == n) {
            *mult = c->mult[i];
            *sum = c->sum[i];
            return;
        }
    jump_of(n, mult, sum);
    if (c->used < JUMPS) {
        c->n[c->used] = n;
        c->mult[c->used] = *mult;
        c->sum[c->used++] = *sum;
    }
}

/* Number q of an episode's draw from origin o (ORIGIN words): flag 0 or 1, the low or high half
 * of output(s); flag 2, the kept half o[5] (q = 0 where the generator held one), whose next
 * number is the low half of the first new output. */
typedef struct {
    u128 s;
    uint64_t flag;
} Cursor;

/* Where number q lies for a generator that kept a half (h) or not: its cursor is (mult s0 + sum
 * inc, flag) from the origin's state s0 and increment inc */
static inline void seek_jump(uint64_t q, uint64_t h, Jumps *jumps, u128 *mult, u128 *sum, uint64_t *flag)
{
    if (h && q == 0) { /* the kept half: the origin's state as it is */
        *mult = 1, *sum = 0, *flag = 2;
        return;
    }
    const uint64_t f = q - h; /* the new half f: output f / 2 + 1, its high half where f is odd */
    jump_cached(jumps, f / 2 + 1, mult, sum);
    *flag = f & 1;
}

static inline Cursor seek(const uint64_t *o, uint64_t q, Jumps *jumps)
{
    Cursor c;
    u128 mult, sum;
    seek_jump(q, o[4] != 0, jumps, &mult, &sum, &c.flag);
    c.s = mult * join(o[0], o[1]) + sum * join(o[2], o[3]);
    return c;
}

static inline float number(const Cursor *c, const uint64_t *o)
{
    if (c->flag == 2)
        return uniform((uint32_t)o[5]);
    const uint64_t word = output(c->s);
    return uniform(c->flag ? (uint32_t)(word >> 32) : (uint32_t)word);
}

static inline void advance(Cursor *c, u128 inc)
{
    if (c->flag == 0) {
        c->flag = 1;
        return;
    }
    c->s = MULTIPLIER * c->s + inc;
    c->flag = 0;
}

/* advance without a branch: where a call's envs are at different steps their flags are as good
 * as random, and the mispredicted branches cost more than the multiplication that the low half
 * does not need (a sixth of the streams' step at N = 4096); where they are at one step, the
 * branch is foreseen and the multiplication costs more */
static inline void advance_unforeseen(Cursor *c, u128 inc)
{
    const u128 next = MULTIPLIER * c->s + inc;
    const uint64_t move = (uint64_t)0 - (uint64_t)(c->flag != 0);
    const u128 keep = ((u128)~move << 64) | ~move;
    c->s = (next & ~keep) | (c->s & keep);
    c->flag = (c->flag == 0);
}

/* The numbers [col, end) from cursor c on: one at a time to a low half, then both halves of each
 * output (a block's reads, `rows`) */
static inline void fill(Cursor c, const uint64_t *o, u128 inc, float *col, const float *end)
{
    if (col < end && c.flag != 0) {
        *col++ = number(&c, o);
        advance(&c, inc);
    }
    while (col < end) {
        const uint64_t word = output(c.s);
        *col++ = uniform((uint32_t)word);
        if (col < end)
            *col++ = uniform((uint32_t)(word >> 32));
        c.s = MULTIPLIER * c.s + inc;
    }
}

/* An env's cursor words: the step they hold, the radius and angle cursors' states, the episode's
 * LCG increment, both cursors' flags, the reference's hold (its first step in the low half, its
 * end in the high one) and level. A step on reads these alone, not the origin. The cursors are
 * one row per word ((STREAM_WORDS, N)): word q of env e at cursors[q N + e], so that a step of
 * consecutive envs loads each word as a vector; W(q) is word q of the env at w (rows s apart). */
enum { AT, R_LO, R_HI, A_LO, A_HI, INC_LO, INC_HI, FLAGS, HOLD, LEVEL, STREAM_WORDS };
enum { NO_END = 0xffffffffu }; /* the last hold's end: past every step */
#define W(q) w[(q) * s]

typedef struct {
    int64_t half, refs_at, holds, shortest, longest;
    double amplitude;
} Layout;

static inline void store(uint64_t *w, Py_ssize_t s, int lo, const Cursor *c)
{
    W(lo) = (uint64_t)c->s;
    W(lo + 1) = (uint64_t)(c->s >> 64);
}

static inline Cursor load(const uint64_t *w, Py_ssize_t s, int lo, uint64_t flag)
{
    Cursor c = {join(W(lo), W(lo + 1)), flag};
    return c;
}

/* the seeks and the hold's search, which a few envs of a step take: out of line, so that the loop
 * over envs keeps its values in registers (a seventh of the streams' step at N = 4096) */
#if defined(__GNUC__) || defined(__clang__)
#define COLD __attribute__((noinline, cold))
#else
#define COLD
#endif

/* The reference's hold at step t and its level: holds of shortest + floor(u (longest - shortest
 * + 1)) steps from the first `holds` uniforms at refs_at, levels (2 u - 1) amplitude from the next
 * `holds`; into the words HOLD (the hold's steps) and LEVEL. */
static COLD void find_hold(uint64_t *w, Py_ssize_t s, const uint64_t *o, int64_t t, const Layout *l,
                           Jumps *jumps)
{
    const u128 inc = join(o[2], o[3]);
    Cursor u = seek(o, (uint64_t)l->refs_at, jumps);
    int64_t begin = 0, end = 0, hold = 0;
    for (; hold < l->holds; hold++) {
        const double x = (double)number(&u, o);
        advance(&u, inc);
        begin = end;
        end += l->shortest + (int64_t)floor(x * (double)(l->longest - l->shortest + 1));
        if (end > t)
            break;
    }
    if (hold == l->holds || end > (int64_t)NO_END) { /* the last hold (the holds cover every episode) */
        hold = hold < l->holds ? hold : l->holds - 1;
        end = NO_END;
    }
    for (int64_t skip = hold + 1; skip < l->holds + hold; skip++) /* to level uniform holds + hold */
        advance(&u, inc);
    double level = 2.0 * (double)number(&u, o) - 1.0;
    level *= l->amplitude;
    W(HOLD) = (uint64_t)begin | ((uint64_t)end << 32);
    memcpy(&W(LEVEL), &level, sizeof level);
}

/* the radius and angle cursors of step t sought from the origin (a restart, or a step that is
 * neither the one held nor the next): out of the loop's hot path */
static COLD void seek_pair(uint64_t *w, Py_ssize_t s, const uint64_t *o, int64_t t, const Layout *l,
                           Jumps *jumps, Cursor *r, Cursor *a)
{
    const int cosine = t < l->half;
    *r = seek(o, (uint64_t)(cosine ? t : t - l->half), jumps);
    *a = seek(o, (uint64_t)(cosine ? l->half + t : t), jumps);
    W(INC_LO) = o[2];
    W(INC_HI) = o[3];
}

/* the radius and angle cursors of the env at w: as held (move 0) or moved on by a number */
static inline void held_pair(const uint64_t *w, Py_ssize_t s, int move, int synced, Cursor *r, Cursor *a)
{
    *r = load(w, s, R_LO, W(FLAGS) & 3);
    *a = load(w, s, A_LO, W(FLAGS) >> 2);
    if (!move)
        return;
    const u128 inc = join(W(INC_LO), W(INC_HI));
    if (synced) {
        advance(r, inc);
        advance(a, inc);
    } else {
        advance_unforeseen(r, inc);
        advance_unforeseen(a, inc);
    }
}

/* the cursors r and a kept as the env's at step t */
static inline void keep_pair(uint64_t *w, Py_ssize_t s, uint64_t t, const Cursor *r, const Cursor *a)
{
    store(w, s, R_LO, r);
    store(w, s, A_LO, a);
    W(FLAGS) = r->flag | a->flag << 2;
    W(AT) = t;
}

/* One env at step t: its radius and angle uniforms (row t of normal_rows: u_t and u_half+t, or
 * u_t-half and u_t from t = half on) and its reference; the cursors move on from the step they
 * hold where t is that step or the next, and are sought from the origin otherwise (or fresh);
 * synced: every env of the call at one step. */
static inline void stream_step(uint64_t *w, Py_ssize_t s, const uint64_t *o, int64_t t, int fresh, int synced,
                               const Layout *l, Jumps *jumps, float *radius, float *angle, double *ref)
{
    Cursor r, a;
    const int64_t held = (int64_t)W(AT);
    if (!fresh && (held == t || (held + 1 == t && t != l->half)))
        held_pair(w, s, held != t, synced, &r, &a);
    else
        seek_pair(w, s, o, t, l, jumps, &r, &a);
    keep_pair(w, s, (uint64_t)t, &r, &a);
    *radius = number(&r, o);
    *angle = number(&a, o);
    const uint64_t hold = W(HOLD);
    if (fresh || (uint64_t)t < (hold & NO_END) || (uint64_t)t >= (hold >> 32))
        find_hold(w, s, o, t, l, jumps);
    memcpy(ref, &W(LEVEL), sizeof *ref);
}

/* Whether the env at w steps on by one to t inside its reference's hold: what the step of all
 * but restarts, the noise's turn to sines and a hold's end is. After such an advance a cursor's
 * flag is 0 or 1: no kept half to read, so no origin either. */
static inline int steps_on(const uint64_t *w, Py_ssize_t s, uint64_t t, int64_t half)
{
    const uint64_t hold = W(HOLD);
    return W(AT) + 1 == t && t != (uint64_t)half && t >= (hold & NO_END) && t < (hold >> 32);
}

/* The envs j of [j0, j1) that step on (steps_on): their cursors moved and values written as
 * stream_step would; the others' j into later, their count returned, for stream_step. */
static Py_ssize_t step_on(uint64_t *cursors, Py_ssize_t s, const int64_t *envs, const int64_t *t, Py_ssize_t j0,
                          Py_ssize_t j1, int64_t half, int synced, float *radius, float *angle, double *refs,
                          Py_ssize_t *later)
{
    Py_ssize_t m = 0;
    for (Py_ssize_t j = j0; j < j1; j++) {
        uint64_t *w = cursors + envs[j];
        if (!steps_on(w, s, (uint64_t)t[j], half)) {
            later[m++] = j;
            continue;
        }
        Cursor r, a;
        held_pair(w, s, 1, synced, &r, &a);
        keep_pair(w, s, (uint64_t)t[j], &r, &a);
        radius[j] = number(&r, NULL);
        angle[j] = number(&a, NULL);
        memcpy(refs + j, &W(LEVEL), sizeof *refs);
    }
    return m;
}

#include "_draw_wide.h"

#endif /* SSME_ENVS_DRAW_STREAMS_H */
