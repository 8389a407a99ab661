"""Steps 3 and 4 of DSR_e (:mod:`ssme_envs.identification.subspace`): the realization of a candidate
order, and, for a noisy record, the candidate whose model minimizes BIC of its one-step prediction
errors (rule in :func:`~ssme_envs.identification.subspace.dsr_e`).

Scoring every candidate exactly (:func:`realize`, whose regression is an SVD least-squares solve,
then :func:`~ssme_envs.identification.subspace_checks.prediction_criterion`, a sample-by-sample
predictor) in every pass took most of DSR_e's time. So the candidates are screened first by the same
two quantities computed by faster routes (:mod:`ssme_envs.identification.subspace_screen`) that
agree with the exact ones to round-off. Then the candidates within ``TIE_MARGIN`` of the smallest
screened BIC (almost always that one alone) are scored exactly, and the smallest exact BIC wins
with its exact model: the same choice and model as scoring every candidate exactly, unless the
screen erred by more than ``TIE_MARGIN / 2``. A candidate the screen does not vouch for is scored
exactly from the start (its BIC from its exact model, with the screened prediction criterion where
that vouches for itself).
"""

from __future__ import annotations

import math

import numpy as np

from ssme_envs.identification.innovations_model import InnovationsModel
from ssme_envs.identification.subspace_checks import prediction_criterion
from ssme_envs.identification.subspace_regression import input_matrices
from ssme_envs.identification.subspace_screen import Spectra, screened_criterion, screened_input_matrices
from ssme_envs.models.linear import spectral_radius

# Candidates whose screened BIC lies within this of the smallest are scored exactly. Measured on
# 94 noisy random records (the tests' systems, 2000 samples, 1-20 % noise, and the bench's, 5000),
# 1483 screened candidates in 165 passes: screened BICs within 2.5e-8 of the exact ones, and the two
# best candidates of a pass at least 3 apart. Near the noise-free threshold (noise 1e-8 of the
# spread) the screen's error grows to about 5e-4 of BIC, still 100 times below TIE_MARGIN / 2. The
# margin rarely lets a second candidate in.
TIE_MARGIN = 0.1


def observability_pair(
    left: np.ndarray, singular_values: np.ndarray, order: int, p: int
) -> tuple[np.ndarray, np.ndarray]:
    """(A, C) of ``order`` states from the SVD of ``Z``: ``C`` the first block row of the
    extended observability matrix, ``A`` the least-squares solution of its shift invariance."""
    obs = left[:, :order] * np.sqrt(singular_values[:order])
    a, *_ = np.linalg.lstsq(obs[:-p], obs[p:], rcond=None)
    return a, obs[:p].copy()


def realize(
    left: np.ndarray, singular_values: np.ndarray, order: int, u: np.ndarray, y: np.ndarray,
    e: np.ndarray | None, past: int, dt: float,
) -> InnovationsModel:  # fmt: skip
    """The model of ``order`` states from the SVD of ``Z``: (A, C) by shift invariance, then B, D
    and K by regression on the samples from ``past`` on (``e`` None: noise-free, K = 0)."""
    a, c = observability_pair(left, singular_values, order, y.shape[1])
    b, d, k = input_matrices(a, c, u[past:], y[past:], e)
    return InnovationsModel(a, b, c, d, k, dt)


def _bic(count: int, criterion: float, order: int, m: int, p: int) -> float:
    return count * criterion + math.log(count) * (order * (2 * p + m) + p * m)


def _exact_bic(model: InnovationsModel, u: np.ndarray, y: np.ndarray, past: int) -> float | None:
    """The BIC as the rule defines it; None when the candidate does not compete."""
    criterion = prediction_criterion(model, u, y, past)
    if not math.isfinite(criterion):
        return None
    return _bic(y.shape[0] - past, criterion, model.n_states, u.shape[1], y.shape[1])


def record_bic(model: InnovationsModel, u: np.ndarray, y: np.ndarray, first: int) -> float | None:
    """The BIC of ``model``'s one-step prediction errors on the record from sample ``first`` on,
    as the order rule scores a candidate; None where its predictor is unstable."""
    return _exact_bic(model, u, y, first)


