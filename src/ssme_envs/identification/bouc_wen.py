"""Bouc-Wen flexible-joint identification from a torque -> angle record.

The model (see :mod:`ssme_envs.models.nozzle`) is fitted in its identifiable, normalized form
``theta = (J, b, k_el, k_hys, beta_n, gamma_n, n)``; the Table 1 form follows from a stated
normalization of ``A`` (default 0.35, Table 1's value, so that numbers compare with the paper).

1. **Global search** with :func:`scipy.optimize.differential_evolution` (an evolutionary search,
   like the paper's genetic algorithm) over the three shape parameters only: the hysteresis
   scale ``w_max = (beta_n + gamma_n)^(-1/n)`` relative to the record's amplitude, the split
   ``beta_n / (beta_n + gamma_n)`` and ``n``. For each candidate the hysteretic variable ``w``
   follows from the measured angle path alone (``dw = dx (1 - |w|^n (...))`` is rate
   independent), and J, b, k_el, k_hys enter linearly: they come from a least-squares fit of
   the equation of motion after a state-variable filter ``(wf / (s + wf))^3`` (no numerical
   differentiation of noisy data). The population is evaluated as one array operation.
2. **Refinement** of all seven parameters by :func:`scipy.optimize.least_squares` on the
   simulation (output) error over the whole record, with the RK4 nozzle core: first with a
   coarse step, then a few iterations with the step :func:`recommended_substeps` asks for. The
   Jacobian's columns are simulated in ``workers`` processes.
3. **Identifiability**: a linear joint (J, b, k) is fitted the same way. The hysteresis counts
   as determined only if the Bouc-Wen model describes the record (fit >= 80 %), lowers the
   residual significantly (F-test, p < 1e-3), and the standard errors from the Jacobian (the
   regression covariance ``s^2 (J^T J)^-1``, ``s^2 = SSE / (N - 7)``, infinite for a parameter
   the record does not determine: :func:`regression_covariance`) leave
   ``k_hys``, ``n`` and the loading and unloading coefficients known to better than 50 %.
   Otherwise the fit says so and returns no Bouc-Wen parameters, rather than numbers the data
   do not support.

The record must start at rest at the zero of the angle (deviations from the rest position).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize
import scipy.stats

from ssme_envs.identification.alpha_canonical import check_record
from ssme_envs.identification.bouc_wen_costs import (
    NORMALIZED_NAMES,
    _EquationError,
    _make_pool,
    _Residuals,
    _shape_from_search,
    _Simulator,
    _svf,
)
from ssme_envs.identification.metrics import fit_percent
from ssme_envs.identification.nozzle_uncertainty import regression_covariance
from ssme_envs.models.nozzle import NozzleParameters, recommended_substeps
from ssme_envs.models.statespace import check_dt

DEFAULT_NORMALIZATION_A = 0.35
# RK4 substeps: the first refinement uses a coarse step (h * rate <= 0.5, stable, about 1e-3
# relative error), the last iterations the accurate one (h * rate <= 0.2), capped for time.
COARSE_STEP_RATE = 0.5
MIN_FIT_PERCENT = 80.0  # below this the model structure, not its parameters, is the problem
MAX_FIT_SUBSTEPS = 8
SEARCH_SAMPLES = 2000  # the global search looks at the first 16 s; the refinement at all of it


@dataclass
class BoucWenFit:
    """Outcome of :func:`fit_bouc_wen`.

    Attributes
    ----------
    determined : bool
        Whether the record determines the hysteresis parameters.
    params : NozzleParameters or None
        Table 1 form under ``normalization_A``; None when not determined.
    linear : NozzleParameters
        The linear joint (J, b, k) fitted by output error on the same record.
    normalized : dict
        Best normalized Bouc-Wen parameters (reported even when not determined).
    relative_std : dict
        Standard error over value of each normalized parameter (inf when the record does not
        determine it at all).
    standard_errors : dict
        Standard error of each normalized parameter (:func:`regression_covariance`; inf when the
        record does not determine it).
    covariance : ndarray (7, 7) or None
        Their joint covariance in the order of ``NORMALIZED_NAMES``; None when some parameter is
        not determined (an infinite variance).
    p_value : float
        F-test of the Bouc-Wen model against the linear one.
    fit_percent, linear_fit_percent : float
        NRMSE fit of the simulated angle, %.
    reason : str
        One sentence on the decision.
    """

    determined: bool
    params: NozzleParameters | None
    linear: NozzleParameters
    normalized: dict[str, float]
    relative_std: dict[str, float]
    standard_errors: dict[str, float]
    covariance: np.ndarray | None
    p_value: float
    fit_percent: float
    linear_fit_percent: float
    reason: str
    normalization_A: float
    seconds: float = 0.0
    details: dict[str, float] = field(default_factory=dict)


# A record whose angle never exceeds this (rad) shows no nozzle motion (sensor noise alone is about
# 1e-4 rad); angles near 1e-300 underflowed in the joint fit's filtered derivatives (a divide by zero).
MIN_MOTION = 1e-12


def check_torque_record(
    tau: np.ndarray, x: np.ndarray, min_samples: int = 200, names: tuple[str, str] = ("torque", "angle")
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a torque -> angle record (``names`` for the messages); returns 1-D float arrays.

    Beyond :func:`check_record` (lengths, NaN/inf, constant signals): enough samples, enough
    torque changes, an angle that moves by at least ``MIN_MOTION`` rad and starts at rest at zero,
    as the simulated model does.
    """
    tau, x = np.asarray(tau, dtype=float), np.asarray(x, dtype=float)
    if tau.ndim != 1 or x.ndim != 1:
        raise ValueError(f"{names[0]} and {names[1]} must be 1-D sequences")
    u2, y2 = check_record(tau[:, None], x[:, None], names[:1], names[1:])
    tau, x = u2[:, 0], y2[:, 0]
    if tau.size < min_samples:
        raise ValueError(f"the record has {tau.size} samples; a nozzle fit needs at least {min_samples}")
    changes = np.count_nonzero(np.diff(tau))
    if changes < 10:
        raise ValueError(f"{names[0]} changes only {changes} times: not exciting enough to fit dynamics")
    if np.max(np.abs(x)) < MIN_MOTION:
        raise ValueError(
            f"{names[1]} moves by at most {np.max(np.abs(x)):.3g} rad, below {MIN_MOTION:g} rad: no nozzle "
            "motion to fit (the joint fit's filtered derivatives of it underflow): is it in rad?"
        )
    if abs(x[0]) > 0.05 * np.ptp(x):
        raise ValueError(
            f"{names[1]} starts at {x[0]:.4g}, not at rest at zero: give it as the deviation from the "
            "rest position (the model starts from rest)"
        )
    return tau, x


