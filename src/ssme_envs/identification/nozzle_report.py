"""Markdown report with figures for a nozzle identification (figures 8, 11 and 12 of the paper)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.signal

from ssme_envs.identification.bouc_wen import BoucWenFit
from ssme_envs.identification.metrics import fit_percent
from ssme_envs.identification.nozzle_pipeline import (
    NozzleIdentification,
    NozzleRecord,
    simulate_joint,
    simulate_linear_model,
)
from ssme_envs.identification.nozzle_residuals import (
    OFFSET_CAUSES,
    colour_figures,
    offset_shortfall,
    resampling_shortfall,
)
from ssme_envs.identification.report_figures import agg_pyplot
from ssme_envs.identification.subspace import to_continuous
from ssme_envs.models.nozzle import NozzleCore, NozzleParameters, published_nozzle
from ssme_envs.outputs import save_figure, write_text

# Eq 5 of the paper: G_m(s) = 0.03971 / (s^2 + 14.95 s + 5694), for the frequency-response figure.
PAPER_TF = ([0.03971], [1.0, 14.95, 5694.0])


def plot_frequency_response(path: Path, ident: NozzleIdentification) -> None:
    """Figure 8: magnitude and phase of the identified linear model, with the paper's eq 5."""
    plt = agg_pyplot()
    ac, bc, cc, dc = to_continuous(ident.subspace.model)
    w = np.logspace(0, np.log10(np.pi / ident.model.dt), 400)
    fig, (mag_ax, ph_ax) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    # from the state space directly: scipy's bode goes through transfer-function coefficients,
    # which overflow for a record in extreme units (torque in units of 1e-300: gain 1e300)
    identified = np.array([(cc @ np.linalg.solve(1j * wk * np.eye(len(ac)) - ac, bc) + dc)[0, 0] for wk in w])
    for label, response, style in (
        ("identified (DSR_e)", identified, "-"),
        ("paper eq 5", scipy.signal.freqs(*PAPER_TF, worN=w)[1], "--"),
    ):
        mag = 20.0 * np.log10(np.abs(response))
        phase = np.degrees(np.unwrap(np.angle(response)))
        mag_ax.semilogx(w / (2 * np.pi), mag, style, label=label)
        ph_ax.semilogx(w / (2 * np.pi), phase, style, label=label)
    mag_ax.set_ylabel("magnitude (dB, rad/(N m))")
    ph_ax.set_ylabel("phase (deg)")
    ph_ax.set_xlabel("frequency (Hz)")
    mag_ax.legend(fontsize=8)
    for ax in (mag_ax, ph_ax):
        ax.grid(alpha=0.3, which="both")
    fig.suptitle("Frequency response of the linear model")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def _predictions(ident: NozzleIdentification, record: NozzleRecord) -> dict[str, np.ndarray]:
    out = {"linear (DSR_e)": simulate_linear_model(ident.model, record)}
    if ident.model.bouc_wen is not None:
        out["Bouc-Wen"] = simulate_joint(ident.model.bouc_wen, record)
    return out


