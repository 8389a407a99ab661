/* The nozzle joint's arithmetic, compiled: the power of joint_power.py, the RK4 steps of
 * nozzle_joint.rk4_floats and rk4_arrays, and the launcher's servo samples, with no Python in
 * them. Included by _joint_kernel.c alone (after Python.h, math.h, stdint.h and string.h), which
 * reads the arguments; its notes on the bits hold here. */
#ifndef SSME_ENVS_JOINT_ARITHMETIC_H
#define SSME_ENVS_JOINT_ARITHMETIC_H

#include "_clones.h"

#define BLOCK 128
#define STRIDE (BLOCK + 8) /* a block's column rows: room for a whole vector stored past its lanes */

static inline double from_bits(uint64_t u) { double d; memcpy(&d, &u, sizeof d); return d; }
static inline uint64_t to_bits(double d) { uint64_t u; memcpy(&u, &d, sizeof u); return u; }

/* joint_power.tables()'s log c and 2^(j/64), set once by set_tables before any use (its 1/c is
 * the IEEE quotient 1.0 / c, which the power computes: a division costs less than a table read
 * in the vector loops, where each lane's read is emulated) */
static double log_c[128], exp2_table[64];
static int tables_set = 0;

/* x^n in two halves: power_log takes a positive normal x (whose exponent field less `bias` is
 * e in x = m 2^e, m in [1, 2)) to t = y 64/log(2) + 1.5 2^52 (y = n log x, clipped; its low bits
 * hold j) and the reduced argument r; power_exp takes them to exp(y). The batch loops run
 * them as two passes, so that each pass's dependency chain is half as long. */
static const double ROUND = 6755399441055744.0; /* 1.5 2^52 */
static const double TWO52 = 4503599627370496.0;  /* 2^52 */

static inline double power_log(double x, double n, double bias, double *r_out)
{
    const double ln2_hi = 0x1.62e42feep-1, ln2_lo = 0x1.a39ef35793c76p-33;
    const double step_hi = 0x1.62e42feep-7, step_lo = 0x1.a39ef35793c76p-39; /* log(2)/64 */
    const double inv_step = 0x1.71547652b82fep6, y_limit = 800.0;           /* 64/log(2) */
    uint64_t bits = to_bits(x);
    uint64_t mantissa = bits & 0x000fffffffffffffULL;
    uint64_t i = mantissa >> 45;
    double m = from_bits(mantissa | 0x3ff0000000000000ULL);
    double c = from_bits((mantissa & 0x000fe00000000000ULL) | 0x3ff0100000000000ULL); /* 1 + (i + 1/2)/128 */
    double e = from_bits((bits >> 52) | 0x4330000000000000ULL) - (TWO52 + bias);
    double r = (m - c) * (1.0 / c);
    double log1p =
        r + r * r * (-0.5 + r * (0x1.5555555555555p-2 + r * (-0.25 + r * (0.2 + r * -0x1.5555555555555p-3))));
    double y = n * ((e * ln2_hi + log_c[i]) + (e * ln2_lo + log1p));
    y = y < -y_limit ? -y_limit : (y > y_limit ? y_limit : y);
    double t = y * inv_step + ROUND;
    double k = t - ROUND;
    *r_out = (y - k * step_hi) - k * step_lo;
    return t;
}

static inline double power_exp(double t, double r)
{
    double k = t - ROUND;
    uint64_t j = to_bits(t) & 63;
    double q = (k - (from_bits(j | 0x4330000000000000ULL) - TWO52)) * 0.015625;
    double expm1 =
        r + r * r * (0.5 + r * (0x1.5555555555555p-3 + r * (0x1.5555555555555p-5 + r * 0x1.1111111111111p-7)));
    double s = exp2_table[j];
    double q1 = (q * 0.5 - 0.25 + ROUND) - ROUND;
    /* 2^j as bits: j + 1023 sits in the low bits of (j + 1023) + 2^52, exactly */
    double s1 = from_bits(to_bits(q1 + (TWO52 + 1023.0)) << 52);
    double s2 = from_bits(to_bits((q - q1) + (TWO52 + 1023.0)) << 52);
    return ((s * expm1 + s) * s1) * s2;
}

