"""The horizons of DSR_e (:mod:`ssme_envs.identification.subspace`): their defaults and caps, the
refinement of an automatic past horizon, and the retry at other horizons when a pass with a given
order fails or comes out unstable (rules in :func:`~ssme_envs.identification.subspace.dsr_e`).

The functions here take one DSR_e pass as a callable ``one_pass(past, future)`` returning
``(model, singular_values, order, noise_free)`` and raising ValueError when the pass fails.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ssme_envs.identification.innovations_model import InnovationsModel
from ssme_envs.identification.subspace_checks import most_predictive
from ssme_envs.models.linear import spectral_radius

# Target for the neglected term of the innovations estimate: rho(A - K C)^J below this.
PREDICTOR_DECAY = 1e-3
# The stacked data matrix must have at least this many columns per row ...
MIN_COLUMNS_PER_ROW = 2
# ... and the automatic past horizon keeps at least this many (statistical headroom).
AUTO_COLUMNS_PER_ROW = 6
# Refinements of the automatic past horizon after the first pass.
HORIZON_REFINEMENTS = 2
# With order= given, a pass that fails or gives an unstable A or predictor is retried at past
# horizons RETRY_PAST_FACTOR**k times the automatic one (k < RETRY_PASTS, capped as the automatic
# one is) and, when the future horizon is automatic, also at RETRY_FUTURE_FACTOR times it.
RETRY_PAST_FACTOR = 2
RETRY_PASTS = 3
RETRY_FUTURE_FACTOR = 2

Pass = Callable[[int, int], tuple[InnovationsModel, np.ndarray, int, bool]]
# a model's BIC on the record from a sample on; None where it is not scored (an unstable
# predictor, or prediction errors that are not finite or have a singular covariance)
Score = Callable[[InnovationsModel, int], float | None]


class HorizonFit(NamedTuple):
    """A pass's model, the singular values of its ``Z``, its order and the horizons it used."""

    model: InnovationsModel
    singular_values: np.ndarray
    order: int
    past: int
    future: int


def stack_rows(m: int, p: int, past: int, future: int) -> int:
    """Rows of ``[U_f; E_f; U_p; Y_p; Y_f]``."""
    return (future + 1) * (m + 2 * p) + past * (m + p)


def samples_needed(m: int, p: int, past: int, future: int, per_row: int = MIN_COLUMNS_PER_ROW) -> int:
    """Record length giving ``per_row`` columns per row of the stacked data matrix."""
    return past + future + per_row * stack_rows(m, p, past, future)


def past_horizon_cap(n_samples: int, m: int, p: int, future: int, per_row: int = AUTO_COLUMNS_PER_ROW) -> int:
    """Largest past horizon that keeps ``per_row`` columns per row."""
    fixed = future + per_row * (future + 1) * (m + 2 * p)
    return (n_samples - fixed) // (1 + per_row * (m + p))


def check_past_holds_order(n_samples: int, m: int, p: int, past: int, future: int, order: int) -> None:
    """ValueError naming the record length needed when the automatic past horizon, capped by a
    short record, has too few rows for ``order`` states (a pass would fail on the horizons, which
    a command-line user does not set); where the horizon rule itself is too short for the order,
    a longer record would not help and the pass names the horizons."""
    need = math.ceil((order + 1) / (m + p))
    if past >= need or rule_past(future) < need:  # long enough, or the horizon rule's cap binds
        return
    samples = samples_needed(m, p, need, future, AUTO_COLUMNS_PER_ROW)  # where past_horizon_cap reaches it
    raise ValueError(
        f"the record has {n_samples} samples; {order} states need a past horizon of {need}, which the "
        f"automatic horizons (future horizon {future}) reach from {samples} samples on: use a longer record"
    )


def default_future(max_order: int, p: int) -> int:
    """The automatic future horizon ``L``: orders up to ``max_order`` fit in ``L p``."""
    return max(math.ceil(max_order / p), 2)


def rule_past(future: int) -> int:
    """The automatic first past horizon's rule, ``J = max(2 (L + 1), 10)``, before the record's cap."""
    return max(2 * (future + 1), 10)


def default_past(n_samples: int, m: int, p: int, future: int) -> int:
    """The automatic first past horizon :func:`rule_past`, capped by the record (at least 1)."""
    return min(rule_past(future), max(past_horizon_cap(n_samples, m, p, future), 1))


