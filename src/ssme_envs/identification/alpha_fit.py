"""One alpha-canonical structure fitted to a record: the per-output regressions (eq 27), the
instrumental-variable passes, and the realization of the coefficients as A, B, C and the lambda
gains (eqs 5-8, 36-45). :mod:`.alpha_canonical` chooses the structure; every candidate it weighs
is fitted here the same way, and so is the one it keeps."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ssme_envs.identification.output_error import linear_response
from ssme_envs.identification.structure import lagged
from ssme_envs.models.engine import TruthConfig, simulate
from ssme_envs.models.statespace import AlphaCanonicalModel, AlphaStructure

IV_PASSES = 2
# Simulated outputs beyond this cannot serve as instruments (their squares overflow).
OVERFLOW_GUARD = 1e100
# Regressor columns whose lengths span more than this (a record in units far from the intercept's
# ones) are solved as unit columns: lstsq would lose the small ones' digits to the large ones'.
COLUMN_SPREAD = 1e6


# lambda of an input whose |u| varies by less than this share of its mean (RMS) comes from the
# intercept with |u| taken as its mean (eq 42): fitted from |u| lags nearly collinear with the
# intercept it was noise (a 1e-6 jitter on a +-0.01 PRBS gave 7.4 for Table I's 0.86), and up to
# this spread the intercept's estimate is the better one (PRBS with jittered magnitudes: lambda
# within 0.2 % where the lags' missed by up to 1.1 %; tests/test_identification_inputs.py)
BINARY_SPREAD = 0.25
# |u| that is an affine function of u to within this share of its mean: two levels of different
# magnitude, with which lambda cannot be told apart from B and an offset
COLLINEAR_SHARE = 0.05


def _binary_amplitudes(u: np.ndarray, names: Sequence[str] | None = None) -> np.ndarray:
    """Per input: the mean |u| of a binary-like (PRBS) input, whose |u| varies by at most
    :data:`BINARY_SPREAD` of it (lambda then comes from the intercept, eq 42), or NaN for an input
    whose |u| varies enough to fit lambda from its lags.

    Raises
    ------
    ValueError
        For an input that never changes sign (its |u| is u or -u), or one that switches between
        two levels of different magnitude (to within
        :data:`COLLINEAR_SHARE`): its |u| is an affine function of u, so lambda cannot be told
        apart from B and an offset.
    """
    mag = np.abs(u)
    out = np.full(u.shape[1], np.nan)
    for j in range(u.shape[1]):
        scale = mag[:, j].mean()
        if not scale > 0:
            continue
        if np.all(u[:, j] >= 0.0) or np.all(u[:, j] <= 0.0):  # |u| is +-u: no asymmetry to see
            name = names[j] if names is not None else f"u{j}"
            raise ValueError(
                f"input '{name}' never changes sign (from {u[:, j].min():g} to {u[:, j].max():g}): the "
                "asymmetric gains lambda (eq 36) act about the operating point, so the inputs must be "
                "deviations from it; subtract the operating point, or identify without the asymmetric "
                "gains (--symmetric)"
            )
        spread = _rms(mag[:, j] - scale)
        design = np.column_stack([np.ones(u.shape[0]), u[:, j]])
        coef = np.linalg.lstsq(design, mag[:, j], rcond=None)[0]
        if spread > COLLINEAR_SHARE * scale and _rms(mag[:, j] - design @ coef) <= COLLINEAR_SHARE * scale:
            name = names[j] if names is not None else f"u{j}"
            high, low = u[u[:, j] > 0, j].mean(), u[u[:, j] <= 0, j].mean()
            raise ValueError(
                f"input '{name}' switches between two levels of different magnitude (about {low:g} and "
                f"{high:g}): lambda cannot be identified from it; use a PRBS symmetric about 0, or "
                "identify without the asymmetric gains (--symmetric)"
            )
        if spread <= BINARY_SPREAD * scale:
            out[j] = scale
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def _input_features(u: np.ndarray, gamma: np.ndarray, asymmetric: bool) -> np.ndarray:
    """Inputs plus |u| of the non-binary inputs (their asymmetric part)."""
    if not asymmetric:
        return u
    return np.hstack([u, np.abs(u[:, np.isnan(gamma)])])


def _regressors(
    structure: AlphaStructure, output: int, y: np.ndarray, feats: np.ndarray, start: int
) -> np.ndarray:
    """phi_i(k) of eq 11 for k = start..T-1: free output lags, the coupled outputs' current
    samples (free H entries), input-feature lags, a constant."""
    mu_i = structure.indices[output]
    horizon = y.shape[0]
    y_cols = [y[start - 1 - d : horizon - 1 - d, j] for j, d in structure.free_output_lags(output)]
    y_cols += [y[start:, j] for j in structure.coupled_outputs(output)]
    u_cols = lagged(feats, range(1, mu_i + 1), start)
    return np.column_stack([*y_cols, u_cols, np.ones(horizon - start)])


def _simulation_error(
    model: AlphaCanonicalModel, u: np.ndarray, y: np.ndarray
) -> tuple[float, np.ndarray | None]:
    """Sum of squared simulation errors (eqs 51-52) and the simulated outputs; (inf, None) for
    an unstable model."""
    if model.spectral_radius() >= 1.0:
        return float("inf"), None
    simulated = linear_response(model, u)
    return float(np.sum((y - simulated) ** 2)), simulated


@dataclass
class _Fit:
    """One structure fitted: the model and what its covariance needs."""

    model: AlphaCanonicalModel
    thetas: list[np.ndarray]
    phis: list[np.ndarray]
    instruments: list[np.ndarray]
    intercept: np.ndarray
    simulated: np.ndarray | None
    start: int
    gamma: np.ndarray  # per input: a binary input's amplitude, NaN for the others (all without lambda)
    build: Callable[[list[np.ndarray]], tuple[AlphaCanonicalModel, np.ndarray]]

    def residuals(self, y: np.ndarray) -> list[np.ndarray]:
        """Equation errors ``y_i - phi_i theta_i`` of each output's regression."""
        pairs = zip(self.phis, self.thetas, strict=True)
        return [y[self.start :, i] - phi @ theta for i, (phi, theta) in enumerate(pairs)]


