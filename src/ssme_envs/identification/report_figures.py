"""The PNG figures of the engine reports: measured vs filter vs model, the structure search's rank
ratios, and responses with bands from the parameter covariance. Apart from the Markdown of
:mod:`.report`, and home of :func:`agg_pyplot`, which the nozzle and main reports draw with too."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ssme_envs.identification.alpha_canonical import Identification
from ssme_envs.identification.metrics import filter_prediction, model_prediction
from ssme_envs.identification.pipeline import EngineRecord
from ssme_envs.models.statespace import AlphaCanonicalModel
from ssme_envs.outputs import save_figure


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
    save_figure(fig, path, dpi=110)
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
    save_figure(fig, path, dpi=110)
    plt.close(fig)


BAND_DRAWS = 200  # models drawn from the parameter covariance for the 95 % bands
BAND_SEED = 0


def _step_and_frequency(model: AlphaCanonicalModel, steps: int, freqs: np.ndarray):
    """Step responses to a positive unit step of each input (eq 36 applied), shape (steps, p, m),
    and gains |G(e^{i w dt})| of the linear part, shape (len(freqs), p, m)."""
    markov = model.markov_parameters(steps) * model.lam
    step = np.concatenate([np.zeros((1, *markov.shape[1:])), np.cumsum(markov, axis=0)[:-1]])
    z = np.exp(1j * 2 * np.pi * freqs * model.dt)
    eye = np.eye(model.A.shape[0])
    gain = np.array([np.abs(model.C @ np.linalg.solve(zk * eye - model.A, model.B)) for zk in z])
    return step, gain


def plot_response_bands(path: Path, model: AlphaCanonicalModel, title: str) -> None:
    """Step and frequency responses of the model with 95 % bands from its parameter covariance
    (``BAND_DRAWS`` models drawn with a fixed seed; percentiles 2.5 and 97.5)."""
    plt = agg_pyplot()
    steps = 100
    freqs = np.logspace(-2, np.log10(0.5 / model.dt), 120)
    step, gain = _step_and_frequency(model, steps, freqs)
    # Unstable draws (possible when the covariance is wide) have no step response to band.
    draws = [m for m in model.sample(np.random.default_rng(BAND_SEED), BAND_DRAWS) if m.spectral_radius() < 1]
    drawn = [_step_and_frequency(m, steps, freqs) for m in draws] or [(step, gain)]
    step_band = np.percentile([d[0] for d in drawn], [2.5, 97.5], axis=0)
    gain_band = np.percentile([d[1] for d in drawn], [2.5, 97.5], axis=0)
    p, m = model.n_outputs, model.n_inputs
    fig, axes = plt.subplots(2, p * m, figsize=(3.2 * p * m, 5.2), squeeze=False)
    t = np.arange(steps) * model.dt
    for i in range(p):
        for j in range(m):
            col = i * m + j
            name = f"{model.input_names[j]} -> {model.output_names[i]}"
            ax = axes[0, col]
            ax.fill_between(t, step_band[0, :, i, j], step_band[1, :, i, j], color="tab:blue", alpha=0.25)
            ax.plot(t, step[:, i, j], color="tab:blue", lw=1.2)
            ax.set_title(name, fontsize=9)
            ax.set_xlabel("time (s)")
            ax.grid(alpha=0.3)
            ax = axes[1, col]
            ax.fill_between(freqs, gain_band[0, :, i, j], gain_band[1, :, i, j], color="tab:red", alpha=0.25)
            ax.loglog(freqs, gain[:, i, j], color="tab:red", lw=1.2)
            ax.set_xlabel("frequency (Hz)")
            ax.grid(alpha=0.3, which="both")
    axes[0, 0].set_ylabel("unit step response")
    axes[1, 0].set_ylabel("|G| (linear part)")
    fig.suptitle(
        f"{title}: responses with 95 % bands from the parameter covariance "
        f"({len(draws)} of {BAND_DRAWS} drawn models stable)"
    )
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
