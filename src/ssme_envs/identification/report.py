"""Markdown reports with PNG figures for engine identification runs."""

from __future__ import annotations

import json
from collections.abc import Sequence
from importlib import resources
from pathlib import Path

import numpy as np

from ssme_envs.identification.alpha_canonical import Identification
from ssme_envs.identification.pipeline import PRBS_AMPLITUDE, EngineRecord, LevelResult
from ssme_envs.identification.report_figures import (
    agg_pyplot,
    plot_comparison,
    plot_response_bands,
    plot_structure_search,
)
from ssme_envs.identification.report_uncertainty import (
    covariance_lines,
    gain_bias_lines,
    parameter_estimates,
    uncertainty_section,
)
from ssme_envs.models.statespace import AlphaCanonicalModel
from ssme_envs.outputs import write_text


def structure_table(search) -> list[str]:
    """The index sets compared, best first, with their criterion and parameter count."""
    lines = [f"| indices | {search.criterion or 'criterion'} | parameters | note |", "|---|---|---|---|"]
    ranked = search.ranked()
    rest = [c for c in search.candidates if c not in ranked]
    for c in ranked + rest:
        crit = f"{c.criterion:.1f}" if np.isfinite(c.criterion) else "not fitted"
        note = c.note or ("chosen" if c.indices == search.indices else "")
        lines.append(f"| {list(c.indices)} | {crit} | {c.parameters} | {note} |")
    return lines


def _fmt_matrix(mat: np.ndarray) -> str:
    return "<br>".join("[" + ", ".join(f"{v:.4f}" for v in row) + "]" for row in np.atleast_2d(mat))


def _validation_table(validation: dict, output_names: Sequence[str]) -> list[str]:
    lines = [
        "| record | predictor | "
        + " | ".join(f"SEE {n}" for n in output_names)
        + " | "
        + " | ".join(f"fit {n} %" for n in output_names)
        + " |",
        "|---|---|" + "---|" * (2 * len(output_names)),
    ]
    for rec_name, per in validation.items():
        for pred_name, figs in per.items():
            cells = [f"{v:.4g}" for v in figs["see"]] + [f"{v:.1f}" for v in figs["fit_percent"]]
            lines.append(f"| {rec_name} | {pred_name} | " + " | ".join(cells) + " |")
    return lines


def write_record_report(
    out_dir: Path,
    model: AlphaCanonicalModel,
    records: dict[str, EngineRecord],
    validation: dict,
    ident: Identification | None = None,
    rank_tol: float | None = None,
) -> Path:
    """report.md for user records: model, fit table, figures, and the structure search if any."""
    title = "Engine identification report" if ident is not None else "Engine model validation report"
    lines = [
        f"# {title}",
        "",
        f"Model: {model.n_inputs} inputs ({', '.join(model.input_names)}) -> {model.n_outputs} outputs "
        f"({', '.join(model.output_names)}), dt = {model.dt:g} s, observability indices "
        f"{list(model.observability_indices)}, spectral radius {model.spectral_radius():.4f}"
        + (f", method `{ident.method}`." if ident is not None else "."),
        "",
        "| matrix | value |",
        "|---|---|",
        f"| A | {_fmt_matrix(model.A)} |",
        f"| B | {_fmt_matrix(model.B)} |",
        f"| C | {_fmt_matrix(model.C)} |",
        f"| lambda | {_fmt_matrix(model.lam[None])} |",
        "",
        "## Fit (SEE of eq 53 and NRMSE fit)",
        "",
        *_validation_table(validation, model.output_names),
        "",
    ]
    if model.uncertainty is not None:
        lines += ["## Parameter uncertainty", ""]
        lines += uncertainty_section(out_dir, model, "response_bands", "Identified model")
    if ident is not None and ident.search is not None and rank_tol is not None:
        plot_structure_search(out_dir / "structure_search.png", ident, rank_tol)
        lines += ["## Structure search", "", ident.search.summary().replace("\n", "\n\n"), ""]
        lines += structure_table(ident.search)
        lines += ["", "![structure search](structure_search.png)", ""]
    lines += ["## Measured vs filter vs model", ""]
    for name, rec in records.items():
        png = f"{name}.png"
        plot_comparison(out_dir / png, rec, model, f"{name}: measured, filter and model")
        lines += [f"![{name}]({png})", ""]
    path = out_dir / "report.md"
    write_text(path, "\n".join(lines))
    return path


def paper_table2() -> dict:
    """NASA TM-104422's Table II as packaged: SEE by record ("prbs", "low_frequency"), kind
    ("model", "filter"), output ("pc", "mr") and power level (a string, %)."""
    doc = json.loads((resources.files("ssme_envs") / "models" / "data" / "engine_table1.json").read_text())
    return doc["table2_see"]