def refined_fit(
    one_pass: Pass, n_samples: int, m: int, p: int, past: int, future: int, refine: bool, score: Score
) -> HorizonFit:
    """A first pass at ``past``, then (``refine``: the past horizon is automatic) up to
    ``HORIZON_REFINEMENTS`` longer past horizons, each until ``rho(A - K C)^J`` reaches
    ``PREDICTOR_DECAY``; a refined pass that fails or turns a stable ``A`` unstable is not kept,
    nor one of another order that ``score`` (a model's BIC on the record from a sample on, None:
    not scored, its predictor unstable or its errors degenerate) puts above the pass it would
    replace, both scored from its horizon on: a longer horizon's innovations estimate on a short
    record can leave every larger order an unstable predictor, and its order scan then drops
    states the record shows. On a noisy record whose length capped ``past`` below the horizon
    rule, then :func:`uncapped_alternative`."""
    model, singular_values, found, noise_free = one_pass(past, future)
    if refine and not noise_free:
        cap = past_horizon_cap(n_samples, m, p, future)
        for _ in range(HORIZON_REFINEMENTS):
            rho = spectral_radius(model.A - model.K @ model.C)
            # rho >= 1 first: a wildly unstable predictor's rho**past overflows
            if rho >= 1.0 or rho**past <= PREDICTOR_DECAY:
                break
            wanted = min(math.ceil(math.log(PREDICTOR_DECAY) / math.log(rho)), cap)
            if wanted <= past:
                break
            try:
                refined = one_pass(wanted, future)
            except ValueError:  # the longer horizon's model fails where this one stands: keep it
                break
            if _turns_unstable(refined[0], model) or (
                refined[2] != found and _scored_worse(score, refined[0], model, wanted)
            ):
                break
            past = wanted
            model, singular_values, found, noise_free = refined
    fit = HorizonFit(model, singular_values, found, past, future)
    if refine and not noise_free:
        fit = uncapped_alternative(one_pass, fit, n_samples, m, p, score)
    return fit


def _turns_unstable(new: InnovationsModel, old: InnovationsModel) -> bool:
    """Whether ``new`` has an unstable ``A`` where ``old``'s is stable (a pass never kept)."""
    return spectral_radius(new.A) >= 1.0 > spectral_radius(old.A)


def _scored_worse(score: Score, new: InnovationsModel, old: InnovationsModel, first: int) -> bool:
    """Whether ``new`` scores worse than ``old`` on the record from sample ``first`` on (an
    unstable predictor scores worst)."""
    new_score, old_score = score(new, first), score(old, first)
    return new_score is None or (old_score is not None and new_score > old_score)


def uncapped_alternative(
    one_pass: Pass, fit: HorizonFit, n_samples: int, m: int, p: int, score: Score
) -> HorizonFit:
    """Where a short record capped the automatic past horizon below its rule (:func:`rule_past`),
    a pass at the rule's horizon as far as ``MIN_COLUMNS_PER_ROW`` allows, kept if ``score`` (BIC
    on the record from the longer horizon on) puts it below ``fit`` and it does not turn a stable
    ``A`` unstable: the capped horizon's innovations estimate is short (lightly damped 300-sample
    records: median fresh-record error 0.22 at the capped horizon, 0.020 with this pass,
    ``experiments/results/short_record_subspace.md``)."""
    past = min(rule_past(fit.future), past_horizon_cap(n_samples, m, p, fit.future, MIN_COLUMNS_PER_ROW))
    if past <= fit.past:  # the record did not cap the first pass below the rule
        return fit
    try:
        trial = HorizonFit(*one_pass(past, fit.future)[:3], past, fit.future)  # in dsr_e's errstate
    except ValueError:
        return fit
    if _turns_unstable(trial.model, fit.model) or _scored_worse(score, trial.model, fit.model, past):
        return fit
    return trial


def retry_horizons(
    one_pass: Pass,
    u: np.ndarray,
    y: np.ndarray,
    first: HorizonFit | None,
    max_order: int,
    past_horizon: int | None,
    future_horizon: int | None,
) -> HorizonFit | None:
    """The fit with the best one-step prediction on the record among ``first`` and passes at the
    retry horizons (those not given); None when none has a stable predictor."""
    n_samples, m = u.shape
    p = y.shape[1]
    default = default_future(max_order, p)
    futures = [future_horizon] if future_horizon is not None else [default, RETRY_FUTURE_FACTOR * default]
    fits = [] if first is None else [first]
    for future in futures:
        cap = max(past_horizon_cap(n_samples, m, p, future), 1)
        start = default_past(n_samples, m, p, future)
        pasts = sorted({min(start * RETRY_PAST_FACTOR**k, cap) for k in range(RETRY_PASTS)})
        for past in pasts if past_horizon is None else [past_horizon]:
            if first is not None and (past, future) == (first.past, first.future):
                continue
            if n_samples < samples_needed(m, p, past, future):
                continue
            try:
                with np.errstate(over="ignore", invalid="ignore"):  # as for the first pass
                    trial = one_pass(past, future)
            except ValueError:
                continue
            fits.append(HorizonFit(*trial[:3], past, future))
    best = most_predictive([fit.model for fit in fits], u, y, max((fit.past for fit in fits), default=0))
    return None if best is None else fits[best]


__all__ = [
    "HorizonFit",
    "default_future",
    "default_past",
    "past_horizon_cap",
    "refined_fit",
    "retry_horizons",
    "samples_needed",
    "uncapped_alternative",
]
