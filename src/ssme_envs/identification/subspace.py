"""Subspace identification of the Kalman filter: DSR_e (Di Ruscio 2008, 2009).

Identifies the innovations form of a MIMO system from one input/output record,

    x(k+1) = A x(k) + B u(k) + K e(k),   y(k) = C x(k) + D u(k) + e(k),

with ``e`` white (the one-step prediction error of the Kalman filter). The data are deviations
from an operating point, one row per sample. The steps:

1. **Innovations.** With the predictor ``x(k+1) = (A - K C) x(k) + (B - K D) u(k) + K y(k)``,
   the state is a linear function of the past ``J`` inputs and outputs up to the term
   ``(A - K C)^J x(k - J)``, which vanishes as ``J`` grows. So the least-squares projection of
   ``y(k)`` on ``u(k)`` and on ``u, y`` at lags ``1..J`` leaves the innovations ``e(k)`` as
   its residual (a high-order ARX fit, solved by ``lstsq``).

2. **Observability matrix.** With ``e`` now a known input, the future outputs (``L + 1``
   block rows) obey ``Y_f = O X_f + H_u U_f + H_e E_f`` and ``X_f`` lies in the row space of
   the past data ``W_p``. One LQ factorization (a QR of the transposed stack
   ``[U_f; E_f; U_p; Y_p; Y_f]``) gives ``Z``, the part of ``Y_f`` that lies in ``W_p`` once
   ``U_f`` and ``E_f`` are removed; ``Z = O M``, so the left singular vectors of ``Z`` span the
   extended observability matrix ``O`` (``L + 1`` block rows, ``n`` columns).

3. **Order**: among the candidates the singular values of ``Z`` allow, the largest drop for a
   noise-free record, else the smallest BIC of the candidate models' one-step prediction errors
   (which needs step 4 for each candidate; rule in :func:`dsr_e`, scan in
   :mod:`ssme_envs.identification.subspace_bic`).

4. **Realization.** ``C`` is the first block row of ``O``, ``A`` the least-squares solution of
   the shift invariance ``O[p:] = O[:-p] A``. ``B``, ``D``, ``K`` and the state at the start
   of the fit are linear in the output given ``A``, ``C`` and the innovations, and come from
   one least-squares regression on simulated unit responses.

5. **Past horizon** ``J`` so that ``(A - K C)^J`` is negligible (rule in :func:`dsr_e`).

Before step 1 a record whose channels differ wildly in size is equilibrated by powers of two
(:mod:`ssme_envs.identification.channel_scales`), and one whose inputs leave some input direction's
gain undetermined is refused (:mod:`ssme_envs.identification.subspace_checks`). With ``order=``
given, a pass that fails or comes out unstable is retried at other horizons (rules in
:func:`dsr_e`).

References: D. Di Ruscio, "Subspace system identification of the Kalman filter: open and closed
loop systems", Proc. IMECS 2008; "Closed and open loop subspace system identification of the
Kalman filter", Modeling, Identification and Control 30(2), 2009.
"""

from __future__ import annotations

import math

import numpy as np

from ssme_envs.identification.alpha_canonical import check_record
from ssme_envs.identification.channel_scales import equilibrated, restore_units
from ssme_envs.identification.innovations_model import (
    InnovationsModel,
    SubspaceResult,
    _as_columns,
    second_order_parameters,
    to_continuous,
)
from ssme_envs.identification.subspace_bic import bic_order, realize, record_bic
from ssme_envs.identification.subspace_checks import (
    arx_innovations,
    check_input_directions,
    record_noise,
    unstable,
)
from ssme_envs.identification.subspace_horizons import (
    check_past_holds_order,
    default_future,
    default_past,
    refined_fit,
    retry_horizons,
    samples_needed,
)
from ssme_envs.models.linear import check_dt

DEFAULT_MAX_ORDER = 10
# Normalized singular values below this are round-off; no order is placed behind one of them.
SINGULAR_VALUE_FLOOR = 1e-10
# An LQ pivot below this fraction of its row's norm marks a row dependent on the rows before it.
PIVOT_TOL = 1e-9
# Innovations below this fraction of the output's spread mean a noise-free record (K = 0).
NOISE_FREE_TOL = 1e-9
# A noise-free record's singular values fall to round-off after its order; one whose value after
# the largest drop is still above this (three decades over the round-off floor) has more states
# than the candidates reach.
NOISE_FREE_DROP = 1e-7


def _positive_int(value: int | None, name: str) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _block_hankel(x: np.ndarray, first: int, rows: int, cols: int) -> np.ndarray:
    """Block row ``i`` holds ``x[first + i + c]`` in column ``c``; shape (rows * channels, cols)."""
    return np.vstack([x[first + i : first + i + cols].T for i in range(rows)])


