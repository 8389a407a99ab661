"""rl-zoo3 makes and trains every registered env with the shipped hyperparameter entries."""

import importlib
import sys

import gymnasium as gym
import pytest

from ssme_envs.zoo import ENV_IDS

pytest.importorskip("rl_zoo3")


def test_every_registered_env_has_an_entry_per_algorithm():
    registered = {env_id for env_id in gym.registry if env_id.startswith("ssme_envs/")}
    assert registered == set(ENV_IDS)
    for algo in ("ppo", "sac", "td3"):
        assert set(importlib.import_module(f"ssme_envs.zoo.{algo}").hyperparams) == registered


@pytest.mark.parametrize(
    ("algo", "env_id"), [("ppo", env_id) for env_id in ENV_IDS] + [("sac", ENV_IDS[0]), ("td3", ENV_IDS[0])]
)
def test_the_zoo_trains_and_saves(algo, env_id, tmp_path, monkeypatch):
    from rl_zoo3.train import train

    small = {"ppo": ["n_envs:4", "n_steps:64", "batch_size:64"], "sac": ["learning_starts:100"],
             "td3": ["learning_starts:100"]}[algo]  # fmt: skip
    argv = [
        "rl_zoo3.train", "--algo", algo, "--env", env_id, "--gym-packages", "ssme_envs",
        "--conf-file", f"ssme_envs.zoo.{algo}", "-n", "400", "--eval-freq", "-1",
        "--log-folder", str(tmp_path), "--seed", "0", "--hyperparams", *small,
    ]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    train()
    name = env_id.replace("/", "-")
    assert (tmp_path / algo / f"{name}_1" / f"{name}.zip").exists()