def plot_hysteresis(
    path: Path, ident: NozzleIdentification, record: NozzleRecord, seconds: float = 4.0
) -> None:
    """Figure 11: the joint's restoring torque against the angle, from the record and the models.

    From the record: ``tau - J x'' - b x'`` with the fitted J, b and Savitzky-Golay derivatives
    of the measured angle. Linear model: ``k x``. Bouc-Wen: ``a k x + (1 - a) k z`` simulated.
    """
    plt = agg_pyplot()
    stop = min(record.tau.size, int(seconds / record.dt))
    joint = ident.model.plant()
    window = 5
    rate = scipy.signal.savgol_filter(record.beta, window, 3, deriv=1, delta=record.dt)
    accel = scipy.signal.savgol_filter(record.beta, window, 3, deriv=2, delta=record.dt)
    # x(k) is the angle before torque k acts, so the torque acting around sample k is tau(k-1).
    held = np.concatenate([[0.0], record.tau[:-1]])
    measured_force = held - joint.J * accel - joint.b * rate
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.scatter(
        np.degrees(record.beta[:stop]),
        measured_force[:stop],
        s=4,
        color="0.4",
        alpha=0.6,
        label="from the record",
    )
    span = np.linspace(record.beta[:stop].min(), record.beta[:stop].max(), 2)
    stiffness = ident.model.linear["k"]
    ax.plot(np.degrees(span), stiffness * span, "--", color="tab:blue", label="linear model: k x")
    if ident.model.bouc_wen is not None:
        core = NozzleCore(ident.model.bouc_wen, dt=record.dt, torque_limit=np.inf)
        angle, force = np.empty(stop), np.empty(stop)
        for k in range(stop):
            angle[k], force[k] = core.state[0, 0], core.restoring_torque()[0]
            core.step(record.tau[k])
        ax.plot(np.degrees(angle), force, "-", color="tab:red", lw=0.8, label="Bouc-Wen: a k x + (1-a) k z")
    ax.set_xlabel("nozzle angle (deg)")
    ax.set_ylabel("restoring torque (N m)")
    ax.set_title(f"Hysteresis curve, first {stop * record.dt:.0f} s")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def plot_prediction(
    path: Path, record: NozzleRecord, preds: dict[str, np.ndarray], title: str
) -> dict[str, float]:
    """Figure 12: measured angle against the models' simulated angles; returns their fit %."""
    plt = agg_pyplot()
    t = np.arange(record.tau.size) * record.dt
    fig, (ax, zoom) = plt.subplots(2, 1, figsize=(9, 5.5))
    stop = min(record.tau.size, int(1.0 / record.dt))
    for axis, end in ((ax, record.tau.size), (zoom, stop)):
        axis.plot(t[:end], np.degrees(record.beta[:end]), "k-", lw=1.0, label="measured")
        for (label, pred), style in zip(preds.items(), ("--", ":"), strict=False):
            axis.plot(t[:end], np.degrees(pred[:end]), style, lw=1.0, label=label)
        axis.set_ylabel("angle (deg)")
        axis.grid(alpha=0.3)
    zoom.set_xlabel("time (s)")
    ax.legend(fontsize=8, ncol=3)
    ax.set_title(title)
    zoom.set_title("first second")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return {label: float(fit_percent(record.beta, pred)) for label, pred in preds.items()}


def _percent(fit: float) -> str:
    """A fit in %, two decimals; a fit far below zero (a record the model does not describe at
    all) in three significant digits instead of a hundred."""
    return f"{fit:.2f}" if abs(fit) < 1e4 else f"{fit:.3g}"


def parameter_row(name: str, p: NozzleParameters | None) -> str:
    """One markdown table row: J, b, k, a, A, beta, gamma, n ("-" for a linear joint)."""
    if p is None:
        return f"| {name} | not determined | | | | | | | |"
    if p.is_linear:
        return f"| {name} | {p.J:.2f} | {p.b:.2f} | {p.k:.4g} | - | - | - | - | - |"
    return (
        f"| {name} | {p.J:.2f} | {p.b:.2f} | {p.k:.4g} | {p.a:.3f} | {p.A:.2f} | {p.beta:.3f} | "
        f"{p.gamma:.3f} | {p.n:.3f} |"
    )


def standard_error_row(ident: NozzleIdentification) -> str:
    """The parameter table's row with the standard errors of the identified J, b, k."""
    se = ident.linear_uncertainty.as_dict()
    return f"| standard error (bootstrap) | {se['J']:.2g} | {se['b']:.2g} | {se['k']:.2g} | | | | | |"


def bias_text(bias: dict[str, float], key: str) -> str:
    """The simulated acquisition bias as the report gives it (estimate minus truth, what the
    corrected values had subtracted), naming the model.json entry ``key`` that holds it."""
    return "bias " + ", ".join(f"{name} {value:+.4g}" for name, value in bias.items()) + f", `{key}`"


