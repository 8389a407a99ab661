"""Structure and parameter identification in alpha-canonical form (NASA TM-104422, eqs 9-47).

Any number of inputs and outputs and any observability indices. The steps:

1. **Structure** (eqs 28-33). The past outputs ``Q`` (lags ``1..L`` of every output), after
   their projection on the lagged inputs ``R`` is removed, span the same row space as the
   observability matrix (``Q_o = V M V^T``, eq 31). A row-by-row search over ``C``, ``CA``,
   ``CA^2``, ... keeps each output's next row while it adds a new direction; the number of
   rows kept for output ``i`` is ``mu_i``. The projections come from one QR factorization of
   ``[R Z Q]`` (never from inverting ``R R^T``). ``Z`` holds older inputs: projecting ``Q``
   on them as instruments removes white measurement noise, so dependent rows shrink towards
   zero as the record grows while independent ones do not.

   Decision rule: a candidate row is independent when the norm of its component orthogonal
   to the rows already kept exceeds ``rank_tol`` (default 0.1) times its own norm. Noise-free
   data give ratios near 1e-15 for dependent rows; with the instrument projection, white
   output noise lifts them only in proportion to the noise-to-signal ratio over sqrt(N)
   (below 0.02 for 5 % noise on 2000 samples of the Table I models), while independent rows
   of those models sit at 0.45 or more. The threshold sits between the two on a log scale;
   the report plots every ratio so the margin can be seen.

2. **Parameters** (eq 27). Each output's one-step equation ``y_i(k) = theta_i phi_i(k)`` is
   solved by least squares with only the regressors eq 8 leaves free, plus a constant. With
   ``method="iv"`` (default) two instrumental-variable passes follow, the instruments being
   the lags of the previous model's simulated output: consistent under white output noise,
   and identical to least squares on noise-free data.

3. **Asymmetric gains** (eqs 36-45). For a constant-amplitude (binary) input
   ``u* = u + (lambda - 1) |u|`` is ``u`` plus a constant, so the regression's constant
   equals ``theta_u_bar (Lambda - I) gamma`` (eq 42) and gives lambda exactly. For other
   inputs the lags of ``|u|`` enter the regression and lambda is the least-squares ratio of
   their coefficients to those of ``u``.

4. **Realization**: row ``(i, d)`` of ``[K B]`` is the coefficient of ``[y; u](k-1-d)`` in
   output ``i``'s equation; ``A = A_o + K C``, ``C = [0 I]`` (eqs 5-8).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from ssme_envs.models.engine import TruthConfig, simulate
from ssme_envs.models.statespace import AlphaCanonicalModel, AlphaStructure, check_dt

DEFAULT_MAX_INDEX = 6
DEFAULT_RANK_TOL = 0.1


@dataclass
class StructureSearch:
    """Outcome of the row-by-row rank search.

    Attributes
    ----------
    indices : tuple of int
        Observability index of each output.
    ratios : list of (output, power, ratio, kept)
        For each candidate row ``c_output A^power`` examined: the norm of its new component over
        its norm, and whether it was kept.
    """

    indices: tuple[int, ...]
    ratios: list[tuple[int, int, float, bool]] = field(default_factory=list)


@dataclass
class Identification:
    """An identified engine model with what produced it."""

    model: AlphaCanonicalModel
    search: StructureSearch | None
    intercept: np.ndarray
    method: str


def _names(names: Sequence[str] | None, count: int, prefix: str) -> tuple[str, ...]:
    return tuple(names) if names is not None else tuple(f"{prefix}{i}" for i in range(count))


def check_record(
    u: np.ndarray,
    y: np.ndarray,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Validate an input/output record; returns float arrays of shapes (T, m), (T, p).

    Raises
    ------
    ValueError
        Naming the problem: shapes, NaN/inf, constant or linearly dependent signals.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    u = u[:, None] if u.ndim == 1 else u
    y = y[:, None] if y.ndim == 1 else y
    if u.ndim != 2 or y.ndim != 2:
        raise ValueError("inputs and outputs must be arrays of shape (samples, channels)")
    if u.shape[0] != y.shape[0]:
        raise ValueError(f"inputs have {u.shape[0]} samples but outputs have {y.shape[0]}")
    in_names = _names(input_names, u.shape[1], "u")
    out_names = _names(output_names, y.shape[1], "y")
    for arr, names, kind in ((u, in_names, "input"), (y, out_names, "output")):
        bad = ~np.isfinite(arr)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise ValueError(f"{kind} '{names[col]}' has NaN or inf at sample {row} ({bad.sum()} bad values)")
    for arr, names, kind, what in (
        (u, in_names, "input", "does not excite the system"),
        (y, out_names, "output", "does not respond"),
    ):
        for j in range(arr.shape[1]):
            if np.ptp(arr[:, j]) <= 1e-12 * max(1.0, np.max(np.abs(arr[:, j]))):
                raise ValueError(f"{kind} '{names[j]}' is constant: it {what}")
        centered = arr - arr.mean(axis=0)
        if arr.shape[1] > 1:
            s = np.linalg.svd(centered / np.linalg.norm(centered, axis=0), compute_uv=False)
            if s[-1] < 1e-8 * s[0]:
                raise ValueError(
                    f"the {kind}s {', '.join(names)} are linearly dependent (rank-deficient record)"
                )
    return u, y


def _binary_amplitudes(u: np.ndarray, names: Sequence[str] | None = None) -> np.ndarray:
    """Per input: the constant |u| of a symmetric binary (PRBS-like) input, or NaN if |u| varies.

    Raises
    ------
    ValueError
        For an input that switches between two levels of different magnitude: its |u| is an
        affine function of u, so lambda cannot be told apart from B and an offset.
    """
    mag = np.abs(u)
    out = np.full(u.shape[1], np.nan)
    for j in range(u.shape[1]):
        top = mag[:, j].max()
        if top > 0 and mag[:, j].min() >= top * (1 - 1e-9):
            out[j] = mag[:, j].mean()
            continue
        levels = np.unique(u[:, j])
        if levels.size == 2:
            name = names[j] if names is not None else f"u{j}"
            raise ValueError(
                f"input '{name}' switches between two levels of different magnitude ({levels[0]:g}, "
                f"{levels[1]:g}): lambda cannot be identified from it; use a PRBS symmetric about 0, or "
                "identify without the asymmetric gains (--symmetric)"
            )
    return out


def _lags(x: np.ndarray, lags: Sequence[int], start: int) -> np.ndarray:
    """Columns ``x[k - lag]`` for k = start..T-1, for each lag and each channel (lag-major)."""
    horizon = x.shape[0]
    if not lags:
        return np.empty((horizon - start, 0))
    return np.hstack([x[start - lag : horizon - lag] for lag in lags])


def _input_features(u: np.ndarray, gamma: np.ndarray, asymmetric: bool) -> np.ndarray:
    """Inputs plus |u| of the non-binary inputs (their asymmetric part)."""
    if not asymmetric:
        return u
    return np.hstack([u, np.abs(u[:, np.isnan(gamma)])])


def estimate_indices(
    u: np.ndarray,
    y: np.ndarray,
    max_index: int = DEFAULT_MAX_INDEX,
    rank_tol: float = DEFAULT_RANK_TOL,
    asymmetric: bool = True,
    output_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
) -> StructureSearch:
    """Observability indices by the row-by-row rank search on Q_o (eqs 28-33).

    Parameters
    ----------
    u, y : arrays, shapes (T, m), (T, p)
        Input and output record (deviations), already checked by :func:`check_record`.
    max_index : int
        Largest observability index searched (the lag window L).
    rank_tol : float
        Relative norm below which a candidate row counts as dependent.
    asymmetric : bool
        Allow for the piecewise-linear input gain of eq 36.
    output_names, input_names : sequences of str, optional
        Used in error messages.
    """
    if max_index < 1:
        raise ValueError(f"max_index must be >= 1, got {max_index}")
    if not 0 < rank_tol < 1:
        raise ValueError(f"rank_tol must be in (0, 1), got {rank_tol}")
    horizon, p = y.shape
    names = _names(output_names, p, "y")
    window = max_index
    gamma = _binary_amplitudes(u, input_names) if asymmetric else np.full(u.shape[1], np.nan)
    feats = _input_features(u, gamma, asymmetric)
    n_feat = feats.shape[1]
    start = 2 * window
    needed = (window * n_feat + 1) + window * n_feat + window * p
    if horizon - start < 2 * needed:
        raise ValueError(
            f"the record has {horizon} samples; a structure search up to index {max_index} needs at "
            f"least {start + 2 * needed} (use a longer record or a smaller max_index)"
        )
    lags = range(1, window + 1)
    r_block = np.hstack([_lags(feats, lags, start), np.ones((horizon - start, 1))])
    z_block = _lags(feats, range(window + 1, 2 * window + 1), start)
    # Column (k, i) of q_block is y_i(t - L + k), which carries the row c_i A^k.
    q_block = _lags(y, range(window, 0, -1), start)
    n_r, n_z = r_block.shape[1], z_block.shape[1]
    tri = scipy.linalg.qr(np.hstack([r_block, z_block, q_block]), mode="r", check_finite=False)[0]
    diag = np.abs(np.diag(tri)[: n_r + n_z])
    if diag.min() < 1e-9 * diag.max():
        raise ValueError(
            f"the inputs are not persistently exciting over {2 * window} lags (the lagged-input "
            "matrix is rank-deficient): use a richer input such as a PRBS"
        )
    instrumented = tri[n_r : n_r + n_z, n_r + n_z :]  # Q projected on the instruments, orthonormal coords

    basis = np.empty((n_z, 0))
    active = [True] * p
    indices = [0] * p
    ratios: list[tuple[int, int, float, bool]] = []
    for power in range(window):
        for i in range(p):
            if not active[i]:
                continue
            col = instrumented[:, power * p + i]
            norm = np.linalg.norm(col)
            resid = col - basis @ (basis.T @ col)
            ratio = float(np.linalg.norm(resid) / norm) if norm > 0 else 0.0
            kept = ratio > rank_tol
            ratios.append((i, power, ratio, kept))
            if kept:
                basis = np.column_stack([basis, resid / np.linalg.norm(resid)])
                indices[i] += 1
            else:
                active[i] = False
    for i in range(p):
        if indices[i] == 0:
            raise ValueError(
                f"output '{names[i]}' adds nothing to the earlier outputs (C is not of full row rank)"
            )
        if active[i]:
            raise ValueError(
                f"the observability index of output '{names[i]}' exceeds max_index={max_index}: raise "
                "max_index, or the data may be too noisy for the rank tolerance"
            )
    return StructureSearch(tuple(indices), ratios)


def _regressors(
    structure: AlphaStructure, output: int, y: np.ndarray, feats: np.ndarray, start: int
) -> np.ndarray:
    """phi_i(k) of eq 11 for k = start..T-1: free output lags, input-feature lags, a constant."""
    mu_i = structure.indices[output]
    y_cols = [y[start - 1 - d : y.shape[0] - 1 - d, j] for j, d in structure.free_output_lags(output)]
    u_cols = _lags(feats, range(1, mu_i + 1), start)
    return np.column_stack([*y_cols, u_cols, np.ones(y.shape[0] - start)])


def _simulation_error(
    model: AlphaCanonicalModel, u: np.ndarray, y: np.ndarray
) -> tuple[float, np.ndarray | None]:
    """Sum of squared simulation errors (eqs 51-52) and the simulated outputs; (inf, None) for
    an unstable model."""
    if model.spectral_radius() >= 1.0:
        return float("inf"), None
    simulated = simulate(model, u, TruthConfig.ideal())[1]
    return float(np.sum((y - simulated) ** 2)), simulated


def identify(
    u: np.ndarray,
    y: np.ndarray,
    dt: float,
    indices: Sequence[int] | None = None,
    method: str = "iv",
    asymmetric: bool = True,
    max_index: int = DEFAULT_MAX_INDEX,
    rank_tol: float = DEFAULT_RANK_TOL,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> Identification:
    """Identify an alpha-canonical model with asymmetric input gains from one record.

    Parameters
    ----------
    u, y : arrays, shapes (T, m), (T, p)
        Inputs and outputs as deviations from the operating point, one row per sample.
    dt : float
        Sample time, s.
    indices : sequence of int, optional
        Observability indices; estimated by :func:`estimate_indices` when omitted.
    method : {"iv", "ls"}
        "ls" is eq 27 as in the paper; "iv" adds two instrumental-variable passes.
    asymmetric : bool
        Estimate the lambda gains of eq 36 (otherwise lambda = 1).
    max_index, rank_tol : see :func:`estimate_indices`.
    input_names, output_names : sequences of str, optional
        Carried into the model and used in error messages.

    Returns
    -------
    Identification
    """
    if method not in ("iv", "ls"):
        raise ValueError(f"method must be 'iv' or 'ls', got {method!r}")
    dt = check_dt(dt)
    in_names = _names(input_names, np.shape(u)[-1] if np.ndim(u) == 2 else 1, "u")
    out_names = _names(output_names, np.shape(y)[-1] if np.ndim(y) == 2 else 1, "y")
    u, y = check_record(u, y, in_names, out_names)
    m, p = u.shape[1], y.shape[1]

    search = None
    if indices is None:
        search = estimate_indices(u, y, max_index, rank_tol, asymmetric, out_names, in_names)
        indices = search.indices
    structure = AlphaStructure.from_indices(indices)
    if structure.n_outputs != p:
        raise ValueError(f"{len(structure.indices)} observability indices given for {p} outputs")

    gamma = _binary_amplitudes(u, in_names) if asymmetric else np.full(m, np.nan)
    feats = _input_features(u, gamma, asymmetric)
    n_feat = feats.shape[1]
    start = max(structure.indices)
    n_params = max(len(structure.free_output_lags(i)) + start * n_feat + 1 for i in range(p))
    if u.shape[0] - start < 2 * n_params:
        raise ValueError(
            f"the record has {u.shape[0]} samples; observability indices {list(structure.indices)} "
            f"need at least {start + 2 * n_params}"
        )

    phis = [_regressors(structure, i, y, feats, start) for i in range(p)]
    thetas = []
    for i, phi in enumerate(phis):
        theta, _, rank, _ = np.linalg.lstsq(phi, y[start:, i], rcond=None)
        if rank < phi.shape[1]:
            raise ValueError(
                f"the regression for output '{out_names[i]}' is rank-deficient ({rank} of "
                f"{phi.shape[1]}): the record does not determine indices {list(structure.indices)}"
            )
        thetas.append(theta)

    def build(parts: tuple) -> AlphaCanonicalModel:
        a, b, c, lam, _ = parts
        return AlphaCanonicalModel(
            A=a,
            B=b,
            C=c,
            dt=dt,
            observability_indices=structure.indices,
            lam=lam,
            input_names=in_names,
            output_names=out_names,
            fit={"method": method, "samples": int(u.shape[0])},
        )

    parts = _realize(structure, thetas, m, gamma, asymmetric, out_names)
    model = build(parts)
    if method == "iv":
        # Each pass takes the previous model's simulated output as instruments; a pass is kept
        # only if its model is stable and simulates the record at least as well (weak
        # instruments can otherwise throw the estimate away from the least-squares one).
        best, simulated = _simulation_error(model, u, y)
        for _ in range(2):
            if simulated is None:  # an unstable start still gives instruments
                simulated = simulate(model, u, TruthConfig.ideal())[1]
            thetas = []
            for i, phi in enumerate(phis):
                instruments = _regressors(structure, i, simulated, feats, start)
                thetas.append(
                    np.linalg.lstsq(instruments.T @ phi, instruments.T @ y[start:, i], rcond=None)[0]
                )
            candidate_parts = _realize(structure, thetas, m, gamma, asymmetric, out_names)
            candidate = build(candidate_parts)
            error, candidate_simulated = _simulation_error(candidate, u, y)
            if not error <= best:
                break
            parts, model, best, simulated = candidate_parts, candidate, error, candidate_simulated
    intercept = parts[4]
    return Identification(model, search, intercept, method)


def _realize(
    structure: AlphaStructure,
    thetas: list[np.ndarray],
    m: int,
    gamma: np.ndarray,
    asymmetric: bool,
    output_names: Sequence[str],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C, lambda, unexplained intercept) from the per-output regression coefficients."""
    n, p = structure.n_states, structure.n_outputs
    k_gain = np.zeros((n, p))
    b = np.zeros((n, m))
    asym = np.zeros((n, m))  # coefficients of |u| lags (non-binary inputs only)
    nonbinary = np.flatnonzero(np.isnan(gamma)) if asymmetric else np.empty(0, dtype=int)
    n_feat = m + nonbinary.size
    intercept = np.empty(p)
    for i, theta in enumerate(thetas):
        free = structure.free_output_lags(i)
        for (j, d), value in zip(free, theta[: len(free)], strict=True):
            k_gain[structure.position(i, d), j] = value
        u_coef = theta[len(free) : -1].reshape(structure.indices[i], n_feat)
        for d in range(structure.indices[i]):
            row = structure.position(i, d)
            b[row] = u_coef[d, :m]
            asym[row, nonbinary] = u_coef[d, m:]
        intercept[i] = theta[-1]
    c = structure.output_matrix()
    a = structure.shift_matrix() + k_gain @ c
    lam = np.ones(m)
    if asymmetric:
        for j in nonbinary:
            lam[j] = 1.0 + float(asym[:, j] @ b[:, j] / (b[:, j] @ b[:, j]))
        binary = np.flatnonzero(~np.isnan(gamma))
        if binary.size:
            # eq 42: intercept = theta_u_bar (Lambda - I) gamma, theta_u_bar = sum_d C A_o^d B
            theta_u_bar = np.zeros((p, m))
            for i in range(p):
                for d in range(structure.indices[i]):
                    theta_u_bar[i] += b[structure.position(i, d)]
            offsets, _, rank, _ = np.linalg.lstsq(theta_u_bar[:, binary], intercept, rcond=None)
            if rank < binary.size:
                raise ValueError(
                    f"the {binary.size} PRBS inputs' gains lambda cannot be separated with the outputs "
                    f"{', '.join(output_names)} (eq 42 needs as many independent outputs as PRBS inputs); "
                    "identify without the asymmetric gains (--symmetric)"
                )
            lam[binary] = 1.0 + offsets / gamma[binary]
            intercept = intercept - theta_u_bar[:, binary] @ offsets
    return a, b, c, lam, intercept
