"""What the nozzle's linear model leaves of its record: the output error ``y - G u`` (rad).

Its figures are kept in a model's ``fit["dsr_e"]["output_error"]`` (:func:`output_error_colour`)
and said where they matter (:func:`output_error_notes`): where the bootstrap of J, b, k did not
resample the noise with its colour (:func:`resampling_shortfall`; the default bootstrap draws
DSR_e's ARX residuals as white noise, right for white sensor noise only), and where the error's
mean stands out of its spread (:func:`offset_shortfall`): an angle measured from an offset, a
drift, or a record that does not start at rest, which J, b, k absorb. Neither can be told from
the record alone with certainty (a slow mode, a transient), so both are notes, not refusals.
"""

from __future__ import annotations

import numpy as np

from ssme_envs.identification.noise_sieve import fit_sieve

# Colour above which a note speaks: a lag-1 autocorrelation of 0.3 (AR(1) noise of coefficient 0.3,
# under which the white bootstrap's J, b, k intervals are already too narrow:
# experiments/results/nozzle_coloured_noise.md) or a long-run variance twice the variance (a
# narrow-band error, a hum, has a high lag 1 and a low long-run ratio; white noise stays near 1).
COLOURED_LAG1 = 0.3
COLOURED_LONG_RUN_RATIO = 2.0
# An output error this many times the white noise the bootstrap resampled is not that noise.
LARGER_THAN_RESAMPLED = 3.0
# A mean this many times the output error's spread: the packaged models' bench records give 0.064
# and 0.0034 (their fit.dsr_e.output_error), AR(1) sensor noise up to 0.95 stays inside it
# (tests/test_nozzle_residuals.py), and a record cut from the bench mid-motion reached 2.2 (so a
# note, not a refusal).
OFFSET_SPREADS = 1.0
# what such a mean is, and what it does: said by the CLI's note and the report
OFFSET_CAUSES = (
    "an angle measured from an offset, a drift, or a record that does not start at rest moves J, b, k"
)


def output_error_colour(residual: np.ndarray) -> dict[str, float | int] | None:
    """The output error's mean and std (rad), lag-1 autocorrelation, the order of its AR sieve and the
    sieve's long-run variance over its variance (1 for white noise;
    :class:`~ssme_envs.identification.noise_sieve.ARSieve`). None where the error is not
    finite (an unstable model's simulation)."""
    if not np.all(np.isfinite(residual)):
        return None
    scale = float(np.max(np.abs(residual)))
    z = residual / scale if scale > 0 else residual  # no overflow of the squares at 1e154 rad
    mean, std = scale * float(np.mean(z)), scale * float(np.std(z))
    if not np.ptp(residual) > 0:  # an exact fit: nothing to colour
        flat = {"lag1_autocorrelation": 0.0, "sieve_order": 0, "long_run_ratio": 1.0}
        return {"mean": mean, "std": std, **flat}
    sieve = fit_sieve(residual)
    return {
        "mean": mean,
        "std": std,
        "lag1_autocorrelation": sieve.lag1,
        "sieve_order": sieve.order,
        "long_run_ratio": sieve.long_run_ratio,
    }


def offset_shortfall(dsr_e_fit: dict) -> str | None:
    """Where a model's output error (``fit["dsr_e"]``) has a mean over ``OFFSET_SPREADS`` times
    its spread, what it is; else None (and for a fit without these figures)."""
    error = dsr_e_fit.get("output_error")
    if error is None or "mean" not in error or not abs(error["mean"]) > OFFSET_SPREADS * error["std"]:
        return None
    mean, std = error["mean"], error["std"]
    spreads = f"{abs(mean) / std:.3g} times its spread" if std > 0 else "its spread 0"
    return f"has a mean of {mean:+.3g} rad, {spreads}"


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


def output_error_notes(dsr_e_fit: dict) -> list[str]:
    """The CLI's notes on a model's output error (``dsr_e_fit``: its ``fit["dsr_e"]``): the
    bootstrap's shortfall (:func:`resampling_shortfall`) and an offset
    (:func:`offset_shortfall`), each where there is one."""
    notes = []
    shortfall = resampling_shortfall(dsr_e_fit)
    if shortfall is not None:
        notes.append(
            f"note: the linear model's output error is {shortfall}; J, b, k's standard errors, "
            f"bootstrapped with {dsr_e_fit['bootstrap']['noise']} noise, are too narrow if that error "
            "is sensor noise: --bootstrap-noise sieve resamples it with its colour (and counts "
            "structure the linear model lacks, such as a hysteresis, as noise too)"
        )
    offset = offset_shortfall(dsr_e_fit)
    if offset is not None:
        notes.append(
            f"note: the linear model's output error {offset}: {OFFSET_CAUSES} (subtract the angle at "
            "rest, cut the record where the joint rests)"
        )
    return notes


__all__ = [
    "colour_figures",
    "offset_shortfall",
    "output_error_colour",
    "output_error_notes",
    "resampling_shortfall",
]
