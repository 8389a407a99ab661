"""Validation of identified engine models: the state-variable filter, model simulation, SEE, fit."""

from __future__ import annotations

import math

import numpy as np

from ssme_envs.models.engine import TruthConfig, simulate
from ssme_envs.models.statespace import AlphaCanonicalModel, asymmetric_gain


def filter_prediction(model: AlphaCanonicalModel, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """One-step prediction of the state-variable filter (eq 50), shape (T, p).

    ``y_f(k) = sum_{d < mu} C A_o^d [K B] [y(k-1-d); u*(k-1-d)]``, measured outputs and inputs
    in, lags before the record taken as zero.
    """
    structure = model.structure
    a_o = structure.shift_matrix()
    u_star = asymmetric_gain(u, model.lam)
    pred = np.zeros((u.shape[0], model.n_outputs))
    c_ad = model.C.copy()
    for d in range(max(structure.indices)):
        if d + 1 >= u.shape[0]:
            break
        pred[d + 1 :] += y[: -d - 1] @ (c_ad @ model.K).T + u_star[: -d - 1] @ (c_ad @ model.B).T
        c_ad = c_ad @ a_o
    return pred


def model_prediction(model: AlphaCanonicalModel, u: np.ndarray) -> np.ndarray:
    """Output of the identified model driven by the inputs alone (eqs 51-52), shape (T, p)."""
    return simulate(model, u, TruthConfig.ideal())[1]


def see(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Standard error of estimate of eq 53 for each output: sum (z - y)^2 / sum y^2."""
    measured = np.asarray(measured, dtype=float)
    err = np.asarray(predicted, dtype=float) - measured
    return np.sum(err**2, axis=0) / np.sum(measured**2, axis=0)


def fit_percent(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """NRMSE fit for each output, %: 100 (1 - ||y - z|| / ||y - mean(y)||)."""
    measured = np.asarray(measured, dtype=float)
    err = np.linalg.norm(np.asarray(predicted, dtype=float) - measured, axis=0)
    return 100.0 * (1.0 - err / np.linalg.norm(measured - measured.mean(axis=0), axis=0))


def validate(model: AlphaCanonicalModel, u: np.ndarray, y: np.ndarray) -> dict[str, dict[str, list[float]]]:
    """SEE and fit of the filter and of the model on one record, per output."""
    out = {}
    for name, pred in (("filter", filter_prediction(model, u, y)), ("model", model_prediction(model, u))):
        out[name] = {"see": see(y, pred).tolist(), "fit_percent": fit_percent(y, pred).tolist()}
    return out


def finite_validation(
    model: AlphaCanonicalModel, u: np.ndarray, y: np.ndarray, where: str
) -> dict[str, dict[str, list[float]]]:
    """:func:`validate`, with a ValueError naming ``where`` (the record), the predictor, the figure
    and the output where a figure comes out NaN or inf (a prediction that overflows: an unstable
    model, or inputs near the float range's end), or where the record is shorter than twice the
    model's states plus one (a 2-sample record gave a fit of 96 %); no floating-point warnings."""
    needed = 2 * (model.n_states + 1)
    if u.shape[0] < needed:
        raise ValueError(
            f"{where}: the record has {u.shape[0]} samples; SEE and fit of a {model.n_states}-state model "
            f"need at least {needed} (its filter's first {max(model.observability_indices)} are its start-up)"
        )
    with np.errstate(all="ignore"):  # an overflow is refused just below
        scores = validate(model, u, y)
    for predictor, figures in scores.items():
        for metric, values in figures.items():
            for name, value in zip(model.output_names, values, strict=True):
                if not math.isfinite(value):
                    radius = model.spectral_radius()
                    why = f": the model is unstable, spectral radius {radius:.4g}" if radius >= 1.0 else ""
                    raise ValueError(
                        f"{where}: the {predictor}'s {metric} for output '{name}' is {value} "
                        f"(its prediction overflows on this record{why})"
                    )
    return scores


def fit_warning(model: AlphaCanonicalModel, fit: list[float]) -> str | None:
    """A line for the console when the model's simulation fits a record worse than the outputs'
    means (negative NRMSE fit, ``fit`` per output, %), saying what that means; None otherwise."""
    bad = [(name, value) for name, value in zip(model.output_names, fit, strict=True) if value < 0.0]
    if not bad:
        return None
    figures = ", ".join(f"{name} {value:.3g} %" for name, value in bad)
    radius = model.spectral_radius()
    if radius >= 1.0:
        why = (
            f"the model is unstable (spectral radius {radius:.4g}), and an unstable model's simulation "
            "drifts away from any record, so SEE and fit say little of it: judge it by the filter's "
            "one-step figures"
        )
    else:
        why = "the record may not suit the model: check the structure (--indices) or try --method oe"
    return f"warning: the model's simulation fits the record worse than the outputs' means ({figures}): {why}"
