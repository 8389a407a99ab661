"""Nozzle identification pipeline: bench experiment, DSR_e linear model, Bouc-Wen joint.

``bench_experiment`` (truth simulation at the bench rate, decimated) -> ``NozzleRecord`` ->
``identify_nozzle`` -> ``NozzleModel`` (model.json) -> ``validate_nozzle``.

The bench record (:mod:`.nozzle_bench`) follows the VLS nozzle paper: a PRBS torque keeping the
nozzle within about +-3 deg, acquisition at 2.5 kHz for 59.8 s, decimation by 20 to Ts = 0.008 s
(N = 7476), plus sensor noise. This module identifies and validates from any such record, the
bench's or a user's.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ssme_envs.identification.arguments import MAX_SEED
from ssme_envs.identification.bouc_wen import (
    DEFAULT_NORMALIZATION_A,
    NORMALIZED_NAMES,
    BoucWenFit,
    check_torque_record,
    fit_bouc_wen,
    remove_bias,
)
from ssme_envs.identification.metrics import fit_percent
from ssme_envs.identification.nozzle_bench import (
    BENCH_SAMPLES,
    DECIMATION,
    DEFAULT_SEED,
    RANGE_DEG,
    SENSOR_NOISE,
    NozzleRecord,
    acquire,
    acquisition_bias,
    bench_experiment,
    bench_motion,
    bouc_wen_acquisition_bias,
    read_nozzle_record,
    strong_hysteresis_nozzle,
    validation_experiment,
    write_nozzle_record,
)
from ssme_envs.identification.nozzle_residuals import output_error_colour
from ssme_envs.identification.nozzle_uncertainty import (
    DEFAULT_REPLICATES,
    MIN_REPLICATES,
    BootstrapUncertainty,
    check_noise_model,
    count_at_least,
    dsr_e_uncertainty,
)
from ssme_envs.identification.subspace import InnovationsModel, SubspaceResult, dsr_e, second_order_parameters
from ssme_envs.models.nozzle import (
    MAX_SUBSTEPS,
    NozzleModel,
    NozzleParameters,
    accuracy_rate,
    published_nozzle,
    recommended_substeps,
    simulate_nozzle,
)
from ssme_envs.models.uncertainty import ParameterUncertainty

# Simulated acquisitions whose mean is the acquisition chain's bias on J, b, k.
BIAS_DRAWS = 8
BOUC_WEN_METHOD = (
    "regression covariance s^2 (J^T J)^-1 of the output-error fit at the optimum: J the "
    "forward-difference Jacobian of the simulated angle, s^2 = SSE / (N - 7)"
)


@dataclass
class NozzleIdentification:
    model: NozzleModel
    subspace: SubspaceResult
    bouc_wen: BoucWenFit
    linear_uncertainty: BootstrapUncertainty | None = None


def _finite(value: float) -> float | None:
    """JSON has no NaN or inf: what is not a finite number is written as null."""
    return float(value) if np.isfinite(value) else None


def _finite_or_none(values: dict[str, float]) -> dict[str, float | None]:
    """An undetermined parameter's standard error is written as null (:func:`_finite`)."""
    return {key: _finite(v) for key, v in values.items()}


