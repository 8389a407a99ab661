"""The learning subcommands of ``ssme-envs``: ``train`` (stable-baselines3) and ``tune`` (Optuna on a
shared study); their parsers and what they run."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ssme_envs.cli_checks import check_training, integer
from ssme_envs.cli_identify import noting_replacement
from ssme_envs.outputs import check_file_target, output_directory


def add_learning_commands(commands: Any) -> None:
    """Add ``train`` and ``tune`` to the subparsers ``commands``."""
    train = commands.add_parser(
        "train",
        help="train a stable-baselines3 agent on an env (policy.json, policy.safetensors, normalization, "
        "config; no pickle)",
    )
    train.add_argument("--env", help="env id (or 'env' in the config)")
    train.add_argument("--algo", help="ppo, sac or td3 (or 'algo' in the config)")
    train.add_argument(
        "--steps",
        type=integer,
        help="environment steps, rounded up to whole rollouts (a line says so) (default: the config's, "
        "else 200000)",
    )
    train.add_argument("--seed", type=integer, help="seed (default: the config's, else 0)")
    train.add_argument("--config", type=Path, help="TOML config (hyperparameters, env options, ...)")
    train.add_argument("--tensorboard", action="store_true", help="write TensorBoard logs under --out")
    train.add_argument("--out", type=Path, required=True, help="output directory")

    tune = commands.add_parser(
        "tune",
        help="tune hyperparameters with Optuna on a study that several processes or machines share",
        description="Run --trials trials of an Optuna study held in --storage: each trial trains with "
        "sampled hyperparameters for --timesteps steps and is scored by the mean episode cost (unpromising "
        "trials pruned). Start the command in several processes or on several machines with the same "
        "--storage and --study and they work on one study. --out: the best trial's settings as a "
        "config of 'ssme-envs train' (written atomically).",
    )
    tune.add_argument("--env", required=True, help="env id, e.g. ssme_envs/NozzleTVC-v0")
    tune.add_argument("--algo", required=True, help="ppo, sac or td3")
    tune.add_argument(
        "--storage",
        required=True,
        help="journal:PATH (a journal file on a filesystem the workers share) or a database URL "
        "(sqlite:///study.db, postgresql://user:password@host/db, mysql+pymysql://...)",
    )
    tune.add_argument("--study", required=True, help="study name; created by the first worker")
    tune.add_argument(
        "--trials", type=integer, default=10, help="this worker's trials (default: %(default)s)"
    )
    tune.add_argument(
        "--timesteps",
        type=integer,
        default=100_000,
        help="environment steps per trial (default: %(default)s)",
    )
    tune.add_argument(
        "--seed", type=integer, default=0, help="seed of this worker's sampler and training; give each "
        "worker its own (default: %(default)s)",
    )  # fmt: skip
    tune.add_argument("--num-envs", type=integer, help="parallel envs in training (default: train's)")
    tune.add_argument(
        "--evaluations",
        type=integer,
        default=4,
        help="evaluations per trial, for pruning (default: %(default)s)",
    )
    tune.add_argument(
        "--eval-episodes", type=integer, default=10, help="episodes per evaluation (default: %(default)s)"
    )
    tune.add_argument("--out", help="write the best trial's config (TOML) to this file")


def train_command(args: argparse.Namespace) -> int:
    from agents.run_config import MAX_SEED
    from agents.sb3 import check_config, load_config, plan_steps, train
    from ssme_envs.evaluation import check_env_id

    config = load_config(args.config) if args.config is not None else {}
    overrides = {"env": args.env, "algo": args.algo, "steps": args.steps, "seed": args.seed}
    config.update({k: v for k, v in overrides.items() if v is not None})
    if args.tensorboard:
        config["tensorboard"] = True
    source = f"config {args.config}" if args.config is not None else "options"
    if args.seed is not None and not 0 <= args.seed <= MAX_SEED:  # named as given, not as the config's
        raise ValueError(f"--seed must be within 0-{MAX_SEED}, got {args.seed}")
    config = check_config(config, source)
    check_env_id(config["env"])  # before the output directory is made
    check_training(config)
    plan_steps(config, source)  # its refusals too before the output directory is made
    with noting_replacement(args.out), output_directory(args.out) as work:
        if config["tensorboard"]:
            print(
                f"TensorBoard logs while it trains: {work / 'tensorboard'} (then in {args.out})",
                file=sys.stderr,
            )
        summary = train(config, work, source=source)
    kept = summary["kept"]
    which = "final policy" if kept["model"] == "final" else "best evaluation's policy"
    print(
        f"trained {summary['algo']} on {summary['env']}: {summary['steps']:,} steps in "
        f"{summary['seconds']:.0f} s ({summary['steps_per_s']:,.0f} steps/s); kept the {which} "
        f"({kept['steps']:,} steps, evaluation return {summary['best_return']:.3f}); "
        f"wrote {args.out / 'policy.json'}, policy.safetensors and normalization.json"
    )
    return 0


def tune_command(args: argparse.Namespace) -> int:
    from ssme_envs import tuning

    if args.out is not None:
        check_file_target(args.out)  # before the trials: their hours are not lost to a late refusal
    study = tuning.tune(args.env, args.algo, args.storage, args.study, args.trials, args.timesteps,
                        args.seed, args.num_envs, args.evaluations, args.eval_episodes)  # fmt: skip
    print(tuning.summary(study))
    if args.out is not None:
        print(f"wrote {tuning.write_best_config(study, args.out)}")
    return 0


__all__ = ["add_learning_commands", "train_command", "tune_command"]
