"""The ``ssme-envs`` command.

``ssme-envs report --out DIR`` runs the main job: identify the engine and the nozzle, evaluate every
controller on every env, write one report.md. ``ssme-envs evaluate --env ID --controllers pi,lqi
--out DIR`` scores controllers on an env's scenarios. ``ssme-envs identify nozzle [--data FILE.csv]
--out DIR`` identifies the movable nozzle (DSR_e and
Bouc-Wen). ``ssme-envs identify engine [--data FILE.csv] --out DIR`` identifies an alpha-canonical engine
model from a record, or, without ``--data``, runs the embedded experiment on the truth at the
five Table I power levels. ``ssme-envs validate engine --model model.json --data FILE.csv
[--data FILE.csv ...] --out DIR`` scores a model on records. Errors in what the user gave (and a
full disk, a locked or unusable --out, ...) print one line ``error: ...`` and exit with code 2;
Ctrl-C exits with code 130. A run writes into a fresh directory beside --out that replaces --out
only once the run has succeeded (see :mod:`ssme_envs.outputs`).
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from ssme_envs.cli_checks import error_line, integer, number, one_line, sigint_in_main_process
from ssme_envs.cli_commands import UsageError as _UsageError
from ssme_envs.cli_commands import bench_command as _bench
from ssme_envs.cli_commands import evaluate_choices as _evaluate_choices
from ssme_envs.cli_commands import evaluate_command as _evaluate
from ssme_envs.cli_commands import report_command as _report
from ssme_envs.cli_identify import identify_engine as _identify_engine
from ssme_envs.cli_identify import identify_nozzle as _identify_nozzle
from ssme_envs.cli_identify import validate_engine as _validate_engine
from ssme_envs.cli_learn import add_learning_commands, train_command, tune_command
from ssme_envs.outputs import check_inputs_outside

OUTPUT_NOTE = (
    "--out is built in a fresh directory beside it and swapped in when the run succeeds: an earlier "
    "ssme-envs run there is replaced, a failed or interrupted run leaves it as it was, a directory "
    "holding other files is refused, and a second run into the same --out at the same time is "
    "refused (lock file .NAME.lock beside it)."
)


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, epilog_factory: Callable[[], str] | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.epilog_factory = epilog_factory  # help text built only when --help asks for it

    def format_help(self) -> str:
        if self.epilog_factory is not None:
            self.epilog = self.epilog_factory()
        return super().format_help()

    def error(self, message: str) -> None:  # one line; the help when a subcommand is missing
        subcommands = self._subparsers._group_actions if self._subparsers is not None else []
        missing = [a for a in subcommands if a.required and a.dest in message.rpartition(":")[2].split()]
        if message.startswith("the following arguments are required") and missing:
            choices = ", ".join(missing[0].choices)
            raise _UsageError(f"{self.prog}: choose one of {choices}", usage=self.format_help())
        raise _UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="ssme-envs",
        description="Identified SSME engine and movable-nozzle models, Gymnasium environments on them and "
        "controllers: identify, validate, evaluate, train, benchmark, and the main report. "
        "'ssme-envs COMMAND --help' describes a command.",
        epilog=OUTPUT_NOTE + " Errors print one line 'error: ...' and exit with code 2; Ctrl-C exits 130.",
    )
    from ssme_envs import __version__

    parser.add_argument("--version", action="version", version=f"ssme-envs {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    identify = commands.add_parser(
        "identify",
        help="identify a plant model from input/output records",
        description="Identify a plant model (engine or nozzle) from a CSV record, or from the embedded "
        "experiment on the truth; write model.json, report.md and figures under --out.",
        epilog=OUTPUT_NOTE,
    )
    plants = identify.add_subparsers(dest="plant", required=True, parser_class=_Parser)

    engine = plants.add_parser(
        "engine",
        help="SSME valves -> Pc, MR in alpha-canonical form",
        description="Identify an alpha-canonical engine model (NASA TM-104422). Without --data, run "
        "the embedded PRBS experiment on the truth at 70-110 % power and compare with Tables I and II.",
        epilog=OUTPUT_NOTE,
    )
    engine.add_argument(
        "--data", type=Path, help="CSV record with a header row (default: embedded experiment)"
    )
    engine.add_argument("--out", type=Path, required=True, help="output directory")
    engine.add_argument(
        "--inputs", default="beta_opov,beta_fpov", help="input columns (default: %(default)s)"
    )
    engine.add_argument("--outputs", default="pc,mr", help="output columns (default: %(default)s)")
    engine.add_argument("--dt", type=number, help="sample time in s, if the CSV has no 't' column")
    engine.add_argument("--validate", type=Path, help="a second CSV record to validate on")
    engine.add_argument("--indices", help="observability indices, e.g. 2,2 (default: estimated)")
    engine.add_argument(
        "--max-index",
        type=integer,
        default=6,
        help="largest index of the rank search; the walk over neighbouring sets may go past it, "
        "to 12 states in all (default: %(default)s)",  # identification.structure.MAX_WALK_ORDER
    )
    engine.add_argument(
        "--rank-tol", type=number, default=0.1, help="rank-search threshold (default: %(default)s)"
    )
    engine.add_argument(
        "--method",
        choices=("iv", "ls", "oe"),  # identification.arguments.METHODS (not imported here: heavy)
        default="iv",
        help="parameter estimator: instrumental variables, least squares, or output error (slower; "
        "intervals right under white output noise where iv falls back to ls) (default: %(default)s)",
    )
    engine.add_argument("--symmetric", action="store_true", help="do not estimate the lambda gains")
    engine.add_argument(
        "--seed", type=integer, default=None, help="seed of the embedded experiment (default: 2024)"
    )

    nozzle = plants.add_parser(
        "nozzle",
        help="movable nozzle torque -> angle: DSR_e linear model and Bouc-Wen joint",
        description="Identify the movable nozzle (VLS paper): a 2nd-order DSR_e model with J, b, k and a "
        "Bouc-Wen hysteretic joint. Without --data, run the embedded bench test on Table 1's nozzle.",
        epilog=OUTPUT_NOTE,
    )
    nozzle.add_argument(
        "--data", type=Path, help="CSV record with a header row (default: embedded bench test)"
    )
    nozzle.add_argument("--out", type=Path, required=True, help="output directory")
    nozzle.add_argument("--input", default="tau", help="torque column, N m (default: %(default)s)")
    nozzle.add_argument("--output", default="beta", help="angle column, rad (default: %(default)s)")
    nozzle.add_argument("--dt", type=number, help="sample time in s, if the CSV has no 't' column")
    nozzle.add_argument("--validate", type=Path, help="a second CSV record to validate on")
    nozzle.add_argument(
        "--workers", type=integer, default=2, help="processes for the fit (default: %(default)s)"
    )
    nozzle.add_argument(
        "--seed", type=integer, default=None, help="seed of the bench test and of the search (default: 7)"
    )
    nozzle.add_argument(
        "--normalization-a",
        type=number,
        default=0.35,
        help="the A that fixes the Table 1 form (default: %(default)s)",
    )
    nozzle.add_argument(
        "--bootstrap-noise",
        choices=("white", "innovations", "sieve"),  # identification.nozzle_uncertainty.NOISE_MODELS
        default="white",
        help="how the bootstrap of J, b, k's standard errors resamples the noise: white (white sensor "
        "noise), innovations (through DSR_e's noise model) or sieve (coloured sensor noise: an AR "
        "sieve of the linear model's output error) (default: %(default)s)",
    )

    bench = commands.add_parser(
        "bench",
        help="environment steps per second beside Pendulum-v1 and CartPole-v1 (ratios)",
        description="Measure each env's steps per second, single and through its native vector env at "
        "several sizes, in alternating rounds beside Pendulum-v1 and CartPole-v1; print a markdown table "
        "(--out FILE: also write it, atomically). Sizes are checked against the free memory first.",
    )
    bench.add_argument(
        "--rounds",
        type=integer,
        default=5,
        help="alternating rounds per measurement, one episode each; the best counts (default: %(default)s)",
    )
    bench.add_argument("--sizes", default="1,64,1024,4096", help="vector sizes (default: %(default)s)")
    bench.add_argument(
        "--actions",
        default="zero,random",
        help="action kinds, comma-separated: zero (episodes run to their limit), random (episodes "
        "end early, resets timed too) (default: %(default)s)",
    )
    bench.add_argument("--env", action="append", help="env id to measure (repeatable; default: all)")
    bench.add_argument("--out", help="also write the table to this markdown file")

    evaluate = commands.add_parser(
        "evaluate",
        help="score controllers on an env's scenarios (results.json, results.md, plots)",
        description=textwrap.fill(
            "Run each controller on each scenario of an env for --episodes seeded episodes and write "
            "results.json, results.md and one PNG per scenario under --out. --episodes is checked "
            "against the free memory first. " + OUTPUT_NOTE
        ),
        epilog_factory=_evaluate_choices,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    evaluate.add_argument("--env", required=True, help="env id, e.g. ssme_envs/EngineTracking-v0")
    evaluate.add_argument(
        "--controllers",
        help="comma-separated, e.g. pi,lqi,lqi:truth,ppo; ppo:RUN_DIR, sac:RUN_DIR or td3:RUN_DIR for "
        "a run of 'ssme-envs train' (default: every one for the env)",
    )
    evaluate.add_argument(
        "--allow-pickle",
        action="store_true",
        help="also accept ALGO:FILE.zip, a stable-baselines3 zip: loading it unpickles it, which can "
        "execute arbitrary code (use only for files you trust)",
    )
    evaluate.add_argument("--scenario", help="comma-separated scenario names (default: all of the env's)")
    evaluate.add_argument("--episodes", type=integer, help="episodes per scenario (default: 20)")
    evaluate.add_argument(
        "--monte-carlo",
        type=integer,
        metavar="N",
        help="robustness: run each controller over N plants drawn per episode with --plant-spread "
        "(NozzleTVC, LauncherPitch) and write robustness.md (mean, worst case, CVaR 90 %% per "
        "controller, the nominal plant's mean beside); replaces --episodes",
    )
    evaluate.add_argument(
        "--plant-spread",
        default=None,
        help="with --monte-carlo: a relative spread of the joint's parameters (log-normal, e.g. 0.2, "
        "the default) or 'uncertainty' (the covariance of the model.json the env's plant comes from: "
        "with --plant identified, strong_identified or a model.json)",
    )
    evaluate.add_argument(
        "--plant",
        help="the plant of every scenario, in place of the scenario's own: one of the env's plant "
        "names (e.g. identified) or a model.json (default: each scenario's)",
    )
    evaluate.add_argument(
        "--seed", type=integer, default=0, help="seed of the first episode (default: %(default)s)"
    )
    evaluate.add_argument("--out", type=Path, required=True, help="output directory")

    add_learning_commands(commands)

    report = commands.add_parser(
        "report",
        help="the main job: identify the engine and the nozzle, evaluate every controller on every env",
        description="The main job: identify the engine and the nozzle on their embedded experiments, "
        "evaluate the controllers of each env on its scenarios, and write one report.md (with the "
        "sub-reports in engine/, nozzle/ and one folder per env) under --out. --episodes is checked "
        "against the free memory first.",
        epilog=OUTPUT_NOTE,
    )
    report.add_argument("--out", type=Path, required=True, help="output directory")
    report.add_argument(
        "--episodes", type=integer, default=20, help="episodes per scenario (default: %(default)s)"
    )

    check = commands.add_parser(
        "validate",
        help="validate a model.json on input/output records",
        description="Score an identified model.json on CSV records: SEE and fit tables and plots of "
        "measured vs filter vs model, in report.md under --out.",
        epilog=OUTPUT_NOTE,
    )
    check_plants = check.add_subparsers(dest="plant", required=True, parser_class=_Parser)
    check_engine = check_plants.add_parser(
        "engine",
        help="SEE, fit and plots of an engine model.json on CSV records",
        description="Score an engine model.json (schema ssme-envs/engine-model) on one or more CSV "
        "records with its input and output columns; every record is read and checked before any "
        "output is written.",
        epilog=OUTPUT_NOTE,
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
    check_engine.add_argument("--dt", type=number, help="sample time in s, if the CSV has no 't' column")
    for action in commands._choices_actions:  # a command without a description shows its help line
        sub = commands.choices[action.dest]
        sub.description = sub.description or action.help
    return parser


def _inputs(args: argparse.Namespace) -> dict[str, str | Path]:
    """The files and directories a command reads, by option (to keep them out of its --out)."""
    found: dict[str, str | Path] = {}
    for key in ("data", "validate", "model", "config"):
        value = getattr(args, key, None)
        for i, path in enumerate(value if isinstance(value, list) else [value]):
            if path is not None:
                found[f"--{key}" if i == 0 else f"--{key} (#{i + 1})"] = path
    if args.command == "evaluate":
        from ssme_envs.pipelines import evaluation_inputs

        found.update(evaluation_inputs(args.plant, (args.controllers or "").split(","), "--"))
    return found


def _dispatch(args: argparse.Namespace) -> int:
    if getattr(args, "out", None) is not None and args.command not in ("tune", "bench"):  # theirs: a file
        check_inputs_outside(args.out, _inputs(args))
    if args.command == "identify":
        return (_identify_engine if args.plant == "engine" else _identify_nozzle)(args)
    if args.command == "bench":
        return _bench(args)
    if args.command == "evaluate":
        return _evaluate(args)
    if args.command == "report":
        return _report(args)
    if args.command == "tune":
        return tune_command(args)
    if args.command == "train":
        return train_command(args)
    if args.command == "validate" and args.plant == "engine":
        return _validate_engine(args)
    raise _UsageError(f"unknown command {args.command}")  # pragma: no cover


def _interrupted(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt caused ``exc`` (along its chain of causes and contexts)."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code: 0, 2 for an error (one line ``error: ...`` on
    stderr, no traceback), 130 when interrupted (Ctrl-C)."""
    try:
        with sigint_in_main_process():
            return _dispatch(build_parser().parse_args(argv))
    except _UsageError as exc:
        print((exc.usage + "\n" if exc.usage else "") + f"error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted (Ctrl-C)", file=sys.stderr)
        return 130
    except Exception as exc:
        if _interrupted(exc):  # Ctrl-C inside a C extension's import comes back as its ImportError
            print("error: interrupted (Ctrl-C)", file=sys.stderr)
            return 130
        text = error_line(exc)
        if text is None:  # a bug: keep its traceback
            raise
        print(f"error: {one_line(text)}", file=sys.stderr)
        return 2


def _exit(status: int) -> NoReturn:
    """Exit with ``status``, 130 after Ctrl-C included. Under ``python -m``, CPython ends the
    process by SIGINT instead when the last ``exec`` or ``eval`` of a string it ran let a
    KeyboardInterrupt out, even one caught further up (dataclasses and namedtuples are made so:
    a Ctrl-C while a module defines one). Each such exec clears that record as it starts, so an
    empty one here does, and the exit then runs the usual cleanup (atexit, process pools)."""
    exec("")  # a constant, empty string: clears the record (see above)
    raise SystemExit(status)


if __name__ == "__main__":
    _exit(main())
