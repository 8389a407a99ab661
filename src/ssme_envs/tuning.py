"""Hyperparameter search with Optuna on a study that several processes or machines share.

Every worker (``ssme-envs tune``, or :func:`tune`) opens the same study in a shared storage and
runs its own trials; Optuna's storage hands out the trial numbers and the samplers read each
other's results from it, so starting more workers on one study makes the search go faster:

* ``journal:PATH``: Optuna's journal file (``JournalStorage`` on ``JournalFileBackend``), which
  any process that sees PATH can use, also on NFS (its lock needs no ``fcntl``);
* an RDB URL (``sqlite:///study.db``, ``postgresql://user:pw@host/db``, ``mysql+pymysql://...``)
  for machines that reach one database server.

A trial trains PPO, SAC or TD3 with sampled hyperparameters for ``timesteps`` steps on the
env's native vector env through the SB3 adapter (VecNormalize, as ``ssme-envs train`` does), and
scores the policy ``evaluations`` times during training by the evaluation harness's cost (minus
the return, mean over ``eval_episodes`` episodes of the env as registered, seeded from
:data:`EVAL_SEED`, not the harness's seed 0); each score is reported to Optuna so that a
``MedianPruner`` stops unpromising trials, and the last one is the trial's value (minimized).
The search spaces are :data:`SPACES`. The best trial's settings are written as a TOML config of
``ssme-envs train`` (and experiments/train_policies.py).

Seeds: the worker's ``TPESampler`` and the training of its trials take ``seed``. With several
workers a trial's sample depends on which trials the others had finished when it started, so a
shared study is not reproducible bit for bit; a single worker on a fresh study is.
"""

from __future__ import annotations

import math
import os
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ssme_envs.tuning_spaces import (
    PPO_N_STEPS,
    SPACES,
    Budget,
    buffer_size,
    sample_ppo,
    sample_sac,
    sample_td3,
)
from ssme_envs.tuning_storage import log_to_stdout, open_storage

EVAL_SEED = 1_000_000  # first evaluation episode: apart from the harness's seeds (0, ...) that reports use


