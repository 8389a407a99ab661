"""The ``identify engine``, ``identify nozzle`` and ``validate engine`` commands of ``ssme-envs``.

Each checks its options and reads its records first, then writes into :func:`output_directory`
(a fresh directory swapped in for --out when the command succeeds). Errors are ValueErrors
whose message is the one ``error:`` line that :func:`ssme_envs.cli.main` prints.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ssme_envs.cli_checks import check_finite, check_seed, check_workers, os_error_text


def names(text: str, option: str) -> tuple[str, ...]:
    """Comma-separated names; ValueError for an empty one."""
    values = tuple(n.strip() for n in text.split(","))
    if not all(values):
        raise ValueError(f"{option} must be a comma-separated list of names, got {text!r}")
    return values


def indices(text: str) -> tuple[int, ...]:
    """``--indices``: comma-separated positive integers."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--indices must be comma-separated positive integers, got {text!r}") from None
    if any(v < 1 for v in values):
        raise ValueError(f"--indices must be positive integers, got {text!r}")
    return values


@contextmanager
def output_directory(args: argparse.Namespace) -> Iterator[Path]:
    """The directory a command writes into.

    ``args.work`` when set (a folder of ``report``'s own directory), else a fresh directory from
    :func:`ssme_envs.outputs.run_directory` that replaces ``args.out`` when the block succeeds.
    File-system errors inside name ``args.out``, not the temporary directory.
    """
    work = getattr(args, "work", None)
    if work is not None:
        work.mkdir(parents=True, exist_ok=True)
        yield work
        return
    from ssme_envs.outputs import MARKER, run_directory

    earlier = (Path(args.out) / MARKER).is_file()
    with run_directory(args.out) as work:
        try:
            yield work
        except OSError as exc:
            raise ValueError(os_error_text(exc).replace(str(work), str(args.out))) from None
    if earlier:
        print(f"replaced the earlier run in {args.out}", file=sys.stderr)


def _read(reader: Callable[..., Any], path: Path, *args: Any) -> Any:
    """``reader(path, *args)``, with the csv module's own errors (a field over its size limit,
    ...) as a ValueError naming the file."""
    try:
        return reader(path, *args)
    except csv.Error as exc:
        raise ValueError(f"{path}: not a readable CSV record ({exc})") from None


def _needs_data(args: argparse.Namespace, flags: tuple[str, ...], embedded: str) -> None:
    for flag in flags:
        if getattr(args, flag) is not None:
            raise ValueError(f"--{flag} needs --data (the embedded {embedded} sets its own)")


def _check_same_dt(path: Path, dt: float, reference: float, what: str) -> None:
    if abs(dt - reference) > 1e-9 * reference:
        raise ValueError(f"{path}: sample time {dt:g} s differs from the {what}'s {reference:g} s")


def _check_record(path: Path, record: Any) -> None:
    """Refuse a record on which SEE or fit cannot be computed (zero, constant, huge, NaN)."""
    from ssme_envs.identification.records import check_validation_record

    check_validation_record(record.u, record.y, record.input_names, record.output_names, path)


def _check_scores(path: Path, scores: dict, output_names: Sequence[str]) -> None:
    """Refuse SEE or fit values that came out NaN or inf (the model's prediction overflowed)."""
    for predictor, figures in scores.items():
        for metric, values in figures.items():
            for name, value in zip(output_names, values, strict=True):
                if not math.isfinite(value):
                    raise ValueError(
                        f"{path}: the {predictor}'s {metric} for output '{name}' is {value} "
                        "(its prediction overflows on this record)"
                    )


