"""The rl-zoo3 PPO entries are the settings the shipped PPO policies were trained with."""

import ast
import importlib
import sys
from pathlib import Path

import pytest

from ssme_envs.zoo import ENV_IDS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CONFIGS = Path(__file__).resolve().parents[1] / "experiments" / "configs"


def _config_of(env_id: str) -> dict:
    """The env's plain PPO config: of the PPO configs on the env, the one with the shortest name
    (the others, such as ``ppo_<env>_residual.toml``, are variants of it)."""
    configs = {path: tomllib.loads(path.read_text()) for path in CONFIGS.glob("ppo_*.toml")}
    ours = [path for path, config in configs.items() if config["env"] == env_id]
    return configs[min(ours, key=lambda path: len(path.name))]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_zoo_ppo_entry_is_the_shipped_config(env_id):
    # a fresh module: rl-zoo3's train pops keys (n_timesteps) from the dicts it was given
    hyperparams = importlib.reload(importlib.import_module("ssme_envs.zoo.ppo")).hyperparams
    config, entry = _config_of(env_id), hyperparams[env_id]
    assert entry["n_timesteps"] == config["steps"]
    assert entry["n_envs"] == config["num_envs"]
    for key, value in config["hyperparameters"].items():
        assert entry[key] == value, key
    assert (
        ast.literal_eval(entry["policy_kwargs"].removeprefix("dict(net_arch=").removesuffix(")"))
        == (config["policy"]["net_arch"])
    )
    normalize = ast.literal_eval(entry["normalize"])
    assert normalize == {"norm_obs": True, "norm_reward": True, "gamma": config["hyperparameters"]["gamma"]}
