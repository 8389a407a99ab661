"""Engine identification pipeline: records in, identified models and validation figures out.

Each stage is a function with plain data in and out:
``default_experiment`` (truth simulation) -> ``EngineRecord`` -> ``identify_record`` ->
``AlphaCanonicalModel`` -> ``validate``. ``read_record`` / ``write_record`` move records
through CSV files (header row, a ``t`` column in seconds or an explicit ``dt``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ssme_envs.identification.alpha_canonical import Identification, identify
from ssme_envs.identification.metrics import finite_validation, validate
from ssme_envs.identification.records import read_columns, write_columns
from ssme_envs.models.engine import ENGINE_DT, POWER_LEVELS, TruthConfig, published_model, simulate
from ssme_envs.models.statespace import ENGINE_INPUTS, ENGINE_OUTPUTS, AlphaCanonicalModel
from ssme_envs.outputs import atomic_write
from ssme_envs.signals import prbs, step_ramp_test_signal

DEFAULT_SEED = 2024
PRBS_AMPLITUDE = 0.01  # normalized valve travel; figure 3 of the paper stays within +-0.02
IDENTIFICATION_PERIODS = 8  # 127-bit periods: 1016 samples, 40.6 s
VALIDATION_PERIODS = 2


@dataclass
class EngineRecord:
    """An input/output record: deviations from the operating point, one row per sample."""

    u: np.ndarray
    y: np.ndarray
    dt: float
    input_names: tuple[str, ...] = ENGINE_INPUTS
    output_names: tuple[str, ...] = ENGINE_OUTPUTS

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.u.shape[0]) * self.dt


def read_record(
    path: str | Path,
    inputs: Sequence[str] = ENGINE_INPUTS,
    outputs: Sequence[str] = ENGINE_OUTPUTS,
    dt: float | None = None,
) -> EngineRecord:
    """Read an engine record from CSV; columns are chosen by name (see :func:`read_columns`)."""
    data, dt = read_columns(path, [*inputs, *outputs], dt)
    return EngineRecord(data[:, : len(inputs)], data[:, len(inputs) :], dt, tuple(inputs), tuple(outputs))


def write_record(path: str | Path, record: EngineRecord) -> None:
    """Write a record as CSV with columns t, inputs, outputs (atomically)."""
    with atomic_write(path) as fh:
        names = [*record.input_names, *record.output_names]
        write_columns(fh, record.dt, names, np.column_stack([record.u, record.y]))


def identify_record(record: EngineRecord, **options) -> Identification:
    """Identify an alpha-canonical model from a record; options go to :func:`identify`.

    The returned model's ``fit`` holds SEE and NRMSE fit of the filter and of the model on
    the identification record itself; ValueError where one comes out NaN or inf (a model whose
    simulation of the record overflows: :func:`~ssme_envs.identification.metrics.finite_validation`).
    """
    result = identify(
        record.u,
        record.y,
        record.dt,
        input_names=record.input_names,
        output_names=record.output_names,
        **options,
    )
    result.model.fit["identification_record"] = finite_validation(
        result.model, record.u, record.y, "the identification record"
    )
    return result


def default_experiment(
    power_percent: int, seed: int = DEFAULT_SEED, config: TruthConfig | None = None
) -> dict[str, EngineRecord]:
    """The embedded experiment on the truth at one power level.

    Returns records "identification" (8 periods of 127-bit PRBS, amplitude 0.01),
    "validation_prbs" (another primitive polynomial, 2 periods) and "validation_low_frequency"
    (the step and ramp test of figure 3), each with its own noise stream from ``seed``.
    """
    config = TruthConfig() if config is None else config
    truth = published_model(power_percent)
    commands = {
        "identification": prbs(127 * IDENTIFICATION_PERIODS, PRBS_AMPLITUDE),
        "validation_prbs": prbs(127 * VALIDATION_PERIODS, PRBS_AMPLITUDE, variant=1),
        "validation_low_frequency": step_ramp_test_signal(ENGINE_DT),
    }
    streams = np.random.SeedSequence([seed, power_percent]).spawn(len(commands))
    records = {}
    for (name, u), stream in zip(commands.items(), streams, strict=True):
        y, _ = simulate(truth, u, config, np.random.default_rng(stream))
        records[name] = EngineRecord(u, y, ENGINE_DT)
    return records


@dataclass
class LevelResult:
    """Identification and validation at one power level of the embedded experiment."""

    power_percent: int
    published: AlphaCanonicalModel
    identified: Identification
    records: dict[str, EngineRecord]
    validation: dict[str, dict[str, dict[str, list[float]]]]


def run_default(
    seed: int = DEFAULT_SEED,
    power_levels: Sequence[int] = POWER_LEVELS,
    config: TruthConfig | None = None,
    options: dict | None = None,
) -> list[LevelResult]:
    """Run the embedded experiment and identification at each power level.

    ``options`` go to :func:`identify` (method, asymmetric, max_index, rank_tol).
    """
    config = TruthConfig() if config is None else config
    results = []
    for power in power_levels:
        records = default_experiment(power, seed, config)
        ident = identify_record(records["identification"], **(options or {}))
        model = ident.model
        model.fit["power_percent"] = power
        model.fit["seed"] = seed
        model.fit["truth"] = {"model": f"NASA TM-104422 Table I, {power} % power", **asdict(config)}
        validation = {
            name: validate(model, rec.u, rec.y) for name, rec in records.items() if name != "identification"
        }
        model.fit.update(validation)
        results.append(LevelResult(power, published_model(power), ident, records, validation))
    return results