def _exact_scan(
    left: np.ndarray, singular_values: np.ndarray, candidates: list[int], u: np.ndarray, y: np.ndarray,
    e: np.ndarray, past: int, dt: float,
) -> tuple[int, InnovationsModel] | None:  # fmt: skip
    """The rule with every candidate scored exactly: the first of the smallest BICs."""
    best = None
    for order in candidates:
        try:
            model = realize(left, singular_values, order, u, y, e, past, dt)
        except ValueError:  # e.g. a spurious unstable pole leaves B and D undetermined
            continue
        bic = _exact_bic(model, u, y, past)
        if bic is not None and (best is None or bic < best[0]):
            best = (bic, order, model)
    return None if best is None else best[1:]


def bic_order(
    left: np.ndarray, singular_values: np.ndarray, candidates: list[int], u: np.ndarray, y: np.ndarray,
    e: np.ndarray, past: int, dt: float,
) -> tuple[int, InnovationsModel] | None:  # fmt: skip
    """The candidate order whose model minimizes BIC of the one-step prediction error on the
    record (rule in dsr_e), with that model; None when no candidate's predictor is stable.

    Screens the candidates and scores exactly those within ``TIE_MARGIN`` of the smallest screened
    BIC (module docstring); should one of those fail its exact scoring, scores every candidate
    exactly.
    """
    m, p = u.shape[1], y.shape[1]
    count = y.shape[0] - past
    target = (y[past:] - e).T.reshape(-1)
    drive, record = Spectra(np.hstack([u[past:], e])), Spectra(np.hstack([u, y])[:-1])
    screened: dict[int, float] = {}  # screened BIC
    exact: dict[int, float] = {}  # BIC as the rule defines it
    models: dict[int, InnovationsModel | None] = {}  # exact models, where realized (None: refused)

    def exact_model(order: int) -> InnovationsModel | None:
        if order not in models:
            try:
                models[order] = realize(left, singular_values, order, u, y, e, past, dt)
            except ValueError:  # e.g. a spurious unstable pole leaves B and D undetermined
                models[order] = None
        return models[order]

    for order in candidates:
        a, c = observability_pair(left, singular_values, order, p)
        try:
            screened_bdk = screened_input_matrices(a, c, u[past:], target, drive)
        except ValueError:  # A's powers overflow: input_matrices refuses this order for certain
            continue
        if screened_bdk is None:  # the screen does not vouch for this regression: realize exactly
            if (model := exact_model(order)) is None:
                continue
            matrices = (model.A, model.B, model.C, model.D, model.K)
        else:
            matrices = (a, screened_bdk[0], c, screened_bdk[1], screened_bdk[2])
        criterion = screened_criterion(matrices, u, y, past, record)
        if criterion is not None:
            screened[order] = _bic(count, criterion, order, m, p)
            continue
        # nor for these prediction errors: score exactly
        if (model := exact_model(order)) is not None and (bic := _exact_bic(model, u, y, past)) is not None:
            exact[order] = bic
    if not screened and not exact:
        return None
    scores = {**screened, **exact}
    bound = min(scores.values()) + TIE_MARGIN
    contenders = [order for order in candidates if scores.get(order, math.inf) <= bound]
    if any(exact_model(order) is None for order in contenders):
        return _exact_scan(left, singular_values, candidates, u, y, e, past, dt)
    if len(contenders) == 1:
        # alone by more than the screen's error: its exact BIC is not needed, only that it counts:
        # a stable predictor (the screen's margin leaves it that; prediction_criterion's other
        # conditions, finite errors with a regular covariance, the screen checked)
        order = contenders[0]
        model = models[order]
        if order in screened and spectral_radius(model.A - model.K @ model.C) >= 1.0:
            return _exact_scan(left, singular_values, candidates, u, y, e, past, dt)
        return order, model
    for order in contenders:
        if order not in exact:
            if (bic := _exact_bic(models[order], u, y, past)) is None:
                return _exact_scan(left, singular_values, candidates, u, y, e, past, dt)
            exact[order] = bic
    best = min(contenders, key=exact.__getitem__)  # the first of equals, as in the exact scan
    return best, models[best]


__all__ = [
    "TIE_MARGIN",
    "bic_order",
    "observability_pair",
    "realize",
    "record_bic",
]
