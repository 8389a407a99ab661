/* The streams' common envs eight at a time where AVX-512 (F and DQ) runs, for a call on
 * consecutive envs: those that step on (step_on's), then those at step 0 (stream_step's
 * restart), packed into whole vectors. Each lane gets the operations of its env on 64-bit
 * integers: the 128-bit LCG products from 32-bit ones (x86 vectors have no 64 x 64 -> 128-bit
 * product), the output's rotation, the uniform's conversion and the first hold's float steps,
 * all exact or in the scalar order, so the bits are the scalar paths' (the import check and the
 * tests compare them). Included by _draw_streams.h alone, after step_on. WIDE: whether this
 * machine's compiler builds it; a caller also asks the CPU (__builtin_cpu_supports). */
#ifndef SSME_ENVS_DRAW_WIDE_H
#define SSME_ENVS_DRAW_WIDE_H

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#include <immintrin.h>
#define WIDE 1
#define AVX512 __attribute__((target("avx512f,avx512dq")))

static inline AVX512 __m512i low32(void) { return _mm512_set1_epi64(0xffffffffLL); }

/* (hi, lo) <- (a_hi, a_lo) (b_hi, b_lo) mod 2^128, lane by lane: a_lo b_lo in full from its four
 * 32 x 32-bit products, the cross products' low words (their high words fall past 2^128) */
static inline AVX512 void mul_wide(__m512i a_lo, __m512i a_hi, __m512i b_lo, __m512i b_hi, __m512i *lo, __m512i *hi)
{
    const __m512i a1 = _mm512_srli_epi64(a_lo, 32), b1 = _mm512_srli_epi64(b_lo, 32);
    const __m512i p00 = _mm512_mul_epu32(a_lo, b_lo), p01 = _mm512_mul_epu32(a_lo, b1);
    const __m512i p10 = _mm512_mul_epu32(a1, b_lo), p11 = _mm512_mul_epu32(a1, b1);
    const __m512i mid = _mm512_add_epi64(_mm512_srli_epi64(p00, 32), _mm512_add_epi64(_mm512_and_si512(p01, low32()),
                                                                                      _mm512_and_si512(p10, low32())));
    *lo = _mm512_or_si512(_mm512_slli_epi64(mid, 32), _mm512_and_si512(p00, low32()));
    const __m512i top = _mm512_add_epi64(p11, _mm512_add_epi64(_mm512_srli_epi64(p01, 32), _mm512_srli_epi64(p10, 32)));
    const __m512i cross = _mm512_add_epi64(_mm512_mullo_epi64(a_lo, b_hi), _mm512_mullo_epi64(a_hi, b_lo));
    *hi = _mm512_add_epi64(_mm512_add_epi64(top, _mm512_srli_epi64(mid, 32)), cross);
}

/* (hi, lo) <- (hi, lo) + (b_hi, b_lo) mod 2^128 */
static inline AVX512 void add_wide(__m512i *lo, __m512i *hi, __m512i b_lo, __m512i b_hi)
{
    const __m512i sum_lo = _mm512_add_epi64(*lo, b_lo);
    const __mmask8 carry = _mm512_cmplt_epu64_mask(sum_lo, *lo);
    const __m512i sum_hi = _mm512_add_epi64(*hi, b_hi);
    *hi = _mm512_mask_add_epi64(sum_hi, carry, sum_hi, _mm512_set1_epi64(1));
    *lo = sum_lo;
}

/* number's, lane by lane: flag 0 or 1, the low or high half of the state's output; flag 2, the
 * kept half (kept's low 32 bits); eight float32 */
