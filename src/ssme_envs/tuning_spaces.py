"""The hyperparameter search spaces of :mod:`ssme_envs.tuning`: what a trial of PPO, SAC or TD3
samples within its study's budget. They define what a shared study searches, so every worker must
sample them alike, and they need none of the storage, Optuna runs or training that the rest of the
tuning drives."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Budget:
    """What every trial of a study gets: steps, parallel envs and evaluations (the search spaces
    depend on them, so every worker of a study must use the same)."""

    timesteps: int
    num_envs: int
    evaluations: int


def _choices(values: list[int], fits: Callable[[int], bool]) -> list[int]:
    """The values that fit the budget, at least the smallest (a study's choices never change)."""
    return [v for v in values if fits(v)] or values[:1]


_GAMMAS = [0.95, 0.98, 0.99, 0.995, 0.999]
PPO_N_STEPS = [8, 16, 32, 64, 128, 256, 512]


def buffer_size(timesteps: int) -> int:
    """The off-policy replay buffer: every step of a trial, at most SB3's default."""
    return min(1_000_000, timesteps)


def _net(trial: Any, sizes: list[str]) -> list[int]:
    return [int(width) for width in trial.suggest_categorical("net_arch", sizes).split("x")]


def sample_ppo(trial: Any, budget: Budget) -> tuple[dict[str, Any], list[int]]:
    """PPO's hyperparameters and net_arch: rollouts that fit ``evaluations`` times in the budget,
    minibatches dividing them."""
    per_round = budget.timesteps // budget.evaluations
    steps = _choices(PPO_N_STEPS, lambda n: n * budget.num_envs <= per_round)
    n_steps = trial.suggest_categorical("n_steps", steps)
    minibatches = trial.suggest_categorical("minibatches", [1, 2, 4, 8])
    hyper = {
        "n_steps": n_steps,
        "batch_size": max(2, n_steps * budget.num_envs // minibatches),
        "n_epochs": trial.suggest_categorical("n_epochs", [3, 5, 10, 20]),
        "learning_rate": trial.suggest_float("learning_rate", 1e-5, 3e-3, log=True),
        "gamma": trial.suggest_categorical("gamma", _GAMMAS),
        "gae_lambda": trial.suggest_categorical("gae_lambda", [0.8, 0.9, 0.95, 0.98, 1.0]),
        "ent_coef": trial.suggest_float("ent_coef", 1e-8, 1e-2, log=True),
        "clip_range": trial.suggest_categorical("clip_range", [0.1, 0.2, 0.3]),
    }
    return hyper, _net(trial, ["32x32", "64x64", "128x128", "256x256"])


def _off_policy(trial: Any, budget: Budget) -> dict[str, Any]:
    return {
        "learning_rate": trial.suggest_float("learning_rate", 1e-5, 3e-3, log=True),
        "batch_size": trial.suggest_categorical("batch_size", [64, 128, 256, 512]),
        "gamma": trial.suggest_categorical("gamma", _GAMMAS),
        "tau": trial.suggest_categorical("tau", [0.001, 0.005, 0.01, 0.02, 0.05]),
        "train_freq": trial.suggest_categorical("train_freq", [1, 2, 4, 8]),
        "gradient_steps": trial.suggest_categorical("gradient_steps", [1, 2, 4, 8, 16]),
        "learning_starts": trial.suggest_categorical(
            "learning_starts", _choices([0, 1_000, 10_000], lambda n: n <= budget.timesteps // 4)
        ),
        "buffer_size": buffer_size(budget.timesteps),  # not searched
    }


def sample_sac(trial: Any, budget: Budget) -> tuple[dict[str, Any], list[int]]:
    """SAC's hyperparameters and net_arch (entropy coefficient learnt, SB3's default)."""
    return _off_policy(trial, budget), _net(trial, ["64x64", "256x256", "400x300"])


def sample_td3(trial: Any, budget: Budget) -> tuple[dict[str, Any], list[int]]:
    """TD3's hyperparameters and net_arch (no action noise: the configs cannot hold one)."""
    hyper = _off_policy(trial, budget)
    hyper["target_policy_noise"] = trial.suggest_categorical("target_policy_noise", [0.1, 0.2, 0.3])
    return hyper, _net(trial, ["64x64", "256x256", "400x300"])


SPACES: dict[str, Callable[[Any, Budget], tuple[dict[str, Any], list[int]]]] = {
    "ppo": sample_ppo,
    "sac": sample_sac,
    "td3": sample_td3,
}
"""The search space of each algorithm: ``(trial, budget) -> (hyperparameters, net_arch)``."""
