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

3. **Order** from the singular values of ``Z`` (rule in :func:`dsr_e`).

4. **Realization.** ``C`` is the first block row of ``O``, ``A`` the least-squares solution of
   the shift invariance ``O[p:] = O[:-p] A``. ``B``, ``D``, ``K`` and the state at the start
   of the fit are linear in the output given ``A``, ``C`` and the innovations, and come from
   one least-squares regression on simulated unit responses.

5. **Past horizon** ``J`` so that ``(A - K C)^J`` is negligible (rule in :func:`dsr_e`).

Before step 1 a record whose channels differ wildly in size is equilibrated by powers of two
(:mod:`ssme_envs.identification.channel_scales`).

References: D. Di Ruscio, "Subspace system identification of the Kalman filter: open and closed
loop systems", Proc. IMECS 2008; "Closed and open loop subspace system identification of the
Kalman filter", Modeling, Identification and Control 30(2), 2009.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from ssme_envs.identification.alpha_canonical import check_record
from ssme_envs.identification.channel_scales import equilibrated, restore_units
from ssme_envs.identification.innovations_model import (
    InnovationsModel,
    SubspaceResult,
    _as_columns,
    second_order_parameters,
    to_continuous,
)
from ssme_envs.identification.subspace_regression import input_matrices
from ssme_envs.models.linear import check_dt, spectral_radius

DEFAULT_MAX_ORDER = 10
# Target for the neglected term of the innovations estimate: rho(A - K C)^J below this.
PREDICTOR_DECAY = 1e-3
# Normalized singular values below this are round-off; no order is placed behind one of them.
SINGULAR_VALUE_FLOOR = 1e-10
# An LQ pivot below this fraction of its row's norm marks a row dependent on the rows before it.
PIVOT_TOL = 1e-9
# Innovations below this fraction of the output's spread mean a noise-free record (K = 0).
NOISE_FREE_TOL = 1e-9
# The stacked data matrix must have at least this many columns per row ...
MIN_COLUMNS_PER_ROW = 2
# ... and the automatic past horizon keeps at least this many (statistical headroom).
AUTO_COLUMNS_PER_ROW = 6
# Refinements of the automatic past horizon after the first pass.
HORIZON_REFINEMENTS = 2


def _positive_int(value: int | None, name: str) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _block_hankel(x: np.ndarray, first: int, rows: int, cols: int) -> np.ndarray:
    """Block row ``i`` holds ``x[first + i + c]`` in column ``c``; shape (rows * channels, cols)."""
    return np.vstack([x[first + i : first + i + cols].T for i in range(rows)])


def _stack_rows(m: int, p: int, past: int, future: int) -> int:
    """Rows of ``[U_f; E_f; U_p; Y_p; Y_f]``."""
    return (future + 1) * (m + 2 * p) + past * (m + p)


def _samples_needed(m: int, p: int, past: int, future: int, per_row: int) -> int:
    """Record length giving ``per_row`` columns per row of the stacked data matrix."""
    return past + future + per_row * _stack_rows(m, p, past, future)


def _past_horizon_cap(n_samples: int, m: int, p: int, future: int) -> int:
    """Largest past horizon that keeps ``AUTO_COLUMNS_PER_ROW`` columns per row."""
    fixed = future + AUTO_COLUMNS_PER_ROW * (future + 1) * (m + 2 * p)
    return (n_samples - fixed) // (1 + AUTO_COLUMNS_PER_ROW * (m + p))


def _innovations(u: np.ndarray, y: np.ndarray, past: int) -> np.ndarray:
    """Residual of ``y(k)`` projected on ``u(k)`` and ``u, y`` at lags 1..past, k = past..T-1."""
    horizon = u.shape[0]
    lagged = [u[past:]]
    for lag in range(1, past + 1):
        lagged += [u[past - lag : horizon - lag], y[past - lag : horizon - lag]]
    phi = np.hstack(lagged)
    # Rank-revealing QR least squares (gelsy): a noise-free record makes the output lags dependent.
    theta, *_ = scipy.linalg.lstsq(phi, y[past:], lapack_driver="gelsy", check_finite=False)
    return y[past:] - phi @ theta


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


def _select_order(singular_values: np.ndarray, max_order: int, noise_free: bool) -> int:
    """Order at the largest drop in log10 of the normalized singular values (see dsr_e).

    With noisy data every direction the past data span carries noise, so a drop to round-off
    marks the rank limit of the horizons, not the system: such a drop is not a candidate.
    """
    s = singular_values / singular_values[0]
    logs = np.log10(np.maximum(s, np.finfo(float).tiny))
    candidates = [
        n
        for n in range(1, max_order + 1)
        if s[n - 1] > SINGULAR_VALUE_FLOOR and (noise_free or s[n] > SINGULAR_VALUE_FLOOR)
    ]
    if not candidates:
        raise ValueError("the singular values show no order: the record is too short for the horizons")
    gaps = [logs[n - 1] - logs[n] for n in candidates]
    return candidates[int(np.argmax(gaps))]


