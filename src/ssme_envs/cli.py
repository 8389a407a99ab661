"""The ``ssme-envs`` command.

``ssme-envs report --out DIR`` runs the main job: identify the engine and the nozzle, evaluate every
controller on every env, write one report.md. ``ssme-envs evaluate --env ID --controllers pi,lqi
--out DIR`` scores controllers on an env's scenarios. ``ssme-envs identify nozzle [--data FILE.csv]
--out DIR`` identifies the movable nozzle (DSR_e and
Bouc-Wen). ``ssme-envs identify engine [--data FILE.csv] --out DIR`` identifies an alpha-canonical engine
model from a record, or, without ``--data``, runs the embedded experiment on the truth at the
five Table I power levels. ``ssme-envs validate engine --model model.json --data FILE.csv
[--data FILE.csv ...] --out DIR`` scores a model on records. Errors in what the user gave print one
line ``error: ...`` and exit with code 2.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, no usage dump
        raise _UsageError(message)


def _names(text: str, option: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(","))
    if not all(names):
        raise _UsageError(f"{option} must be a comma-separated list of names, got {text!r}")
    return names


def _indices(text: str) -> tuple[int, ...]:
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise _UsageError(f"--indices must be comma-separated positive integers, got {text!r}") from None
    if any(v < 1 for v in values):
        raise _UsageError(f"--indices must be positive integers, got {text!r}")
    return values


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="ssme-envs", description=__doc__.splitlines()[0])
    from ssme_envs import __version__

    parser.add_argument("--version", action="version", version=f"ssme-envs {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    identify = commands.add_parser("identify", help="identify a plant model from input/output records")
    plants = identify.add_subparsers(dest="plant", required=True, parser_class=_Parser)

    engine = plants.add_parser(
        "engine",
        help="SSME valves -> Pc, MR in alpha-canonical form",
        description="Identify an alpha-canonical engine model (NASA TM-104422). Without --data, run "
        "the embedded PRBS experiment on the truth at 70-110 %% power and compare with Tables I and II.",
    )
    engine.add_argument(
        "--data", type=Path, help="CSV record with a header row (default: embedded experiment)"
    )
    engine.add_argument("--out", type=Path, required=True, help="output directory")
    engine.add_argument(
        "--inputs", default="beta_opov,beta_fpov", help="input columns (default: %(default)s)"
    )
    engine.add_argument("--outputs", default="pc,mr", help="output columns (default: %(default)s)")
    engine.add_argument("--dt", type=float, help="sample time in s, if the CSV has no 't' column")
    engine.add_argument("--validate", type=Path, help="a second CSV record to validate on")
    engine.add_argument("--indices", help="observability indices, e.g. 2,2 (default: estimated)")
    engine.add_argument(
        "--max-index", type=int, default=6, help="largest index searched (default: %(default)s)"
    )
    engine.add_argument(
        "--rank-tol", type=float, default=0.1, help="rank-search threshold (default: %(default)s)"
    )
    engine.add_argument(
        "--method", choices=("iv", "ls"), default="iv", help="parameter estimator (default: %(default)s)"
    )
    engine.add_argument("--symmetric", action="store_true", help="do not estimate the lambda gains")
    engine.add_argument("--seed", type=int, default=None, help="seed of the embedded experiment")

    nozzle = plants.add_parser(
        "nozzle",
        help="movable nozzle torque -> angle: DSR_e linear model and Bouc-Wen joint",
        description="Identify the movable nozzle (VLS paper): a 2nd-order DSR_e model with J, b, k and a "
        "Bouc-Wen hysteretic joint. Without --data, run the embedded bench test on Table 1's nozzle.",
    )
    nozzle.add_argument(
        "--data", type=Path, help="CSV record with a header row (default: embedded bench test)"
    )
    nozzle.add_argument("--out", type=Path, required=True, help="output directory")
    nozzle.add_argument("--input", default="tau", help="torque column, N m (default: %(default)s)")
    nozzle.add_argument("--output", default="beta", help="angle column, rad (default: %(default)s)")
    nozzle.add_argument("--dt", type=float, help="sample time in s, if the CSV has no 't' column")
    nozzle.add_argument("--validate", type=Path, help="a second CSV record to validate on")
    nozzle.add_argument("--workers", type=int, default=2, help="processes for the fit (default: %(default)s)")
    nozzle.add_argument("--seed", type=int, default=None, help="seed of the bench test and of the search")
    nozzle.add_argument(
        "--normalization-a",
        type=float,
        default=0.35,
        help="the A that fixes the Table 1 form (default: %(default)s)",
    )

    bench = commands.add_parser(
        "bench", help="environment steps per second beside Pendulum-v1 and CartPole-v1 (ratios)"
    )
    bench.add_argument(
        "--rounds",
        type=int,
        default=5,
        help="alternating rounds per measurement, one episode each; the best counts (default: %(default)s)",
    )
    bench.add_argument("--sizes", default="1,64,1024,4096", help="vector sizes (default: %(default)s)")
    bench.add_argument("--env", action="append", help="env id to measure (repeatable; default: all)")
    bench.add_argument("--out", type=Path, help="also write the table to this markdown file")

    evaluate = commands.add_parser(
        "evaluate", help="score controllers on an env's scenarios (results.json, results.md, plots)"
    )
    evaluate.add_argument("--env", required=True, help="env id, e.g. ssme_envs/EngineTracking-v0")
    evaluate.add_argument(
        "--controllers", help="comma-separated, e.g. pi,lqi,lqi:truth (default: every one for the env)"
    )
    evaluate.add_argument("--scenario", help="comma-separated scenario names (default: all of the env's)")
    evaluate.add_argument(
        "--episodes", type=int, default=20, help="episodes per scenario (default: %(default)s)"
    )
    evaluate.add_argument(
        "--seed", type=int, default=0, help="seed of the first episode (default: %(default)s)"
    )
    evaluate.add_argument("--out", type=Path, required=True, help="output directory")

    train = commands.add_parser(
        "train", help="train a stable-baselines3 agent on an env (model.zip, normalization, config)"
    )
    train.add_argument("--env", help="env id (or 'env' in the config)")
    train.add_argument("--algo", help="ppo, sac or td3 (or 'algo' in the config)")
    train.add_argument("--steps", type=int, help="environment steps (default: the config's, else 200000)")
    train.add_argument("--seed", type=int, help="seed (default: the config's, else 0)")
    train.add_argument("--config", type=Path, help="TOML config (hyperparameters, env options, ...)")
    train.add_argument("--tensorboard", action="store_true", help="write TensorBoard logs under --out")
    train.add_argument("--out", type=Path, required=True, help="output directory")

    report = commands.add_parser(
        "report",
        help="the main job: identify the engine and the nozzle, evaluate every controller on every env",
    )
    report.add_argument("--out", type=Path, required=True, help="output directory")
    report.add_argument(
        "--episodes", type=int, default=20, help="episodes per scenario (default: %(default)s)"
    )

    check = commands.add_parser("validate", help="validate a model.json on input/output records")
    check_plants = check.add_subparsers(dest="plant", required=True, parser_class=_Parser)
    check_engine = check_plants.add_parser(
        "engine", help="SEE, fit and plots of an engine model.json on CSV records"
    )
    check_engine.add_argument("--model", type=Path, required=True, help="engine model.json")
    check_engine.add_argument(
        "--data",
        type=Path,
        required=True,
        nargs="+",
        action="extend",
        help="CSV record(s); repeat --data or list several",
    )
    check_engine.add_argument("--out", type=Path, required=True, help="output directory")
    check_engine.add_argument("--dt", type=float, help="sample time in s, if the CSV has no 't' column")
    return parser


def _needs_data(args: argparse.Namespace, flags: tuple[str, ...], embedded: str) -> None:
    for flag in flags:
        if getattr(args, flag) is not None:
            raise _UsageError(f"--{flag} needs --data (the embedded {embedded} sets its own)")


def _check_same_dt(path: Path, dt: float, reference: float, what: str) -> None:
    if abs(dt - reference) > 1e-9 * reference:
        raise ValueError(f"{path}: sample time {dt:g} s differs from the {what}'s {reference:g} s")


def _check_record(path: Path, record) -> None:
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


def _identify_engine(args: argparse.Namespace) -> int:
    import numpy as np

    from ssme_envs.identification import pipeline, report
    from ssme_envs.identification.metrics import validate
    from ssme_envs.models.engine import TruthConfig

    out: Path = args.out
    _make_dir(out)
    options = {
        "method": args.method,
        "asymmetric": not args.symmetric,
        "max_index": args.max_index,
        "rank_tol": args.rank_tol,
    }
    if args.indices:
        options["indices"] = _indices(args.indices)

    if args.data is None:
        _needs_data(args, ("validate", "dt", "indices"), "experiment")
        seed = pipeline.DEFAULT_SEED if args.seed is None else args.seed
        config = TruthConfig()
        start = time.perf_counter()
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
            f"identified {len(results)} power levels in {time.perf_counter() - start:.2f} s; report: {path}"
        )
        return 0

    if args.seed is not None:
        raise _UsageError("--seed applies to the embedded experiment only (no --data)")
    inputs, outputs = _names(args.inputs, "--inputs"), _names(args.outputs, "--outputs")
    record = pipeline.read_record(args.data, inputs, outputs, args.dt)
    _check_record(args.data, record)
    check = None
    if args.validate is not None:  # refuse a bad validation record before the identification runs
        check = pipeline.read_record(args.validate, inputs, outputs, args.dt)
        _check_same_dt(args.validate, check.dt, record.dt, "data")
        _check_record(args.validate, check)
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
    path = report.write_record_report(out, ident.model, records, validation, ident, args.rank_tol)
    model = ident.model
    if ident.search is not None:
        print(ident.search.summary())
    print(
        f"indices {list(model.observability_indices)}, lambda {[round(float(v), 4) for v in model.lam]}, "
        f"model SEE {[round(v, 4) for v in validation['identification']['model']['see']]}"
    )
    print(f"wrote {out / 'model.json'} and {path}")
    return 0


def _identify_nozzle(args: argparse.Namespace) -> int:
    from ssme_envs.identification import nozzle_pipeline as npipe
    from ssme_envs.identification.nozzle_report import write_nozzle_report
    from ssme_envs.models.nozzle import BENCH_RATE_HZ, NOZZLE_DT, published_nozzle

    if args.workers < 1:
        raise _UsageError(f"--workers must be at least 1, got {args.workers}")
    if not args.normalization_a > 0:
        raise _UsageError(f"--normalization-a must be positive, got {args.normalization_a}")
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
        print(f"simulating the bench test ({bench}) and identifying ...")
        _make_dir(args.out)
        ident, records = npipe.run_default(seed, args.workers, args.normalization_a)
        note = (
            "Bench data simulated from the paper's Table 1 Bouc-Wen nozzle (the truth of this report): "
            f"a PRBS torque keeping the angle within +-{npipe.RANGE_DEG:g} deg, {bench}. Seed {seed}."
        )
    else:
        records = {"identification": npipe.read_nozzle_record(args.data, args.input, args.output, args.dt)}
        if args.validate is not None:
            check = npipe.read_nozzle_record(args.validate, args.input, args.output, args.dt)
            _check_same_dt(args.validate, check.dt, records["identification"].dt, "data")
            records["validation"] = check
        note = f"Data: {args.data}."
        _make_dir(args.out)
        print("identifying: DSR_e linear model, then the Bouc-Wen joint (evolutionary search, least squares)")
        ident = npipe.identify_nozzle(
            records["identification"], seed=seed, workers=args.workers, normalization_A=args.normalization_a
        )
        if "validation" in records:
            ident.model.fit["validation_record"] = npipe.validate_nozzle(ident.model, records["validation"])
    ident.model.save(args.out / "model.json")
    if args.data is None:
        (args.out / "data").mkdir(exist_ok=True)
        for name, rec in records.items():
            npipe.write_nozzle_record(args.out / "data" / f"nozzle_{name}.csv", rec)
    path = write_nozzle_report(args.out, ident, records, truth, note)
    lin = ident.model.linear
    print(f"linear: J {lin['J']:.2f} kg m^2, b {lin['b']:.1f} N m s/rad, k {lin['k']:.4g} N m/rad")
    print(f"Bouc-Wen: {ident.bouc_wen.reason}")
    print(f"done in {time.perf_counter() - start:.1f} s; wrote {args.out / 'model.json'} and {path}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from ssme_envs.bench import ENV_IDS, format_table, run_benchmark

    try:
        sizes = [int(v) for v in args.sizes.split(",")]
    except ValueError:
        raise _UsageError(f"--sizes must be comma-separated positive integers, got {args.sizes!r}") from None
    if any(n < 1 for n in sizes):
        raise _UsageError(f"--sizes must be positive integers, got {args.sizes!r}")
    if not 1 <= args.rounds <= 100:
        raise _UsageError(f"--rounds must be within 1-100, got {args.rounds}")
    env_ids = args.env or list(ENV_IDS)
    unknown = [e for e in env_ids if e not in ENV_IDS]
    if unknown:
        raise _UsageError(f"unknown env {', '.join(unknown)}; choose from {', '.join(ENV_IDS)}")
    rows = run_benchmark(env_ids, sizes, args.rounds, progress=lambda m: print(m, file=sys.stderr))
    table = format_table(rows)
    print(table)
    if args.out is not None:
        args.out.write_text("Command: `ssme-envs bench`\n\n" + table + "\n")
    return 0


def _controllers(env_id: str, specs: str | None) -> dict:
    from agents import controller_names, parse_controller

    names = controller_names(env_id) if specs is None else list(_names(specs, "--controllers"))
    return {name: parse_controller(name, env_id) for name in names}


def _run_evaluation(env_id: str, controllers: dict, scenarios: list[str] | None, episodes: int, out: Path,
                    command: str, seed: int = 0) -> tuple[Path, dict]:  # fmt: skip
    from ssme_envs.evaluation import evaluate
    from ssme_envs.results import write_evaluation

    results = evaluate(
        env_id, controllers, scenarios, episodes, seed, progress=lambda m: print(m, file=sys.stderr)
    )
    path = write_evaluation(env_id, results, out, command)
    return path, results


def _evaluate(args: argparse.Namespace) -> int:
    from ssme_envs.evaluation import check_env_id, check_scenarios

    env_id = check_env_id(args.env)
    if args.episodes < 1:
        raise _UsageError(f"--episodes must be a positive integer, got {args.episodes}")
    scenarios = None
    if args.scenario is not None:
        scenarios = check_scenarios(env_id, _names(args.scenario, "--scenario"))
    controllers = _controllers(env_id, args.controllers)
    _make_dir(args.out)
    command = "ssme-envs " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["evaluate"] else "ssme-envs evaluate"
    path, _ = _run_evaluation(env_id, controllers, scenarios, args.episodes, args.out, command, args.seed)
    print(f"wrote {path}, {args.out / 'results.json'} and the plots")
    return 0


def _train(args: argparse.Namespace) -> int:
    from agents.sb3 import check_config, load_config, train
    from ssme_envs.evaluation import check_env_id

    config = load_config(args.config) if args.config is not None else {}
    overrides = {"env": args.env, "algo": args.algo, "steps": args.steps, "seed": args.seed}
    config.update({k: v for k, v in overrides.items() if v is not None})
    if args.tensorboard:
        config["tensorboard"] = True
    config = check_config(config, str(args.config or "options"))
    check_env_id(config["env"])  # before the output directory is made
    _make_dir(args.out)
    summary = train(config, args.out)
    print(
        f"trained {summary['algo']} on {summary['env']}: {summary['steps']:,} steps in "
        f"{summary['seconds']:.0f} s ({summary['steps_per_s']:,.0f} steps/s), best evaluation return "
        f"{summary['best_return']:.3f}; "
        f"wrote {args.out / 'model.zip'}"
    )
    return 0


def _report(args: argparse.Namespace) -> int:
    from ssme_envs.main_report import REPORT_PLAN, write_main_report

    if args.episodes < 1:
        raise _UsageError(f"--episodes must be a positive integer, got {args.episodes}")
    start = time.perf_counter()
    _make_dir(args.out)
    parser = build_parser()
    print("identifying the engine (embedded experiment, five power levels) ...", file=sys.stderr)
    _identify_engine(parser.parse_args(["identify", "engine", "--out", str(args.out / "engine")]))
    print("identifying the nozzle (embedded bench test) ...", file=sys.stderr)
    _identify_nozzle(parser.parse_args(["identify", "nozzle", "--out", str(args.out / "nozzle")]))
    evaluations = {}
    learned = importlib.util.find_spec("stable_baselines3") is not None
    if not learned:
        print("stable-baselines3 is not installed: the report leaves out the PPO policies "
              '(pip install ".[rl]")', file=sys.stderr)  # fmt: skip
    for env_id, (specs, scenarios) in REPORT_PLAN.items():
        if not learned:
            specs = ",".join(s for s in specs.split(",") if not s.startswith("ppo"))
        folder = args.out / env_id.split("/")[-1]
        command = (
            f"ssme-envs evaluate --env {env_id} --controllers {specs} --scenario {','.join(scenarios)} "
            f"--episodes {args.episodes} --out {folder}"
        )
        print(f"evaluating on {env_id} ...", file=sys.stderr)
        _, evaluations[env_id] = _run_evaluation(
            env_id, _controllers(env_id, specs), scenarios, args.episodes, folder, command
        )
    path = write_main_report(args.out, evaluations, args.episodes, time.perf_counter() - start)
    print(f"report: {path} ({time.perf_counter() - start:.0f} s)")
    return 0


def _validate_engine(args: argparse.Namespace) -> int:
    import numpy as np

    from ssme_envs.identification import pipeline, report
    from ssme_envs.identification.metrics import validate
    from ssme_envs.identification.records import record_labels
    from ssme_envs.models.statespace import AlphaCanonicalModel

    model = AlphaCanonicalModel.load(args.model)
    labels = record_labels(args.data)  # two files called run.csv become run and run_2
    records = {}
    for path, label in zip(args.data, labels, strict=True):  # every record is read and checked first
        record = pipeline.read_record(path, model.input_names, model.output_names, args.dt)
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
    _make_dir(args.out)
    print(f"report: {report.write_record_report(args.out, model, records, validation)}")
    return 0


def _make_dir(path: Path) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"cannot create output directory {path}: {exc.strerror}") from None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command == "identify" and args.plant == "engine":
            return _identify_engine(args)
        if args.command == "identify" and args.plant == "nozzle":
            return _identify_nozzle(args)
        if args.command == "bench":
            return _bench(args)
        if args.command == "evaluate":
            return _evaluate(args)
        if args.command == "report":
            return _report(args)
        if args.command == "train":
            return _train(args)
        if args.command == "validate" and args.plant == "engine":
            return _validate_engine(args)
    except (_UsageError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
