/* step_on for consecutive envs where AVX-512 (F and DQ) runs: eight envs a vector, each lane the
 * operations of step_on's env on 64-bit integers: the 128-bit LCG step from 32-bit products
 * (x86 vectors have no 64 x 64 -> 128-bit product), the output's rotation and the uniform's
 * conversion, all exact, so the bits are step_on's (the import check compares them). Included
 * by _draw_streams.h alone, after step_on. WIDE: whether this machine's compiler builds it; a
 * caller also asks the CPU (__builtin_cpu_supports). */
#ifndef SSME_ENVS_DRAW_WIDE_H
#define SSME_ENVS_DRAW_WIDE_H

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#include <immintrin.h>
#define WIDE 1
#define AVX512 __attribute__((target("avx512f,avx512dq")))

/* (hi, lo) <- (MULTIPLIER (hi, lo) + (inc_hi, inc_lo)) mod 2^128, lane by lane */
static inline AVX512 void lcg_wide(__m512i *lo, __m512i *hi, __m512i inc_lo, __m512i inc_hi)
{
    const uint64_t m_lo = (uint64_t)MULTIPLIER, m_hi = (uint64_t)(MULTIPLIER >> 64);
    const __m512i low32 = _mm512_set1_epi64(0xffffffffLL);
    const __m512i m0 = _mm512_set1_epi64((long long)(m_lo & 0xffffffffu));
    const __m512i m1 = _mm512_set1_epi64((long long)(m_lo >> 32));
    /* m_lo * lo in full from its four 32 x 32-bit products */
    const __m512i s1 = _mm512_srli_epi64(*lo, 32);
    const __m512i p00 = _mm512_mul_epu32(*lo, m0), p01 = _mm512_mul_epu32(s1, m0);
    const __m512i p10 = _mm512_mul_epu32(*lo, m1), p11 = _mm512_mul_epu32(s1, m1);
    const __m512i mid = _mm512_add_epi64(_mm512_srli_epi64(p00, 32),
                                         _mm512_add_epi64(_mm512_and_si512(p01, low32), _mm512_and_si512(p10, low32)));
    const __m512i prod_lo = _mm512_or_si512(_mm512_slli_epi64(mid, 32), _mm512_and_si512(p00, low32));
    __m512i prod_hi = _mm512_add_epi64(p11, _mm512_add_epi64(_mm512_srli_epi64(p01, 32), _mm512_srli_epi64(p10, 32)));
    prod_hi = _mm512_add_epi64(prod_hi, _mm512_srli_epi64(mid, 32));
    /* the cross products' low words (their high words fall past 2^128) */
    const __m512i cross = _mm512_add_epi64(_mm512_mullo_epi64(*hi, _mm512_set1_epi64((long long)m_lo)),
                                           _mm512_mullo_epi64(*lo, _mm512_set1_epi64((long long)m_hi)));
    const __m512i next_lo = _mm512_add_epi64(prod_lo, inc_lo);
    const __mmask8 carry = _mm512_cmplt_epu64_mask(next_lo, prod_lo);
    const __m512i next_hi = _mm512_add_epi64(_mm512_add_epi64(prod_hi, cross), inc_hi);
    *hi = _mm512_mask_add_epi64(next_hi, carry, next_hi, _mm512_set1_epi64(1));
    *lo = next_lo;
}

/* One cursor moved on by a number (advance_unforeseen's), lane by lane: its state (lo, hi) and
 * flag in place; its number (number's, the flag 0 or 1) returned, eight float32 */
static inline AVX512 __m256 cursor_wide(__m512i *lo, __m512i *hi, __m512i *flag, __m512i inc_lo, __m512i inc_hi)
{
    __m512i next_lo = *lo, next_hi = *hi;
    lcg_wide(&next_lo, &next_hi, inc_lo, inc_hi);
    const __mmask8 move = _mm512_test_epi64_mask(*flag, *flag);
    *lo = _mm512_mask_mov_epi64(*lo, move, next_lo);
    *hi = _mm512_mask_mov_epi64(*hi, move, next_hi);
    *flag = _mm512_maskz_mov_epi64((__mmask8)~move, _mm512_set1_epi64(1));
    /* output: the XSL-RR of the state; the flag picks its high half, else its low */
    const __m512i word = _mm512_rorv_epi64(_mm512_xor_si512(*hi, *lo), _mm512_srli_epi64(*hi, 58));
    const __mmask8 high = (__mmask8)~move;
    const __m512i half = _mm512_mask_srli_epi64(_mm512_and_si512(word, _mm512_set1_epi64(0xffffffffLL)), high,
                                                word, 32);
    const __m256 u = _mm512_cvtepu64_ps(_mm512_srli_epi64(half, 8));
    return _mm256_mul_ps(u, _mm256_set1_ps(1.0f / 16777216.0f));
}

/* step_on for the envs e0 + j, j in [j0, j1) (t[j] each), eight at a time */
static AVX512 Py_ssize_t step_on_wide(uint64_t *cursors, Py_ssize_t s, int64_t e0, const int64_t *t, Py_ssize_t j0,
                                      Py_ssize_t j1, int64_t half, float *radius, float *angle, double *refs,
                                      Py_ssize_t *later)
{
    const __m512i one = _mm512_set1_epi64(1), low32 = _mm512_set1_epi64(0xffffffffLL);
    const __m512i halves = _mm512_set1_epi64(half), iota = _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0);
    Py_ssize_t m = 0;
    for (Py_ssize_t j = j0; j < j1; j += 8) {
        const __mmask8 lanes = j1 - j >= 8 ? 0xff : (__mmask8)((1u << (j1 - j)) - 1);
        uint64_t *w = cursors + e0 + j;
        const __m512i tv = _mm512_maskz_loadu_epi64(lanes, t + j);
        const __m512i at = _mm512_maskz_loadu_epi64(lanes, &W(AT));
        const __m512i hold = _mm512_maskz_loadu_epi64(lanes, &W(HOLD));
        __mmask8 on = _mm512_mask_cmpeq_epi64_mask(lanes, _mm512_add_epi64(at, one), tv);
        on = _mm512_mask_cmpneq_epi64_mask(on, tv, halves);
        on = _mm512_mask_cmpge_epu64_mask(on, tv, _mm512_and_si512(hold, low32));
        on = _mm512_mask_cmplt_epu64_mask(on, tv, _mm512_srli_epi64(hold, 32));
        const __mmask8 off = lanes & (__mmask8)~on;
        _mm512_mask_compressstoreu_epi64(later + m, off, _mm512_add_epi64(_mm512_set1_epi64(j), iota));
        m += __builtin_popcount(off);
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
    return m;
}
#else
#define WIDE 0
#endif

#endif /* SSME_ENVS_DRAW_WIDE_H */