def _shift_invariance(obs: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    """(A, C) from the extended observability matrix."""
    a, *_ = np.linalg.lstsq(obs[:-p], obs[p:], rcond=None)
    return a, obs[:p].copy()


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
    e = _innovations(u, y, past)
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
    if order is None:
        order = _select_order(singular_values, min(max_order, most), noise_free)
    elif order > most:
        raise ValueError(
            f"order={order} needs future_horizon >= {math.ceil(order / p)} and past_horizon >= "
            f"{math.ceil((order + 1) / (u.shape[1] + p))} (got {future} and {past})"
        )
    obs = left[:, :order] * np.sqrt(singular_values[:order])
    a, c = _shift_invariance(obs, p)
    b, d, k = input_matrices(a, c, u[past:], y[past:], None if noise_free else e)
    return InnovationsModel(a, b, c, d, k, dt), singular_values, order, noise_free


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
        Outputs (deviations), same length.
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
    ``s_1``; the order is the ``n`` in ``1..min(max_order, L p)`` with the largest drop
    ``log10 s_n - log10 s_(n+1)``, among the ``n`` whose ``s_n / s_1`` exceeds 1e-10 (below that
    the values are round-off, and gaps between them mean nothing); with noisy data also
    ``s_(n+1) / s_1`` must exceed 1e-10, since a drop to round-off is then the rank limit of the
    horizons rather than the system's order. Noise-free data show a drop of ten decades or
    more at the true order; with noise the values beyond the order sit on a floor that falls as
    ``1 / sqrt(T)`` relative to ``s_1``. A weak, barely excited mode can
    have a smaller drop than a strong one: inspect ``singular_values`` and pass ``order=``.

    **Past horizon.** The innovations estimate neglects ``(A - K C)^J x(k - J)``. Without
    ``past_horizon``, a first pass uses ``J = max(2 (L + 1), 10)``; then, with ``rho`` the spectral
    radius of ``A - K C`` of the result, if ``rho^J > 1e-3`` the identification is redone with
    ``J = ceil(log(1e-3) / log(rho))`` (at most two such refinements). ``J`` is capped so that
    the stacked data matrix keeps at least 6 columns per row (about ``T / (6 (m + p))``); a
    noise-free record (innovations below 1e-9 of the output spread) gets ``K = 0`` and no
    refinement, since its outputs are exactly linear in ``n`` past samples. An unstable
    predictor (``rho >= 1``) stops the refinement, and so does a refined pass that fails or
    turns a stable ``A`` unstable (the earlier pass is kept). ``past_horizon`` reports the ``J``
    used.

    **Channel scales.** A record whose channels spread beyond 1e6 in RMS (its outputs beyond
    1e3) is equilibrated first (:mod:`~ssme_envs.identification.channel_scales`). Noisy outputs
    of moderately different sizes still weigh by their units: pass ``order=`` or scale them.

    Raises
    ------
    ValueError
        Bad shapes, NaN/inf (naming channel and sample), constant or linearly dependent inputs,
        inputs not persistently exciting, a record too short for the horizons (with the length
        needed), or bad arguments.
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

    future = future_horizon if future_horizon is not None else max(math.ceil(max_order / p), 2)
    if past_horizon is not None:
        past = past_horizon
    else:
        past = min(max(2 * (future + 1), 10), max(_past_horizon_cap(n_samples, m, p, future), 1))
    needed = _samples_needed(m, p, past, future, MIN_COLUMNS_PER_ROW)
    if n_samples < needed:
        raise ValueError(
            f"the record has {n_samples} samples; past_horizon={past} and future_horizon={future} "
            f"need at least {needed} (use a longer record or smaller horizons)"
        )

    u, y, scales = equilibrated(u, y)
    model, singular_values, found, noise_free = _identify_once(u, y, dt, past, future, order, max_order)
    if past_horizon is None and not noise_free:
        cap = _past_horizon_cap(n_samples, m, p, future)
        for _ in range(HORIZON_REFINEMENTS):
            rho = spectral_radius(model.A - model.K @ model.C)
            # rho >= 1 first: a wildly unstable predictor's rho**past overflows
            if rho >= 1.0 or rho**past <= PREDICTOR_DECAY:
                break
            wanted = min(math.ceil(math.log(PREDICTOR_DECAY) / math.log(rho)), cap)
            if wanted <= past:
                break
            try:
                refined = _identify_once(u, y, dt, wanted, future, order, max_order)
            except ValueError:  # the longer horizon's model fails where this one stands: keep it
                break
            if spectral_radius(refined[0].A) >= 1.0 > spectral_radius(model.A):  # nor stable for unstable
                break
            past = wanted
            model, singular_values, found, noise_free = refined
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
