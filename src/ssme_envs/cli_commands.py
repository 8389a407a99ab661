"""The ``bench``, ``evaluate`` and ``report`` commands of ``ssme-envs``, and the usage error that
commands raise. Each handler checks its options, calls the library function (:mod:`ssme_envs.bench`,
:mod:`ssme_envs.pipelines`) and prints what it did; the parser and the exit codes stay in
:mod:`ssme_envs.cli`, which dispatches here.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
import time

from ssme_envs.cli_checks import check_count, check_seed, check_vector_sizes, positive_integers
from ssme_envs.cli_identify import names as _names
from ssme_envs.cli_identify import noting_replacement
from ssme_envs.outputs import check_file_target, write_text


class UsageError(Exception):
    """A misused command line: :func:`ssme_envs.cli.main` prints ``usage`` (when given), then the
    one ``error:`` line, and returns the exit code 2."""

    def __init__(self, message: str, usage: str = "") -> None:
        super().__init__(message)
        self.usage = usage  # printed before the error line (a command given without a subcommand)


def evaluate_choices() -> str:
    """The envs, their scenarios and controllers, from where they are defined (evaluate --help)."""
    from agents import controller_names
    from agents.shipped import shipped_specs
    from ssme_envs.evaluation import SCENARIOS

    lines = ["envs, their scenarios (default: all) and controllers (default: all; NAME:truth designs on"]
    lines += ["the env's own plant instead of the identified model; ppo:VARIANT the other shipped policies):"]
    for env_id, scenarios in SCENARIOS.items():
        lines.append(f"  {env_id}")
        listed = (("scenarios", list(scenarios)), ("controllers", controller_names(env_id)))
        for label, names in (*listed, ("shipped policies", list(shipped_specs(env_id)))):
            text = f"{label}: {', '.join(names)}"
            lines += textwrap.wrap(text, 96, initial_indent="    ", subsequent_indent="      ")
    return "\n".join(lines)


def bench_command(args: argparse.Namespace) -> int:
    from ssme_envs.bench import ACTIONS, ENV_IDS, format_table, kernels_used, run_benchmark

    try:
        sizes = list(positive_integers("--sizes", args.sizes))
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if not 1 <= args.rounds <= 100:
        raise UsageError(f"--rounds must be within 1-100, got {args.rounds}")
    env_ids = args.env or list(ENV_IDS)
    unknown = [e for e in env_ids if e not in ENV_IDS]
    if unknown:
        raise UsageError(f"unknown env {', '.join(unknown)}; choose from {', '.join(ENV_IDS)}")
    check_vector_sizes(sizes, env_ids)
    if args.out is not None:
        check_file_target(args.out)  # before the rounds, not after them
    actions = args.actions.split(",")
    if not actions or any(kind not in ACTIONS for kind in actions):
        raise UsageError(f"--actions must be among {', '.join(ACTIONS)}, got {args.actions!r}")
    rows = run_benchmark(env_ids, sizes, args.rounds, progress=_to_stderr, actions=actions)
    table = format_table(rows)
    print(table)
    kernels = kernels_used()
    print(kernels)
    if args.out is not None:
        write_text(args.out, "Command: `ssme-envs bench`\n\n" + table + "\n\n" + kernels + "\n")
    return 0


def evaluate_command(args: argparse.Namespace) -> int:
    from ssme_envs.evaluation import check_env_id
    from ssme_envs.pipelines import evaluate_to
    from ssme_envs.robustness import DEFAULT_SPREAD

    env_id = check_env_id(args.env)
    check_seed(args.seed)
    scenarios = None if args.scenario is None else _names(args.scenario, "--scenario")
    controllers = None if args.controllers is None else _names(args.controllers, "--controllers")
    command = "ssme-envs " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["evaluate"] else "ssme-envs evaluate"
    robust = {}
    if args.monte_carlo is not None:
        check_count("--monte-carlo", args.monte_carlo)  # a bad N is named first, whatever else is given
        if args.episodes is not None:
            raise ValueError("give --episodes or --monte-carlo N (N plants, one per episode), not both")
        robust = {
            "monte_carlo": args.monte_carlo,
            "plant_spread": DEFAULT_SPREAD if args.plant_spread is None else args.plant_spread,
        }
    elif args.plant_spread is not None:
        raise ValueError("--plant-spread applies with --monte-carlo N")
    episodes = 20 if args.episodes is None else args.episodes
    with noting_replacement(args.out):
        evaluate_to(
            args.out, env_id, controllers, scenarios, episodes, args.seed,
            allow_pickle=args.allow_pickle, command=command, progress=_to_stderr, plant=args.plant,
            **robust,
        )  # fmt: skip
    extra = f", {args.out / 'robustness.md'}" if robust else ""
    print(f"wrote {args.out / 'results.md'}, {args.out / 'results.json'}{extra} and the plots")
    return 0


def report_command(args: argparse.Namespace) -> int:
    from ssme_envs.pipelines import run_report

    start = time.perf_counter()
    with noting_replacement(args.out):
        path = run_report(args.out, args.episodes, progress=_to_stderr)
    print(f"report: {path} ({time.perf_counter() - start:.0f} s)")
    return 0


def _to_stderr(message: str) -> None:
    print(message, file=sys.stderr)
