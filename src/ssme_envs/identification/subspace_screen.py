"""A fast screening of DSR_e's candidate orders (:mod:`ssme_envs.identification.subspace_bic`): the
regression of B, D and K (:func:`~ssme_envs.identification.subspace_regression.input_matrices`) and
the one-step prediction criterion
(:func:`~ssme_envs.identification.subspace_checks.prediction_criterion`) computed by other routes
that agree with those to round-off, and refuse (None) where they could not vouch for that.

- The regression: the same regressors (unit responses by FFT, the drive's spectrum shared by all
  candidates), solved by the normal equations of the unit-norm regressors with one refinement step
  instead of an SVD of the stacked regressors, where those are well conditioned (``GRAM_FLOOR``).
- The prediction errors: the predictor's output as the FFT convolution of its impulse response
  with the record, instead of a sample-by-sample loop.
- Both drop the powers ``C A^k`` once ``||A^k||`` is below ``NEGLIGIBLE_POWER`` (they would only
  underflow into slow subnormal arithmetic) and then use FFTs just long enough for the rest.
"""

from __future__ import annotations

import numpy as np
import scipy.fft
import scipy.linalg

from ssme_envs.identification.subspace_regression import output_powers
from ssme_envs.models.linear import spectral_radius

# The normal equations are solved only when the Gram matrix of the unit-norm regressors has its
# smallest eigenvalue above this fraction of its largest (regressors' condition number below 1e5):
# their solution is then off by at most about 1e5**2 * eps ~ 1e-6 relative, which one refinement
# step brings to round-off, and input_matrices' rank test (singular values below ~1e-12 of the
# largest) cannot fail. The Gram's eigenvalues are accurate to ~1e-12 of its norm, far below this.
GRAM_FLOOR = 1e-10
# Powers C A^k are dropped from the first doubling step K with ||A^K|| below this (decaying_powers).
NEGLIGIBLE_POWER = 1e-32
# A predictor with spectral radius at or above 1 - PREDICTOR_MARGIN is not screened: the screened K
# is round-off away from the exact one, and only an eigenvalue condition number near 1e9 would carry
# that across this margin to the unit circle, where the exact criterion is inf.
PREDICTOR_MARGIN = 1e-3


class Spectra:
    """Real FFTs of the columns of ``x`` (T samples) as rows, at the FFT lengths asked for, each
    computed once: shared by the candidates of a pass."""

    def __init__(self, x: np.ndarray) -> None:
        self.samples = x.shape[0]
        self._lines = np.ascontiguousarray(x.T)
        self._by_length: dict[int, np.ndarray] = {}

    def length(self, support: int) -> int:
        """FFT length for convolving ``x`` with a response of ``support`` samples: the linear
        convolution's ``T + support - 1`` samples, so none wraps around onto the first ``T``."""
        return scipy.fft.next_fast_len(self.samples + support - 1, real=True)

    def __call__(self, length: int) -> np.ndarray:
        if length not in self._by_length:
            self._by_length[length] = scipy.fft.rfft(self._lines, length, axis=-1)
        return self._by_length[length]


def decaying_powers(a: np.ndarray, c: np.ndarray, count: int) -> tuple[np.ndarray, int]:
    """``C A^k`` for k < count as :func:`output_powers` gives them (to round-off), shape (count, p, n),
    and the support: the number of leading powers kept, the rest being zero.

    Doubling stops at the first ``K`` with ``||A^K|| < NEGLIGIBLE_POWER``: since
    ``||C A^(j+K)|| <= ||C A^j|| ||A^K||``, every dropped power is below ``NEGLIGIBLE_POWER`` times
    the largest kept one, far below the round-off of the sums it would enter.
    """
    p, n = c.shape
    powers = np.zeros((count, p, n))
    powers[0] = c
    filled, a_pow = 1, a
    while filled < count:
        if np.linalg.norm(a_pow) < NEGLIGIBLE_POWER:  # not for NaN: an overflow goes on into the powers
            break
        step = min(filled, count - filled)  # one matrix product for the whole block
        powers[filled : filled + step] = (powers[:step].reshape(step * p, n) @ a_pow).reshape(step, p, n)
        filled += step
        a_pow = a_pow @ a_pow
    return powers, filled


