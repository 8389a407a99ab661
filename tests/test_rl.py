"""RL: config checks, smoke training of each algorithm, the shipped policies."""

import json
import sys

import numpy as np
import pytest

from agents import parse_controller
from agents.sb3 import SHIPPED, PolicyController, check_config, shipped_policy
from ssme_envs.cli import main
from ssme_envs.evaluation import evaluate

TRACKING = "ssme_envs/EngineTracking-v0"


@pytest.mark.parametrize(
    ("config", "message"),
    [
        ({"env": TRACKING, "algo": "ppo", "stepz": 10}, "unknown key 'stepz'"),
        ({"env": TRACKING, "algo": "ppo", "steps": "many"}, "steps must be int"),
        ({"env": TRACKING, "algo": "dqn"}, "unknown algo 'dqn'; choose one of ppo, sac, td3"),
        ({"env": TRACKING, "algo": "ppo", "hyperparameters": {"n_stepz": 8}}, "hyperparameters.n_stepz"),
        ({"env": TRACKING, "algo": "sac", "hyperparameters": {"gamma": "high"}}, "gamma must be a number"),
        ({"env": TRACKING, "algo": "ppo", "policy": {"net_arch": [64, -1]}}, "net_arch"),
        ({"env": TRACKING, "algo": "ppo", "policy": {"activation": "relu"}}, "policy.activation"),
        ({"algo": "ppo"}, "needs 'env' and 'algo'"),
    ],
)
def test_bad_configs_name_the_key(config, message):
    with pytest.raises(ValueError, match=message):
        check_config(config)


def test_train_command_rejects_bad_input(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('env = "ssme_envs/EngineTracking-v0"\nalgo = "ppo"\n[hyperparameters]\nbatch = 64\n')
    option = tmp_path / "option.toml"
    nozzle = 'env = "ssme_envs/NozzleTVC-v0"\nalgo = "ppo"\nnum_envs = 2\n'
    option.write_text(nozzle + "[env_options]\npowr = 90\n")
    value = tmp_path / "value.toml"
    value.write_text(nozzle + "[hyperparameters]\nn_steps = 0\n")
    cases = [
        (["--config", str(option)], "env_options:"),
        (["--config", str(value)], "hyperparameters: `n_steps * n_envs` must be greater than 1"),
        (["--env", TRACKING, "--algo", "a2c"], "unknown algo 'a2c'"),
        (["--env", "Pong-v5", "--algo", "ppo"], "unknown env 'Pong-v5'"),
        (["--config", str(bad)], "hyperparameters.batch is not a ppo hyperparameter"),
        (["--config", str(tmp_path / "missing.toml")], "cannot read config"),
    ]
    for args, message in cases:
        assert main(["train", *args, "--out", str(tmp_path / "run")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error: ") and message in err and "\n" not in err


def test_without_stable_baselines3_the_error_says_what_to_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # import fails as if not installed
    assert main(["train", "--env", TRACKING, "--algo", "ppo", "--out", str(tmp_path / "run")]) == 2
    assert 'pip install "ssme-envs[rl]"' in capsys.readouterr().err
    with pytest.raises(ValueError, match="need stable-baselines3"):
        PolicyController(shipped_policy(TRACKING))


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_each_algorithm_trains_saves_and_acts(algo, tmp_path):
    config = tmp_path / "smoke.toml"
    config.write_text(
        f'env = "{TRACKING}"\nalgo = "{algo}"\nnum_envs = 4\neval_freq = 1024\neval_episodes = 2\n'
        "[env_options]\nepisode_seconds = 2.0\n[policy]\nnet_arch = [16, 16]\n"
        + ("[hyperparameters]\nn_steps = 64\nbatch_size = 64\n" if algo == "ppo" else "")
    )
    out = tmp_path / algo
    assert main(["train", "--config", str(config), "--steps", "2048", "--seed", "1", "--out", str(out)]) == 0
    summary = json.loads((out / "training.json").read_text())
    assert summary["steps"] >= 2048 and summary["evaluations"]
    policy = PolicyController(out)
    results = evaluate(TRACKING, {algo: lambda env: PolicyController(out)}, ["nominal"], episodes=2)
    assert np.isfinite(results["nominal"][algo]["cost_mean"])
    assert policy.act(np.zeros(10, dtype=np.float32)).shape == (2,)
    with pytest.raises(ValueError, match=f"trained on {TRACKING} \\(10 observations\\), got 6"):
        PolicyController(out).act(np.zeros(6))


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policies_load_and_beat_the_zero_action(name):
    env_id = "ssme_envs/" + name.removesuffix("-identified")
    trained_on = "identified" if name.endswith("-identified") else "truth"
    assert (shipped_policy(env_id, trained_on) / "model.zip").exists()
    scenario = {"EngineThrottle-v0": "mission", "NozzleTVC-v0": "random_steps"}.get(name, "noise")
    factories = {
        "zero": parse_controller("zero", env_id),
        "ppo": parse_controller(f"ppo:{trained_on}", env_id),
    }
    results = evaluate(env_id, factories, [scenario], episodes=5)[scenario]
    assert results["ppo"]["cost_mean"] < 0.5 * results["zero"]["cost_mean"]
