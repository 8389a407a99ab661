"""Output-error refinement of an alpha-canonical model: its free parameters moved to minimize the
simulation error on a record (a prediction-error method with the output-error noise model).

The structure choice compares index sets by how well their models simulate held-out data. The
instrumental-variable estimate of a weakly excited or weakly observable mode is noisy, and a
larger structure can then simulate better only because its extra parameters soak up that
estimation error, not because the system needs them. Refining each close contender on the
simulation error it is judged by takes that noise out of the comparison.
"""

from __future__ import annotations

import numpy as np
import scipy.optimize

from ssme_envs.identification.metrics import filter_prediction
from ssme_envs.identification.structure import StructureSearch
from ssme_envs.models.statespace import AlphaCanonicalModel, asymmetric_gain

# Simulation errors below this fraction of an output's spread are round-off (exact fits).
CRITERION_FLOOR = 1e-10
# Candidates within this criterion of the best are refined by output error before the choice
# (a BIC difference of 200 is far beyond what estimation noise alone moves), at most this many.
REFINE_MARGIN = 200.0
MAX_CONTENDERS = 4
# Iteration cap of the refinement, in evaluations per free parameter (each evaluation is one
# simulation of the record); the start is already consistent, so a few Gauss-Newton steps suffice.
EVALUATIONS_PER_PARAMETER = 30
# Relative decrease of the cost below which the refinement stops: the structure choice compares
# N log(mse) across candidates, which a change of 0.1 % in mse moves by N / 1000 (under 1 for the
# held-out parts of typical records), far below the margins that decide.
COST_TOLERANCE = 1e-3


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
    scale = 1.0 / np.maximum(np.std(y, axis=0), np.finfo(float).tiny)
    start = model.parameter_vector()

    def residuals(theta: np.ndarray) -> np.ndarray:
        candidate = model.with_parameters(theta)
        if not candidate.spectral_radius() < 1.0:
            # Out of the stable region: a residual vector larger than the start's keeps the
            # trust region away from it without breaking the solver's arithmetic.
            return np.full(y.size, 1e3)
        with np.errstate(all="ignore"):
            err = (y - linear_response(candidate, u)) * scale
        return np.nan_to_num(err, nan=1e3, posinf=1e3, neginf=-1e3).ravel()

    initial = residuals(start)
    solution = scipy.optimize.least_squares(
        residuals,
        start,
        method="trf",
        x_scale="jac",
        ftol=COST_TOLERANCE,
        max_nfev=EVALUATIONS_PER_PARAMETER * start.size,
    )
    refined = model.with_parameters(solution.x)
    if not (refined.spectral_radius() < 1.0 and solution.cost < 0.5 * float(initial @ initial)):
        return model
    refined.fit = dict(model.fit)
    return refined


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


def refine_contenders(
    search: StructureSearch,
    models: dict[tuple[int, ...], AlphaCanonicalModel],
    u: np.ndarray,
    y: np.ndarray,
    split: int,
) -> None:
    """Rescore the candidates within ``REFINE_MARGIN`` of the best after refining each on the
    simulation error of the estimation part (:func:`.output_error.refine`), and choose again.
    Candidates already at the round-off floor have nothing to gain and are left as they are."""
    ranked = search.ranked()
    if not ranked:
        return
    floor = CRITERION_FLOOR * np.std(y, axis=0)  # the floor held_out_criterion applies
    for cand in ranked[:MAX_CONTENDERS]:
        if cand.criterion > ranked[0].criterion + REFINE_MARGIN or np.all(np.array(cand.rms_error) <= floor):
            continue
        refined = refine(models[cand.indices], u[:split], y[:split])
        cand.criterion, cand.rms_error = held_out_criterion(refined, cand.parameters, u, y, split, True)
        cand.note = "output-error refined"
    search.indices = search.ranked()[0].indices
