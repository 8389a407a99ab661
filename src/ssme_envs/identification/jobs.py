"""Identification jobs: identify the engine or the nozzle, validate an engine model, into a directory.

The public functions are re-exported by :mod:`ssme_envs.pipelines`. Each reads and checks its
records first (ValueErrors naming the file), then writes through
:func:`ssme_envs.outputs.output_directory` (a fresh directory swapped in for ``out_dir``, locked).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ssme_envs.models.statespace import ENGINE_INPUTS, ENGINE_OUTPUTS
from ssme_envs.outputs import output_directory

Progress = Callable[[str], None]


def _silent(_: str) -> None:
    pass


def _read(reader: Callable[..., Any], path: Path, *args: Any) -> Any:
    """``reader(path, *args)``, with the csv module's own errors (a field over its size limit,
    ...) as a ValueError naming the file."""
    try:
        return reader(path, *args)
    except csv.Error as exc:
        raise ValueError(f"{path}: not a readable CSV record ({exc})") from None


def _check_same_dt(path: Path, dt: float, reference: float, what: str) -> None:
    if abs(dt - reference) > 1e-9 * reference:
        raise ValueError(f"{path}: sample time {dt:g} s differs from the {what}'s {reference:g} s")


def _check_record(path: Path, record: Any) -> None:
    """Refuse a record on which SEE or fit cannot be computed (zero, constant, huge, NaN)."""
    from ssme_envs.identification.records import check_validation_record

    check_validation_record(record.u, record.y, record.input_names, record.output_names, path)


def _scores(model: Any, record: Any, path: Path) -> dict:
    """SEE and fit of ``model`` on ``record``; ValueError when a figure comes out NaN or inf (the
    model's prediction overflowed)."""
    from ssme_envs.identification.metrics import finite_validation

    return finite_validation(model, record.u, record.y, str(path))


@dataclass
class EngineRun:
    """What :func:`identify_engine` wrote under ``out_dir``.

    ``levels`` holds the embedded experiment's power levels (empty for a record); ``identified``
    and ``validation`` the identification of a record (None for the embedded experiment).
    """

    report: Path
    seconds: float
    levels: list[Any] = field(default_factory=list)
    identified: Any = None
    validation: dict[str, Any] = field(default_factory=dict)


def engine_embedded_into(work: Path, seed: int | None, options: dict[str, Any]) -> tuple[list[Any], Path]:
    """The embedded experiment at the five power levels, written into ``work``."""
    from ssme_envs.identification import pipeline, report
    from ssme_envs.models.engine import TruthConfig

    seed = pipeline.DEFAULT_SEED if seed is None else seed
    config = TruthConfig()
    work.mkdir(parents=True, exist_ok=True)
    results = pipeline.run_default(seed=seed, config=config, options=options)
    (work / "data").mkdir(exist_ok=True)
    for r in results:
        r.identified.model.save(work / f"model_{r.power_percent}.json")
        for name, rec in r.records.items():
            pipeline.write_record(work / "data" / f"engine_{r.power_percent}_{name}.csv", rec)
    note = (
        f"valve backlash {config.backlash:g}, valve stiction {config.stiction:g} and sensor noise "
        f"(std {list(config.sensor_noise)}) in front of and behind it (normalized units; our assumptions)"
    )
    return results, report.write_default_report(work, results, seed, note, config.backlash)


def identify_engine(
    out_dir: str | Path,
    data: Path | None = None,
    *,
    inputs: Sequence[str] = ENGINE_INPUTS,
    outputs: Sequence[str] = ENGINE_OUTPUTS,
    dt: float | None = None,
    validate: Path | None = None,
    seed: int | None = None,
    **options: Any,
) -> EngineRun:
    """Identify an alpha-canonical engine model; write its model(s), report.md and figures.

    Parameters
    ----------
    out_dir : str or Path
        Output directory (replaced when the run succeeds).
    data : Path, optional
        CSV record with ``inputs`` and ``outputs`` columns; default: the embedded experiment on
        the truth at the five Table I power levels (seeded by ``seed``).
    dt : float, optional
        Sample time, for records without a 't' column.
    validate : Path, optional
        A second record to validate on (same columns and sample time).
    **options
        For :func:`ssme_envs.identification.pipeline.identify_record`: method, asymmetric,
        max_index, rank_tol, indices.

    Returns
    -------
    EngineRun
    """
    from ssme_envs.identification import pipeline, report
    from ssme_envs.identification.structure import DEFAULT_RANK_TOL

    start = time.perf_counter()
    out_dir = Path(out_dir)
    if data is None:
        with output_directory(out_dir) as work:
            levels, path = engine_embedded_into(work, seed, options)
        return EngineRun(out_dir / path.name, time.perf_counter() - start, levels=levels)
    records = {"identification": _read(pipeline.read_record, data, tuple(inputs), tuple(outputs), dt)}
    _check_record(data, records["identification"])
    if validate is not None:  # refuse a bad validation record before the identification runs
        records["validation"] = _read(pipeline.read_record, validate, tuple(inputs), tuple(outputs), dt)
        _check_same_dt(validate, records["validation"].dt, records["identification"].dt, "data")
        _check_record(validate, records["validation"])
    with output_directory(out_dir, {"data": data, "validate": validate}) as work:
        ident = pipeline.identify_record(records["identification"], **options)
        validation = {"identification": ident.model.fit["identification_record"]}
        if validate is not None:
            validation["validation"] = _scores(ident.model, records["validation"], validate)
            ident.model.fit["validation_record"] = validation["validation"]
        ident.model.fit["data"] = str(data)
        ident.model.save(work / "model.json")
        rank_tol = options.get("rank_tol", DEFAULT_RANK_TOL)
        report.write_record_report(work, ident.model, records, validation, ident, rank_tol)
    return EngineRun(
        out_dir / "report.md", time.perf_counter() - start, identified=ident, validation=validation
    )


@dataclass
class NozzleRun:
    """What :func:`identify_nozzle` wrote: the identification and the report's path."""

    identified: Any
    report: Path
    seconds: float


def nozzle_into(work: Path, records: dict[str, Any] | None, seed: int | None, workers: int,
                 normalization_a: float | None, note: str | None, progress: Progress,
                 bootstrap_noise: str = "white") -> Any:  # fmt: skip
    """Identify the nozzle (the embedded bench test when ``records`` is None) into ``work``."""
    from ssme_envs.identification import nozzle_pipeline as npipe
    from ssme_envs.identification.nozzle_report import write_nozzle_report
    from ssme_envs.models.nozzle import BENCH_RATE_HZ, NOZZLE_DT, published_nozzle

    seed = npipe.DEFAULT_SEED if seed is None else seed
    normalization_a = npipe.DEFAULT_NORMALIZATION_A if normalization_a is None else normalization_a
    work.mkdir(parents=True, exist_ok=True)
    truth = None
    if records is None:
        truth = published_nozzle("bouc_wen")
        bench = (
            f"{BENCH_RATE_HZ / 1000:g} kHz acquisition with sensor noise (std {npipe.SENSOR_NOISE:g} rad), "
            f"decimated to {NOZZLE_DT:g} s "
            f"(N = {npipe.BENCH_SAMPLES}, {npipe.BENCH_SAMPLES * NOZZLE_DT:.1f} s)"
        )
        note = (
            "Bench data simulated from the paper's Table 1 Bouc-Wen nozzle (the truth of this report): "
            f"a PRBS torque keeping the angle within +-{npipe.RANGE_DEG:g} deg, {bench}. Seed {seed}."
        )
        progress(f"simulating the bench test ({bench}) and identifying ...")
        ident, records = npipe.run_default(seed, workers, normalization_a, bootstrap_noise=bootstrap_noise)
    else:
        progress(
            "identifying: DSR_e linear model, then the Bouc-Wen joint (evolutionary search, least squares)"
        )
        ident = npipe.identify_nozzle(
            records["identification"], seed=seed, workers=workers, normalization_A=normalization_a,
            progress=progress, bootstrap_noise=bootstrap_noise,
        )  # fmt: skip
        if "validation" in records:
            ident.model.fit["validation_record"] = npipe.validate_nozzle(ident.model, records["validation"])
    ident.model.save(work / "model.json")
    if truth is not None:
        (work / "data").mkdir(exist_ok=True)
        for name, rec in records.items():
            npipe.write_nozzle_record(work / "data" / f"nozzle_{name}.csv", rec)
    write_nozzle_report(work, ident, records, truth, note or "")
    return ident


def identify_nozzle(
    out_dir: str | Path,
    data: Path | None = None,
    *,
    input_column: str = "tau",
    output_column: str = "beta",
    dt: float | None = None,
    validate: Path | None = None,
    workers: int = 2,
    seed: int | None = None,
    normalization_a: float | None = None,
    progress: Progress = _silent,
    bootstrap_noise: str = "white",
) -> NozzleRun:
    """Identify the movable nozzle (DSR_e linear model and Bouc-Wen joint); write model.json,
    report.md and figures.

    Parameters
    ----------
    out_dir : str or Path
        Output directory (replaced when the run succeeds).
    data : Path, optional
        CSV record of torque (N m) and angle (rad); default: the embedded bench test on Table 1's
        Bouc-Wen nozzle (seeded by ``seed``, which also seeds the search).
    validate : Path, optional
        A second record to validate on.
    normalization_a : float, optional
        The A that fixes the Table 1 form of the Bouc-Wen joint (default 0.35).
    bootstrap_noise : {"white", "innovations", "sieve"}
        How the bootstrap of J, b, k's standard errors resamples the noise: white (sensor noise
        that is white), through DSR_e's noise model, or an AR sieve of the linear model's output
        error (coloured sensor noise); see
        (:func:`~ssme_envs.identification.nozzle_uncertainty.dsr_e_uncertainty`).

    Returns
    -------
    NozzleRun
    """
    from ssme_envs.identification import nozzle_pipeline as npipe
    from ssme_envs.identification.nozzle_uncertainty import check_noise_model

    check_noise_model(bootstrap_noise, "bootstrap_noise")  # before the record is read
    start = time.perf_counter()
    out_dir = Path(out_dir)
    records, note = None, None
    if data is not None:
        records = {"identification": _read(npipe.read_nozzle_record, data, input_column, output_column, dt)}
        if validate is not None:
            check = _read(npipe.read_nozzle_record, validate, input_column, output_column, dt)
            _check_same_dt(validate, check.dt, records["identification"].dt, "data")
            records["validation"] = check
        note = f"Data: {data}."
    with output_directory(out_dir, {"data": data, "validate": validate}) as work:
        ident = nozzle_into(work, records, seed, workers, normalization_a, note, progress, bootstrap_noise)
    return NozzleRun(ident, out_dir / "report.md", time.perf_counter() - start)


def load_engine_model(path: Path) -> Any:
    """An engine model.json; ValueError naming the file for anything it cannot be read as."""
    from ssme_envs.models.statespace import AlphaCanonicalModel

    try:
        return AlphaCanonicalModel.load(path)
    except RecursionError:
        raise ValueError(f"{path}: nested too deeply to be a model") from None
    except (TypeError, KeyError, IndexError, AttributeError, OverflowError) as exc:
        raise ValueError(f"{path}: not an engine model ({type(exc).__name__}: {exc})") from None


def validate_engine(out_dir: str | Path, model: Path, data: Sequence[Path], dt: float | None = None) -> dict:
    """SEE, fit and plots of an engine model.json on records, in report.md under ``out_dir``.

    Every record is read and checked before anything is written. Returns ``{label: scores}``,
    labels being the file stems made unique (two files run.csv: run and run_2).
    """
    from ssme_envs.identification import pipeline, report
    from ssme_envs.identification.records import record_labels

    engine = load_engine_model(model)
    labels = record_labels(data)
    records = {}
    for path, label in zip(data, labels, strict=True):
        record = _read(pipeline.read_record, path, engine.input_names, engine.output_names, dt)
        _check_same_dt(path, record.dt, engine.dt, "model")
        _check_record(path, record)
        records[label] = record
    validation = {
        label: _scores(engine, records[label], path) for path, label in zip(data, labels, strict=True)
    }
    inputs = {"model": model, **{f"data[{i}]": path for i, path in enumerate(data)}}
    with output_directory(out_dir, inputs) as work:
        report.write_record_report(work, engine, records, validation)
    return validation


__all__ = [
    "EngineRun",
    "NozzleRun",
    "engine_embedded_into",
    "identify_engine",
    "identify_nozzle",
    "load_engine_model",
    "nozzle_into",
    "validate_engine",
]
