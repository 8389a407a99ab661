"""The power ``|w|^n`` of the Bouc-Wen law, written so that one nozzle and a batch get the same bits.

Neither library power serves both carriers of the joint's RK4 (:mod:`ssme_envs.models.nozzle_joint`):
the C library's ``pow`` is fast on one float but has no SIMD loop, numpy's SIMD power is fast on
arrays but differs from it in the last bit and costs 0.5 us on one float
(``experiments/results/speed_limits.md``). This power is ``exp(n log x)`` built from IEEE additions,
multiplications, table lookups (or the one correctly rounded quotient a table holds, ``1/c``)
and exact scalings only (no fused multiply-add), so
any implementation that performs them in this order gets the same bits: these two (Python
floats, numpy arrays) and the compiled kernel (``_joint_kernel.c``, which receives the tables
from :func:`tables`), which the tests hold to them bit for bit.

- ``log x``: ``x = m 2^e``, ``m`` in ``[1, 2)``; ``c`` the centre of ``m``'s 1/128-wide cell,
  ``r = (m - c) / c`` (``m - c`` exact, times ``1/c``: a table here, the same IEEE quotient
  computed in the compiled kernel), ``log m = log c + log1p r``,
  ``log1p r`` by its series to ``r^6`` (``|r| <= 1/257``: truncation below 2e-18);
  ``e log 2`` in two parts (``LN2_HI`` has 32 significant bits, so ``e LN2_HI`` is exact).
- ``exp y``: ``y = (64 q + j) log(2)/64 + r``, ``|r| <= log(2)/128``, ``q`` and ``j`` from one
  rounding to nearest (adding and subtracting 1.5 2^52); ``exp y = 2^q 2^(j/64) exp r``,
  ``exp r - 1`` by its series to ``r^5`` (truncation below 4e-17); ``2^q`` applied as two exact
  powers of two (the first product is exact, the second rounds once, which also rounds a
  subnormal result correctly). ``y`` is clipped to ``[-800, 800]``, beyond which the result is
  0 or inf anyway.
- The tables (``log c`` and ``2^(j/64)``) come from the ``decimal`` module at 40 digits, so they
  are the same on every platform.

Relative error against the exact power: a few units in the last place plus ``|y|`` ulps from
``y``'s own rounding (``tests/test_joint_kernel.py`` bounds it against ``math.pow``). Domain:
``x >= 0`` (0 gives 0; a subnormal ``x`` is taken as ``m 2^e`` all the same), or inf or NaN,
which are returned as they are; ``n`` positive and finite. (The joint floors ``|w|`` well
above the subnormals, see :func:`~ssme_envs.models.nozzle_joint.rk4_parameters`.)
"""

from __future__ import annotations

import math
from decimal import Context, Decimal
from functools import cache

import numpy as np

LN2_HI = float.fromhex("0x1.62e42feep-1")  # 32 significant bits: e LN2_HI is exact for |e| < 2^21
LN2_LO = float.fromhex("0x1.a39ef35793c76p-33")  # log(2) - LN2_HI
ROUND = float.fromhex("0x1.8p52")  # x + ROUND - ROUND rounds x to an integer, ties to even
LOG_CELLS = 128  # cells of m in [1, 2)
EXP_STEPS = 64  # 2^(j/64), j = 0 .. 63
INV_STEP = float.fromhex("0x1.71547652b82fep6")  # 64/log(2) rounded: it only picks k
STEP_HI, STEP_LO = LN2_HI / EXP_STEPS, LN2_LO / EXP_STEPS  # log(2)/64 in two parts (exact scalings)
Y_LIMIT = 800.0
_FINITE_MAX = 1.7976931348623157e308
_SIXTH = 0.16666666666666666


@cache
def tables() -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """``1/c``, ``log c`` for the cell centres ``c = 1 + (i + 1/2)/128`` and ``2^(j/64)``."""
    ctx = Context(prec=40)
    centres = [1.0 + (i + 0.5) / LOG_CELLS for i in range(LOG_CELLS)]  # exact: 9 significant bits
    ln2 = ctx.ln(Decimal(2))
    return (
        tuple(1.0 / c for c in centres),
        tuple(float(ctx.ln(Decimal(c))) for c in centres),
        tuple(
            float(ctx.exp(ctx.divide(ctx.multiply(ln2, Decimal(j)), Decimal(EXP_STEPS))))
            for j in range(EXP_STEPS)
        ),
    )