def _study(storage: Any, name: str, attrs: dict[str, Any], seed: int) -> Any:
    """The study ``name`` (created if new), checked to be a search of the same env, algorithm and
    budget as ``attrs``."""
    import optuna

    sampler = optuna.samplers.TPESampler(seed=seed, constant_liar=True)  # liar: workers spread out
    pruner = optuna.pruners.MedianPruner(n_startup_trials=5, n_warmup_steps=max(1, attrs["evaluations"] // 3))
    study = optuna.create_study(
        storage=storage, study_name=name, direction="minimize", sampler=sampler, pruner=pruner,
        load_if_exists=True,
    )  # fmt: skip
    if study.direction != optuna.study.StudyDirection.MINIMIZE:
        raise ValueError(f"study {name!r} maximizes; a tuning study minimizes the cost")
    for _ in range(2):  # set by the first worker; a second look catches two creators racing
        held = study.user_attrs
        differ = {
            key: (held[key], value) for key, value in attrs.items() if key in held and held[key] != value
        }
        if differ:
            text = ", ".join(f"{key} {old!r} (asked {new!r})" for key, (old, new) in differ.items())
            raise ValueError(f"study {name!r} is a search with {text}: use another --study")
        for key, value in attrs.items():
            if key not in held:
                study.set_user_attr(key, value)
    return study


def _default_scenario(env_id: str) -> str:
    """The harness's scenario of the env as registered (no options): what a trial trains on."""
    from ssme_envs.evaluation import SCENARIOS

    return next(
        (name for name, options in SCENARIOS[env_id].items() if not options), next(iter(SCENARIOS[env_id]))
    )


def policy_cost(model: Any, venv: Any, env_id: str, algo: str, episodes: int) -> float:
    """The harness's mean episode cost of a model's deterministic policy, observations normalized
    with ``venv``'s current statistics, on the env as registered (episodes seeded from
    :data:`EVAL_SEED`)."""
    from agents.normalization import Normalization
    from agents.policy_files import LoadedPolicy
    from agents.sb3 import PolicyController
    from ssme_envs.evaluation import evaluate

    rms = venv.obs_rms
    stats = Normalization(
        rms.mean.copy(), rms.var.copy(), float(rms.count), float(venv.clip_obs), float(venv.epsilon)
    )
    controller = PolicyController(LoadedPolicy(model.policy, algo, env_id, stats, Path(env_id)))
    scenario = _default_scenario(env_id)
    result = evaluate(env_id, {"trial": lambda env: controller}, [scenario], episodes, EVAL_SEED)
    return float(result[scenario]["trial"].cost_mean)


class _Diverged(Exception):
    """Training produced non-finite numbers: the trial fails, the study goes on."""


def make_objective(
    env_id: str, algo: str, budget: Budget, eval_episodes: int, seed: int
) -> Callable[[Any], float]:
    """The Optuna objective: train with the trial's sample, report each evaluation's cost, return
    the last (minimized); raises ``optuna.TrialPruned`` when the pruner stops the trial."""
    import optuna
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from agents.policy_files import algorithm_class
    from agents.sb3 import check_config, plan_steps
    from ssme_envs.envs.sb3_adapter import make_sb3_vec_env

    def objective(trial: optuna.Trial) -> float:
        hyper, net_arch = SPACES[algo](trial, budget)
        config = check_config({"env": env_id, "algo": algo, "steps": budget.timesteps, "seed": seed,
                               "num_envs": budget.num_envs, "hyperparameters": hyper,
                               "policy": {"net_arch": net_arch}})  # fmt: skip
        steps, hyper, _ = plan_steps(config)
        config["hyperparameters"] = hyper
        trial.set_user_attr("pid", os.getpid())
        trial.set_user_attr("host", socket.gethostname())
        trial.set_user_attr("config", config)  # the settings as `ssme-envs train` reads them
        venv = VecNormalize(VecMonitor(make_sb3_vec_env(env_id, budget.num_envs, seed)), gamma=hyper["gamma"])
        try:
            return _run(trial, venv, steps, hyper, net_arch)
        finally:
            venv.close()

    def _run(trial: optuna.Trial, venv: Any, steps: int, hyper: dict[str, Any], net_arch: list[int]) -> float:
        model = algorithm_class(algo)("MlpPolicy", venv, seed=seed, device="cpu", verbose=0,
                                      policy_kwargs={"net_arch": net_arch}, **hyper)  # fmt: skip
        costs: list[float] = []
        pruned = []

        def score() -> bool:
            """Evaluate and report; False when the pruner stops the trial."""
            cost = policy_cost(model, venv, env_id, algo, eval_episodes)
            if not math.isfinite(cost):
                raise _Diverged(f"trial {trial.number}: cost {cost} at {model.num_timesteps} steps")
            costs.append(cost)
            trial.report(cost, step=len(costs))
            if len(costs) < budget.evaluations and trial.should_prune():
                pruned.append(len(costs))
            return not pruned

        class Evaluations(BaseCallback):
            def _on_step(self) -> bool:  # the last evaluation comes after training
                due = len(costs) + 1
                if due < budget.evaluations and self.model.num_timesteps >= due * steps / budget.evaluations:
                    return score()
                return True

        start = time.perf_counter()
        try:
            model.learn(steps, callback=Evaluations())
        except ValueError as exc:  # SB3's distributions refuse NaN parameters
            raise _Diverged(f"trial {trial.number}: {exc}") from None
        if pruned:
            raise optuna.TrialPruned(f"trial {trial.number} pruned at evaluation {pruned[0]}")
        score()
        trial.set_user_attr("seconds", time.perf_counter() - start)
        return costs[-1]

    return objective


def check_budget(trials: int, timesteps: int, num_envs: int, evaluations: int, eval_episodes: int) -> None:
    """ValueError naming the first count below 1 (or evaluations beyond the steps)."""
    counts = {"--trials": trials, "--timesteps": timesteps, "--num-envs": num_envs,
              "--evaluations": evaluations, "--eval-episodes": eval_episodes}  # fmt: skip
    for option, value in counts.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{option} must be a positive integer, got {value!r}")
    if evaluations > timesteps:
        raise ValueError(f"--evaluations {evaluations} exceeds --timesteps {timesteps}")


def tune(
    env_id: str,
    algo: str,
    storage: str,
    study_name: str,
    trials: int,
    timesteps: int,
    seed: int = 0,
    num_envs: int | None = None,
    evaluations: int = 4,
    eval_episodes: int = 10,
    progress: bool = True,
) -> Any:
    """Run ``trials`` trials of the shared study ``study_name`` in ``storage`` (this worker's;
    other workers add theirs).

    Parameters
    ----------
    env_id, algo : str
        A catalogue env and ppo, sac or td3.
    storage : str
        ``journal:PATH`` or an RDB URL (:func:`open_storage`).
    study_name : str
        The study; created by the first worker, joined by the others.
    trials : int
        Trials this worker runs (finished, pruned or failed).
    timesteps : int
        Environment steps per trial (rounded up to whole rollouts as ``ssme-envs train`` does).
    seed : int
        Seed of this worker's sampler and of its trials' training.
    num_envs : int, optional
        Parallel envs in training (default: ``ssme-envs train``'s).
    evaluations, eval_episodes : int
        Evaluations per trial (the pruner's steps) and episodes in each.
    progress : bool
        Optuna's log lines (one per trial) on stderr.

    Returns
    -------
    optuna.Study
        The study, with every worker's trials so far.
    """
    import optuna

    from agents.policy_files import algorithm_class
    from agents.run_config import DEFAULTS, MAX_SEED
    from ssme_envs.cli_checks import check_episodes, check_training
    from ssme_envs.evaluation import check_env_id

    num_envs = DEFAULTS["num_envs"] if num_envs is None else num_envs
    check_env_id(env_id)
    algorithm_class(algo)  # ValueError naming the algorithms, or the missing rl extra
    check_budget(trials, timesteps, num_envs, evaluations, eval_episodes)
    largest = {"n_steps": max(PPO_N_STEPS)} if algo == "ppo" else {"buffer_size": buffer_size(timesteps)}
    check_training({"env": env_id, "algo": algo, "num_envs": num_envs, "hyperparameters": largest})
    check_episodes(eval_episodes, {env_id: 1}, option="--eval-episodes")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ValueError(f"--seed must be an integer within 0-{MAX_SEED}, got {seed!r}")
    if not study_name:
        raise ValueError("--study must be a non-empty name")
    optuna.logging.set_verbosity(optuna.logging.INFO if progress else optuna.logging.WARNING)
    log_to_stdout()
    budget = Budget(timesteps, num_envs, evaluations)
    attrs = {"env": env_id, "algo": algo, "timesteps": timesteps, "num_envs": num_envs,
             "evaluations": evaluations, "eval_episodes": eval_episodes}  # fmt: skip
    study = _study(open_storage(storage), study_name, attrs, seed)
    objective = make_objective(env_id, algo, budget, eval_episodes, seed)
    study.optimize(objective, n_trials=trials, catch=(_Diverged,))
    return study


def best_config(study: Any) -> tuple[dict[str, Any], Any]:
    """The config of the study's best finished trial (all workers'), and that trial;
    ValueError when no trial has finished."""
    import optuna

    done = [t for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))]
    if not done:
        raise ValueError(f"study {study.study_name!r} has no finished trial yet")
    best = min(done, key=lambda t: (t.value, t.number))
    return dict(best.user_attrs["config"]), best


