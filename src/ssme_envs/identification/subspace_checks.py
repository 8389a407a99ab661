"""Checks around DSR_e (:mod:`ssme_envs.identification.subspace`): whether a record's inputs excite
every input direction well enough for the model's gains to be determined (also run by the
alpha-canonical ``identify``), and the one-step prediction criterion by which a retry with other
horizons chooses among its fits."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import scipy.linalg

from ssme_envs.identification.innovations_model import InnovationsModel
from ssme_envs.models.linear import spectral_radius

# A record is refused when the model's gain along some input direction would be uncertain by more
# than COLLINEAR_GAIN_ERROR times the system's gain. Least squares over T samples determines a gain
# along a direction excited r times less than the strongest one (singular values of the centred
# inputs, each divided by its own RMS, so that units do not count) to about rho / (r sqrt(T)) of
# the system's gain, rho being the outputs' noise as a fraction of their spread (the innovations
# estimate of DSR_e's step 1; the largest over the outputs). Measured with DSR_e, order given, on
# random stable systems (order 2-4, one or two outputs, two inputs u1 = u0 + delta w, T = 1000):
# - with output noise 1e-3 and 0.1 and delta 1e-1..1e-7, the static gain's error along the weak
#   direction (relative to the gain's norm) was 0.1 to 4 times that estimate throughout;
# - over 600 records with delta log-uniform in 1e-7..1, those the threshold 0.25 keeps had their
#   frequency response along the weak direction off by at most 0.87 of its peak: the threshold
#   sits where the gain along the direction can be off by its own size;
# - without noise the gain was right to about 1e-16 / r (5e-9 at r = 5e-8): sample count and
#   round-off alone never call for a refusal above the exact-dependence test of ``check_record``
#   (r < 1e-8). A fixed condition number would refuse such noise-free records, which identify
#   well, yet keep noisy ones that do not (r = 5e-4, condition number of the input covariance
#   4e6, noise 0.1: gain errors 1 to 25 times the gain).
COLLINEAR_GAIN_ERROR = 0.25


def input_directions(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Singular values (relative to the largest) and right singular vectors (rows) of the centred
    inputs, each divided by its own size: the excitation of each input direction, unit-free."""
    x = u - u.mean(axis=0)
    x = x / np.max(np.abs(x), axis=0)  # through the peak first: x**2 may overflow
    x = x / np.linalg.norm(x, axis=0)
    _, s, vt = np.linalg.svd(x, full_matrices=False)
    return s / s[0], vt


def _direction(v: np.ndarray, names: Sequence[str]) -> str:
    """``0.707 u0 - 0.707 u1``, the larger of the signs first."""
    v = v if v[np.argmax(np.abs(v))] > 0 else -v
    terms = [(c, names[i]) for i, c in enumerate(v) if abs(c) >= 0.01]
    text = " ".join(f"{'-' if c < 0 else '+'} {abs(c):.3g} {name}" for c, name in terms)
    return text[2:] if text.startswith("+ ") else "-" + text[2:]


def check_input_directions(
    u: np.ndarray, measure_noise: Callable[[], float], names: Sequence[str] | None = None
) -> None:
    """Raise ValueError when the inputs are so nearly collinear that the gain along some input
    direction is not determined by the record (``COLLINEAR_GAIN_ERROR``).

    ``measure_noise`` gives the outputs' noise as a fraction of their spread (at most 1); it is
    called only when some direction is excited so weakly that even noise as large as the outputs'
    spread could leave its gain undetermined, so a well-conditioned record costs one SVD.
    ``names``: the inputs' names in the message (default u0, u1, ...).
    """
    n_samples, m = u.shape
    if m < 2:
        return
    ratios, vt = input_directions(u)
    sqrt_t = math.sqrt(n_samples)
    if ratios[-1] * sqrt_t * COLLINEAR_GAIN_ERROR >= 1.0:
        return
    rho = min(float(measure_noise()), 1.0)
    uncertainty = rho / (np.maximum(ratios, np.finfo(float).tiny) * sqrt_t)
    weak = np.flatnonzero(uncertainty > COLLINEAR_GAIN_ERROR)
    if weak.size == 0:
        return
    names = [f"u{i}" for i in range(m)] if names is None else list(names)
    listed = ", ".join(names)
    noise = f"with output noise at {100 * rho:.3g} % of the outputs' spread and {n_samples} samples"
    remedy = (
        "Excite the inputs independently (e.g. uncorrelated PRBS), use a longer or less noisy record, "
        "or identify with fewer inputs (e.g. their sum)"
    )
    if weak.size == 1:
        i = weak[0]
        raise ValueError(
            f"the inputs {listed} are nearly collinear: the input direction {_direction(vt[i], names)} (each "
            f"input divided by its RMS) is excited {1 / ratios[i]:.3g} times less than the strongest "
            f"one; {noise}, the model's gain along it would be uncertain by about {uncertainty[i]:.3g} "
            f"times the system's gain, so it is not determined by this record. {remedy}"
        )
    directions = ", ".join(
        f"{_direction(vt[i], names)} (excited {1 / ratios[i]:.3g} times less than the strongest one, gain "
        f"uncertain by about {uncertainty[i]:.3g} times the system's gain)"
        for i in weak
    )
    raise ValueError(
        f"the inputs {listed} are nearly collinear: along the input directions {directions} (each "
        f"input divided by its RMS), {noise}, the model's gains are not determined by this record. "
        f"{remedy}"
    )


