"""The ``identify engine``, ``identify nozzle`` and ``validate engine`` commands of ``ssme-envs``.

Each handler checks its options, calls the library function of :mod:`ssme_envs.pipelines` (which
reads and checks the records, then writes into a fresh directory swapped in for --out) and prints
what it did. Errors are ValueErrors whose message is the one ``error:`` line that
:func:`ssme_envs.cli.main` prints.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ssme_envs.cli_checks import check_finite, check_seed, check_workers, positive_integers
from ssme_envs.outputs import holds_run


def names(text: str, option: str) -> tuple[str, ...]:
    """Comma-separated names; ValueError for an empty one."""
    values = tuple(n.strip() for n in text.split(","))
    if not all(values):
        raise ValueError(f"{option} must be a comma-separated list of names, got {text!r}")
    return values


def indices(text: str) -> tuple[int, ...]:
    """``--indices``: comma-separated positive integers."""
    return positive_integers("--indices", text)


@contextmanager
def noting_replacement(out: Path) -> Iterator[None]:
    """Say on stderr, after a successful run, that it replaced an earlier run in ``out``."""
    earlier = holds_run(out)
    yield
    if earlier:
        print(f"replaced the earlier run in {out}", file=sys.stderr)


def check_dt_option(value: float | None) -> None:
    """``--dt``: a positive number of seconds, from a nanosecond to a day (:data:`MIN_DT`,
    :data:`MAX_DT`)."""
    from ssme_envs.identification.records import MAX_DT, MIN_DT

    check_finite("--dt", value, positive=True)
    if value is not None and value > MAX_DT:
        raise ValueError(
            f"--dt must be at most {MAX_DT:g} s (a day): a slower record holds no dynamics, got {value:g}"
        )
    if value is not None and value < MIN_DT:
        raise ValueError(f"--dt must be at least {MIN_DT:g} s (a nanosecond), got {value:g}")


def _needs_data(args: argparse.Namespace, flags: tuple[str, ...], embedded: str) -> None:
    for flag in flags:
        if getattr(args, flag) is not None:
            raise ValueError(f"--{flag} needs --data (the embedded {embedded} sets its own)")


def _least_squares_note(model: Any, where: str) -> None:
    """Print a note where method "iv" kept the least-squares estimate of ``model`` (its
    uncertainty says so), naming the model by ``where``."""
    from ssme_envs.identification.covariance import least_squares_kept, least_squares_note

    if model.uncertainty is not None and least_squares_kept(model.uncertainty.method):
        print(least_squares_note(where))


def identify_engine(args: argparse.Namespace) -> int:
    """``ssme-envs identify engine``: the embedded experiment, or a record from --data."""
    from ssme_envs import pipelines

    check_finite("--rank-tol", args.rank_tol)
    check_dt_option(args.dt)
    check_seed(args.seed)
    options: dict[str, Any] = {
        "method": args.method,
        "asymmetric": not args.symmetric,
        "max_index": args.max_index,
        "rank_tol": args.rank_tol,
    }
    if args.indices is not None:
        options["indices"] = indices(args.indices)
    if args.data is None:
        _needs_data(args, ("validate", "dt", "indices"), "experiment")
    elif args.seed is not None:
        raise ValueError("--seed applies to the embedded experiment only (no --data)")
    else:
        options["inputs"] = names(args.inputs, "--inputs")
        options["outputs"] = names(args.outputs, "--outputs")
    with noting_replacement(args.out):
        run = pipelines.identify_engine(
            args.out, args.data, dt=args.dt, validate=args.validate, seed=args.seed, **options
        )
    if args.data is None:
        for r in run.levels:
            see = r.validation["validation_low_frequency"]["model"]["see"]
            if r.identified.search is not None and r.identified.search.close:
                print(f"{r.power_percent:>3d} % power: {r.identified.search.summary()}")
            print(
                f"{r.power_percent:>3d} % power: indices {list(r.identified.model.observability_indices)}, "
                f"lambda {[round(float(v), 4) for v in r.identified.model.lam]}, model SEE on the "
                f"low-frequency test {[round(v, 4) for v in see]}"
            )
            _least_squares_note(r.identified.model, f"{r.power_percent} % power")
        print(f"identified {len(run.levels)} power levels in {run.seconds:.2f} s; report: {run.report}")
        return 0
    model = run.identified.model
    if run.identified.search is not None:
        print(run.identified.search.summary())
    print(
        f"indices {list(model.observability_indices)}, lambda {[round(float(v), 4) for v in model.lam]}, "
        f"model SEE {[round(v, 4) for v in run.validation['identification']['model']['see']]}"
    )
    from ssme_envs.identification.metrics import fit_warning

    _least_squares_note(model, "the model")
    warning = fit_warning(model, run.validation["identification"]["model"]["fit_percent"])
    if warning is not None:
        print(warning)
    print(f"wrote {args.out / 'model.json'} and {run.report}")
    return 0


def identify_nozzle(args: argparse.Namespace) -> int:
    """``ssme-envs identify nozzle``: the embedded bench test, or a record from --data."""
    from ssme_envs import pipelines

    check_workers(args.workers)
    check_finite("--normalization-a", args.normalization_a, positive=True)
    check_dt_option(args.dt)
    check_seed(args.seed)
    if args.data is None:
        _needs_data(args, ("validate", "dt"), "bench test")
    with noting_replacement(args.out):
        run = pipelines.identify_nozzle(
            args.out,
            args.data,
            input_column=args.input,
            output_column=args.output,
            dt=args.dt,
            validate=args.validate,
            workers=args.workers,
            seed=args.seed,
            normalization_a=args.normalization_a,
            progress=print,
            bootstrap_noise=args.bootstrap_noise,
        )
    lin = run.identified.model.linear
    if args.data is not None:  # the bench's sensor noise is white: its colour is the hysteresis
        from ssme_envs.identification.nozzle_residuals import output_error_notes

        for note in output_error_notes(run.identified.model.fit["dsr_e"]):
            print(note)
    print(f"linear: J {lin['J']:.4g} kg m^2, b {lin['b']:.4g} N m s/rad, k {lin['k']:.4g} N m/rad")
    print(f"Bouc-Wen: {run.identified.bouc_wen.reason}")
    print(f"done in {run.seconds:.1f} s; wrote {args.out / 'model.json'} and {run.report}")
    return 0


def validate_engine(args: argparse.Namespace) -> int:
    """``ssme-envs validate engine``: SEE, fit and plots of a model.json on records."""
    from ssme_envs import pipelines
    from ssme_envs.identification.records import record_labels

    check_dt_option(args.dt)
    with noting_replacement(args.out):
        validation = pipelines.validate_engine(args.out, args.model, args.data, args.dt)
    for path, label in zip(args.data, record_labels(args.data), strict=True):
        see = [round(v, 5) for v in validation[label]["model"]["see"]]
        named = "" if label == path.stem else f" (reported as {label})"
        print(f"{path}{named}: model SEE {see}")
    print(f"report: {args.out / 'report.md'}")
    return 0


__all__ = [
    "check_dt_option",
    "identify_engine",
    "identify_nozzle",
    "indices",
    "names",
    "noting_replacement",
    "validate_engine",
]
