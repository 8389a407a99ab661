"""Whether a record shows direct feedthrough, which the alpha-canonical form cannot hold.

The alpha-canonical model is strictly proper: ``y(k)`` depends on the inputs up to ``u(k - 1)``.
A plant whose outputs respond to ``u(k)`` within the sample (``D != 0``) is then fitted by a model
that is wrong without a sign of it in the fit itself: on random plants with ``D`` at 30 % of the
static gain the model's simulation missed the noise-free response by 12-47 % of its spread.

The test: the model's one-step prediction error ``r(k)`` (the state-variable filter of eq 50,
which depends on inputs and outputs up to ``k - 1`` only) is regressed on a constant, ``u(k)`` and
``u(k - 1) .. u(k - q)``. Under a strictly proper plant ``u(k)`` carries nothing about ``r(k)``
that its lags do not (open loop: the noise is independent of the inputs, and a misfit of the
dynamics is a function of past inputs, which the lags take up), so its coefficient is zero up
to the estimate's error. The coefficient's standard error is the Newey-West one, since ``r`` is
coloured wherever the model is not exact. A record is refused when some coefficient is both
beyond ``FEEDTHROUGH_T`` standard errors and larger than ``FEEDTHROUGH_SHARE`` of the output's
spread per unit of the input's (the feedthrough's own share of the output).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ssme_envs.identification.covariance import lag_window_meat
from ssme_envs.identification.metrics import filter_prediction
from ssme_envs.models.statespace import AlphaCanonicalModel

# Refusal thresholds (module docstring). Measured on random stable plants (orders 1-4, 1-2 inputs
# and outputs, 1500 samples, white Gaussian or held binary inputs, 10 % output noise; scratch
# scan of 60 records each): with D = 0 the largest |t| was 2.6 and the largest share 0.013; with
# D at 2 % of the largest static gain the median |t| was 6.6-12, at 10 % 28-62.
FEEDTHROUGH_T = 6.0
FEEDTHROUGH_SHARE = 0.01
# Input lags in the regression; fewer on a short record, and no test below MIN_LAGS.
FEEDTHROUGH_LAGS = 20
MIN_LAGS = 2
# Samples per regression column the test asks for.
SAMPLES_PER_COLUMN = 10


class Feedthrough(NamedTuple):
    """The regression's estimate for each (output, input) pair, arrays of shape (p, m)."""

    coefficient: np.ndarray  # of u_j(k) in output i's prediction error, output units per input unit
    t: np.ndarray  # its t statistic (Newey-West standard error)
    share: np.ndarray  # |coefficient| std(u_j) / std(y_i)


def _lags(n_samples: int, n_inputs: int) -> int:
    """Input lags for a record of ``n_samples``: ``FEEDTHROUGH_LAGS`` or as many as leave
    ``SAMPLES_PER_COLUMN`` samples per column."""
    return min(FEEDTHROUGH_LAGS, n_samples // (SAMPLES_PER_COLUMN * n_inputs) - 2)


def feedthrough_estimate(model: AlphaCanonicalModel, u: np.ndarray, y: np.ndarray) -> Feedthrough | None:
    """The regression of the module docstring on record ``u`` (T, m), ``y`` (T, p); None when the
    record is too short for ``MIN_LAGS`` lags."""
    n_samples, m = u.shape
    q = _lags(n_samples, m)
    if q < MIN_LAGS:
        return None
    spread_y = np.maximum(y.std(axis=0), np.finfo(float).tiny)
    # in units of each output's spread: outputs near 1e150 (accepted: finite squares) stay finite
    residual = (y - filter_prediction(model, u, y))[q:] / spread_y
    rows = n_samples - q
    x = np.column_stack([np.ones(rows)] + [u[q - lag : n_samples - lag] for lag in range(q + 1)])
    # columns scaled to unit size so the normal matrix's condition is the inputs' own
    norms = np.maximum(np.linalg.norm(x, axis=0), np.finfo(float).tiny)
    xs = x / norms
    q_x, r_x = np.linalg.qr(xs)
    beta = np.linalg.solve(r_x, q_x.T @ residual)
    errors = residual - xs @ beta
    r_inv = np.linalg.inv(r_x)
    bread = r_inv @ r_inv.T  # (X'X)^-1 = R^-1 R^-T
    bandwidth = math.floor(4.0 * (rows / 100.0) ** (2.0 / 9.0))
    bartlett = 1.0 - np.arange(1, bandwidth + 1) / (bandwidth + 1.0)
    current = slice(1, 1 + m)
    t = np.zeros((y.shape[1], m))
    coefficient = (beta[current] / norms[current, None]).T  # output spreads per input unit
    for i in range(y.shape[1]):
        meat = lag_window_meat(xs * errors[:, [i]], bartlett)
        variance = np.diag(bread @ meat @ bread)[current]
        se = np.sqrt(np.maximum(variance, 0.0)) / norms[current]
        with np.errstate(divide="ignore", invalid="ignore"):
            t[i] = np.where(se > 0, coefficient[i] / se, np.where(coefficient[i] == 0, 0.0, np.inf))
    share = np.abs(coefficient) * u.std(axis=0)[None, :]
    return Feedthrough(coefficient * spread_y[:, None], t, share)


def check_feedthrough(
    model: AlphaCanonicalModel,
    u: np.ndarray,
    y: np.ndarray,
    input_names: Sequence[str],
    output_names: Sequence[str],
) -> None:
    """Raise ValueError naming the output and input when the record shows direct feedthrough
    (module docstring)."""
    found = feedthrough_estimate(model, u, y)
    if found is None:
        return
    coefficient, t, share = found
    flagged = (np.abs(t) > FEEDTHROUGH_T) & (share > FEEDTHROUGH_SHARE)
    if not flagged.any():
        return
    i, j = np.unravel_index(np.argmax(np.where(flagged, share, -1.0)), share.shape)
    pairs = ", ".join(f"'{output_names[a]}' on '{input_names[b]}'" for a, b in np.argwhere(flagged))
    raise ValueError(
        f"the outputs respond to the inputs within the sample (direct feedthrough: {pairs}), which "
        "the alpha-canonical form (strictly proper) cannot hold, so its model would be wrong. "
        f"Largest: '{output_names[i]}' moves {coefficient[i, j]:.3g} per unit of '{input_names[j]}' at "
        f"the same sample (t = {t[i, j]:.3g}), {100 * share[i, j]:.3g} % of the output's spread. "
        "Pair each output sample with the next input sample (u[1:] with y[:-1]): the model then holds "
        "the feedthrough behind a one-sample delay. Or identify with dsr_e, which estimates D"
    )


__all__ = ["FEEDTHROUGH_SHARE", "FEEDTHROUGH_T", "Feedthrough", "check_feedthrough", "feedthrough_estimate"]