def _uncertainty_note(ident: NozzleIdentification) -> list[str]:
    boot = ident.linear_uncertainty
    bias = ident.model.fit["dsr_e"].get("acquisition_bias")
    lines = []
    if bias is not None:
        lines += [
            "J, b, k are corrected for the bench's acquisition chain (anti-alias FIR filter and "
            "decimation by 20): its bias at the estimate, simulated, is subtracted "
            f"({bias_text(bias, 'fit.dsr_e.acquisition_bias')}); the DSR_e state-space model is what "
            "the data give.",
            "",
        ]
    if boot is None:
        return lines
    return [
        *lines,
        f"Standard errors of J, b, k: {boot.method}. They measure the scatter the sensor noise causes "
        "(noise std on the record "
        f"{boot.noise_std:.3g} rad), not the systematic error of a second-order model of this record "
        "(a hysteretic joint's linearization"
        + ("" if bias is not None else ", a decimation filter's distortion")
        + ")."
        + _colour_sentence(ident.model.fit["dsr_e"]),
        "",
    ]


def _colour_sentence(dsr_e_fit: dict) -> str:
    """The output error's colour (``fit.dsr_e.output_error``) and what it means for the standard
    errors; empty where the model.json has no such figures (written before they were kept, or an
    output error that is not finite)."""
    colour = dsr_e_fit.get("output_error")
    if colour is None:
        return ""
    text = f" The linear model's output error: {colour_figures(colour)}."
    if "acquisition_bias" in dsr_e_fit:  # the embedded bench, whose sensor noise is white
        text += " The bench's sensor noise is white: the colour is what the linear model leaves out."
    elif (shortfall := resampling_shortfall(dsr_e_fit)) is not None:
        text += (
            f" It is {shortfall}: bootstrapped with {dsr_e_fit['bootstrap']['noise']} noise, the standard "
            "errors are too narrow if it is sensor noise (`--bootstrap-noise sieve` resamples it with "
            "its colour)."
        )
    if (offset := offset_shortfall(dsr_e_fit)) is not None:
        text += f" It {offset}: {OFFSET_CAUSES}."
    return text


def _bouc_wen_section(bw: BoucWenFit, bias: dict[str, float] | None = None) -> list[str]:
    """Verdict, and the normalized parameters with their standard errors only when determined;
    ``bias``: the acquisition chain's, removed from them (the model's ``fit``), when the record
    came from the embedded bench."""
    fits = (
        f"Simulation fit {_percent(bw.fit_percent)} % (a linear joint fitted the same way: "
        f"{_percent(bw.linear_fit_percent)} %)."
    )
    if not bw.determined:
        return [f"Bouc-Wen fit: {fits} No Bouc-Wen parameters are reported: {bw.reason}.", ""]
    rows = []
    for name, value in bw.normalized.items():
        se, rel = bw.standard_errors[name], bw.relative_std[name]
        rows.append(f"| {name} | {value:.6g} | {se:.2g} | {rel:.2g} |")
    return [
        f"Bouc-Wen fit: {bw.reason}. {fits}",
        "",
        "A, beta, gamma and (1 - a) k are not jointly identifiable (scaling z leaves the motion unchanged); "
        "the fit estimates k_el = a k, k_hys = (1 - a) k A, beta_n = beta A^(n-1), gamma_n = gamma A^(n-1) "
        "and n, and the Table 1 form above fixes A. Estimated (normalized) parameters with their standard "
        "errors (regression covariance s^2 (J^T J)^-1 of the output-error fit, s^2 = SSE / (N - 7); "
        "s^2 counts any model error in the residual as noise, and like the linear model's they do not "
        "cover systematic errors):",
        "",
        "| parameter | value | standard error | relative |",
        "|---|---|---|---|",
        *rows,
        "",
        *(
            []
            if bias is None
            else [
                "The values are corrected for the bench's acquisition chain: its bias at the estimate, "
                "simulated (the fitted joint at the bench rate, acquired without noise and fitted "
                f"again), is subtracted ({bias_text(bias, 'fit.bouc_wen.acquisition_bias')}); the standard "
                "errors are the noise's.",
                "",
            ]
        ),
    ]