def _engine_default(args: argparse.Namespace, options: dict[str, Any]) -> int:
    from ssme_envs.identification import pipeline, report
    from ssme_envs.models.engine import TruthConfig

    _needs_data(args, ("validate", "dt", "indices"), "experiment")
    seed = pipeline.DEFAULT_SEED if args.seed is None else args.seed
    config = TruthConfig()
    start = time.perf_counter()
    with output_directory(args) as out:
        results = pipeline.run_default(seed=seed, config=config, options=options)
        (out / "data").mkdir(exist_ok=True)
        for r in results:
            r.identified.model.save(out / f"model_{r.power_percent}.json")
            for name, rec in r.records.items():
                pipeline.write_record(out / "data" / f"engine_{r.power_percent}_{name}.csv", rec)
            see = r.validation["validation_low_frequency"]["model"]["see"]
            if r.identified.search is not None and r.identified.search.close:
                print(f"{r.power_percent:>3d} % power: {r.identified.search.summary()}")
            print(
                f"{r.power_percent:>3d} % power: indices {list(r.identified.model.observability_indices)}, "
                f"lambda {[round(float(v), 4) for v in r.identified.model.lam]}, model SEE on the "
                f"low-frequency test {[round(v, 4) for v in see]}"
            )
        note = (
            f"valve backlash {config.backlash:g}, valve stiction {config.stiction:g} and sensor noise "
            f"(std {list(config.sensor_noise)}) in front of and behind it (normalized units; our assumptions)"
        )
        path = report.write_default_report(out, results, seed, note)
    print(
        f"identified {len(results)} power levels in {time.perf_counter() - start:.2f} s; "
        f"report: {args.out / path.name}"
    )
    return 0


def identify_engine(args: argparse.Namespace) -> int:
    """``ssme-envs identify engine``: the embedded experiment, or a record from --data."""
    import numpy as np

    from ssme_envs.identification import pipeline, report
    from ssme_envs.identification.metrics import validate

    check_finite("--rank-tol", args.rank_tol)
    check_finite("--dt", args.dt, positive=True)
    check_seed(args.seed)
    options: dict[str, Any] = {
        "method": args.method,
        "asymmetric": not args.symmetric,
        "max_index": args.max_index,
        "rank_tol": args.rank_tol,
    }
    if args.indices:
        options["indices"] = indices(args.indices)
    if args.data is None:
        return _engine_default(args, options)

    if args.seed is not None:
        raise ValueError("--seed applies to the embedded experiment only (no --data)")
    inputs, outputs = names(args.inputs, "--inputs"), names(args.outputs, "--outputs")
    record = _read(pipeline.read_record, args.data, inputs, outputs, args.dt)
    _check_record(args.data, record)
    check = None
    if args.validate is not None:  # refuse a bad validation record before the identification runs
        check = _read(pipeline.read_record, args.validate, inputs, outputs, args.dt)
        _check_same_dt(args.validate, check.dt, record.dt, "data")
        _check_record(args.validate, check)
    with output_directory(args) as out:
        ident = pipeline.identify_record(record, **options)
        records = {"identification": record}
        validation = {"identification": ident.model.fit["identification_record"]}
        if check is not None:
            records["validation"] = check
            with np.errstate(all="ignore"):  # an overflow is refused just below, without warnings
                validation["validation"] = validate(ident.model, check.u, check.y)
            _check_scores(args.validate, validation["validation"], outputs)
            ident.model.fit["validation_record"] = validation["validation"]
        ident.model.fit["data"] = str(args.data)
        ident.model.save(out / "model.json")
        report.write_record_report(out, ident.model, records, validation, ident, args.rank_tol)
    model = ident.model
    if ident.search is not None:
        print(ident.search.summary())
    print(
        f"indices {list(model.observability_indices)}, lambda {[round(float(v), 4) for v in model.lam]}, "
        f"model SEE {[round(v, 4) for v in validation['identification']['model']['see']]}"
    )
    print(f"wrote {args.out / 'model.json'} and {args.out / 'report.md'}")
    return 0


