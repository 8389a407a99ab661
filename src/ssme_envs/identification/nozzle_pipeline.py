"""Nozzle identification pipeline: bench experiment, DSR_e linear model, Bouc-Wen joint.

``bench_experiment`` (truth simulation at the bench rate, decimated) -> ``NozzleRecord`` ->
``identify_nozzle`` -> ``NozzleModel`` (model.json) -> ``validate_nozzle``.

The bench follows the VLS nozzle paper: a PRBS torque keeping the nozzle within about +-3 deg,
acquisition at 2.5 kHz for 59.8 s, decimation by 20 to Ts = 0.008 s (N = 7476), plus sensor
noise. The PRBS switches on the 0.008 s grid so that the decimated torque is exactly
zero-order held; the angle is low-pass filtered (zero-phase FIR) before decimation.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.signal

from ssme_envs.identification.bouc_wen import (
    DEFAULT_NORMALIZATION_A,
    NORMALIZED_NAMES,
    BoucWenFit,
    check_torque_record,
    fit_bouc_wen,
)
from ssme_envs.identification.metrics import fit_percent
from ssme_envs.identification.nozzle_uncertainty import (
    DEFAULT_REPLICATES,
    BootstrapUncertainty,
    dsr_e_uncertainty,
)
from ssme_envs.identification.records import read_columns, write_columns
from ssme_envs.identification.subspace import InnovationsModel, SubspaceResult, dsr_e, second_order_parameters
from ssme_envs.models.nozzle import (
    BENCH_RATE_HZ,
    DEFAULT_TORQUE_LIMIT,
    NOZZLE_DT,
    NozzleModel,
    NozzleParameters,
    published_nozzle,
    recommended_substeps,
    simulate_nozzle,
    strong_nozzle,
)
from ssme_envs.models.uncertainty import ParameterUncertainty
from ssme_envs.outputs import atomic_write
from ssme_envs.signals import prbs

DEFAULT_SEED = 7
BENCH_SAMPLES = 7476  # the paper's N at Ts = 0.008 s (59.8 s)
DECIMATION = round(BENCH_RATE_HZ * NOZZLE_DT)  # 20
# Simulated acquisitions whose mean is the acquisition chain's bias on J, b, k.
BIAS_DRAWS = 8
SENSOR_NOISE = 1e-4  # rad, std of the angle sensor at 2.5 kHz (an assumption: 0.006 deg)
RANGE_DEG = 3.0
BOUC_WEN_METHOD = (
    "regression covariance s^2 (J^T J)^-1 of the output-error fit at the optimum: J the "
    "forward-difference Jacobian of the simulated angle, s^2 = SSE / (N - 7)"
)


@dataclass
class NozzleRecord:
    """Torque (N m) and measured angle (rad) at a fixed sample time (s)."""

    tau: np.ndarray
    beta: np.ndarray
    dt: float
    input_name: str = "tau"
    output_name: str = "beta"


# the bench tests' name for the strong-hysteresis nozzle of the models
strong_hysteresis_nozzle = strong_nozzle


def _bench_torque(samples: int, n_bits: int, clock: int, amplitude: float) -> np.ndarray:
    return prbs(samples, amplitude=amplitude, n_inputs=1, n_bits=n_bits, clock_samples=clock)[:, 0]


def bench_experiment(
    params: NozzleParameters,
    seed: int = DEFAULT_SEED,
    samples: int = BENCH_SAMPLES,
    n_bits: int = 12,
    clock: int = 2,
    range_deg: float = RANGE_DEG,
    noise_std: float = SENSOR_NOISE,
    torque_limit: float = DEFAULT_TORQUE_LIMIT,
) -> NozzleRecord:
    """Simulate the bench test of a nozzle and return the decimated record.

    Parameters
    ----------
    params : NozzleParameters
        The nozzle on the bench (the truth).
    seed : int
        Seed of the sensor noise.
    samples : int
        Record length at Ts = 0.008 s (7476 as in the paper).
    n_bits, clock : int
        PRBS register length and bit length in 0.008 s samples (12 bits, 16 ms: flat spectrum
        to about 30 Hz, past the joint's resonance near 12 Hz).
    range_deg : float
        The PRBS amplitude is scaled so that the angle peaks at this value.
    noise_std : float
        Angle sensor noise at the bench rate, rad.
    torque_limit : float
        Actuator torque limit, N m.
    """
    tau, angle = bench_motion(params, samples, n_bits, clock, range_deg, torque_limit)
    return NozzleRecord(tau, acquire(angle, seed, noise_std), NOZZLE_DT)


def bench_motion(
    params: NozzleParameters,
    samples: int = BENCH_SAMPLES,
    n_bits: int = 12,
    clock: int = 2,
    range_deg: float = RANGE_DEG,
    torque_limit: float = DEFAULT_TORQUE_LIMIT,
) -> tuple[np.ndarray, np.ndarray]:
    """The bench's torque at Ts = 0.008 s (N m) and the true angle at the bench rate (rad).

    The noise-free half of :func:`bench_experiment` (same arguments); :func:`acquire` adds the
    rest, so that many noise seeds can share one simulation.
    """
    if samples < 50:
        raise ValueError(f"samples must be at least 50, got {samples}")
    if not range_deg > 0:
        raise ValueError(f"range_deg must be positive, got {range_deg!r}")
    # Scale the amplitude on the decimated model (cheap), three passes for the nonlinearity.
    amplitude = params.small_signal_stiffness * np.radians(range_deg) * 0.3
    for _ in range(3):
        peak = np.max(np.abs(simulate_nozzle(params, _bench_torque(samples, n_bits, clock, amplitude))))
        amplitude *= np.radians(range_deg) / peak
    amplitude = min(amplitude, torque_limit)  # the actuator cannot do more
    tau = _bench_torque(samples, n_bits, clock, amplitude)
    return tau, _bench_rate_angle(params, tau, torque_limit)


def _bench_rate_angle(joint: NozzleParameters, tau: np.ndarray, torque_limit: float) -> np.ndarray:
    """The joint's true angle at the bench rate (rad) under the torque held over each Ts sample."""
    return simulate_nozzle(
        joint, np.repeat(tau, DECIMATION), dt=NOZZLE_DT / DECIMATION, substeps=1, torque_limit=torque_limit
    )


def acquire(angle: np.ndarray, seed: int = DEFAULT_SEED, noise_std: float = SENSOR_NOISE) -> np.ndarray:
    """The measured angle at Ts: sensor noise (std ``noise_std`` rad, seeded) added at the bench
    rate, then the anti-alias FIR filter (zero phase) and decimation by 20."""
    measured = angle + noise_std * np.random.default_rng(seed).standard_normal(angle.size)
    return scipy.signal.decimate(measured, DECIMATION, ftype="fir", zero_phase=True)


def acquisition_bias(
    tau: np.ndarray,
    jbk: tuple[float, float, float],
    noise_std: float = 0.0,
    draws: int = 1,
    seed: int = DEFAULT_SEED,
) -> dict[str, float]:
    """The bias of DSR_e's J, b, k that the bench's acquisition chain causes, by simulation.

    The anti-alias filter of :func:`acquire` changes the motion in the band the ZOH model
    describes (about -0.05 % on J, +0.14 % on b, -0.07 % on k for Table 1's joint: ten to thirty
    standard errors of the noise), and the innovations form then trades that mismatch against
    the sensor noise, so the bias depends on the noise level too. The linear joint with the
    estimated J, b, k is driven by the record's torque at the bench rate, acquired ``draws``
    times with sensor noise of ``noise_std`` (seeded) and identified again; the mean change is
    the bias at the estimate (corrected estimate: estimate minus it; what remains is second order
    in the estimate's error, plus the draws' scatter, 1/draws of the noise's variance).

    Parameters
    ----------
    tau : array, shape (T,)
        The record's torque at Ts = 0.008 s, N m.
    jbk : (float, float, float)
        Estimated J (kg m^2), b (N m s/rad), k (N m/rad).
    noise_std : float
        Sensor noise of the record at the bench rate, rad (0: one noise-free acquisition).
    draws : int
        Simulated acquisitions averaged (used when ``noise_std`` > 0).
    seed : int
        Seed of the simulated noise.

    Returns
    -------
    dict
        ``{"J", "b", "k"}``: mean identified from the simulated acquisitions minus ``jbk``.
    """
    fast = _bench_rate_angle(NozzleParameters.linear(*jbk), tau, np.inf)
    seeds = np.random.SeedSequence(seed).generate_state(draws if noise_std > 0 else 1)
    found = []
    for draw_seed in seeds:
        tf = second_order_parameters(
            dsr_e(tau, acquire(fast, int(draw_seed), noise_std), NOZZLE_DT, order=2).model
        )
        found.append([tf["J"], tf["b"], tf["k"]])
    mean = np.mean(found, axis=0)
    return {key: float(m - value) for key, m, value in zip(("J", "b", "k"), mean, jbk, strict=True)}


def validation_experiment(params: NozzleParameters, seed: int = DEFAULT_SEED + 1) -> NozzleRecord:
    """A second bench record the fit never sees: 11-bit PRBS with a 24 ms clock, 20 s."""
    return bench_experiment(params, seed=seed, samples=2500, n_bits=11, clock=3)


def read_nozzle_record(
    path: str | Path, input_name: str = "tau", output_name: str = "beta", dt: float | None = None
) -> NozzleRecord:
    """A torque -> angle record from CSV, checked as the fit and the validation need it."""
    data, dt = read_columns(path, [input_name, output_name], dt)
    try:
        check_torque_record(data[:, 0], data[:, 1], names=(input_name, output_name))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return NozzleRecord(data[:, 0], data[:, 1], dt, input_name, output_name)


def write_nozzle_record(path: str | Path, record: NozzleRecord) -> None:
    """Write a record as CSV with columns t, torque, angle (atomically)."""
    with atomic_write(path) as fh:
        names = [record.input_name, record.output_name]
        write_columns(fh, record.dt, names, np.column_stack([record.tau, record.beta]))


@dataclass
class NozzleIdentification:
    model: NozzleModel
    subspace: SubspaceResult
    bouc_wen: BoucWenFit
    linear_uncertainty: BootstrapUncertainty | None = None


def _finite_or_none(values: dict[str, float]) -> dict[str, float | None]:
    """JSON has no inf: an undetermined parameter's standard error is written as null."""
    return {key: (float(v) if np.isfinite(v) else None) for key, v in values.items()}


def identify_nozzle(
    record: NozzleRecord,
    seed: int = 0,
    workers: int = 2,
    normalization_A: float = DEFAULT_NORMALIZATION_A,
    replicates: int = DEFAULT_REPLICATES,
    bench_noise: float | None = None,
) -> NozzleIdentification:
    """DSR_e second-order linear model (as in the paper, for J, b, k) and the Bouc-Wen joint fit.

    With the standard errors of J, b, k from a residual bootstrap of ``replicates`` records
    (:func:`dsr_e_uncertainty`, seeded by ``seed``; 0: none) and those of the Bouc-Wen joint's
    normalized parameters from the fit's regression covariance, both in the model's
    ``uncertainty`` blocks. ``bench_noise`` (rad at the bench rate): the record comes through the
    embedded bench's acquisition chain (:func:`acquire`) with this sensor noise; the chain's bias
    on J, b, k is then removed (:func:`acquisition_bias`, ``BIAS_DRAWS`` simulated acquisitions,
    their scatter added to the covariance); the discrete model stays what the data give.
    """
    check_torque_record(record.tau, record.beta, names=(record.input_name, record.output_name))
    subspace = dsr_e(record.tau, record.beta, record.dt, order=2)
    linear = subspace.model
    tf = second_order_parameters(linear)
    bias = None
    if bench_noise is not None:
        bias = acquisition_bias(record.tau, (tf["J"], tf["b"], tf["k"]), bench_noise, BIAS_DRAWS, seed)
        tf = {**tf, **{key: tf[key] - bias[key] for key in bias}}
    boot = None
    if replicates:
        boot = dsr_e_uncertainty(
            record.tau, record.beta, record.dt, subspace, replicates=replicates, seed=seed, workers=workers
        )
    if boot is not None and bias is not None:
        boot = dataclasses.replace(
            boot,
            estimate=np.array([tf["J"], tf["b"], tf["k"]]),
            covariance=boot.covariance * (1 + 1 / BIAS_DRAWS),
            method=f"{boot.method}; J, b, k corrected for the bench's acquisition chain (bias "
            f"averaged over {BIAS_DRAWS} simulated acquisitions), covariance times 1 + 1/{BIAS_DRAWS} "
            "for their scatter",
        )
    bw = fit_bouc_wen(
        record.tau, record.beta, record.dt, seed=seed, workers=workers, normalization_A=normalization_A
    )
    sim_linear = linear.simulate(record.tau[:, None])[:, 0]
    fit = {
        "samples": int(record.tau.size),
        "dsr_e": {
            "order": subspace.order,
            "past_horizon": subspace.past_horizon,
            "future_horizon": subspace.future_horizon,
            "singular_values": [float(v) for v in subspace.singular_values],
            "transfer_function": {"numerator": tf["numerator"], "denominator": tf["denominator"]},
            "natural_frequency_hz": tf["natural_frequency_hz"],
            "resonance_frequency_hz": tf["resonance_frequency_hz"],
            "damping_ratio": tf["damping_ratio"],
            "fit_percent": float(fit_percent(record.beta, sim_linear)),
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
                    },
                }
            ),
        },
        "bouc_wen": {
            "determined": bw.determined,
            "reason": bw.reason,
            "normalized": bw.normalized,
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
    """The joint's angle under the record's torque, with the RK4 step its motion needs."""
    amplitude = max(float(np.max(np.abs(record.beta))), 1e-12)
    substeps = recommended_substeps(joint, record.dt, amplitude)
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
) -> tuple[NozzleIdentification, dict[str, NozzleRecord]]:
    """The embedded bench test of a nozzle: identification and validation records.

    ``truth``: ``"table1"`` (Table 1's Bouc-Wen nozzle, the packaged ``nozzle_identified.json``)
    or ``"strong"`` (:func:`strong_hysteresis_nozzle`, ``nozzle_strong_identified.json``). The
    model's ``fit`` carries the validation figures; wall time is left out so that the same seed
    gives the same model file.
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
    )
    ident.model.fit["bouc_wen"].pop("seconds")
    ident.model.fit["validation_record"] = validate_nozzle(ident.model, records["validation"])
    described = {
        "table1": "VLS nozzle paper, Table 1 nonlinear row",
        "strong": "strong-hysteresis nozzle (yields within +-3 deg; not VLS data)",
    }
    ident.model.fit["truth"] = f"{described[truth]}; embedded bench test, seed {seed}"
    return ident, records