def _fit(
    structure: AlphaStructure,
    u: np.ndarray,
    y: np.ndarray,
    dt: float,
    method: str,
    asymmetric: bool,
    names: tuple[tuple[str, ...], tuple[str, ...]],
) -> _Fit:
    """Least squares (eq 27), then for ``method="iv"`` (and "oe", which starts from it) up to two
    instrumental-variable passes."""
    in_names, out_names = names
    m, p = u.shape[1], y.shape[1]
    if structure.n_outputs != p:
        raise ValueError(f"{len(structure.indices)} observability indices given for {p} outputs")
    gamma = _binary_amplitudes(u, in_names) if asymmetric else np.full(m, np.nan)
    feats = _input_features(u, gamma, asymmetric)
    start = max(structure.indices)
    phis = [_regressors(structure, i, y, feats, start) for i in range(p)]
    n_params = max(phi.shape[1] for phi in phis)
    if u.shape[0] - start < 2 * n_params:
        raise ValueError(
            f"the record has {u.shape[0]} samples; observability indices {list(structure.indices)} "
            f"need at least {start + 2 * n_params}"
        )
    thetas = []
    for i, phi in enumerate(phis):
        theta, rank = _least_squares(phi, y[start:, i])
        if rank < phi.shape[1]:
            raise ValueError(
                f"the regression for output '{out_names[i]}' is rank-deficient ({rank} of "
                f"{phi.shape[1]}): the record does not determine indices {list(structure.indices)}"
            )
        thetas.append(theta)

    def build(thetas: list[np.ndarray]) -> tuple[AlphaCanonicalModel, np.ndarray]:
        a, b, c, lam, intercept = _realize(structure, thetas, m, gamma, asymmetric, out_names)
        model = AlphaCanonicalModel(
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
        return model, intercept

    model, intercept = build(thetas)
    best, simulated = _simulation_error(model, u, y)
    fit = _Fit(model, thetas, phis, phis, intercept, simulated, start, gamma, build)
    if method in ("iv", "oe"):
        # Each pass takes the previous model's simulated output as instruments; a pass is kept
        # only if its model is stable and simulates the record at least as well (weak
        # instruments can otherwise throw the estimate away from the least-squares one).
        for _ in range(IV_PASSES):
            source = fit.simulated
            if source is None:  # an unstable start still gives instruments, unless it overflows
                with np.errstate(over="ignore", invalid="ignore"):
                    source = simulate(fit.model, u, TruthConfig.ideal())[1]
                if not np.all(np.isfinite(source)) or np.max(np.abs(source)) > OVERFLOW_GUARD:
                    break
            instruments = [_regressors(structure, i, source, feats, start) for i in range(p)]
            # (Z^T Phi) theta = Z^T y, solved through Z's orthonormal basis Q (Z = Q R): the
            # same estimate, without squaring Phi's condition number.
            thetas = []
            for i, (z, phi) in enumerate(zip(instruments, phis, strict=True)):
                q = np.linalg.qr(z)[0]
                thetas.append(_least_squares(q.T @ phi, q.T @ y[start:, i])[0])
            candidate, intercept = build(thetas)
            error, candidate_simulated = _simulation_error(candidate, u, y)
            if not error <= best:
                break
            best = error
            fit = _Fit(
                candidate, thetas, phis, instruments, intercept, candidate_simulated, start, gamma, build
            )
    return fit


def _least_squares(phi: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, int]:
    """(theta, rank) of ``phi theta = y`` by least squares, with unit columns where lstsq on
    ``phi`` as it is finds it rank-deficient or its columns' lengths span more than
    :data:`COLUMN_SPREAD`: lstsq's cut is relative to the largest singular value, and a record in
    small or large units beside the intercept's column of ones is only scaled, not deficient.
    (Other systems keep lstsq's own solution, bit for bit.)"""
    lengths = np.linalg.norm(phi, axis=0)
    used = lengths[lengths > 0.0]
    if used.size == lengths.size and used.max() <= COLUMN_SPREAD * used.min():
        theta, _, rank, _ = np.linalg.lstsq(phi, y, rcond=None)
        if rank == phi.shape[1]:
            return theta, int(rank)
    lengths[lengths == 0.0] = 1.0
    theta, _, rank, _ = np.linalg.lstsq(phi / lengths, y, rcond=None)
    return theta / lengths, int(rank)


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
    coupling = np.zeros((p, p))  # y_i(k) = sum_j coupling[i, j] y_j(k) + ...: H = (I - coupling)^-1
    b = np.zeros((n, m))
    asym = np.zeros((n, m))  # coefficients of |u| lags (non-binary inputs only)
    nonbinary = np.flatnonzero(np.isnan(gamma)) if asymmetric else np.empty(0, dtype=int)
    n_feat = m + nonbinary.size
    intercept = np.empty(p)
    for i, theta in enumerate(thetas):
        free = structure.free_output_lags(i)
        coupled = structure.coupled_outputs(i)
        for (j, d), value in zip(free, theta[: len(free)], strict=True):
            k_gain[structure.position(i, d), j] = value
        coupling[i, coupled] = theta[len(free) : len(free) + len(coupled)]
        u_coef = theta[len(free) + len(coupled) : -1].reshape(structure.indices[i], n_feat)
        for d in range(structure.indices[i]):
            row = structure.position(i, d)
            b[row] = u_coef[d, :m]
            asym[row, nonbinary] = u_coef[d, m:]
        intercept[i] = theta[-1]
    eye = np.eye(p)
    h = eye if not coupling.any() else scipy.linalg.solve_triangular(eye - coupling, eye, lower=True)
    c = structure.output_matrix(h)
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
