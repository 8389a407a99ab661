/* CLONES: a function compiled for x86-64-v4 (AVX-512 F, BW, CD, DQ, VL), AVX2 and the baseline,
 * the best of them picked at load time (GCC on x86-64 Linux; elsewhere the baseline alone). The
 * kernels' bits do not depend on which: no fused multiply-add, no fast math, the same IEEE
 * operations at every width. */
#ifndef SSME_ENVS_CLONES_H
#define SSME_ENVS_CLONES_H

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define CLONES
#endif

#endif /* SSME_ENVS_CLONES_H */
