"""Step 4 of DSR_e (:mod:`ssme_envs.identification.subspace`): ``B``, ``D`` and ``K`` given ``A``,
``C`` and the innovations, by one least-squares regression on simulated unit responses."""

from __future__ import annotations

import numpy as np
import scipy.signal

from ssme_envs.models.linear import spectral_radius


def output_powers(a: np.ndarray, c: np.ndarray, count: int) -> np.ndarray:
    """``C A^k`` for k = 0..count-1, shape (count, p, n), by doubling."""
    powers = c[None]
    a_pow = a
    while powers.shape[0] < count:
        powers = np.concatenate([powers, powers @ a_pow])
        a_pow = a_pow @ a_pow
    return powers[:count]


def input_matrices(
    a: np.ndarray, c: np.ndarray, u: np.ndarray, y: np.ndarray, e: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(B, D, K) by least squares given A, C, the inputs and the innovations.

    Choice: regression on simulated unit responses rather than on an estimated state sequence.
    Given A and C the output ``y(k) - e(k) = C A^k x0 + sum_j C A^(k-1-j) [B K] [u; e](j) + D u(k)``
    is linear in ``x0``, ``B``, ``K`` and ``D``, so one least-squares fit over the whole record
    gives them all, with no state estimate, no further horizon, and an exact answer on noise-free
    data. The unit responses are convolutions of ``C A^k`` with each input channel (FFT).
    ``e`` is None for a noise-free record (then K = 0).
    """
    horizon, m = u.shape
    p, n = c.shape
    drive = u if e is None else np.hstack([u, e])
    target = y if e is None else y - e
    n_drive = drive.shape[1]
    powers = output_powers(a, c, horizon)  # (T, p, n)
    conv = scipy.signal.fftconvolve(powers[:, :, :, None], drive[:, None, None, :], axes=0)[:horizon]
    responses = np.zeros((horizon, p, n, n_drive))
    responses[1:] = conv[:-1]  # state k sums inputs up to k-1
    feedthrough = np.zeros((horizon, p, p, m))
    for i in range(p):
        feedthrough[:, i, i, :] = u
    phi = np.concatenate(
        [powers, responses.reshape(horizon, p, n * n_drive), feedthrough.reshape(horizon, p, p * m)], axis=2
    ).reshape(horizon * p, -1)
    if not np.all(np.isfinite(phi)):
        raise ValueError(
            f"the identified A is unstable (spectral radius {spectral_radius(a):.4g}) "
            "and its unit responses overflow over the record: try another order or horizons"
        )
    # columns to unit norm: the rank test (relative to the largest singular value) then does not
    # depend on the units of the inputs against those of the initial state's columns
    norms = np.linalg.norm(phi, axis=0)
    norms[norms == 0.0] = 1.0
    theta, _, rank, _ = np.linalg.lstsq(phi / norms, target.reshape(-1), rcond=None)
    theta = theta / norms
    if rank < phi.shape[1]:
        radius = spectral_radius(a)
        if radius > 1.0:  # growing unit responses swamp the rest of the regression, whatever the input
            raise ValueError(
                f"the identified A is unstable (spectral radius {radius:.4g}): its unit responses grow "
                f"by {np.max(np.abs(powers[-1])) / np.max(np.abs(powers[0])):.3g} over the record and "
                f"leave the regression of B and D rank {rank} of {phi.shape[1]}: try another order "
                "or horizons"
            )
        raise ValueError(
            f"the inputs do not determine B and D (regression rank {rank} of {phi.shape[1]}): "
            "use a richer input, a lower order or longer horizons"
        )
    gains = theta[n : n + n * n_drive].reshape(n, n_drive)
    d = theta[n + n * n_drive :].reshape(p, m)
    k = gains[:, m:] if e is not None else np.zeros((n, p))
    return gains[:, :m], d, k


__all__ = ["input_matrices", "output_powers"]
