"""The engine reports' parameter uncertainty: each parameter's estimate and standard error, the
covariance each model carries in words, the response bands, and the gain bias the intervals
leave out."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ssme_envs.identification.pipeline import LevelResult
from ssme_envs.identification.report_figures import plot_response_bands
from ssme_envs.models.statespace import AlphaCanonicalModel


def parameter_estimates(model: AlphaCanonicalModel) -> dict[str, tuple[float, float]]:
    """(estimate, standard error) of each parameter the uncertainty block covers."""
    values = dict(zip(model.parameter_names(), model.parameter_vector(), strict=True))
    unc = model.uncertainty
    return {
        name: (float(values[name]), float(se))
        for name, se in zip(unc.parameters, unc.standard_errors, strict=True)
    }


def parameter_table(model: AlphaCanonicalModel) -> list[str]:
    """Markdown rows: each free parameter, its estimate, standard error and relative error."""
    if model.uncertainty is None:
        return ["The model carries no parameter covariance."]
    lines = ["| parameter | estimate | standard error | relative |", "|---|---|---|---|"]
    for name, (value, se) in parameter_estimates(model).items():
        rel = f"{se / abs(value):.2%}" if value != 0 else "-"
        lines.append(f"| {name} | {value:.5g} | {se:.2g} | {rel} |")
    return lines


def uncertainty_section(out_dir: Path, model: AlphaCanonicalModel, stem: str, title: str) -> list[str]:
    """Report lines with the standard errors and the band figure (written to ``stem``.png)."""
    if model.uncertainty is None:
        return []
    plot_response_bands(out_dir / f"{stem}.png", model, title)
    return [
        "Standard errors from the regression's covariance "
        f"({model.uncertainty.method}); K and H entries as in `model.json` (`K = A[:, n-p:] H^-1`, "
        "`H = C[:, n-p:]`).",
        "",
        *parameter_table(model),
        "",
        f"![responses with 95 % bands]({stem}.png)",
        "",
    ]


def covariance_lines(results: list[LevelResult]) -> list[str]:
    """What the levels' standard errors come from (each model's ``uncertainty.method``: once where
    every level has the same, else level by level); where method "iv" kept least squares, that
    text says so and what follows (biased, intervals that may under-cover)."""
    lead = (
        "Estimate and standard error of each free parameter (`model_<power>.json` holds the full "
        "covariance; published values beside them in the first table above)"
    )
    groups: dict[str, list[int]] = {}
    for r in results:
        groups.setdefault(r.identified.model.uncertainty.method, []).append(r.power_percent)
    if len(groups) == 1:
        return [f"{lead}: {next(iter(groups))}."]
    return [f"{lead}:", "", *(f"- {', '.join(f'{p} %' for p in ps)}: {text}." for text, ps in groups.items())]


def gain_bias_lines(results: list[LevelResult], backlash: float, amplitude: float) -> list[str]:
    """How far the identified steady-state gains lie from Table I's, in % and in the standard
    errors of B, beside what the truth's valve backlash (width ``backlash``) takes off a PRBS of
    amplitude ``amplitude``: a bias of the linear model that the intervals (the noise's) leave out."""
    ratios, z = [], []
    for r in results:
        pub, ide = r.published, r.identified.model
        with np.errstate(divide="ignore", invalid="ignore"):
            ratios.append(ide.dc_gain() / pub.dc_gain())
        if ide.uncertainty is not None and ide.observability_indices == pub.observability_indices:
            truth = dict(zip(pub.parameter_names(), pub.parameter_vector(), strict=True))
            z += [
                abs(v - truth[n]) / se
                for n, (v, se) in parameter_estimates(ide).items()
                if n[0] == "B" and se > 0
            ]
    ratios = np.concatenate([r.ravel() for r in ratios]) if ratios else np.empty(0)
    ratios = ratios[np.isfinite(ratios)]  # a zero entry of Table I's gain has no ratio
    if not ratios.size:
        return []
    if not (ratios.max() < 1.0 and backlash > 0.0):
        return [
            f"The identified steady-state gains are {ratios.min():.3f}-{ratios.max():.3f} times Table I's."
        ]
    low, high = 100 * (1 - ratios.max()), 100 * (1 - ratios.min())
    said = f"The identified steady-state gains are {low:.1f}-{high:.1f} % below Table I's at every level"
    if z:
        said += (
            f" (B entries a median {np.median(z):.0f} and up to {max(z):.0f} standard errors from Table I's)"
        )
    said += (
        f": the truth's valve backlash (width {backlash:g}), which the linear model cannot represent, "
        f"takes {backlash:g} / (2 x {amplitude:g}) = {100 * backlash / (2.0 * amplitude):.1f} % off the "
        "valve travel of each step of the PRBS. The standard errors and bands are the sensor noise's "
        "and leave this bias out."
    )
    return [said]


__all__ = [
    "covariance_lines",
    "gain_bias_lines",
    "parameter_estimates",
    "parameter_table",
    "uncertainty_section",
]