static inline AVX512 __m256 number_wide(__m512i lo, __m512i hi, __m512i flag, __m512i kept)
{
    const __m512i word = _mm512_rorv_epi64(_mm512_xor_si512(hi, lo), _mm512_srli_epi64(hi, 58));
    const __mmask8 high = _mm512_cmpeq_epi64_mask(flag, _mm512_set1_epi64(1));
    __m512i half = _mm512_mask_srli_epi64(_mm512_and_si512(word, low32()), high, word, 32);
    half = _mm512_mask_and_epi64(half, _mm512_cmpeq_epi64_mask(flag, _mm512_set1_epi64(2)), kept, low32());
    const __m256 u = _mm512_cvtepu64_ps(_mm512_srli_epi64(half, 8));
    return _mm256_mul_ps(u, _mm256_set1_ps(1.0f / 16777216.0f));
}

/* One cursor moved on by a number (advance_unforeseen's), lane by lane: its state (lo, hi) and
 * flag in place; its number returned (the flag is then 0 or 1) */
static inline AVX512 __m256 cursor_wide(__m512i *lo, __m512i *hi, __m512i *flag, __m512i inc_lo, __m512i inc_hi)
{
    __m512i next_lo, next_hi;
    mul_wide(*lo, *hi, _mm512_set1_epi64((long long)(uint64_t)MULTIPLIER),
             _mm512_set1_epi64((long long)(uint64_t)(MULTIPLIER >> 64)), &next_lo, &next_hi);
    add_wide(&next_lo, &next_hi, inc_lo, inc_hi);
    const __mmask8 move = _mm512_test_epi64_mask(*flag, *flag);
    *lo = _mm512_mask_mov_epi64(*lo, move, next_lo);
    *hi = _mm512_mask_mov_epi64(*hi, move, next_hi);
    *flag = _mm512_maskz_mov_epi64((__mmask8)~move, _mm512_set1_epi64(1));
    return number_wide(*lo, *hi, *flag, _mm512_setzero_si512());
}

/* The jumps of a restart (an env at step 0, sought from its origin): its radius's number 0, its
 * angle's number half, its reference's first hold length (number refs_at) and first level
 * (number refs_at + holds), each for a generator that kept a half or not (seek_jump's) */
enum { STARTS = 4 };
typedef struct {
    uint64_t mult[2][STARTS][2], sum[2][STARTS][2], flag[2][STARTS]; /* [kept][which][low, high] */
} Restarts;

static void restarts_of(const Layout *l, Jumps *jumps, Restarts *r)
{
    const uint64_t at[STARTS] = {0, (uint64_t)l->half, (uint64_t)l->refs_at, (uint64_t)(l->refs_at + l->holds)};
    for (int h = 0; h < 2; h++)
        for (int q = 0; q < STARTS; q++) {
            u128 mult, sum;
            seek_jump(at[q], (uint64_t)h, jumps, &mult, &sum, &r->flag[h][q]);
            r->mult[h][q][0] = (uint64_t)mult, r->mult[h][q][1] = (uint64_t)(mult >> 64);
            r->sum[h][q][0] = (uint64_t)sum, r->sum[h][q][1] = (uint64_t)(sum >> 64);
        }
}

/* per lane, the kept generators' value (if_kept) where kept, else the other's */
static inline AVX512 __m512i pick(__mmask8 kept, uint64_t if_not, uint64_t if_kept)
{
    return _mm512_mask_blend_epi64(kept, _mm512_set1_epi64((long long)if_not), _mm512_set1_epi64((long long)if_kept));
}

/* the first `count` of eight lanes (all eight from eight on) */
static inline __mmask8 first_lanes(Py_ssize_t count) { return count >= 8 ? 0xff : (__mmask8)((1u << count) - 1); }

/* The restart of envs env (a vector of env indices; lanes `lanes`) at step 0: stream_step's
 * seek_pair, numbers and find_hold (at step 0 the first hold, whose level is number refs_at +
 * holds), from their origins gathered lane by lane; their cursor words scattered into cursors,
 * and their values into radius, angle and refs at the lanes' j. */