def fit_bouc_wen(
    tau: np.ndarray,
    x: np.ndarray,
    dt: float,
    seed: int = 0,
    workers: int = 2,
    normalization_A: float = DEFAULT_NORMALIZATION_A,
    maxiter: int = 40,
    popsize: int = 15,
    torque_limit: float = np.inf,
) -> BoucWenFit:
    """Fit a Bouc-Wen joint to a torque -> angle record (see the module docstring).

    Parameters
    ----------
    tau : array (T,)
        Torque, N m, held over each sample.
    x : array (T,)
        Measured angle, rad, starting from rest.
    dt : float
        Sample time, s.
    seed : int
        Seed of the evolutionary search (same seed, same result, for any ``workers``).
    workers : int
        Processes for the refinement's Jacobian (1: this process only).
    normalization_A : float
        The value of A under which the Table 1 form is reported.
    maxiter, popsize : int
        Differential-evolution generations and population multiplier.
    torque_limit : float
        Torque saturation of the simulated model, N m (the record's torque is already applied).
    """
    # candidates whose simulation overflows are expected and dropped by their non-finite costs:
    # numpy's overflow warnings about them are noise (a CLI run printed one before its error)
    with np.errstate(over="ignore", invalid="ignore"):
        return _fit_bouc_wen(tau, x, dt, seed, workers, normalization_A, maxiter, popsize, torque_limit)