def write_best_config(study: Any, path: str | Path) -> Path:
    """Write the best trial's settings as a TOML config of ``ssme-envs train`` (atomically);
    its ``steps`` are the tuning budget: raise them for a full run."""
    from agents.run_config import config_toml as _toml
    from ssme_envs.outputs import write_text

    config, trial = best_config(study)
    if not np.isfinite(trial.value):
        raise ValueError(f"study {study.study_name!r}: the best trial's cost is {trial.value}")
    header = (
        f"# Best trial {trial.number} of Optuna study {study.study_name!r}: cost {trial.value:.6g} "
        f"(mean over {study.user_attrs.get('eval_episodes')} episodes from seed {EVAL_SEED}).\n"
        f"# Tuned with {config['steps']:,} steps per trial: raise steps for a full run.\n"
    )
    path = Path(path)
    write_text(path, header + _toml(config))
    return path


def summary(study: Any) -> str:
    """One line: the study's trials by state and its best trial."""
    import optuna

    states = [t.state for t in study.get_trials(deepcopy=False)]
    counts = ", ".join(
        f"{states.count(s)} {s.name.lower()}" for s in optuna.trial.TrialState if states.count(s)
    )
    try:
        _, best = best_config(study)
    except ValueError:
        return f"study {study.study_name!r}: {len(states)} trials ({counts}); none finished"
    return (f"study {study.study_name!r}: {len(states)} trials ({counts}); best trial {best.number}: "
            f"cost {best.value:.6g}")  # fmt: skip


__all__ = ["EVAL_SEED", "PPO_N_STEPS", "SPACES", "Budget", "best_config", "buffer_size", "check_budget",
           "make_objective", "open_storage", "policy_cost", "sample_ppo", "sample_sac", "sample_td3",
           "summary", "tune", "write_best_config"]  # fmt: skip