def arx_innovations(u: np.ndarray, y: np.ndarray, past: int) -> np.ndarray:
    """Residual of ``y(k)`` projected on ``u(k)`` and ``u, y`` at lags 1..past, k = past..T-1."""
    horizon = u.shape[0]
    lagged = [u[past:]]
    for lag in range(1, past + 1):
        lagged += [u[past - lag : horizon - lag], y[past - lag : horizon - lag]]
    phi = np.hstack(lagged)
    # Rank-revealing QR least squares (gelsy): a noise-free record makes the output lags dependent.
    theta, *_ = scipy.linalg.lstsq(phi, y[past:], lapack_driver="gelsy", check_finite=False)
    return y[past:] - phi @ theta


def record_noise(u: np.ndarray, y: np.ndarray, past: int) -> float:
    """The outputs' noise as a fraction of their spread (:func:`noise_fraction`) from the ARX
    innovations of ``past`` lags, fitted on the channels brought to unit peaks: on raw channels
    the fit's rank cut, relative to the largest column, dropped inputs in units far from the
    outputs' and counted their response as noise (69 % for 0.1 %)."""
    us, ys = u / np.max(np.abs(u), axis=0), y / np.max(np.abs(y), axis=0)
    return noise_fraction(arx_innovations(us, ys, past), ys[past:])


def noise_fraction(e: np.ndarray, y: np.ndarray) -> float:
    """The outputs' noise as a fraction of their spread: the largest over the outputs of the norm
    of the innovations estimate ``e`` over that of the output ``y`` (same samples) less its mean."""
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    return float(np.max(np.linalg.norm(e, axis=0) / np.maximum(spread, np.finfo(float).tiny)))


def unstable(model: InnovationsModel) -> bool:
    """Whether ``A`` or the predictor ``A - K C`` has a pole on or outside the unit circle."""
    return spectral_radius(model.A) >= 1.0 or spectral_radius(model.A - model.K @ model.C) >= 1.0


def prediction_criterion(model: InnovationsModel, u: np.ndarray, y: np.ndarray, first: int) -> float:
    """Log-determinant of the covariance of the model's one-step prediction errors on the record
    from sample ``first`` on (the Gaussian likelihood criterion, which does not depend on the
    outputs' units); inf when the predictor ``A - K C`` is unstable or the errors are not finite."""
    if spectral_radius(model.A - model.K @ model.C) >= 1.0:
        return math.inf
    with np.errstate(over="ignore", invalid="ignore"):
        residual = (y - model.simulate(u, y))[first:]
        if not np.all(np.isfinite(residual)):
            return math.inf
        sign, logdet = np.linalg.slogdet(residual.T @ residual / residual.shape[0])
    return float(logdet) if sign > 0 else -math.inf


def most_predictive(
    models: Sequence[InnovationsModel], u: np.ndarray, y: np.ndarray, first: int
) -> int | None:
    """Index of the model that predicts the record best one step ahead (:func:`prediction_criterion`
    from sample ``first`` on), the first of equals; None when none has a stable predictor."""
    scores = [prediction_criterion(model, u, y, first) for model in models]
    if not scores or min(scores) == math.inf:
        return None
    return int(np.argmin(scores))


__all__ = [
    "COLLINEAR_GAIN_ERROR",
    "arx_innovations",
    "check_input_directions",
    "input_directions",
    "most_predictive",
    "noise_fraction",
    "prediction_criterion",
    "record_noise",
    "unstable",
]