def _fit_bouc_wen(
    tau: np.ndarray, x: np.ndarray, dt: float, seed: int, workers: int, normalization_A: float,
    maxiter: int, popsize: int, torque_limit: float,
) -> BoucWenFit:  # fmt: skip
    """:func:`fit_bouc_wen`'s work."""
    start = time.perf_counter()
    tau, x = check_torque_record(tau, x)
    dt = check_dt(dt)
    if isinstance(normalization_A, bool) or not (
        isinstance(normalization_A, int | float | np.integer | np.floating) and 0 < normalization_A < np.inf
    ):
        raise ValueError(f"normalization_A must be a positive finite number, got {normalization_A!r}")
    amplitude = float(np.max(np.abs(x - x[0])))
    seg = slice(0, min(x.size, SEARCH_SAMPLES))

    # A first linear equation-error fit sets the filter band around the joint's resonance.
    probe = _EquationError(tau[seg], x[seg], dt, wf=min(0.25 * np.pi / dt, 100.0))
    j0, b0, k0 = probe.linear_part(None, 0.0)
    if not (j0 > 0 and k0 > 0):
        raise ValueError("the record does not show a mass-spring response (fitted inertia or stiffness <= 0)")
    seg_seconds = (seg.stop - seg.start) * dt
    wf = float(np.clip(2.0 * np.sqrt(k0 / j0), 40.0 / seg_seconds, 0.5 * np.pi / dt))
    eq = _EquationError(tau[seg], x[seg], dt, wf)

    def population_cost(z: np.ndarray) -> np.ndarray:
        return eq.costs(*_shape_from_search(z.reshape(3, -1), amplitude))[0]

    # w_max from a tenth to a hundred times the amplitude (beyond: linear), any split, n in 0.5..3.
    search = scipy.optimize.differential_evolution(
        population_cost,
        [(-1.0, 2.0), (0.0, 1.0), (0.5, 3.0)],
        seed=seed,
        maxiter=maxiter,
        popsize=popsize,
        tol=1e-8,
        polish=False,
        vectorized=True,
        updating="deferred",
    )
    shape = list(_shape_from_search(search.x[:, None], amplitude))
    _, k_hys = eq.costs(*shape)
    fw = _svf(eq.hysteresis_path(*shape), dt, wf, 0)[0]
    j1, b1, k_el1 = eq.linear_part(fw[eq.keep], float(k_hys[0]))
    lower = np.array([1e-6 * j0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3])
    floor = lower.copy()
    floor[3] = 1e-6 * k0  # start with some hysteresis so that its gradient is not zero
    theta0 = np.maximum([j1, b1, k_el1, float(k_hys[0]), *(float(v[0]) for v in shape)], floor)

    simulator = _Simulator(tau, dt, torque_limit)
    pool = _make_pool(workers, simulator)

    def refine(theta: np.ndarray, substeps: int, max_nfev: int) -> scipy.optimize.OptimizeResult:
        resid = _Residuals(simulator, x, pool, substeps)
        return scipy.optimize.least_squares(
            resid,
            theta,
            jac=resid.jacobian,
            bounds=(lower, np.inf),
            x_scale=np.maximum(np.abs(theta), 1e-3),
            max_nfev=max_nfev,
            xtol=1e-10,
            ftol=1e-10,
        )

    def substeps_for(theta: np.ndarray, step_rate: float) -> int:
        joint = NozzleParameters.from_normalized(*theta, A=1.0)
        return min(recommended_substeps(joint, dt, amplitude, step_rate), MAX_FIT_SUBSTEPS)

    try:
        coarse = substeps_for(theta0, COARSE_STEP_RATE)
        if not np.all(np.isfinite(simulator(theta0, coarse))):
            raise ValueError("the global search found no model that stays bounded on this record")
        refined = refine(theta0, coarse, 40)
        # Then a few iterations with the step the fitted joint needs (stiff hysteresis: more).
        substeps = substeps_for(refined.x, 0.2)
        if substeps > coarse:
            refined = refine(refined.x, substeps, 6)
        substeps = max(substeps, coarse)

        def linear_theta(th: np.ndarray) -> np.ndarray:
            return np.array([th[0], th[1], th[2], 0.0, 0.0, 0.0, 1.0])

        lin_resid = _Residuals(simulator, x, pool, substeps)
        lin = scipy.optimize.least_squares(
            lambda th: lin_resid(linear_theta(th)),
            np.array([j0, max(b0, 0.0), k0]),
            jac=lambda th: lin_resid.jacobian(linear_theta(th), columns=3),
            bounds=([1e-6 * j0, 0.0, 1e-6 * k0], np.inf),
            x_scale=np.abs([j0, max(abs(b0), 1e-3), k0]),
            max_nfev=40,
        )
    except BaseException:
        if pool is not None:
            pool.terminate()  # do not wait for the running evaluations
        raise
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    return _assess(refined, lin, x, normalization_A, start, search, wf, substeps)