/* x^n for a positive normal x, whose exponent field less `bias` is e in x = m 2^e, m in [1, 2) */
static inline double power_parts(double x, double n, double bias)
{
    double r, t = power_log(x, n, bias, &r);
    return power_exp(t, r);
}

#define FINITE_MAX 0x1.fffffffffffffp1023

/* joint_power.power_float where x is a positive normal float, inf or NaN (the RK4's floored |w|):
 * the same bits, without the passes for zero and subnormals */
static inline double joint_power_normal(double x, double n)
{
    int finite = x <= FINITE_MAX;
    double out = power_parts(finite ? x : 1.0, n, 1023.0);
    return finite ? out : x;
}

/* joint_power.power_float: x^n for x >= 0 (0 for 0; a subnormal scaled by 2^54, exactly; inf and
 * NaN returned as they are) */
static inline double joint_power(double x, double n)
{
    if (x == 0.0)
        return 0.0;
    if (x < 0x1p-1022)
        return power_parts(x * 0x1p54, n, 1077.0);
    return joint_power_normal(x, n);
}

typedef struct {
    double inv_j, b_j, k_el_j, k_hys_j, beta, gamma, n, floor;
} Joint;

/* the power's base in the Bouc-Wen rate: max(|w|, floor) */
static inline double rate_base(double w, const Joint *p)
{
    double aw = fabs(w);
    return p->floor > aw ? p->floor : aw;
}

/* v (1 - (gamma sign(v w) + beta) power), power = rate_base(w)^n */
static inline double rate_of_power(double v, double w, double power, const Joint *p)
{
    return v * (1.0 - (copysign(p->gamma, v * w) + p->beta) * power);
}

/* v (1 - (gamma sign(v w) + beta) max(|w|, floor)^n), as rk4_floats spells it */
static inline double bouc_wen_rate(double v, double w, const Joint *p)
{
    return rate_of_power(v, w, joint_power_normal(rate_base(w, p), p->n), p);
}

/* one RK4 step of length h of one linear nozzle (w moves as x does); accel0 = tau / J */
static inline void rk4_step_linear(double *px, double *pv, double *pw, double accel0, double h, const Joint *p)
{
    double x = *px, v = *pv, w = *pw;
    double half = 0.5 * h, sixth = h / 6.0;
    double a1 = accel0 - p->b_j * v - p->k_el_j * x - p->k_hys_j * w;
    double x2 = half * v + x, v2 = half * a1 + v, w2 = half * v + w;
    double a2 = accel0 - p->b_j * v2 - p->k_el_j * x2 - p->k_hys_j * w2;
    double x3 = half * v2 + x, v3 = half * a2 + v, w3 = half * v2 + w;
    double a3 = accel0 - p->b_j * v3 - p->k_el_j * x3 - p->k_hys_j * w3;
    double x4 = h * v3 + x, v4 = h * a3 + v, w4 = h * v3 + w;
    double a4 = accel0 - p->b_j * v4 - p->k_el_j * x4 - p->k_hys_j * w4;
    double dx = sixth * ((v2 + v3) * 2.0 + v + v4);
    *px = dx + x;
    *pv = sixth * ((a2 + a3) * 2.0 + a1 + a4) + v;
    *pw = dx + w;
}