def _projected_future(
    u: np.ndarray, y: np.ndarray, e: np.ndarray, past: int, future: int, noise_free: bool
) -> np.ndarray:
    """``Z``: the future outputs, ``U_f`` and ``E_f`` removed, projected on the past data.

    Raises ValueError when the future-input Hankel matrix is rank-deficient.
    """
    m, p = u.shape[1], y.shape[1]
    cols = u.shape[0] - past - future
    blocks = [_block_hankel(u, past, future + 1, cols)]
    if not noise_free:
        blocks.append(_block_hankel(e, 0, future + 1, cols))  # e[0] is sample `past`
    n_removed = sum(b.shape[0] for b in blocks)
    blocks += [
        _block_hankel(u, 0, past, cols),
        _block_hankel(y, 0, past, cols),
        _block_hankel(y, past, future + 1, cols),
    ]
    stack = np.vstack(blocks)
    tri = np.linalg.qr(stack.T, mode="r")  # stack = tri.T @ Q.T: the LQ factorization
    pivots = np.abs(np.diag(tri)) / np.maximum(np.linalg.norm(stack, axis=1), np.finfo(float).tiny)
    n_uf = (future + 1) * m
    if pivots[:n_uf].min() < PIVOT_TOL:
        raise ValueError(
            f"the inputs are not persistently exciting of order {future + 1} (the future-input Hankel "
            f"matrix with future_horizon={future} is rank-deficient): use a richer input such as a "
            "PRBS or white noise, or a smaller future_horizon"
        )
    n_past = past * (m + p)
    z = tri[n_removed : n_removed + n_past, n_removed + n_past :].T.copy()
    # A past row that adds nothing new (noise-free outputs, a periodic input) has a round-off
    # pivot; its orthogonal direction is arbitrary, so its column of Z is dropped.
    z[:, pivots[n_removed : n_removed + n_past] < PIVOT_TOL] = 0.0
    return z


def _order_candidates(singular_values: np.ndarray, max_order: int, noise_free: bool) -> list[int]:
    """The orders ``1..max_order`` not placed behind round-off (see dsr_e).

    With noisy data every direction the past data span carries noise, so a drop to round-off
    marks the rank limit of the horizons, not the system: such a drop is not a candidate.
    """
    s = singular_values / singular_values[0]
    candidates = [
        n
        for n in range(1, max_order + 1)
        if s[n - 1] > SINGULAR_VALUE_FLOOR and (noise_free or s[n] > SINGULAR_VALUE_FLOOR)
    ]
    if not candidates:
        raise ValueError("the singular values show no order: the record is too short for the horizons")
    return candidates


def _largest_drop(singular_values: np.ndarray, candidates: list[int]) -> int:
    """The candidate order at the largest drop in log10 of the normalized singular values."""
    logs = np.log10(np.maximum(singular_values / singular_values[0], np.finfo(float).tiny))
    return candidates[int(np.argmax([logs[n - 1] - logs[n] for n in candidates]))]


def _identify_once(
    u: np.ndarray,
    y: np.ndarray,
    dt: float,
    past: int,
    future: int,
    order: int | None,
    max_order: int,
) -> tuple[InnovationsModel, np.ndarray, int, bool]:
    """One DSR_e pass at fixed horizons: (model, singular values, order, noise-free)."""
    p = y.shape[1]
    e = arx_innovations(u, y, past)
    spread = np.linalg.norm(y - y.mean(axis=0))
    noise_free = bool(np.linalg.norm(e) <= NOISE_FREE_TOL * spread)
    z = _projected_future(u, y, e, past, future, noise_free)
    left, singular_values, _ = np.linalg.svd(z, full_matrices=False)
    if singular_values[0] <= NOISE_FREE_TOL * math.sqrt(future + 1) * spread:
        raise ValueError(
            "the projected future outputs are zero: the outputs have no dynamics beyond a direct "
            f"feedthrough of the inputs, or past_horizon={past} is too short for the innovations "
            "estimate (the innovations then absorb the state)"
        )
    most = min(future * p, len(singular_values) - 1)
    noise = None if noise_free else e
    if order is None:
        candidates = _order_candidates(singular_values, min(max_order, most), noise_free)
        chosen = None if noise_free else bic_order(left, singular_values, candidates, u, y, e, past, dt)
        if chosen is not None:
            return chosen[1], singular_values, chosen[0], noise_free
        order = _largest_drop(singular_values, candidates)
        if noise_free and singular_values[order] > NOISE_FREE_DROP * singular_values[0]:
            raise ValueError(
                f"the record is noise-free, but its singular values do not fall to round-off by order "
                f"{candidates[-1]} (s_{order + 1} / s_1 = {singular_values[order] / singular_values[0]:.2g} "
                f"after the largest drop, at order {order}): the system has more states than max_order="
                f"{max_order} and future_horizon={future} reach; raise them, or give order="
            )
    elif order > most:
        raise ValueError(
            f"order={order} needs future_horizon >= {math.ceil(order / p)} and past_horizon >= "
            f"{math.ceil((order + 1) / (u.shape[1] + p))} (got {future} and {past})"
        )
    return realize(left, singular_values, order, u, y, noise, past, dt), singular_values, order, noise_free