MARKOV_COUNT = 11  # C A^k B, k = 0..10, compared across structures


def markov_difference(published: AlphaCanonicalModel, identified: AlphaCanonicalModel) -> float:
    """||M(identified) - M(published)|| / ||M(published)||, M the Markov parameters C A^k B for
    k = 0..10 stacked (Frobenius norm): comparable whatever the two models' observability
    indices, and weighted as the impulse response is (the decayed tail counts little)."""
    pub, ide = published.markov_parameters(MARKOV_COUNT), identified.markov_parameters(MARKOV_COUNT)
    return float(np.linalg.norm(ide - pub) / np.linalg.norm(pub))


def _table1_rows(results: list[LevelResult], markov: bool = False) -> list[str]:
    """Table I published beside identified: indices, spectral radius, lambda, K and B differences
    ("-" where the structures differ), and with ``markov`` the relative Markov difference."""
    lines = [
        "| power % | indices | spectral radius (pub / id) | lambda (pub) | lambda (id) "
        "| max abs diff K | max abs diff B |" + (" Markov difference |" if markov else ""),
        "|---|---|---|---|---|---|---|" + ("---|" if markov else ""),
    ]
    for r in results:
        pub, ide = r.published, r.identified.model
        same = pub.K.shape == ide.K.shape
        diffs = (
            [f"{np.max(np.abs(pub.K - ide.K)):.4f}", f"{np.max(np.abs(pub.B - ide.B)):.4f}"]
            if same
            else ["-", "-"]
        )
        lines.append(
            f"| {r.power_percent} | {list(ide.observability_indices)} | {pub.spectral_radius():.4f} / "
            f"{ide.spectral_radius():.4f} | {_fmt_matrix(pub.lam[None])} | {_fmt_matrix(ide.lam[None])} | "
            f"{diffs[0]} | {diffs[1]} |" + (f" {markov_difference(pub, ide):.4f} |" if markov else "")
        )
    return lines


def _table2_rows(results: list[LevelResult], record_name: str, paper: dict) -> list[str]:
    """Table II: the SEE of the filter and the model on a validation record, paper / ours."""
    powers = [r.power_percent for r in results]
    outputs = results[0].identified.model.output_names
    lines = [
        "| predictor | output | " + " | ".join(f"{p} %" for p in powers) + " |",
        "|---|---|" + "---|" * len(powers),
    ]
    key = "prbs" if record_name == "validation_prbs" else "low_frequency"
    for predictor in ("filter", "model"):
        for i, out in enumerate(outputs):
            cells = []
            for r in results:
                ours = r.validation[record_name][predictor]["see"][i]
                theirs = paper[key][predictor][out].get(str(r.power_percent))
                cells.append(f"{theirs:.4g} / {ours:.4g}" if theirs is not None else f"- / {ours:.4g}")
            lines.append(f"| {predictor} | {out} | " + " | ".join(cells) + " |")
    return lines


TABLE2_RECORDS = (
    ("validation_prbs", "PRBS signal"),
    ("validation_low_frequency", "Low frequency test signal"),
)


def write_default_report(
    out_dir: Path, results: list[LevelResult], seed: int, truth_note: str, backlash: float
) -> Path:
    """report.md of the embedded experiment: Table I and Table II comparisons and figures 4-8
    (``backlash``: the truth's valve backlash width, whose gain bias it states)."""
    paper = paper_table2()
    powers = [r.power_percent for r in results]
    lines = [
        "# SSME identification on the embedded experiment",
        "",
        "The data come from a truth we chose: each Table I point model of NASA TM-104422 with "
        f"{truth_note}. The paper's data came from Rocketdyne's nonlinear engine simulation, so "
        "its Table II figures and ours measure different things; they are set side by side for scale. "
        f"Seed {seed}; every record is reproducible bit for bit.",
        "",
        "Experiment: two uncorrelated 127-bit PRBS (0.04 s clock, amplitude 0.01) for 8 periods "
        "(1016 samples) to identify; a PRBS from another primitive polynomial (254 samples) and the "
        "step/ramp test of figure 3 (300 samples) to validate. SEE (eq 53) is taken against the "
        "measured (noisy) outputs.",
        "",
        "## Table I: published vs identified",
        "",
        *_table1_rows(results),
    ]
    lines += ["", "Parameters side by side (published / identified):", ""]
    lines += [
        "| power % | K published | K identified | B published | B identified |",
        "|---|---|---|---|---|",
    ]
    for r in results:
        pub, ide = r.published, r.identified.model
        lines.append(
            f"| {r.power_percent} | {_fmt_matrix(pub.K)} | {_fmt_matrix(ide.K)} | "
            f"{_fmt_matrix(pub.B)} | {_fmt_matrix(ide.B)} |"
        )
    for record_name, title in TABLE2_RECORDS:
        lines += [
            "",
            f"## Table II: SEE, {title} (paper / ours)",
            "",
            *_table2_rows(results, record_name, paper),
        ]
    lines += [
        "",
        "## Parameter uncertainty",
        "",
    ]
    models = [r.identified.model for r in results]
    if any(m.uncertainty is None for m in models):
        lines.append("A model carries no parameter covariance.")
    else:
        lines += [
            *covariance_lines(results),
            "",
            "| parameter | " + " | ".join(f"{p} %" for p in powers) + " |",
            "|---|" + "---|" * len(powers),
        ]
        names = models[0].parameter_names()
        table = [parameter_estimates(m) for m in models]
        for name in names:
            cells = [f"{t[name][0]:.4f} ± {t[name][1]:.4f}" if name in t else "-" for t in table]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines += ["", *gain_bias_lines(results, backlash, PRBS_AMPLITUDE)]
        lines += [
            "",
            "Step and frequency responses with 95 % bands (200 models drawn from the covariance):",
            "",
        ]
        for r in results:
            png = f"engine_{r.power_percent}_bands.png"
            plot_response_bands(out_dir / png, r.identified.model, f"{r.power_percent} % power")
            lines += [f"![{r.power_percent} % bands]({png})", ""]
    lines += ["", "## Figures 4-8: low-frequency test, measured vs filter vs model", ""]
    for r in results:
        png = f"engine_{r.power_percent}_low_frequency.png"
        plot_comparison(
            out_dir / png,
            r.records["validation_low_frequency"],
            r.identified.model,
            f"{r.power_percent} % power: low-frequency test",
        )
        lines += [f"![{r.power_percent} %]({png})", ""]
    path = out_dir / "report.md"
    write_text(path, "\n".join(lines))
    return path