static AVX512 void restart_wide(uint64_t *cursors, Py_ssize_t s, const uint64_t *origins, __m512i env, __m512i j,
                                __mmask8 lanes, const Restarts *r, const Layout *l, float *radius, float *angle,
                                double *refs)
{
    const __m512i rows = _mm512_mullo_epi64(env, _mm512_set1_epi64(ORIGIN));
    __m512i o[ORIGIN];
    for (int q = 0; q < ORIGIN; q++)
        o[q] = _mm512_mask_i64gather_epi64(_mm512_setzero_si512(), lanes, _mm512_add_epi64(rows, _mm512_set1_epi64(q)),
                                           (const long long *)origins, 8);
    const __mmask8 kept = _mm512_test_epi64_mask(o[4], o[4]);
    __m512i lo[STARTS], hi[STARTS], flag[STARTS];
    __m256 u[STARTS];
    for (int q = 0; q < STARTS; q++) { /* each cursor mult s0 + sum inc, and its number */
        __m512i c_lo, c_hi;
        mul_wide(o[0], o[1], pick(kept, r->mult[0][q][0], r->mult[1][q][0]),
                 pick(kept, r->mult[0][q][1], r->mult[1][q][1]), &lo[q], &hi[q]);
        mul_wide(o[2], o[3], pick(kept, r->sum[0][q][0], r->sum[1][q][0]), pick(kept, r->sum[0][q][1], r->sum[1][q][1]),
                 &c_lo, &c_hi);
        add_wide(&lo[q], &hi[q], c_lo, c_hi);
        flag[q] = pick(kept, r->flag[0][q], r->flag[1][q]);
        u[q] = number_wide(lo[q], hi[q], flag[q], o[5]);
    }
    /* the first hold: [0, shortest + floor(u (longest - shortest + 1))), an end beyond NO_END
     * held at NO_END; its level (2 u - 1) amplitude */
    __m512d x = _mm512_mul_pd(_mm512_cvtps_pd(u[2]), _mm512_set1_pd((double)(l->longest - l->shortest + 1)));
    x = _mm512_roundscale_pd(x, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
    __m512i end = _mm512_add_epi64(_mm512_set1_epi64(l->shortest), _mm512_cvttpd_epi64(x));
    end = _mm512_min_epu64(end, _mm512_set1_epi64(NO_END));
    __m512d level = _mm512_sub_pd(_mm512_mul_pd(_mm512_set1_pd(2.0), _mm512_cvtps_pd(u[3])), _mm512_set1_pd(1.0));
    level = _mm512_mul_pd(level, _mm512_set1_pd(l->amplitude));
    const __m512i words[STREAM_WORDS] = {
        [AT] = _mm512_setzero_si512(), [R_LO] = lo[0], [R_HI] = hi[0], [A_LO] = lo[1], [A_HI] = hi[1],
        [INC_LO] = o[2], [INC_HI] = o[3], [FLAGS] = _mm512_or_si512(flag[0], _mm512_slli_epi64(flag[1], 2)),
        [HOLD] = _mm512_slli_epi64(end, 32), [LEVEL] = _mm512_castpd_si512(level),
    };
    for (int q = 0; q < STREAM_WORDS; q++)
        _mm512_mask_i64scatter_epi64(cursors + q * s, lanes, env, words[q], 8);
    _mm512_mask_i64scatter_ps(radius, lanes, j, u[0], 4);
    _mm512_mask_i64scatter_ps(angle, lanes, j, u[1], 4);
    _mm512_mask_i64scatter_pd(refs, lanes, j, level, 8);
}

/* step_on for the envs e0 + j, j in [j0, j1) (t[j] each), eight at a time; those at step 0 are
 * restarted here too (restart_wide) */
static AVX512 Py_ssize_t step_on_wide(uint64_t *cursors, Py_ssize_t s, const uint64_t *origins, int64_t e0,
                                      const int64_t *t, Py_ssize_t j0, Py_ssize_t j1, const Layout *l,
                                      const Restarts *restarts, float *radius, float *angle, double *refs,
                                      Py_ssize_t *later)
{
    const __m512i one = _mm512_set1_epi64(1), iota = _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0);
    Py_ssize_t m = 0, f = 0, firsts[STREAM_CHUNK];
    for (Py_ssize_t j = j0; j < j1; j += 8) {
        const __mmask8 lanes = first_lanes(j1 - j);
        uint64_t *w = cursors + e0 + j;
        const __m512i tv = _mm512_maskz_loadu_epi64(lanes, t + j);
        const __m512i at = _mm512_maskz_loadu_epi64(lanes, &W(AT));
        const __m512i hold = _mm512_maskz_loadu_epi64(lanes, &W(HOLD));
        __mmask8 on = _mm512_mask_cmpeq_epi64_mask(lanes, _mm512_add_epi64(at, one), tv);
        on = _mm512_mask_cmpneq_epi64_mask(on, tv, _mm512_set1_epi64(l->half));
        on = _mm512_mask_cmpge_epu64_mask(on, tv, _mm512_and_si512(hold, low32()));
        on = _mm512_mask_cmplt_epu64_mask(on, tv, _mm512_srli_epi64(hold, 32));
        const __mmask8 start = _mm512_mask_cmpeq_epi64_mask(lanes & (__mmask8)~on, tv, _mm512_setzero_si512());
        const __mmask8 off = lanes & (__mmask8)~(on | start);
        const __m512i jv = _mm512_add_epi64(_mm512_set1_epi64(j), iota);
        _mm512_mask_compressstoreu_epi64(later + m, off, jv);
        m += __builtin_popcount(off);
        _mm512_mask_compressstoreu_epi64(firsts + f, start, jv);
        f += __builtin_popcount(start);
        if (on == 0)
            continue;
        __m512i r_lo = _mm512_maskz_loadu_epi64(on, &W(R_LO)), r_hi = _mm512_maskz_loadu_epi64(on, &W(R_HI));
        __m512i a_lo = _mm512_maskz_loadu_epi64(on, &W(A_LO)), a_hi = _mm512_maskz_loadu_epi64(on, &W(A_HI));
        const __m512i inc_lo = _mm512_maskz_loadu_epi64(on, &W(INC_LO));
        const __m512i inc_hi = _mm512_maskz_loadu_epi64(on, &W(INC_HI));
        const __m512i flags = _mm512_maskz_loadu_epi64(on, &W(FLAGS));
        __m512i r_flag = _mm512_and_si512(flags, _mm512_set1_epi64(3)), a_flag = _mm512_srli_epi64(flags, 2);
        const __m256 r_u = cursor_wide(&r_lo, &r_hi, &r_flag, inc_lo, inc_hi);
        const __m256 a_u = cursor_wide(&a_lo, &a_hi, &a_flag, inc_lo, inc_hi);
        _mm512_mask_storeu_epi64(&W(R_LO), on, r_lo);
        _mm512_mask_storeu_epi64(&W(R_HI), on, r_hi);
        _mm512_mask_storeu_epi64(&W(A_LO), on, a_lo);
        _mm512_mask_storeu_epi64(&W(A_HI), on, a_hi);
        _mm512_mask_storeu_epi64(&W(FLAGS), on, _mm512_or_si512(r_flag, _mm512_slli_epi64(a_flag, 2)));
        _mm512_mask_storeu_epi64(&W(AT), on, tv);
        _mm512_mask_storeu_ps(radius + j, (__mmask16)on, _mm512_castps256_ps512(r_u));
        _mm512_mask_storeu_ps(angle + j, (__mmask16)on, _mm512_castps256_ps512(a_u));
        _mm512_mask_storeu_epi64(refs + j, on, _mm512_maskz_loadu_epi64(on, &W(LEVEL)));
    }
    for (Py_ssize_t i = 0; i < f; i += 8) { /* the restarts, eight a vector */
        const __mmask8 lanes = first_lanes(f - i);
        const __m512i j = _mm512_maskz_loadu_epi64(lanes, firsts + i);
        restart_wide(cursors, s, origins, _mm512_add_epi64(j, _mm512_set1_epi64(e0)), j, lanes, restarts, l, radius,
                     angle, refs);
    }
    return m;
}
#else
#define WIDE 0
#endif

#endif /* SSME_ENVS_DRAW_WIDE_H */
