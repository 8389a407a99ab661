"""Covariance of identified alpha-canonical parameters.

Each output's equation ``y_i(k) = phi_i(k) theta_i + v_i(k)`` is solved by least squares or by
instrumental variables with instruments ``z_i`` (least squares: ``z_i = phi_i``). The estimate's
covariance is the sandwich

    cov(theta) = G^-1 S G^-T,   G = blockdiag(z_i^T phi_i),   S = sum_{|l| <= L} sum_k g(k) g(k-l)^T,

with ``g(k)`` the stacked ``z_i(k) v_i(k)`` of all outputs. The sum over lags is there because the
equation error is not white: with white noise ``e`` on the measured outputs,
``v_i(k) = e_i(k) - sum_d K e(k-1-d)`` is a moving average of order ``mu_i``, and the outputs'
errors are correlated with each other, so ``L = max(mu)`` and the cross terms are kept (a
heteroscedasticity and autocorrelation consistent estimate with the lag window the model
implies). The model's free parameters (K, H, B, lambda) are functions of the stacked theta;
their covariance follows by the delta method.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg

from ssme_envs.models.uncertainty import ParameterUncertainty, jacobian

if TYPE_CHECKING:
    from ssme_envs.identification.alpha_fit import _Fit
    from ssme_envs.models.statespace import AlphaCanonicalModel


def lag_window_meat(scores: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The sandwich's meat of ``scores`` (T, k): ``S^T S`` plus, for each lag ``l`` from 1,
    ``weights[l - 1]`` times the lag's cross products and their transpose."""
    meat = scores.T @ scores
    for lag, weight in enumerate(weights, start=1):
        cross = scores[lag:].T @ scores[:-lag]
        meat += weight * (cross + cross.T)
    return meat


def theta_covariance_factor(
    phis: list[np.ndarray], instruments: list[np.ndarray], residuals: list[np.ndarray], lags: int
) -> np.ndarray:
    """A factor ``F`` of the stacked per-output estimates' sandwich covariance, ``cov = F F^T``
    (see the module docstring). A factor, not the product: mapped through the delta method's
    Jacobian ``J`` as ``(J F)(J F)^T`` the covariance stays positive semi-definite on any record,
    where ``J cov J^T`` loses it to round-off when the regression is nearly exact (the bread's
    large entries cancel in ``J``)."""
    g = np.hstack([z * v[:, None] for z, v in zip(instruments, residuals, strict=True)])
    # Each column through its own size: the window's sum is not positive semi-definite on every
    # record, and its negative part, dropped below, must be the same in any units (on the raw
    # columns it is not: K's standard errors changed 7-fold between outputs in units 1e-3 and 1);
    # and outputs near 1e100, whose squares are still finite, give products beyond float64.
    sizes = np.maximum(np.max(np.abs(g), axis=0), np.finfo(float).tiny)
    g = g / sizes
    meat = lag_window_meat(g, np.ones(lags))
    values, vectors = np.linalg.eigh(0.5 * (meat + meat.T))
    root = sizes[:, None] * vectors * np.sqrt(np.clip(values, 0.0, None))
    bread = scipy.linalg.block_diag(
        *[np.linalg.inv(z.T @ phi) for z, phi in zip(instruments, phis, strict=True)]
    )
    n, k = g.shape[0], g.shape[1]
    return bread @ root * np.sqrt(n / max(n - k / len(phis), 1))


# what ``kept_estimator`` says where method "iv" kept least squares; its opening identifies it
LEAST_SQUARES_KEPT = (
    "least squares (kept: no instrumental-variable pass simulated the record better; biased "
    "under white output noise, so the intervals may under-cover: method 'oe' corrects both)"
)


def kept_estimator(fit: _Fit, method: str) -> str:
    """The estimator whose estimate ``fit`` holds, in words: for ``method="iv"`` least squares
    where no instrumental-variable pass simulated the record better (least squares is biased under
    white output noise, which its intervals do not cover)."""
    if fit.instruments is not fit.phis:
        return "instrumental variables"
    return LEAST_SQUARES_KEPT if method == "iv" else "least squares"


def least_squares_kept(uncertainty_method: str) -> bool:
    """Whether a model's ``uncertainty.method`` text says that method "iv" kept least squares."""
    return uncertainty_method.startswith(LEAST_SQUARES_KEPT)


def least_squares_note(where: str) -> str:
    """A console line saying that method "iv" kept least squares for the model of ``where``, and
    what follows for its estimate and intervals."""
    return (
        f"note: {where}: no instrumental-variable pass simulated the record better, so the estimate "
        "is least squares', biased under white output noise, and its intervals may under-cover: "
        "--method oe corrects both"
    )


def parameter_uncertainty(fit: _Fit, y: np.ndarray, method: str) -> ParameterUncertainty:
    """Covariance of the fitted model's free parameters (K, H, B, lambda) from its regression."""
    residuals = fit.residuals(y)
    lags = max(fit.model.observability_indices)
    factor = theta_covariance_factor(fit.phis, fit.instruments, residuals, lags)
    sizes = np.cumsum([th.size for th in fit.thetas])[:-1]

    def parameters(flat: np.ndarray) -> np.ndarray:
        return fit.build(np.split(flat, sizes))[0].parameter_vector()

    mapped = jacobian(parameters, np.concatenate(fit.thetas)) @ factor
    cov = mapped @ mapped.T
    return ParameterUncertainty(
        tuple(fit.model.parameter_names()),
        0.5 * (cov + cov.T),
        method=f"{kept_estimator(fit, method)}, sandwich covariance with {lags} lags of the equation "
        "error, delta method to the model parameters",
        samples=int(y.shape[0]),
    )


def markov_standard_errors(model: AlphaCanonicalModel, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Markov parameters ``C A^k B`` (k < count) and their standard errors by the delta method on
    the model's parameter covariance; both of shape (count, p, m)."""
    rows = model.uncertain_rows()
    mean = model.parameter_vector()

    def markov(values: np.ndarray) -> np.ndarray:
        return model.with_parameters(model.filled(values)).markov_parameters(count).ravel()

    cov = model.uncertainty.propagate(markov, mean[rows])
    shape = (count, model.n_outputs, model.n_inputs)
    return markov(mean[rows]).reshape(shape), np.sqrt(np.clip(np.diag(cov), 0, None)).reshape(shape)