def write_nozzle_report(
    out_dir: Path,
    ident: NozzleIdentification,
    records: dict[str, NozzleRecord],
    truth: NozzleParameters | None = None,
    note: str = "",
) -> Path:
    """report.md with the parameter table, the fit figures and figures 8, 11 and 12."""
    model, bw = ident.model, ident.bouc_wen
    lin = model.linear
    dsr = model.fit["dsr_e"]
    num, den = dsr["transfer_function"]["numerator"], dsr["transfer_function"]["denominator"]
    lines = ["# Nozzle identification report", ""]
    if note:
        lines += [note, ""]
    lines += [
        "## Linear model (DSR_e)",
        "",
        f"Order {dsr['order']} (past horizon {dsr['past_horizon']}, future horizon {dsr['future_horizon']}), "
        f"simulation fit {dsr['fit_percent']:.1f} % on the identification record.",
        "",
        f"G(s) = ({num[0]:.3g} s^2 + {num[1]:.4g} s + {num[2]:.5g}) / (s^2 + {den[1]:.4g} s + {den[2]:.5g}); "
        f"the paper's eq 5: {PAPER_TF[0][0]:g} / (s^2 + {PAPER_TF[1][1]:g} s + {PAPER_TF[1][2]:g}).",
        "",
        f"Natural frequency {dsr['natural_frequency_hz']:.2f} Hz, damping ratio {dsr['damping_ratio']:.4f}, "
        + (
            "no resonance peak (damping ratio at least 1/sqrt(2))"
            if dsr["resonance_frequency_hz"] is None
            else f"resonance {dsr['resonance_frequency_hz']:.2f} Hz"
        )
        + " (paper: 11.88 Hz resonance, damping 0.0971).",
        "",
        "## Parameters",
        "",
        "| model | J | b | k | a | A | beta | gamma | n |",
        "|---|---|---|---|---|---|---|---|---|",
        parameter_row("paper, linear row (Table 1)", published_nozzle("linear")),
        parameter_row(
            "identified linear (DSR_e, eq 5 form)", NozzleParameters.linear(lin["J"], lin["b"], lin["k"])
        ),
        *([standard_error_row(ident)] if ident.linear_uncertainty is not None else []),
        parameter_row("paper, nonlinear row (Table 1)", published_nozzle("bouc_wen")),
    ]
    if truth is not None:
        lines.append(parameter_row("truth of this bench", truth))
    lines += [
        parameter_row(f"identified Bouc-Wen (normalization A = {bw.normalization_A:g})", bw.params),
        "",
        *_uncertainty_note(ident),
        *_bouc_wen_section(bw, model.fit["bouc_wen"].get("acquisition_bias")),
        "## Figures",
        "",
    ]
    plot_frequency_response(out_dir / "frequency_response.png", ident)
    lines += ["![frequency response (figure 8)](frequency_response.png)", ""]
    last = list(records)[-1]
    plot_hysteresis(out_dir / "hysteresis.png", ident, records[last])
    lines += [f"![hysteresis (figure 11), {last} record](hysteresis.png)", ""]
    predictions = {name: _predictions(ident, record) for name, record in records.items()}
    labels = list(predictions[last])
    lines += ["| record | " + " | ".join(f"fit {k} %" for k in labels) + " |", "|---|" + "---|" * len(labels)]
    for name, record in records.items():
        fits = plot_prediction(
            out_dir / f"prediction_{name}.png", record, predictions[name], f"{name} record"
        )
        lines.append(f"| {name} | " + " | ".join(_percent(v) for v in fits.values()) + " |")
    lines.append("")
    lines += [f"![prediction, {name} (figure 12)](prediction_{name}.png)" for name in records]
    path = out_dir / "report.md"
    write_text(path, "\n".join(lines) + "\n")
    return path