def screened_input_matrices(
    a: np.ndarray, c: np.ndarray, u: np.ndarray, target: np.ndarray, drive: Spectra
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(B, D, K) as :func:`~ssme_envs.identification.subspace_regression.input_matrices` gives them
    with innovations, solved by the normal equations; None where that solve cannot be trusted to
    round-off (``GRAM_FLOOR``, overflow).

    The regressors are input_matrices' (``x0``, then ``[B K]`` by input, then ``D``) with the rows
    ordered by output then sample (a least-squares fit does not depend on the order of its rows):
    ``u`` and ``target`` (``y - e``, flattened in that order) are from the past horizon on, and
    ``drive`` holds the spectra of ``[u, e]``.

    Raises
    ------
    ValueError
        Where input_matrices raises for certain: its ``C A^k`` (:func:`output_powers`, which its
        regressors hold) overflow.
    """
    horizon, m = u.shape
    p, n = c.shape
    powers, support = decaying_powers(a, c, horizon)
    if not np.all(np.isfinite(powers)):
        if not np.all(np.isfinite(output_powers(a, c, horizon))):  # input_matrices' own powers
            raise ValueError(f"the identified A is unstable (spectral radius {spectral_radius(a):.4g})")
        return None
    length = drive.length(support)
    spectra = drive(length)
    n_drive = spectra.shape[0]
    n_cols = n + n * n_drive + p * m
    phi = np.zeros((n_cols, p, horizon))
    phi[:n] = powers.transpose(2, 1, 0)
    # unit responses: every (state, output) line of C A^k against every drive channel
    lines = scipy.fft.rfft(phi[:n, :, :support], length, axis=-1)
    conv = scipy.fft.irfft(lines[:, None] * spectra[None, :, None], length, axis=-1)
    phi[n : n + n * n_drive].reshape(n, n_drive, p, horizon)[..., 1:] = conv[..., : horizon - 1]
    for i in range(p):  # D: output i's rows hold the inputs
        phi[n + n * n_drive + i * m : n + n * n_drive + (i + 1) * m, i] = u.T
    phi = phi.reshape(n_cols, p * horizon)
    gram = phi @ phi.T  # not finite where phi is not
    if not np.all(np.isfinite(gram)):
        return None
    norms = np.sqrt(np.diag(gram))
    norms[norms == 0.0] = 1.0
    gram = gram / np.outer(norms, norms)
    eigenvalues = np.linalg.eigvalsh(gram)
    if eigenvalues[0] < GRAM_FLOOR * eigenvalues[-1]:
        return None
    try:
        factor = scipy.linalg.cho_factor(gram, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    theta = scipy.linalg.cho_solve(factor, phi @ target / norms, check_finite=False)
    residual = target - (theta / norms) @ phi
    theta = (theta + scipy.linalg.cho_solve(factor, phi @ residual / norms, check_finite=False)) / norms
    if not np.all(np.isfinite(theta)):
        return None
    gains = theta[n : n + n * n_drive].reshape(n, n_drive)
    return gains[:, :m], theta[n + n * n_drive :].reshape(p, m), gains[:, m:]


def screened_criterion(
    matrices: tuple[np.ndarray, ...], u: np.ndarray, y: np.ndarray, past: int, record: Spectra
) -> float | None:
    """prediction_criterion of the model ``matrices`` = (A, B, C, D, K) on the record from sample
    ``past`` on; None where the screen does not vouch for it (a predictor within
    ``PREDICTOR_MARGIN`` of the unit circle, overflow, a singular error covariance). ``record``
    holds the spectra of ``[u, y]`` but its last sample."""
    a, b, c, d, k = matrices
    predictor = a - k @ c
    if spectral_radius(predictor) >= 1.0 - PREDICTOR_MARGIN:
        return None
    horizon = y.shape[0]
    gain = np.hstack([b - k @ d, k])
    powers, support = decaying_powers(predictor, c, horizon - 1)
    impulse = powers[:support].reshape(-1, c.shape[1]) @ gain
    impulse = impulse.reshape(support, -1, gain.shape[1]).transpose(1, 2, 0)  # (p, m + p, support)
    length = record.length(support)
    lines = scipy.fft.rfft(np.ascontiguousarray(impulse), length, axis=-1)
    # x(0) = 0, so y_hat(t) = D u(t) + sum_j impulse_j w(t-1-j): the convolution, one sample late
    convolved = scipy.fft.irfft(np.einsum("iwf,wf->if", lines, record(length)), length, axis=-1)
    predicted = u @ d.T
    predicted[1:] += convolved[:, : horizon - 1].T
    residual = (y - predicted)[past:]
    if not np.all(np.isfinite(residual)):
        return None
    sign, logdet = np.linalg.slogdet(residual.T @ residual / residual.shape[0])
    return float(logdet) if sign > 0 else None


__all__ = [
    "GRAM_FLOOR",
    "NEGLIGIBLE_POWER",
    "PREDICTOR_MARGIN",
    "Spectra",
    "decaying_powers",
    "screened_criterion",
    "screened_input_matrices",
]
