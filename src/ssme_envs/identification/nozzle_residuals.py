"""What the nozzle's linear model leaves of its record: the output error ``y - G u`` (rad).

Its colour is kept in a model's ``fit["dsr_e"]["output_error"]`` (:func:`output_error_colour`)
and said where the bootstrap of J, b, k did not resample the noise with it
(:func:`resampling_shortfall`, :func:`coloured_error_note`): the default bootstrap draws DSR_e's
ARX residuals as white noise, right for white sensor noise only. An output error whose mean
stands out of its spread is an angle measured from an offset, and is refused
(:func:`check_offset`): the second-order model would absorb it into J and k.
"""

from __future__ import annotations

import numpy as np

from ssme_envs.identification.noise_sieve import fit_sieve

# Colour above which a note speaks: a lag-1 autocorrelation of 0.6 or a long-run variance 4 times
# the variance, AR(1) noise of coefficient 0.6, under which white resampling halves the standard
# error of a mean. (A narrow-band error, a hum, has a high lag 1 and a low long-run ratio.)
COLOURED_LAG1 = 0.6
COLOURED_LONG_RUN_RATIO = 4.0
# An output error this many times the white noise the bootstrap resampled is not that noise.
LARGER_THAN_RESAMPLED = 3.0
# A mean this many times the output error's spread is an offset: good records, hysteretic joints
# and AR(1) 0.95 sensor noise included, stay under 0.5.
OFFSET_SPREADS = 2.0


def output_error_colour(residual: np.ndarray) -> dict[str, float | int] | None:
    """The output error's std (rad), lag-1 autocorrelation, the order of its AR sieve and the
    sieve's long-run variance over its variance (1 for white noise;
    :class:`~ssme_envs.identification.noise_sieve.ARSieve`). None where the error is not
    finite (an unstable model's simulation)."""
    if not np.all(np.isfinite(residual)):
        return None
    std = float(np.std(residual))
    if not np.ptp(residual) > 0:  # an exact fit: nothing to colour
        return {"std": std, "lag1_autocorrelation": 0.0, "sieve_order": 0, "long_run_ratio": 1.0}
    sieve = fit_sieve(residual)
    return {
        "std": std,
        "lag1_autocorrelation": sieve.lag1,
        "sieve_order": sieve.order,
        "long_run_ratio": sieve.long_run_ratio,
    }


def check_offset(residual: np.ndarray, name: str) -> None:
    """Refuse an output error (rad) whose mean is more than ``OFFSET_SPREADS`` times its
    spread: the angle ``name`` measured from an offset, or a drift the model does not have."""
    spread = float(np.std(residual))
    mean = float(np.mean(residual))
    if np.isfinite(mean) and abs(mean) > OFFSET_SPREADS * spread:
        raise ValueError(
            f"the angle {name!r} sits {mean:+.3g} rad off the linear model's response, "
            f"{abs(mean) / spread:.3g} times the spread of what the model leaves: it is measured from an "
            "offset (subtract the angle at rest) or drifts, and J, b, k would absorb it"
        )


def colour_figures(colour: dict) -> str:
    """:func:`output_error_colour`'s figures as the CLI and the report give them."""
    return (
        f"lag-1 autocorrelation {colour['lag1_autocorrelation']:.2f}, long-run variance "
        f"{colour['long_run_ratio']:.3g} times its variance (1 for white noise), "
        f"AR({colour['sieve_order']}) sieve"
    )


def resampling_shortfall(dsr_e_fit: dict) -> str | None:
    """How a model's bootstrap (``fit["dsr_e"]``) fell short of its output error, where it did:
    the error coloured (above ``COLOURED_LAG1`` or ``COLOURED_LONG_RUN_RATIO``) and not
    resampled by the sieve, or more than ``LARGER_THAN_RESAMPLED`` times the white noise it
    resampled. None otherwise, and for a fit without these figures."""
    colour = dsr_e_fit.get("output_error")
    boot = dsr_e_fit.get("bootstrap")
    if colour is None or boot is None or boot.get("noise") == "sieve":
        return None
    reasons = []
    lag1, ratio = abs(colour["lag1_autocorrelation"]), colour["long_run_ratio"]
    if lag1 > COLOURED_LAG1 or ratio > COLOURED_LONG_RUN_RATIO:
        reasons.append(f"coloured ({colour_figures(colour)})")
    std, resampled = colour.get("std", 0.0), boot["noise_std"]
    if boot["noise"] == "white" and std > LARGER_THAN_RESAMPLED * resampled:
        reasons.append(
            f"{std / resampled:.3g} times as large as the white noise the bootstrap resampled"
            if resampled > 0
            else "larger than the white noise the bootstrap resampled, which is zero"
        )
    return " and ".join(reasons) or None


def coloured_error_note(dsr_e_fit: dict) -> str | None:
    """The CLI's note where :func:`resampling_shortfall` finds one (``dsr_e_fit``: a model's
    ``fit["dsr_e"]``); else None."""
    shortfall = resampling_shortfall(dsr_e_fit)
    if shortfall is None:
        return None
    return (
        f"note: the linear model's output error is {shortfall}; J, b, k's standard errors, "
        f"bootstrapped with {dsr_e_fit['bootstrap']['noise']} noise, are too narrow if that error is "
        "sensor noise: --bootstrap-noise sieve resamples it with its colour (and counts structure "
        "the linear model lacks, such as a hysteresis, as noise too)"
    )


__all__ = [
    "check_offset",
    "colour_figures",
    "coloured_error_note",
    "output_error_colour",
    "resampling_shortfall",
]
