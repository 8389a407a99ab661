"""Output-error estimation of an alpha-canonical model: its free parameters moved to minimize the
simulation error on a record (a prediction-error method with the output-error noise model).

Two uses:

- :func:`refine`, in the structure choice. It compares index sets by how well their models
  simulate held-out data. The instrumental-variable estimate of a weakly excited or weakly
  observable mode is noisy, and a larger structure can then simulate better only because its
  extra parameters soak up that estimation error, not because the system needs them. Refining
  each close contender on the simulation error it is judged by takes that noise out of the
  comparison (:mod:`.structure_refined`).
- :func:`fit_output_error`, ``identify(method="oe")``: the estimate itself and its covariance.
  Under white output noise it is consistent whatever the instrumental-variable passes did, and
  its intervals are those of the Gauss-Newton information (Ljung, System Identification, 2nd ed.,
  eq 9.17): the least-squares fallback of ``method="iv"`` is biased there, and its intervals
  under-cover.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.linalg
import scipy.optimize

from ssme_envs.identification.metrics import filter_prediction
from ssme_envs.models.statespace import AlphaCanonicalModel, asymmetric_gain
from ssme_envs.models.uncertainty import ParameterUncertainty, jacobian

# Simulation errors below this fraction of an output's spread are round-off (exact fits).
CRITERION_FLOOR = 1e-10
# Iteration cap of the refinement, in evaluations per free parameter (each evaluation is one
# simulation of the record); the start is already consistent, so a few Gauss-Newton steps suffice.
EVALUATIONS_PER_PARAMETER = 30
# Relative decrease of the cost below which the refinement stops: the structure choice compares
# N log(mse) across candidates, which a change of 0.1 % in mse moves by N / 1000 (under 1 for the
# held-out parts of typical records), far below the margins that decide.
COST_TOLERANCE = 1e-3
# The estimate itself (method="oe") is solved to round-off: its covariance is taken where the
# gradient vanishes.
ESTIMATE_TOLERANCE = 1e-12
ESTIMATE_EVALUATIONS_PER_PARAMETER = 200
# The residuals' whiteness (Ljung-Box, over this many lags) is checked at this level: the
# intervals assume white output noise, and the covariance's method says when the record refutes it.
WHITENESS_LAGS = 20
WHITENESS_LEVEL = 0.01
# Residual entries an unstable or overflowing candidate gets: larger than any the stable start
# has, they keep the trust region away without breaking the solver's arithmetic.
OUTSIDE = 1e3


def _minimize(
    residuals: Callable[[np.ndarray], np.ndarray], start: np.ndarray, evaluations_per_parameter: int,
    **tolerances: float,
) -> scipy.optimize.OptimizeResult:  # fmt: skip
    """Least squares of ``residuals`` from ``start`` by scipy's trust region (trf, scaled by the
    Jacobian's columns), at most ``evaluations_per_parameter`` simulations per parameter;
    ``tolerances``: ftol, xtol, gtol (scipy's defaults where not given)."""
    return scipy.optimize.least_squares(
        residuals,
        start,
        method="trf",
        x_scale="jac",
        max_nfev=evaluations_per_parameter * start.size,
        **tolerances,
    )


def _scaled_errors(
    model: AlphaCanonicalModel, u: np.ndarray, y: np.ndarray, free: np.ndarray | None = None,
    basis: np.ndarray | None = None,
) -> Callable[[np.ndarray], np.ndarray]:  # fmt: skip
    """The residual function of the simulation error scaled by each output's spread, flattened.
    Its argument: the model's free parameters (those of ``free``, a mask over
    ``parameter_vector()``; all by default, the others held at the model's values), then the
    coordinates of a constant output offset in the columns of ``basis`` (p, k), if given."""
    scale = 1.0 / np.maximum(np.std(y, axis=0), np.finfo(float).tiny)
    full = model.parameter_vector()
    free = np.ones(full.size, dtype=bool) if free is None else free
    size = int(free.sum())

    def residuals(theta: np.ndarray) -> np.ndarray:
        values = full.copy()
        values[free] = theta[:size]
        candidate = model.with_parameters(values)
        if not candidate.spectral_radius() < 1.0:
            return np.full(y.size, OUTSIDE)
        with np.errstate(all="ignore"):
            simulated = linear_response(candidate, u)
            if basis is not None:
                simulated = simulated + basis @ theta[size:]
            err = (y - simulated) * scale
        return np.nan_to_num(err, nan=OUTSIDE, posinf=OUTSIDE, neginf=-OUTSIDE).ravel()

    return residuals


def refine(
    model: AlphaCanonicalModel,
    u: np.ndarray,
    y: np.ndarray,
) -> AlphaCanonicalModel:
    """The model whose free parameters minimize the scaled sum of squared simulation errors.

    Parameters
    ----------
    model : AlphaCanonicalModel
        Start (a stable model, e.g. the instrumental-variable estimate); its structure is kept.
    u, y : arrays, shapes (T, m), (T, p)
        Record the simulation error is taken on (deviations from the operating point).

    Returns
    -------
    AlphaCanonicalModel
        The refined model, or ``model`` itself when the refinement does not lower the error
        while staying stable (the start is never made worse).
    """
    start = model.parameter_vector()
    residuals = _scaled_errors(model, u, y)
    initial = residuals(start)
    solution = _minimize(residuals, start, EVALUATIONS_PER_PARAMETER, ftol=COST_TOLERANCE)
    refined = model.with_parameters(solution.x)
    if not (refined.spectral_radius() < 1.0 and solution.cost < 0.5 * float(initial @ initial)):
        return model
    refined.fit = dict(model.fit)
    return refined


def fit_output_error(
    model: AlphaCanonicalModel,
    offsets: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    asymmetric: bool,
    binary: np.ndarray,
    uncertainty: bool = True,
) -> tuple[AlphaCanonicalModel, np.ndarray, ParameterUncertainty | None]:
    """The output-error estimate: the free parameters and a constant output offset that minimize
    the sum of squared simulation errors, each output's weighted by its spread.

    Parameters
    ----------
    model : AlphaCanonicalModel
        Start (the instrumental-variable or least-squares estimate); its structure is kept.
    offsets : array, shape (p,)
        Start of the constant output offset (the regression's unexplained intercept).
    u, y : arrays, shapes (T, m), (T, p)
        The record, as deviations from the operating point.
    asymmetric : bool
        Estimate lambda (otherwise it is held at the model's value).
    binary : bool array, shape (m,)
        The binary inputs whose lambda is estimated. Such a lambda shifts the outputs by a constant
        along the input's static gain (eq 42), so the offset is estimated only across those
        directions (none when they span the outputs), as the regression's eq 42 does.
    uncertainty : bool
        Also return the parameters' covariance.

    Returns
    -------
    model, offsets, uncertainty
        The estimate (``model.fit`` kept), its offset, and the covariance of its free parameters
        (the offset marginalized; held parameters 0): the inverse of the Gauss-Newton information
        with each output's residual variance, which assumes white output noise; its ``method``
        says when the residuals are not white (Ljung-Box at ``WHITENESS_LEVEL``). None when not
        asked for.

    Raises
    ------
    ValueError
        The start is unstable (a simulation error is not defined), or the estimate is.
    """
    radius = model.spectral_radius()
    if not radius < 1.0:
        raise ValueError(
            f"method 'oe' simulates the model, and the instrumental-variable estimate it starts from "
            f"is unstable (spectral radius {radius:.4g}): use method 'iv' for a record of an unstable plant"
        )
    full = model.parameter_vector()
    free = np.ones(full.size, dtype=bool)
    free[full.size - model.n_inputs :] = asymmetric
    basis = scipy.linalg.null_space(model.dc_gain()[:, binary].T)
    residuals = _scaled_errors(model, u, y, free, basis)
    start = np.concatenate([full[free], basis.T @ offsets])
    solution = _minimize(
        residuals, start, ESTIMATE_EVALUATIONS_PER_PARAMETER, ftol=ESTIMATE_TOLERANCE,
        xtol=ESTIMATE_TOLERANCE, gtol=ESTIMATE_TOLERANCE,
    )  # fmt: skip
    size = int(free.sum())
    full[free] = solution.x[:size]
    estimate = model.with_parameters(full)
    if not estimate.spectral_radius() < 1.0:
        raise ValueError("the output-error estimate is unstable: use method 'iv'")
    estimate.fit = dict(model.fit)
    offset = basis @ solution.x[size:]
    if not uncertainty:
        return estimate, offset, None
    cov = np.zeros((full.size, full.size))
    free_cov, note = _information_covariance(residuals, solution.x, size, y.shape, estimate.output_names)
    cov[np.ix_(free, free)] = free_cov
    return (
        estimate,
        offset,
        ParameterUncertainty(
            tuple(estimate.parameter_names()),
            cov,
            method="output error, inverse Gauss-Newton information with each output's residual variance "
            f"(white output noise assumed){note}",
            samples=y.shape[0],
        ),
    )


def _information_covariance(
    residuals: Callable[[np.ndarray], np.ndarray], theta: np.ndarray, size: int, shape: tuple[int, int],
    names: tuple[str, ...],
) -> tuple[np.ndarray, str]:  # fmt: skip
    """Covariance of the first ``size`` entries of ``theta`` (the model's free parameters, then the
    offset's) at the output-error estimate: (J^T W J)^-1, J the scaled residuals' Jacobian (central
    differences), W each output's inverse residual variance, the offset marginalized; and the
    caveat for the method text where the residuals of an output are not white ("" otherwise)."""
    samples, p = shape
    errors = residuals(theta).reshape(shape)
    jac = jacobian(residuals, theta).reshape(samples, p, theta.size)
    dof = max(samples - theta.size / p, 1.0)
    sigma = np.sqrt(np.sum(errors**2, axis=0) / dof)
    # an exact record's residuals are round-off: floored as the structure choice floors them
    weighted = (jac / np.maximum(sigma, CRITERION_FLOOR)[None, :, None]).reshape(-1, theta.size)
    # Through the SVD (the information's condition number is the square of the Jacobian's), of
    # columns brought to one size first: B and the offset scale with the outputs' units and K does
    # not, and the rank cut on raw columns dropped one kind in extreme units (variance 0).
    norms = np.linalg.norm(weighted, axis=0)
    norms = np.where(norms > 0.0, norms, 1.0)
    _, singular, vt = np.linalg.svd(weighted / norms, full_matrices=False)
    kept = singular > singular[0] * np.finfo(float).eps * max(weighted.shape)
    root = vt[kept].T / singular[kept] / norms[:, None]
    cov = root[:size] @ root[:size].T
    # (round-off residuals of an exact record are not tested: they are no noise to assume white)
    whiteness = [_ljung_box(errors[:, i]) if sigma[i] > CRITERION_FLOOR else 1.0 for i in range(p)]
    rejected = [
        f"{n} (Ljung-Box p = {v:.2g})" for n, v in zip(names, whiteness, strict=True) if v < WHITENESS_LEVEL
    ]
    note = (
        f"; the residuals of {', '.join(rejected)} are not white, so the intervals may under-cover"
        if rejected
        else ""
    )
    return 0.5 * (cov + cov.T), note


def _ljung_box(errors: np.ndarray) -> float:
    """p-value of the Ljung-Box test that ``errors`` are white, over ``WHITENESS_LAGS`` lags."""
    import scipy.stats  # only here, and a heavy import

    centered = errors - errors.mean()
    n, power = len(centered), float(centered @ centered)
    lags = min(WHITENESS_LAGS, n - 1)
    if power == 0.0 or lags < 1:
        return 1.0
    rho = np.array([centered[k:] @ centered[:-k] for k in range(1, lags + 1)]) / power
    statistic = n * (n + 2) * float(np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    return float(scipy.stats.chi2.sf(statistic, lags))


def linear_response(model: AlphaCanonicalModel, u: np.ndarray) -> np.ndarray:
    """Zero-state response to ``u`` (eq 36 applied), by transfer-function filters (compiled loops:
    the identification simulates every candidate model many times).

    The common denominator is det(zI - A); the numerators follow from it and the Markov
    parameters h_k = C A^(k-1) B by Cayley-Hamilton (num_k = sum_l den_l h_(k-l)), which costs one
    characteristic polynomial instead of one per input-output pair."""
    import scipy.signal  # heavy import, needed only here

    u_star = asymmetric_gain(u, model.lam)
    n = model.A.shape[0]
    den = np.poly(model.A)
    markov = np.zeros((n + 1, model.n_outputs, model.n_inputs))
    power = model.B
    for k in range(1, n + 1):
        markov[k] = model.C @ power
        power = model.A @ power
    num = np.array([np.tensordot(den[: k + 1][::-1], markov[: k + 1], axes=1) for k in range(n + 1)])
    out = np.zeros((u.shape[0], model.n_outputs))
    for j in range(model.n_inputs):
        for i in range(model.n_outputs):
            out[:, i] += scipy.signal.lfilter(num[:, i, j], den, u_star[:, j])
    return out


def held_out_criterion(
    model: AlphaCanonicalModel, parameters: int, u: np.ndarray, y: np.ndarray, split: int, simulation: bool
) -> tuple[float, tuple[float, ...]]:
    """BIC-like score of a model fitted on the samples before ``split``, on the samples after it:
    N sum_i log(mse_i) + parameters log N, with mse_i the mean squared simulation error of output i
    (the filter's one-step error when ``simulation`` is off, for unstable plants), floored at
    round-off so that exact fits tie and the smaller model wins."""
    if simulation:
        if model.spectral_radius() >= 1.0:
            return float("inf"), ()
        predicted = linear_response(model, u)
    else:
        predicted = filter_prediction(model, u, y)
    err = (y - predicted)[split:]
    n = err.shape[0]
    mse = np.mean(err**2, axis=0)
    floor = (CRITERION_FLOOR * np.std(y, axis=0)) ** 2
    score = float(n * np.sum(np.log(np.maximum(mse, floor))) + parameters * np.log(n))
    return score, tuple(np.sqrt(mse).tolist())
