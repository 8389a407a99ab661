"""The nozzle's torque -> angle record: simulated on the embedded bench (PRBS torque, sensor noise,
anti-alias filter and decimation, and the bias that chain puts on DSR_e's J, b, k and on the
Bouc-Wen fit's parameters) or read from and written to CSV. Apart from :mod:`.nozzle_pipeline`,
which identifies and validates from any such record, the bench's or a user's."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.signal

from ssme_envs.identification.bouc_wen import BoucWenFit, check_torque_record, fit_bouc_wen
from ssme_envs.identification.records import check_magnitudes, read_columns, write_columns
from ssme_envs.identification.subspace import dsr_e, second_order_parameters
from ssme_envs.models.nozzle import (
    BENCH_RATE_HZ,
    DEFAULT_TORQUE_LIMIT,
    NOZZLE_DT,
    NozzleParameters,
    simulate_nozzle,
    strong_nozzle,
)
from ssme_envs.outputs import atomic_write
from ssme_envs.signals import prbs

DEFAULT_SEED = 7
BENCH_SAMPLES = 7476  # the paper's N at Ts = 0.008 s (59.8 s)
DECIMATION = round(BENCH_RATE_HZ * NOZZLE_DT)  # 20
SENSOR_NOISE = 1e-4  # rad, std of the angle sensor at 2.5 kHz (an assumption: 0.006 deg)
RANGE_DEG = 3.0
# Angles in a record read from CSV stay within a quarter turn: a nozzle deflects a few degrees (the
# paper's +-3, the SSME gimbal's +-10.5), so an angle past 90 deg is a glitch or not in rad, and
# simulating the joint out there needs RK4 substeps without bound (1e5 rad asked for 9e5 a sample).
MAX_ANGLE = np.pi / 2


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


def bouc_wen_acquisition_bias(tau: np.ndarray, fit: BoucWenFit, seed: int, workers: int) -> dict[str, float]:
    """The bias of the Bouc-Wen fit's normalized parameters that the bench's acquisition chain
    causes, by simulation: the fitted joint driven by the record's torque at the bench rate,
    acquired without noise (:func:`acquire`) and fitted again as the record was; the change is
    the bias at the estimate. The fit is output error, so the noise adds no bias of its own to
    first order (one noise-free acquisition, unlike :func:`acquisition_bias`). Corrected
    estimate: the estimate minus it (:func:`~ssme_envs.identification.bouc_wen.remove_bias`);
    what remains is second order in the estimate's error.

    Parameters
    ----------
    tau : array, shape (T,)
        The record's torque at Ts = 0.008 s, N m.
    fit : BoucWenFit
        A determined fit of the record.
    seed, workers : int
        As the record's fit used them.
    """
    if not fit.determined:
        raise ValueError("only a determined fit has a joint to simulate")
    fast = _bench_rate_angle(fit.params, tau, np.inf)
    measured = acquire(fast, seed, 0.0)
    again = fit_bouc_wen(
        tau, measured, NOZZLE_DT, seed=seed, workers=workers, normalization_A=fit.normalization_A
    )
    return {name: again.normalized[name] - value for name, value in fit.normalized.items()}


def validation_experiment(params: NozzleParameters, seed: int = DEFAULT_SEED + 1) -> NozzleRecord:
    """A second bench record the fit never sees: 11-bit PRBS with a 24 ms clock, 20 s."""
    return bench_experiment(params, seed=seed, samples=2500, n_bits=11, clock=3)


def read_nozzle_record(
    path: str | Path, input_name: str = "tau", output_name: str = "beta", dt: float | None = None
) -> NozzleRecord:
    """A torque -> angle record from CSV, checked as the fit and the validation need it.

    Beyond :func:`check_torque_record`: values whose squares overflow float64
    (:func:`check_magnitudes`) and angles beyond ``MAX_ANGLE`` rad are refused, naming the column.

    Raises
    ------
    ValueError
        Naming the file and the problem.
    """
    data, dt = read_columns(path, [input_name, output_name], dt)
    check_magnitudes(data[:, :1], [input_name], "input", path)
    check_magnitudes(data[:, 1:], [output_name], "output", path)
    try:
        check_torque_record(data[:, 0], data[:, 1], names=(input_name, output_name))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    far = np.abs(data[:, 1]) > MAX_ANGLE
    if far.any():
        k = int(np.argmax(far))
        raise ValueError(
            f"{path}: output '{output_name}' reaches {data[k, 1]:.4g} at sample {k}, beyond "
            f"+-{MAX_ANGLE:.4g} rad ({np.degrees(MAX_ANGLE):g} deg) where no nozzle deflects: a glitch, "
            "or an angle not in rad?"
        )
    return NozzleRecord(data[:, 0], data[:, 1], dt, input_name, output_name)


def write_nozzle_record(path: str | Path, record: NozzleRecord) -> None:
    """Write a record as CSV with columns t, torque, angle (atomically)."""
    with atomic_write(path) as fh:
        names = [record.input_name, record.output_name]
        write_columns(fh, record.dt, names, np.column_stack([record.tau, record.beta]))