def dsr_e(
    u: np.ndarray,
    y: np.ndarray,
    dt: float,
    order: int | None = None,
    past_horizon: int | None = None,
    future_horizon: int | None = None,
    max_order: int = DEFAULT_MAX_ORDER,
) -> SubspaceResult:
    """Identify the Kalman-filter innovations form by DSR_e.

    Parameters
    ----------
    u : array, shape (T, m) or (T,)
        Inputs (deviations from the operating point), one row per sample.
    y : array, shape (T, p) or (T,)
        Outputs (deviations), same length. An offset reads as a mode at 1, which the automatic
        order adds to the states: subtract the operating point.
    dt : float
        Sample time, s.
    order : int, optional
        Number of states; selected from the singular values when omitted.
    past_horizon : int, optional
        ``J``: lags of ``u`` and ``y`` in the innovations estimate and in the past data ``W_p``.
        Chosen automatically when omitted (rule below).
    future_horizon : int, optional
        ``L``: the future data have ``L + 1`` block rows, so orders up to ``L p`` can be found.
        Default ``max(ceil(max_order / p), 2)``.
    max_order : int
        Largest order the automatic selection considers.

    Returns
    -------
    SubspaceResult

    Notes
    -----
    **Order selection.** The singular values ``s_1 >= s_2 >= ...`` of ``Z`` are normalized by
    ``s_1``; the candidate orders are the ``n`` in ``1..min(max_order, L p)`` whose ``s_n / s_1``
    exceeds 1e-10 (below that the values are round-off); with noisy data also ``s_(n+1) / s_1``
    must exceed 1e-10, since a drop to round-off is then the rank limit of the horizons rather
    than the system's order. A noise-free record (no innovations) takes the candidate with the
    largest drop ``log10 s_n - log10 s_(n+1)``: ten decades or more at the true order; where
    ``s_(n+1) / s_1`` is still above ``NOISE_FREE_DROP`` (1e-7) the system has more states than
    the candidates reach, and the record is refused (it used to give a smaller model: 5 states
    for a 14-state one, fit 99.1 %), naming ``max_order`` and ``future_horizon``. A noisy
    one takes the candidate whose model minimizes BIC of its one-step prediction errors on the
    record, ``N log det(Sigma_n) + log(N) (n (2 p + m) + p m)`` over the ``N = T - J`` samples
    after the past horizon (candidates whose B and D cannot be fitted or whose predictor is
    unstable are skipped; the largest drop decides if none is left). The candidates are screened
    by faster computations of the same BIC and those near the smallest are scored exactly, which
    chooses as scoring all exactly would unless the screen erred by more than half the margin
    (:mod:`~ssme_envs.identification.subspace_bic`). The
    largest drop alone under-orders noisy records: the values beyond the order sit on a floor
    that falls only as ``1 / sqrt(T)`` relative to ``s_1``, and a weak mode's drop can be smaller
    than a strong one's. On random stable systems of order 2-6 with 5 % output noise (200 records,
    ``experiments/results/subspace_order.md``) the largest drop found the order on 36 % of
    records and the 90th percentile of the model's simulation error was 12 % of the output's
    spread; BIC found it on 71 %, with 0.65 % (the true order's model: 0.64 %). ``order=`` overrides.

    **Past horizon.** The innovations estimate neglects ``(A - K C)^J x(k - J)``. Without
    ``past_horizon``, a first pass uses ``J = max(2 (L + 1), 10)``; then, with ``rho`` the spectral
    radius of ``A - K C`` of the result, if ``rho^J > 1e-3`` the identification is redone with
    ``J = ceil(log(1e-3) / log(rho))`` (at most two such refinements). ``J`` is capped so that
    the stacked data matrix keeps at least 6 columns per row (about ``T / (6 (m + p))``); a
    noise-free record (innovations below 1e-9 of the output spread) gets ``K = 0`` and no
    refinement, since its outputs are exactly linear in ``n`` past samples. An unstable
    predictor (``rho >= 1``) stops the refinement, and so does a refined pass that fails, turns a
    stable ``A`` unstable or (the order automatic) changes the order to one whose BIC on the
    record is worse (the earlier pass is kept). Where the record's length caps the first ``J``
    below the rule, a noisy record also gets a pass at the rule's ``J`` with at least 2 columns
    per row, kept where its BIC on the record is lower and it leaves a stable ``A`` stable.
    ``past_horizon`` reports the ``J`` used.

    **Given order.** With ``order=`` and a horizon left automatic, a first pass (with its
    refinements) that fails or gives an unstable ``A`` or predictor ``A - K C`` is retried at
    past horizons 1, 2 and 4 times the automatic one (capped as above; the given one if given)
    and, when ``future_horizon`` is automatic, also at twice the automatic future horizon (the
    default sizes ``L`` by ``max_order``, and an order near ``L p`` leaves the shift invariance
    barely determined: on random stable systems with two outputs, orders 7-10 and output noise
    2-30 %, 9-28 % of the records gave such a first pass, and the retry a stable one in all
    1600). Among the first pass and the retries the model with the smallest one-step prediction
    error on the record is kept (log-determinant of its covariance from the largest past
    horizon tried on; models with an unstable predictor do not compete); when none predicts,
    the first pass stands (or its error is raised). A stable first pass is kept as it is (a
    stable but poor one is not detected: compare fits at other horizons yourself).

    **Collinear inputs.** The gain along an input direction excited ``r`` times less than the
    strongest (singular values of the centred inputs, each divided by its RMS) is determined to
    about ``rho / (r sqrt(T))`` of the system's gain, ``rho`` the outputs' noise as a fraction
    of their spread (innovations estimate): beyond 0.25 the record is refused
    (:data:`~ssme_envs.identification.subspace_checks.COLLINEAR_GAIN_ERROR`). Noise-free
    records are refused only for exact dependence (``check_record``).

    **Channel scales.** A record whose channels spread beyond 1e6 in RMS (its outputs beyond
    1e3) is equilibrated first (:mod:`~ssme_envs.identification.channel_scales`). Noisy outputs
    of moderately different sizes still weigh by their units: pass ``order=`` or scale them.

    Raises
    ------
    ValueError
        Bad shapes, NaN/inf (naming channel and sample), constant or linearly dependent inputs,
        inputs so nearly collinear that the gain along some input direction is not determined
        (naming the inputs and the direction), inputs not persistently exciting, a record too
        short for the horizons (with the length needed), or bad arguments.
    """
    dt = check_dt(dt)
    order = _positive_int(order, "order")
    past_horizon = _positive_int(past_horizon, "past_horizon")
    future_horizon = _positive_int(future_horizon, "future_horizon")
    max_order = _positive_int(max_order, "max_order")
    u, y = _as_columns(u, "u", "inputs"), _as_columns(y, "y", "outputs")
    u, y = check_record(u, y)
    n_samples, m = u.shape
    p = y.shape[1]

    future = future_horizon if future_horizon is not None else default_future(max_order, p)
    past = past_horizon if past_horizon is not None else default_past(n_samples, m, p, future)
    if order is not None and past_horizon is None:
        check_past_holds_order(n_samples, m, p, past, future, order)
    needed = samples_needed(m, p, past, future)
    if n_samples < needed:
        raise ValueError(
            f"the record has {n_samples} samples; past_horizon={past} and future_horizon={future} "
            f"need at least {needed} (use a longer record or smaller horizons)"
        )

    u, y, scales = equilibrated(u, y)
    check_input_directions(u, lambda: record_noise(u, y, past))

    def one_pass(past: int, future: int) -> tuple[InnovationsModel, np.ndarray, int, bool]:
        return _identify_once(u, y, dt, past, future, order, max_order)

    def score(model: InnovationsModel, first: int) -> float | None:
        return record_bic(model, u, y, first)

    try:  # an unstable trial's unit responses overflow: its ValueError says so, not a RuntimeWarning
        with np.errstate(over="ignore", invalid="ignore"):
            fit = refined_fit(one_pass, n_samples, m, p, past, future, past_horizon is None, score)
            error = None
    except ValueError as exc:
        fit, error = None, exc
    automatic = past_horizon is None or future_horizon is None
    if order is not None and automatic and (fit is None or unstable(fit.model)):
        fit = retry_horizons(one_pass, u, y, fit, max_order, past_horizon, future_horizon) or fit
    if fit is None:
        raise error
    model, singular_values, found, past, future = fit
    if scales is not None:
        model, singular_values = restore_units(model, singular_values, *scales)
    return SubspaceResult(model, singular_values, found, past, future)


__all__ = [
    "DEFAULT_MAX_ORDER",
    "InnovationsModel",
    "SubspaceResult",
    "dsr_e",
    "second_order_parameters",
    "to_continuous",
]