/* one RK4 step of length h of one Bouc-Wen nozzle; accel0 = tau / J */
static inline void rk4_step_hysteretic(double *px, double *pv, double *pw, double accel0, double h,
                                       const Joint *p)
{
    double x = *px, v = *pv, w = *pw;
    double half = 0.5 * h, sixth = h / 6.0;
    double a1 = accel0 - p->b_j * v - p->k_el_j * x - p->k_hys_j * w;
    double r1 = bouc_wen_rate(v, w, p);
    double x2 = half * v + x, v2 = half * a1 + v, w2 = half * r1 + w;
    double a2 = accel0 - p->b_j * v2 - p->k_el_j * x2 - p->k_hys_j * w2;
    double r2 = bouc_wen_rate(v2, w2, p);
    double x3 = half * v2 + x, v3 = half * a2 + v, w3 = half * r2 + w;
    double a3 = accel0 - p->b_j * v3 - p->k_el_j * x3 - p->k_hys_j * w3;
    double r3 = bouc_wen_rate(v3, w3, p);
    double x4 = h * v3 + x, v4 = h * a3 + v, w4 = h * r3 + w;
    double a4 = accel0 - p->b_j * v4 - p->k_el_j * x4 - p->k_hys_j * w4;
    double r4 = bouc_wen_rate(v4, w4, p);
    *px = sixth * ((v2 + v3) * 2.0 + v + v4) + x;
    *pv = sixth * ((a2 + a3) * 2.0 + a1 + a4) + v;
    *pw = sixth * ((r2 + r3) * 2.0 + r1 + r4) + w;
}

/* `steps` RK4 steps of `len` (<= BLOCK) nozzles: state rows x, v, w; per-nozzle values in
 * rows of `cols` (tau and the joint's eight parameters), or the joint `shared` by every nozzle
 * (NULL: none; else only tau is read from cols), held in registers instead of eight loads a
 * lane and stage; steps outermost and one loop per joint kind, so that the loop over nozzles is
 * the one the compiler vectorizes.
 * Inlined into rk4_block with `shared` NULL or not, so that each form is compiled on its own. */
static inline __attribute__((always_inline)) void rk4_lanes(double *restrict x, double *restrict v,
                                                            double *restrict w, double (*restrict cols)[STRIDE],
                                                            Py_ssize_t len, double h, long steps, int hys,
                                                            const Joint *shared)
{
    double accel0[BLOCK];
    const Joint one = shared != NULL ? *shared : (Joint){0};
    for (Py_ssize_t i = 0; i < len; i++)
        accel0[i] = cols[0][i] * (shared != NULL ? one.inv_j : cols[1][i]);
#define JOINT_AT(i)                                                                                                 \
    (shared != NULL ? one                                                                                       \
                    : (Joint){cols[1][i], cols[2][i], cols[3][i], cols[4][i], cols[5][i], cols[6][i], cols[7][i], \
                              cols[8][i]})
    if (hys) {
        /* rk4_step_hysteretic's operations, loops per RK4 stage (one power each) with the
         * stage values kept in L1 between loops: a fused loop of four powers spills registers */
        double acc[4][BLOCK], rate[4][BLOCK], vel[4][BLOCK], xs[BLOCK], ws[BLOCK], t[BLOCK], r[BLOCK];
        const double half = 0.5 * h, sixth = h / 6.0;
        for (long s = 0; s < steps; s++) {
            for (int k = 0; k < 4; k++) {
                const double *xk = k ? xs : x, *vk = k ? vel[k] : v, *wk = k ? ws : w;
                /* bouc_wen_rate in two passes, one half of the power's dependency chain each
                 * (power_log, power_exp): out-of-order execution overlaps more lanes of a
                 * shorter chain */
                for (Py_ssize_t i = 0; i < len; i++) {
                    const Joint p = JOINT_AT(i);
                    double xi = xk[i], vi = vk[i], wi = wk[i], base = rate_base(wi, &p), ri;
                    acc[k][i] = accel0[i] - p.b_j * vi - p.k_el_j * xi - p.k_hys_j * wi;
                    t[i] = power_log(base <= FINITE_MAX ? base : 1.0, p.n, 1023.0, &ri);
                    r[i] = ri;
                }
                for (Py_ssize_t i = 0; i < len; i++) {
                    const Joint p = JOINT_AT(i);
                    double vi = vk[i], wi = wk[i], base = rate_base(wi, &p), power = power_exp(t[i], r[i]);
                    rate[k][i] = rate_of_power(vi, wi, base <= FINITE_MAX ? power : base, &p);
                }
                if (k == 0)
                    memcpy(vel[0], v, (size_t)len * sizeof(double));
                if (k < 3) {
                    const double weight = k < 2 ? half : h;
                    for (Py_ssize_t i = 0; i < len; i++) {
                        xs[i] = weight * vel[k][i] + x[i];
                        vel[k + 1][i] = weight * acc[k][i] + v[i];
                        ws[i] = weight * rate[k][i] + w[i];
                    }
                }
            }
            for (Py_ssize_t i = 0; i < len; i++) {
                x[i] = sixth * ((vel[1][i] + vel[2][i]) * 2.0 + vel[0][i] + vel[3][i]) + x[i];
                v[i] = sixth * ((acc[1][i] + acc[2][i]) * 2.0 + acc[0][i] + acc[3][i]) + v[i];
                w[i] = sixth * ((rate[1][i] + rate[2][i]) * 2.0 + rate[0][i] + rate[3][i]) + w[i];
            }
        }
    } else {
        for (long s = 0; s < steps; s++)
            for (Py_ssize_t i = 0; i < len; i++) {
                const Joint p = JOINT_AT(i);
                rk4_step_linear(&x[i], &v[i], &w[i], accel0[i], h, &p);
            }
    }
#undef JOINT_AT
}

