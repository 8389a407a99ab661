"""The runs tried beside the shipped policies (experiments/tried/): each config in
experiments/configs that the records read as a tried run has its run there, trained from that
config, and its kept policy loads through a controller spec and acts within the action space."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import ssme_envs  # noqa: F401  (registers the environments)
from agents import parse_controller

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"
# the configs the records read as tried runs: the off-policy algorithms and the penalized residual
TRIED_CONFIGS = sorted(
    path.stem
    for pattern in ("sac_*.toml", "td3_*.toml", "ppo_*_residual_penalty.toml")
    for path in (EXPERIMENTS / "configs").glob(pattern)
)
# what `ssme-envs train` writes beside the source config's keys when the config leaves them out
FILLED = {"env_options": {}, "tensorboard": False}


def test_every_tried_config_has_its_run_and_no_other_run_is_there() -> None:
    assert TRIED_CONFIGS  # the globs above still find the configs
    runs = sorted(p.name for p in (EXPERIMENTS / "tried").iterdir() if p.is_dir())
    assert runs == TRIED_CONFIGS


@pytest.mark.parametrize("name", TRIED_CONFIGS)
def test_a_tried_run_is_its_config_trained(name: str) -> None:
    run = EXPERIMENTS / "tried" / name
    source = tomllib.loads((EXPERIMENTS / "configs" / f"{name}.toml").read_text())
    used = tomllib.loads((run / "config.toml").read_text())
    assert used == {**FILLED, **source}
    training = json.loads((run / "training.json").read_text())
    assert (training["env"], training["algo"]) == (source["env"], source["algo"])
    assert training["steps_requested"] == source["steps"]
    # PPO trains whole rollouts (num_envs x n_steps); the off-policy algorithms, the steps asked
    rollout = source["num_envs"] * source["hyperparameters"]["n_steps"] if source["algo"] == "ppo" else 1
    assert 0 <= training["steps"] - source["steps"] < rollout
    assert 0 < training["kept"]["steps"] <= training["steps"]
    kept = [e for e in training["evaluations"] if e["steps"] == training["kept"]["steps"]]
    assert training["kept"]["model"] == "final" or kept, "the best policy is one of the evaluations"


@pytest.mark.parametrize("name", TRIED_CONFIGS)
def test_a_tried_policy_loads_and_acts_within_the_action_space(name: str) -> None:
    run = EXPERIMENTS / "tried" / name
    config = tomllib.loads((run / "config.toml").read_text())
    env = gym.make(config["env"])
    controller = parse_controller(f"{config['algo']}:{run}", config["env"])(env.unwrapped)
    controller.reset(seed=0)
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        action = np.asarray(controller.act(obs[None, :]))[0]
        assert env.action_space.contains(action.astype(env.action_space.dtype)), action
        obs, *_ = env.step(action)
    env.close()