def _assess(
    refined, lin, x: np.ndarray, normalization_A: float, start: float, search, wf: float, substeps: int
) -> BoucWenFit:
    """Decide whether the data determine the hysteresis, and package the fit."""
    linear = NozzleParameters.linear(*(float(v) for v in lin.x))
    sse_bw, sse_lin = float(refined.fun @ refined.fun), float(lin.fun @ lin.fun)
    dof = x.size - len(NORMALIZED_NAMES)
    f_stat = ((sse_lin - sse_bw) / 4.0) / (sse_bw / dof) if sse_bw > 0 else np.inf
    p_value = float(scipy.stats.f.sf(f_stat, 4, dof)) if np.isfinite(f_stat) else 0.0
    theta = refined.x
    normalized = dict(zip(NORMALIZED_NAMES, (float(v) for v in theta), strict=True))
    cov = regression_covariance(refined.jac, sse_bw / dof)
    std = np.sqrt(np.diag(cov))
    relative_std = {
        name: float(s / abs(v)) if v != 0 else float("inf")
        for name, s, v in zip(NORMALIZED_NAMES, std, theta, strict=True)
    }
    load = theta[4] + theta[5]
    checks = {
        "k_hys": relative_std["k_hys"],
        "n": relative_std["n"],
        "beta_n, gamma_n (over beta_n + gamma_n)": float(max(std[4], std[5]) / load) if load > 0 else np.inf,
    }
    loose = {k: v for k, v in checks.items() if not v < 0.5}
    fit = float(fit_percent(x, x + refined.fun))
    if not fit >= MIN_FIT_PERCENT:
        reason = (
            f"the Bouc-Wen model does not describe the record (simulation fit {fit:.1f} % < "
            f"{MIN_FIT_PERCENT:g} %): its parameters are not determined; check that the record is a "
            "torque -> angle test starting at rest"
        )
    elif p_value >= 1e-3:
        reason = (
            "the hysteresis parameters are not determined by the data: the Bouc-Wen model fits no better "
            f"than a linear joint (F-test p = {p_value:.2g}); the record likely stays in the linear range"
        )
    elif loose:
        errors = ", ".join(f"{k} {v:.2g}" for k, v in loose.items())
        reason = (
            "the hysteresis parameters are not determined by the data: "
            f"relative standard errors {errors} exceed 0.5"
        )
    else:
        reason = (
            f"hysteresis determined (F-test p = {p_value:.2g}, "
            f"largest relative standard error {max(checks.values()):.2g})"
        )
    determined = fit >= MIN_FIT_PERCENT and p_value < 1e-3 and not loose
    return BoucWenFit(
        determined=determined,
        params=_table1_form(normalized, normalization_A) if determined else None,
        linear=linear,
        normalized=normalized,
        relative_std=relative_std,
        standard_errors=dict(zip(NORMALIZED_NAMES, (float(v) for v in std), strict=True)),
        covariance=cov if np.all(np.isfinite(cov)) else None,
        p_value=p_value,
        fit_percent=fit,
        linear_fit_percent=float(fit_percent(x, x + lin.fun)),
        reason=reason,
        normalization_A=normalization_A,
        seconds=time.perf_counter() - start,
        details={
            "search_cost": float(search.fun),
            "search_generations": int(search.nit),
            "filter_rad_s": wf,
            "substeps": substeps,  # of the final refinement
        },
    )


def remove_bias(fit: BoucWenFit, bias: Mapping[str, float]) -> BoucWenFit:
    """``fit`` with ``bias`` subtracted from its normalized parameters (a determined fit): the
    Table 1 form rebuilt from them and the relative standard errors recomputed; the standard
    errors and covariance, the noise's, are kept."""
    if not fit.determined:
        raise ValueError("only a determined fit has parameters to correct")
    normalized = {name: value - float(bias[name]) for name, value in fit.normalized.items()}
    relative = {
        name: fit.standard_errors[name] / abs(v) if v != 0 else float("inf") for name, v in normalized.items()
    }
    return dataclasses.replace(
        fit,
        params=_table1_form(normalized, fit.normalization_A),
        normalized=normalized,
        relative_std=relative,
    )


def _table1_form(normalized: dict[str, float], normalization_A: float) -> NozzleParameters:
    """The joint in Table 1's form under ``normalization_A``, or ValueError when that A rounds a
    part of it away (A = 1e20 made a = 1: the hysteresis gone from the stored model)."""
    joint = NozzleParameters.from_normalized(**normalized, A=normalization_A)
    back = joint.normalized()
    lost = [
        key
        for key in ("k_el", "k_hys", "beta_n", "gamma_n")
        if not math.isclose(back[key], normalized[key], rel_tol=1e-6)
    ]
    if lost:
        raise ValueError(
            f"the normalization A = {normalization_A:g} cannot hold the identified joint in Table 1's "
            f"form ({', '.join(f'{key} {normalized[key]:g} -> {back[key]:g}' for key in lost)}); "
            "choose an A nearer the hysteresis scale (default 0.35)"
        )
    return joint
