"""Markdown reports with PNG figures for engine identification runs."""

from __future__ import annotations

import json
from collections.abc import Sequence
from importlib import resources
from pathlib import Path

import numpy as np

from ssme_envs.identification.alpha_canonical import Identification
from ssme_envs.identification.metrics import filter_prediction, model_prediction
from ssme_envs.identification.pipeline import EngineRecord, LevelResult
from ssme_envs.models.statespace import AlphaCanonicalModel


def agg_pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_comparison(path: Path, record: EngineRecord, model: AlphaCanonicalModel, title: str) -> None:
    """Measured outputs vs the state-variable filter (eq 50) and the model (eqs 51-52)."""
    plt = agg_pyplot()
    filt = filter_prediction(model, record.u, record.y)
    sim = model_prediction(model, record.u)
    n_out = record.y.shape[1]
    fig, axes = plt.subplots(n_out + 1, 1, figsize=(8, 2.2 * (n_out + 1)), sharex=True)
    t = record.t
    for i, ax in enumerate(axes[:n_out]):
        ax.plot(t, record.y[:, i], color="k", lw=1.2, label="measured")
        ax.plot(t, filt[:, i], color="tab:blue", lw=0.9, ls="--", label="filter (eq 50)")
        ax.plot(t, sim[:, i], color="tab:red", lw=0.9, label="model (eqs 51-52)")
        ax.set_ylabel(f"d {record.output_names[i]}")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncol=3)
    for j in range(record.u.shape[1]):
        axes[-1].step(t, record.u[:, j], where="post", lw=0.9, label=record.input_names[j])
    axes[-1].set_ylabel("input")
    axes[-1].set_xlabel("time (s)")
    axes[-1].legend(loc="upper right", fontsize=8)
    axes[-1].grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_structure_search(path: Path, ident: Identification, rank_tol: float) -> None:
    """Bar chart of the rank-search ratios with the decision threshold."""
    plt = agg_pyplot()
    search = ident.search
    fig, ax = plt.subplots(figsize=(7, 3))
    names = ident.model.output_names
    labels = [f"c_{names[i]} A^{k}" for i, k, _, _ in search.ratios]
    ratios = [max(r, 1e-17) for _, _, r, _ in search.ratios]
    colors = ["tab:green" if kept else "tab:gray" for *_, kept in search.ratios]
    ax.bar(range(len(ratios)), ratios, color=colors)
    ax.axhline(rank_tol, color="tab:red", ls="--", label=f"rank_tol = {rank_tol:g}")
    ax.set_yscale("log")
    ax.set_xticks(range(len(ratios)), labels, rotation=45, ha="right", fontsize=8)
    ax.set_ylabel("new-direction ratio")
    ax.set_title(f"Structure search: indices {list(search.indices)} (green: kept)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
    if ident is not None and ident.search is not None and rank_tol is not None:
        plot_structure_search(out_dir / "structure_search.png", ident, rank_tol)
        lines += ["## Structure search", "", "![structure search](structure_search.png)", ""]
    lines += ["## Measured vs filter vs model", ""]
    for name, rec in records.items():
        png = f"{name}.png"
        plot_comparison(out_dir / png, rec, model, f"{name}: measured, filter and model")
        lines += [f"![{name}]({png})", ""]
    path = out_dir / "report.md"
    path.write_text("\n".join(lines))
    return path


def _paper_table2() -> dict:
    doc = json.loads((resources.files("ssme_envs") / "models" / "data" / "engine_table1.json").read_text())
    return doc["table2_see"]


def write_default_report(out_dir: Path, results: list[LevelResult], seed: int, truth_note: str) -> Path:
    """report.md of the embedded experiment: Table I and Table II comparisons and figures 4-8."""
    paper = _paper_table2()
    powers = [r.power_percent for r in results]
    outputs = results[0].identified.model.output_names
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
        "| power % | indices | spectral radius (pub / id) | lambda (pub) | lambda (id) "
        "| max abs diff K | max abs diff B |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in results:
        pub, ide = r.published, r.identified.model
        lines.append(
            f"| {r.power_percent} | {list(ide.observability_indices)} | {pub.spectral_radius():.4f} / "
            f"{ide.spectral_radius():.4f} | {_fmt_matrix(pub.lam[None])} | {_fmt_matrix(ide.lam[None])} | "
            f"{np.max(np.abs(pub.K - ide.K)):.4f} | {np.max(np.abs(pub.B - ide.B)):.4f} |"
        )
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
    for record_name, title in (
        ("validation_prbs", "PRBS signal"),
        ("validation_low_frequency", "Low frequency test signal"),
    ):
        lines += [
            "",
            f"## Table II: SEE, {title} (paper / ours)",
            "",
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
    path.write_text("\n".join(lines))
    return path