def identify_nozzle(
    record: NozzleRecord,
    seed: int = 0,
    workers: int = 2,
    normalization_A: float = DEFAULT_NORMALIZATION_A,
    replicates: int = DEFAULT_REPLICATES,
    bench_noise: float | None = None,
    progress: Callable[[str], None] | None = None,
    bootstrap_noise: str = "white",
) -> NozzleIdentification:
    """DSR_e second-order linear model (as in the paper, for J, b, k) and the Bouc-Wen joint fit.

    With the standard errors of J, b, k from a residual bootstrap of ``replicates`` records
    (:func:`dsr_e_uncertainty`, seeded by ``seed``; 0: none) and those of the Bouc-Wen joint's
    normalized parameters from the fit's regression covariance, both in the model's
    ``uncertainty`` blocks. ``bench_noise`` (rad at the bench rate): the record comes through the
    embedded bench's acquisition chain (:func:`acquire`) with this sensor noise; the chain's bias
    on J, b, k is then removed (:func:`acquisition_bias`, ``BIAS_DRAWS`` simulated acquisitions,
    their scatter added to the covariance), and its bias on a determined Bouc-Wen fit's
    parameters (:func:`bouc_wen_acquisition_bias`, one noise-free acquisition and refit; the
    covariance kept); the discrete model stays what the data give. ``progress``: called with a
    line before each stage, with the bootstrap's expected time (its cost grows with the record).
    ``bootstrap_noise``: how the bootstrap resamples the noise (``dsr_e_uncertainty``'s ``noise``);
    the fit records the colour of the linear model's output error either way
    (``fit["dsr_e"]["output_error"]``, :func:`output_error_colour`).
    """
    check_torque_record(record.tau, record.beta, names=(record.input_name, record.output_name))
    check_noise_model(bootstrap_noise, "bootstrap_noise")
    count_at_least(workers, "workers", 1)
    if count_at_least(replicates, "replicates", 0) and replicates < MIN_REPLICATES:  # 0: none
        raise ValueError(f"replicates must be 0 (none) or at least {MIN_REPLICATES}, got {replicates}")
    if count_at_least(seed, "seed", 0) > MAX_SEED:  # the Bouc-Wen search's generator takes no more
        raise ValueError(f"seed must be at most 2**32 - 1, got {seed}")
    say = progress or (lambda line: None)
    start = time.perf_counter()
    subspace = dsr_e(record.tau, record.beta, record.dt, order=2)
    once = time.perf_counter() - start
    linear = subspace.model
    sim_linear = linear.simulate(record.tau[:, None])[:, 0]
    tf = second_order_parameters(linear)
    bias = None
    if bench_noise is not None:
        bias = acquisition_bias(record.tau, (tf["J"], tf["b"], tf["k"]), bench_noise, BIAS_DRAWS, seed)
        tf = {**tf, **{key: tf[key] - bias[key] for key in bias}}
    boot = None
    if replicates:
        say(
            f"DSR_e: {once:.2g} s; the standard errors of J, b, k: {replicates} bootstrap records "
            f"(up to about {replicates * once / max(workers, 1):.2g} s)"
        )
        boot = dsr_e_uncertainty(
            record.tau, record.beta, record.dt, subspace, replicates=replicates, seed=seed, workers=workers,
            noise=bootstrap_noise,
        )  # fmt: skip
    if boot is not None and bias is not None:
        boot = dataclasses.replace(
            boot,
            estimate=np.array([tf["J"], tf["b"], tf["k"]]),
            covariance=boot.covariance * (1 + 1 / BIAS_DRAWS),
            method=f"{boot.method}; J, b, k corrected for the bench's acquisition chain (bias "
            f"averaged over {BIAS_DRAWS} simulated acquisitions), covariance times 1 + 1/{BIAS_DRAWS} "
            "for their scatter",
        )
    say(f"the Bouc-Wen joint: evolutionary search, then least squares on all {record.tau.size} samples")
    bw = fit_bouc_wen(
        record.tau, record.beta, record.dt, seed=seed, workers=workers, normalization_A=normalization_A
    )
    bw_bias = None
    if bench_noise is not None and bw.determined:
        bw_bias = bouc_wen_acquisition_bias(record.tau, bw, seed, workers)
        bw = remove_bias(bw, bw_bias)
    colour = output_error_colour(record.beta - sim_linear)
    fit = {
        "samples": int(record.tau.size),
        "dsr_e": {
            "order": subspace.order,
            "past_horizon": subspace.past_horizon,
            "future_horizon": subspace.future_horizon,
            "singular_values": [float(v) for v in subspace.singular_values],
            "transfer_function": {"numerator": tf["numerator"], "denominator": tf["denominator"]},
            "natural_frequency_hz": tf["natural_frequency_hz"],
            # none for a joint damped past 1 / sqrt(2): its magnitude has no peak (JSON has no NaN)
            "resonance_frequency_hz": _finite(tf["resonance_frequency_hz"]),
            "damping_ratio": tf["damping_ratio"],
            "fit_percent": float(fit_percent(record.beta, sim_linear)),
            **({} if colour is None else {"output_error": colour}),
            **({} if bias is None else {"acquisition_bias": bias}),
            **(
                {}
                if boot is None
                else {
                    "standard_errors": boot.as_dict(),
                    "bootstrap": {
                        "replicates": len(boot.replicates),
                        "failed": boot.failed,
                        "noise_std": boot.noise_std,
                        "noise": bootstrap_noise,
                    },
                }
            ),
        },
        "bouc_wen": {
            "determined": bw.determined,
            "reason": bw.reason,
            "normalized": bw.normalized,
            **({} if bw_bias is None else {"acquisition_bias": bw_bias}),
            "standard_errors": _finite_or_none(bw.standard_errors),
            "relative_std": _finite_or_none(bw.relative_std),
            "p_value": bw.p_value,
            "normalization": f"A = {bw.normalization_A:g}",
            "fit_percent": bw.fit_percent,
            "linear_joint": bw.linear.to_dict(),
            "linear_joint_fit_percent": bw.linear_fit_percent,
            "seconds": bw.seconds,
        },
    }
    model = NozzleModel(
        linear={
            "A": linear.A,
            "B": linear.B,
            "C": linear.C,
            "D": linear.D,
            "K": linear.K,
            "dt": record.dt,
            "J": float(tf["J"]),
            "b": float(tf["b"]),
            "k": float(tf["k"]),
        },
        bouc_wen=bw.params,
        fit=fit,
        input_name=record.input_name,
        output_name=record.output_name,
        linear_uncertainty=None if boot is None else boot.parameter_uncertainty(),
        bouc_wen_uncertainty=(
            ParameterUncertainty(NORMALIZED_NAMES, bw.covariance, BOUC_WEN_METHOD, int(record.tau.size))
            if bw.determined and bw.covariance is not None
            else None
        ),
    )
    return NozzleIdentification(model, subspace, bw, boot)