static void CLONES rk4_block(double *restrict x, double *restrict v, double *restrict w,
                             double (*restrict cols)[STRIDE], Py_ssize_t len, double h, long steps, int hys,
                             const Joint *shared)
{
    if (shared != NULL)
        rk4_lanes(x, v, w, cols, len, h, steps, hys, shared);
    else
        rk4_lanes(x, v, w, cols, len, h, steps, hys, NULL);
}

/* The launcher's nozzle servo (launcher_servo.servo_floats and LauncherTask.plant_step's array loop),
 * `samples` samples of `len` (<= BLOCK) launchers: the torque clip(drive - k_p x - k_d v, -lim,
 * lim), times the fault's gain (gain NULL: none), into cols[0]; the rigid body's transition
 * with the deflection before the sample; the joint's RK4 over it; the deflection after.
 * servo = (k_p, k_d, lim), body = (p00, p01, p10, p11, g0_theta, g0_q, g1_theta, g1_q). */
static void CLONES servo_block(double *restrict x, double *restrict v, double *restrict w, double *restrict theta,
                               double *restrict q, const double *restrict drive, const double *restrict gain,
                               const double *restrict servo, const double *restrict body,
                               double (*restrict cols)[STRIDE], Py_ssize_t len, double h, long steps,
                               long samples, int hys, const Joint *shared)
{
    double theta_next[BLOCK], q_next[BLOCK];
    const double k_p = servo[0], k_d = servo[1], lim = servo[2], low = -lim;
    for (long s = 0; s < samples; s++) {
        for (Py_ssize_t i = 0; i < len; i++) {
            double torque = drive[i] - k_p * x[i] - k_d * v[i];
            torque = low > torque ? low : torque;
            torque = lim < torque ? lim : torque;
            cols[0][i] = torque;
            theta_next[i] = body[0] * theta[i] + body[1] * q[i] + body[4] * x[i];
            q_next[i] = body[2] * theta[i] + body[3] * q[i] + body[5] * x[i];
        }
        if (gain != NULL)
            for (Py_ssize_t i = 0; i < len; i++)
                cols[0][i] = cols[0][i] * gain[i];
        rk4_block(x, v, w, cols, len, h, steps, hys, shared);
        for (Py_ssize_t i = 0; i < len; i++) {
            theta[i] = theta_next[i] + body[6] * x[i];
            q[i] = q_next[i] + body[7] * x[i];
        }
    }
}

#endif /* SSME_ENVS_JOINT_ARITHMETIC_H */