def power_float(x: float, n: float) -> float:
    """``x^n`` on Python floats (see the module docstring for the domain)."""
    if not x <= _FINITE_MAX:  # inf or NaN, as they are
        return x
    if x <= 0.0:
        if x == 0.0:
            return 0.0
        raise ValueError(f"the joint's power takes x >= 0, got {x!r}")
    inv_c, log_c, exp2 = tables()
    m, e = math.frexp(x)
    m, e_f = m + m, float(e - 1)
    i = int((m - 1.0) * 128.0)
    r = (m - (1.0 + (i + 0.5) * 0.0078125)) * inv_c[i]
    log1p = r + r * r * (-0.5 + r * (0.3333333333333333 + r * (-0.25 + r * (0.2 + r * -_SIXTH))))
    y = n * ((e_f * LN2_HI + log_c[i]) + (e_f * LN2_LO + log1p))
    y = -Y_LIMIT if y < -Y_LIMIT else (Y_LIMIT if y > Y_LIMIT else y)
    k = (y * INV_STEP + ROUND) - ROUND
    r = (y - k * STEP_HI) - k * STEP_LO
    j = int(k) & 63
    q = (k - float(j)) * 0.015625
    expm1 = r + r * r * (0.5 + r * (_SIXTH + r * (0.041666666666666664 + r * 0.008333333333333333)))
    s = exp2[j]
    q1 = (q * 0.5 - 0.25 + ROUND) - ROUND  # floor(q / 2)
    return ((s * expm1 + s) * math.ldexp(1.0, int(q1))) * math.ldexp(1.0, int(q - q1))


@cache
def _array_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`tables` as read-only arrays, made once."""
    arrays = tuple(np.array(t) for t in tables())
    for a in arrays:
        a.flags.writeable = False
    return arrays


def _two_to(k: np.ndarray) -> np.ndarray:
    """2^k for integral float k in the normal range, exactly."""
    return ((k.astype(np.int64) + 1023) << 52).view(np.float64)


def power_array(x: np.ndarray, n: np.ndarray | float) -> np.ndarray:
    """``x^n`` elementwise on float64 arrays, the operations of :func:`power_float`."""
    inv_c, log_c, exp2 = _array_tables()
    x = np.asarray(x, dtype=np.float64)
    if np.any(x < 0.0):
        raise ValueError(f"the joint's power takes x >= 0, got {x[x < 0.0].flat[0]!r} among the bases")
    finite, zero = x <= _FINITE_MAX, x == 0.0
    m, e = np.frexp(np.where(finite & ~zero, x, 1.0))
    m, e_f = m + m, (e - 1).astype(np.float64)
    i = ((m - 1.0) * 128.0).astype(np.int64)
    r = (m - (1.0 + (i + 0.5) * 0.0078125)) * inv_c[i]
    log1p = r + r * r * (-0.5 + r * (0.3333333333333333 + r * (-0.25 + r * (0.2 + r * -_SIXTH))))
    y = np.clip(n * ((e_f * LN2_HI + log_c[i]) + (e_f * LN2_LO + log1p)), -Y_LIMIT, Y_LIMIT)
    k = (y * INV_STEP + ROUND) - ROUND
    r = (y - k * STEP_HI) - k * STEP_LO
    j = k.astype(np.int64) & 63
    q = (k - j) * 0.015625
    expm1 = r + r * r * (0.5 + r * (_SIXTH + r * (0.041666666666666664 + r * 0.008333333333333333)))
    s = exp2[j]
    q1 = (q * 0.5 - 0.25 + ROUND) - ROUND
    with np.errstate(over="ignore"):
        out = ((s * expm1 + s) * _two_to(q1)) * _two_to(q - q1)
    return np.where(finite, np.where(zero, 0.0, out), x)


__all__ = ["power_array", "power_float", "tables"]