def simulate_joint(joint: NozzleParameters, record: NozzleRecord) -> np.ndarray:
    """The joint's angle under the record's torque, with the RK4 step its motion needs.

    Raises
    ------
    ValueError
        When the record's largest angle asks for more than ``MAX_SUBSTEPS`` RK4 substeps per
        sample (the hysteresis rate grows with the amplitude; 1e5 rad asked for 9e5 a sample).
    """
    amplitude = max(float(np.max(np.abs(record.beta))), 1e-12)
    substeps = recommended_substeps(joint, record.dt, amplitude)
    if substeps > MAX_SUBSTEPS:
        rate = accuracy_rate(joint, amplitude)
        raise ValueError(
            f"simulating the joint over the record's angles up to {amplitude:.4g} rad needs {substeps} RK4 "
            f"substeps per {record.dt:g} s sample, more than {MAX_SUBSTEPS}: its {rate.name} is "
            f"{rate.rate:.4g} 1/s ({rate.detail})"
        )
    return simulate_nozzle(joint, record.tau, record.dt, substeps=substeps, torque_limit=np.inf)


def simulate_linear_model(model: NozzleModel, record: NozzleRecord) -> np.ndarray:
    """The DSR_e state-space model's simulated angle (no innovations) under the record's torque."""
    lin = model.linear
    ss = InnovationsModel(lin["A"], lin["B"], lin["C"], lin["D"], lin["K"], lin["dt"])
    return ss.simulate(record.tau[:, None])[:, 0]


def validate_nozzle(model: NozzleModel, record: NozzleRecord) -> dict[str, float]:
    """Fit % of the simulated angle: DSR_e model, and the joint (Bouc-Wen, else linear J, b, k)."""
    check_torque_record(record.tau, record.beta, names=(record.input_name, record.output_name))
    if abs(record.dt - model.dt) > 1e-9 * model.dt:
        raise ValueError(f"the record's sample time {record.dt:g} s differs from the model's {model.dt:g} s")
    return {
        "dsr_e_fit_percent": float(fit_percent(record.beta, simulate_linear_model(model, record))),
        "joint_fit_percent": float(fit_percent(record.beta, simulate_joint(model.plant(), record))),
    }


def run_default(
    seed: int = DEFAULT_SEED,
    workers: int = 2,
    normalization_A: float = DEFAULT_NORMALIZATION_A,
    truth: str = "table1",
    bootstrap_noise: str = "white",
) -> tuple[NozzleIdentification, dict[str, NozzleRecord]]:
    """The embedded bench test of a nozzle: identification and validation records.

    ``truth``: ``"table1"`` (Table 1's Bouc-Wen nozzle, the packaged ``nozzle_identified.json``)
    or ``"strong"`` (:func:`strong_hysteresis_nozzle`, ``nozzle_strong_identified.json``). The
    model's ``fit`` carries the validation figures; wall time is left out so that the same seed
    gives the same model file. ``bootstrap_noise``: as :func:`identify_nozzle`'s (the bench's
    sensor noise is white, and its model's output error is coloured by the hysteresis).
    """
    truths = {"table1": published_nozzle("bouc_wen"), "strong": strong_hysteresis_nozzle()}
    if truth not in truths:
        raise ValueError(f"truth must be one of {', '.join(truths)}, got {truth!r}")
    joint = truths[truth]
    records = {
        "identification": bench_experiment(joint, seed=seed),
        "validation": validation_experiment(joint, seed=seed + 1),
    }
    ident = identify_nozzle(
        records["identification"],
        seed=seed,
        workers=workers,
        normalization_A=normalization_A,
        bench_noise=SENSOR_NOISE,
        bootstrap_noise=bootstrap_noise,
    )
    ident.model.fit["bouc_wen"].pop("seconds")
    ident.model.fit["validation_record"] = validate_nozzle(ident.model, records["validation"])
    described = {
        "table1": "VLS nozzle paper, Table 1 nonlinear row",
        "strong": "strong-hysteresis nozzle (yields within +-3 deg; not VLS data)",
    }
    ident.model.fit["truth"] = f"{described[truth]}; embedded bench test, seed {seed}"
    return ident, records


__all__ = [
    "BENCH_SAMPLES",
    "BIAS_DRAWS",
    "BOUC_WEN_METHOD",
    "DECIMATION",
    "DEFAULT_NORMALIZATION_A",
    "DEFAULT_SEED",
    "RANGE_DEG",
    "SENSOR_NOISE",
    "NozzleIdentification",
    "NozzleRecord",
    "acquire",
    "acquisition_bias",
    "bench_experiment",
    "bench_motion",
    "identify_nozzle",
    "read_nozzle_record",
    "run_default",
    "simulate_joint",
    "simulate_linear_model",
    "strong_hysteresis_nozzle",
    "validate_nozzle",
    "validation_experiment",
    "write_nozzle_record",
]
