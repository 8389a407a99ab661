"""Coloured noise for a bootstrap: an autoregressive sieve of a record's residuals.

A residual bootstrap that resamples residuals one by one (with replacement) makes white noise,
whatever the colour of the record's: under slowly varying sensor noise its replicates scatter
far less than the estimates do over noise realizations, and the intervals come out too narrow.
The AR sieve (Kreiss 1992; Buehlmann 1997) keeps the colour: it fits an autoregression
``A(q) v = e`` to the residuals ``v``, its order by Akaike's criterion, resamples the
autoregression's own residuals ``e`` (white to the order's accuracy) and filters them back
through ``1 / A(q)``. On white residuals the criterion picks order 0 or nearly so, and the
sieve is the plain resampling.

The coefficients are the Yule-Walker estimates (:func:`scipy.linalg.solve_toeplitz` on the
biased autocovariance), whose polynomial has its roots inside the unit circle, so the filter
is stable and, after a burn-in as long as the draw, stationary.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal


@dataclass(frozen=True, eq=False)
class ARSieve:
    """An autoregression ``A(q) v = e`` of a residual record and its centred innovations.

    Attributes
    ----------
    denominator : ndarray (p + 1,)
        ``[1, a_1, ..., a_p]``: the filter ``1 / A(q)`` that colours white draws.
    innovations : ndarray (T - p,)
        ``e`` of the record, centred and inflated by ``sqrt(n / (n - p))`` for the ``p``
        coefficients estimated, in the residuals' units.
    lag1 : float
        The residuals' lag-1 autocorrelation.
    long_run_ratio : float
        The autoregression's long-run variance ``var(e) / A(1)^2`` over the residuals' variance:
        1 for white noise, ``(1 + a) / (1 - a)`` for AR(1) noise of coefficient a, the factor by
        which resampling the residuals as white understates the variance of their mean.
    """

    denominator: np.ndarray
    innovations: np.ndarray
    lag1: float
    long_run_ratio: float

    @property
    def order(self) -> int:
        return len(self.denominator) - 1

    def draw(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """``size`` samples of the coloured noise: ``size`` burn-in samples then ``size`` kept,
        the innovations resampled with replacement."""
        e = self.innovations[rng.integers(0, self.innovations.size, 2 * size)]
        return scipy.signal.lfilter([1.0], self.denominator, e)[size:]


def max_sieve_order(samples: int) -> int:
    """The largest order the criterion considers: ``10 log10(T)``, and at most ``T / 4``."""
    return int(min(10 * np.log10(max(samples, 1)), samples // 4))


def fit_sieve(v: np.ndarray, max_order: int | None = None) -> ARSieve:
    """The AR sieve of the residuals ``v`` (T,): the order in ``0..max_order`` (default
    :func:`max_sieve_order`) with the least ``T log(s2_p) + 2 p``, ``s2_p`` the Yule-Walker
    prediction error variance of order ``p``.

    Raises
    ------
    ValueError
        ``v`` not one finite channel of at least 8 samples, constant, or ``max_order`` not an
        integer in ``0..T / 4``.
    """
    v = np.asarray(v, dtype=float)
    if v.ndim != 1 or v.size < 8:
        raise ValueError(f"the residuals must be one channel of at least 8 samples, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("the residuals have NaN or inf entries")
    n = v.size
    limit = max_sieve_order(n) if max_order is None else max_order
    if isinstance(limit, bool) or not isinstance(limit, int | np.integer) or not 0 <= limit <= n // 4:
        raise ValueError(f"max_order must be an integer in 0..{n // 4}, got {max_order!r}")
    v = v - v.mean()
    scale = float(np.max(np.abs(v)))
    if not scale > 0:
        raise ValueError("the residuals are constant: there is no noise to resample")
    z = v / scale  # the coefficients do not depend on the units; 1e-300 or 1e300 rad stay finite
    # biased autocovariance (a stable polynomial), by FFT for long records
    gamma = scipy.signal.correlate(z, z, mode="full")[n - 1 : n + max(limit, 1)] / n
    best, best_score = np.ones(1), n * np.log(gamma[0])
    for p in range(1, limit + 1):
        try:
            a = scipy.linalg.solve_toeplitz(gamma[:p], gamma[1 : p + 1])
        except np.linalg.LinAlgError:  # exactly predictable at this order: keep the last
            break
        variance = gamma[0] - a @ gamma[1 : p + 1]
        if not variance > 0:
            break
        score = n * np.log(variance) + 2 * p
        if score < best_score:
            best, best_score = np.concatenate(([1.0], -a)), score
    e = scipy.signal.lfilter(best, [1.0], z)[best.size - 1 :]
    kept = e.size
    e = (e - e.mean()) * np.sqrt(kept / max(kept - (best.size - 1), 1))
    ratio = float(np.var(e) / np.sum(best) ** 2 / gamma[0])
    return ARSieve(best, e * scale, float(gamma[1] / gamma[0]), ratio)


__all__ = ["ARSieve", "fit_sieve", "max_sieve_order"]