def identify_nozzle(args: argparse.Namespace) -> int:
    """``ssme-envs identify nozzle``: the embedded bench test, or a record from --data."""
    from ssme_envs.identification import nozzle_pipeline as npipe
    from ssme_envs.identification.nozzle_report import write_nozzle_report
    from ssme_envs.models.nozzle import BENCH_RATE_HZ, NOZZLE_DT, published_nozzle

    check_workers(args.workers)
    check_finite("--normalization-a", args.normalization_a, positive=True)
    check_finite("--dt", args.dt, positive=True)
    check_seed(args.seed)
    seed = npipe.DEFAULT_SEED if args.seed is None else args.seed
    truth = None
    start = time.perf_counter()
    if args.data is None:
        _needs_data(args, ("validate", "dt"), "bench test")
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
    else:
        first = _read(npipe.read_nozzle_record, args.data, args.input, args.output, args.dt)
        records = {"identification": first}
        if args.validate is not None:
            check = _read(npipe.read_nozzle_record, args.validate, args.input, args.output, args.dt)
            _check_same_dt(args.validate, check.dt, records["identification"].dt, "data")
            records["validation"] = check
        note = f"Data: {args.data}."
    with output_directory(args) as out:
        if args.data is None:
            print(f"simulating the bench test ({bench}) and identifying ...")
            ident, records = npipe.run_default(seed, args.workers, args.normalization_a)
        else:
            print("identifying: DSR_e linear model, then the Bouc-Wen joint (evolutionary search, "
                  "least squares)")  # fmt: skip
            ident = npipe.identify_nozzle(
                records["identification"],
                seed=seed,
                workers=args.workers,
                normalization_A=args.normalization_a,
            )
            if "validation" in records:
                ident.model.fit["validation_record"] = npipe.validate_nozzle(
                    ident.model, records["validation"]
                )
        ident.model.save(out / "model.json")
        if args.data is None:
            (out / "data").mkdir(exist_ok=True)
            for name, rec in records.items():
                npipe.write_nozzle_record(out / "data" / f"nozzle_{name}.csv", rec)
        write_nozzle_report(out, ident, records, truth, note)
    lin = ident.model.linear
    print(f"linear: J {lin['J']:.2f} kg m^2, b {lin['b']:.1f} N m s/rad, k {lin['k']:.4g} N m/rad")
    print(f"Bouc-Wen: {ident.bouc_wen.reason}")
    print(
        f"done in {time.perf_counter() - start:.1f} s; wrote {args.out / 'model.json'} and "
        f"{args.out / 'report.md'}"
    )
    return 0


def load_engine_model(path: Path) -> Any:
    """An engine model.json; ValueError naming the file for anything it cannot be read as."""
    from ssme_envs.models.statespace import AlphaCanonicalModel

    try:
        return AlphaCanonicalModel.load(path)
    except RecursionError:
        raise ValueError(f"{path}: nested too deeply to be a model") from None
    except (TypeError, KeyError, IndexError, AttributeError, OverflowError) as exc:
        raise ValueError(f"{path}: not an engine model ({type(exc).__name__}: {exc})") from None


def validate_engine(args: argparse.Namespace) -> int:
    """``ssme-envs validate engine``: SEE, fit and plots of a model.json on records."""
    import numpy as np

    from ssme_envs.identification import pipeline, report
    from ssme_envs.identification.metrics import validate
    from ssme_envs.identification.records import record_labels

    check_finite("--dt", args.dt, positive=True)
    model = load_engine_model(args.model)
    labels = record_labels(args.data)  # two files called run.csv become run and run_2
    records = {}
    for path, label in zip(args.data, labels, strict=True):  # every record is read and checked first
        record = _read(pipeline.read_record, path, model.input_names, model.output_names, args.dt)
        _check_same_dt(path, record.dt, model.dt, "model")
        _check_record(path, record)
        records[label] = record
    validation = {}
    for path, label in zip(args.data, labels, strict=True):
        with np.errstate(all="ignore"):  # an overflow is refused just below, without warnings
            validation[label] = validate(model, records[label].u, records[label].y)
        _check_scores(path, validation[label], model.output_names)
        see = [round(v, 5) for v in validation[label]["model"]["see"]]
        named = "" if label == path.stem else f" (reported as {label})"
        print(f"{path}{named}: model SEE {see}")
    with output_directory(args) as out:
        report.write_record_report(out, model, records, validation)
    print(f"report: {args.out / 'report.md'}")
    return 0


__all__ = ["identify_engine", "identify_nozzle", "indices", "names", "output_directory", "validate_engine"]