def nonlinear_section(
    results: list[LevelResult], seed: int, test_scale: float, amplitude: Sequence[float]
) -> list[str]:
    """Report lines: the same experiment on the nonlinear engine truth, Table I beside the
    identified models and Table II's SEE (paper / ours).

    ``results`` from :func:`~ssme_envs.identification.engine_nonlinear_pipeline.run_nonlinear`;
    ``amplitude``: the largest |command| of each valve in the figure 3 test, normalized travel.
    """
    paper = paper_table2()
    lines = [
        "## The nonlinear engine truth",
        "",
        "The same experiment (seed "
        f"{seed}, the same PRBS and noise streams) on the synthetic nonlinear engine of "
        "`ssme_envs.models.engine_nonlinear` (EngineTracking-v0 and EngineThrottle-v0 with "
        '`plant="nonlinear"`): Table I interpolated in power and scheduled on the power implied by '
        "the engine's own chamber pressure, a valve authority that falls away from the trim "
        "(calibrated so that the figure 3 test shows Table II's range of model SEE) and a smooth valve "
        "flow curve whose chords on a +-0.01 input are close to eq 36's lambda gains, and the valve "
        "backlash, stiction and sensor noise above. It is consistent with the paper's published local "
        "models (its linearization at each Table I level is Table I's model), not Rocketdyne's "
        "simulation; the identified models below see what it adds: the schedule, the authority and the "
        f"flow curve away from a +-0.01 input. Truth: {results[0].identified.model.fit.get('truth', '-')}.",
        "",
        "### Table I: published vs identified on the nonlinear truth",
        "",
        "Markov difference: ||M (identified) - M (Table I)|| / ||M (Table I)||, M the Markov parameters "
        "C A^k B for k = 0..10 stacked (K and B differences only where the identified indices are "
        "Table I's (2, 2)).",
        "",
        *_table1_rows(results, markov=True),
    ]
    scale = ", ".join(
        f"{name} within +-{a:g}" for name, a in zip(results[0].published.input_names, amplitude, strict=True)
    )
    for record_name, title in TABLE2_RECORDS:
        lines += ["", f"### Table II on the nonlinear truth: SEE, {title} (paper / ours)", ""]
        if record_name == "validation_low_frequency":
            lines += [
                f"The figure 3 step/ramp test times {test_scale:g} ({scale}, normalized valve travel).",
                "",
            ]
        lines += _table2_rows(results, record_name, paper)
    return lines


def append_section(path: Path, lines: Sequence[str]) -> Path:
    """Rewrite the report at ``path`` with ``lines`` added at its end."""
    write_text(path, path.read_text().rstrip("\n") + "\n\n" + "\n".join(lines) + "\n")
    return path


__all__ = [
    "MARKOV_COUNT",
    "TABLE2_RECORDS",
    "agg_pyplot",
    "append_section",
    "markov_difference",
    "nonlinear_section",
    "plot_comparison",
    "plot_response_bands",
    "plot_structure_search",
    "structure_table",
    "uncertainty_section",
    "write_default_report",
    "write_record_report",
]
