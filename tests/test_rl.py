"""RL: config checks, smoke training of each algorithm, the train + evaluate path, the shipped
policies."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from agents import parse_controller
from agents.sb3 import SHIPPED, PolicyController, check_config, load_config, plan_steps, shipped_policy
from ssme_envs.cli import main
from ssme_envs.evaluation import evaluate
from ssme_envs.outputs import MARKER

TRACKING = "ssme_envs/EngineTracking-v0"
NOZZLE = "ssme_envs/NozzleTVC-v0"
RUN_FILES = ["config.toml", "normalization.json", "policy.json", "policy.safetensors", "training.json"]


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
        ({"env": TRACKING, "algo": "ppo", "action_noise_std": 0.1}, "SAC's and TD3's exploration, not ppo's"),
        (
            {"env": TRACKING, "algo": "td3", "action_noise_std": -0.1},
            r"action_noise_std must be a number in \[0, 1\]",
        ),
        ({"env": TRACKING, "algo": "td3", "action_noise_std": float("nan")}, "action_noise_std must be"),
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
    assert summary["steps"] == 2048 and [e["steps"] for e in summary["evaluations"]] == [1024, 2048]
    assert sorted(p.name for p in out.iterdir() if p.name != MARKER) == RUN_FILES  # no zip, nothing pickled
    best = max(summary["evaluations"], key=lambda e: e["return"])
    assert summary["kept"] == {"model": "final" if best["steps"] == 2048 else "best", "steps": best["steps"]}
    policy = PolicyController(out)
    results = evaluate(TRACKING, {algo: lambda env: PolicyController(out)}, ["nominal"], episodes=2)
    assert np.isfinite(results["nominal"][algo]["cost_mean"])
    assert policy.act(np.zeros(10, dtype=np.float32)).shape == (2,)
    with pytest.raises(ValueError, match=f"trained on {TRACKING} \\(10 observations\\), got 6"):
        PolicyController(out).act(np.zeros(6))


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policies_load_and_beat_the_zero_action(name):
    env_name, _, suffix = name.partition("-v0")
    env_id, trained_on = f"ssme_envs/{env_name}-v0", suffix.removeprefix("-") or "truth"
    files = sorted(p.name for p in shipped_policy(env_id, trained_on).iterdir())
    assert files == RUN_FILES
    scenario = {
        "EngineThrottle": "mission",
        "NozzleTVC": "random_steps",
        "LauncherPitch": "random_steps",
    }.get(env_name, "noise")
    factories = {
        "zero": parse_controller("zero", env_id),
        "ppo": parse_controller(f"ppo:{trained_on}", env_id),
    }
    results = evaluate(env_id, factories, [scenario], episodes=5)[scenario]
    assert results["ppo"]["cost_mean"] < 0.5 * results["zero"]["cost_mean"]


@pytest.mark.parametrize(
    ("config", "steps", "hyper", "note"),
    [
        ({"algo": "ppo", "steps": 20_000}, 20_032, {"n_steps": 313}, "n_steps 313 fitted"),
        ({"algo": "ppo", "steps": 5000, "num_envs": 4}, 5056, {"n_steps": 1264}, "5,056 steps for the 5,000"),
        ({"algo": "ppo", "steps": 5000, "hyperparameters": {"n_steps": 64}}, 8192, {"n_steps": 64},
         "whole rollouts of n_steps 64 x 64 envs: 8,192 steps for the 5,000 asked"),
        ({"algo": "ppo", "steps": 8192, "hyperparameters": {"n_steps": 64}}, 8192, {"n_steps": 64}, None),
        ({"algo": "sac", "steps": 5000}, 5056, {}, "train_freq 1 x 64 envs: 5,056 steps for the 5,000"),
        ({"algo": "td3", "steps": 100, "num_envs": 4, "hyperparameters": {"train_freq": 8}}, 128,
         {"train_freq": 8}, "128 steps"),
    ],
)  # fmt: skip
def test_steps_round_to_whole_rollouts_and_say_so(config, steps, hyper, note):
    planned, hyperparameters, said = plan_steps(check_config({"env": NOZZLE, **config}))
    assert (planned, hyperparameters) == (steps, hyper)
    assert said is None if note is None else note in said


def test_train_shorter_than_the_evaluation_interval_keeps_the_final_policy_and_evaluate_scores_it(
    tmp_path, capsys
):
    config = tmp_path / "tiny.toml"
    config.write_text(
        f'env = "{NOZZLE}"\nalgo = "ppo"\nnum_envs = 4\neval_episodes = 2\n'
        "[env_options]\nepisode_seconds = 0.4\n[policy]\nnet_arch = [16, 16]\n"
    )
    out = tmp_path / "run"
    args = ["train", "--config", str(config), "--steps", "300", "--tensorboard", "--out", str(out)]
    assert main(args) == 0  # 300 steps, far below the 50,000-step evaluation interval
    captured = capsys.readouterr()
    assert "ppo trains in whole rollouts of n_steps 80 x 4 envs: 320 steps for the 300 asked" in captured.err
    assert "kept the final policy (320 steps" in captured.out and "100%" in captured.err
    summary = json.loads((out / "training.json").read_text())
    assert summary["steps"] == 320 and summary["kept"] == {"model": "final", "steps": 320}
    assert load_config(out / "config.toml")["hyperparameters"] == {"n_steps": 80}
    assert sorted(p.name for p in out.iterdir() if p.name != MARKER) == sorted([*RUN_FILES, "tensorboard"])
    events = [p for p in (out / "tensorboard").rglob("*") if p.name.startswith("events.out.tfevents")]
    assert events
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    logged = EventAccumulator(str(events[0]))
    logged.Reload()
    # each evaluation at its own step, the final one too (it was recorded but never written)
    written = [(e.step, e.value) for e in logged.Scalars("eval/mean_reward")]
    evaluations = [(e["steps"], pytest.approx(e["return"], rel=1e-6)) for e in summary["evaluations"]]
    assert written == evaluations
    report = tmp_path / "eval"
    args = ["evaluate", "--env", NOZZLE, "--controllers", f"lqi,ppo:{out}", "--scenario", "step",
            "--episodes", "2", "--out", str(report)]  # fmt: skip
    assert main(args) == 0
    scored = json.loads((report / "results.json").read_text())["scenarios"]["step"]
    assert sorted(scored) == sorted(["lqi", f"ppo:{out}"]) and np.isfinite(scored[f"ppo:{out}"]["cost_mean"])
    assert main([*args[:4], f"sac:{out}", *args[5:]]) == 2
    assert capsys.readouterr().err.strip().endswith(f"{out}: holds a ppo policy, not sac")


def test_the_rl_extra_installs_what_training_uses():
    pyproject = load_config(Path(__file__).parents[1] / "pyproject.toml")
    extras = pyproject["project"]["optional-dependencies"]
    for extra, needed in (("rl", {"safetensors", "tqdm", "rich", "tensorboard"}), ("test", {"safetensors"})):
        names = {req.split(">")[0].split("=")[0].split(";")[0].strip() for req in extras[extra]}
        assert needed <= names, f"{extra} lacks {needed - names}"
        assert "torch==2.13.0" in extras[extra]


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_the_documented_5000_step_runs_train_and_score(algo, tmp_path):
    out = tmp_path / algo
    assert main(["train", "--env", NOZZLE, "--algo", algo, "--steps", "5000", "--out", str(out)]) == 0
    assert json.loads((out / "training.json").read_text())["steps"] == 5056  # 79 x 64 envs
    args = ["evaluate", "--env", NOZZLE, "--controllers", f"lqi,{algo}:{out}", "--episodes", "2",
            "--out", str(tmp_path / "eval")]  # fmt: skip
    assert main(args) == 0
    scored = json.loads((tmp_path / "eval" / "results.json").read_text())["scenarios"]
    assert all(np.isfinite(scored[scenario][f"{algo}:{out}"]["cost_mean"]) for scenario in scored)


def test_init_policy_starts_from_a_trained_run(tmp_path):
    """``init_policy`` loads a run's weights before training: with a zero learning rate the new
    run's weights are the old run's, bit for bit; a run of another env or network is refused."""
    from safetensors.numpy import load_file

    base = (f'env = "{TRACKING}"\nalgo = "ppo"\nnum_envs = 4\neval_freq = 256\neval_episodes = 2\n'
            "[env_options]\nepisode_seconds = 2.0\n[policy]\nnet_arch = [8, 8]\n")  # fmt: skip
    first = tmp_path / "first.toml"
    first.write_text(base + "[hyperparameters]\nn_steps = 64\nbatch_size = 64\n")
    assert main(["train", "--config", str(first), "--steps", "256", "--out", str(tmp_path / "a")]) == 0
    second = tmp_path / "second.toml"
    hyper = "[hyperparameters]\nn_steps = 64\nbatch_size = 64\nlearning_rate = 0.0\n"
    second.write_text(f'init_policy = "{tmp_path / "a"}"\n' + base + hyper)
    assert (
        main(
            ["train", "--config", str(second), "--steps", "256", "--seed", "5", "--out", str(tmp_path / "b")]
        )
        == 0
    )
    a, b = (load_file(tmp_path / run / "policy.safetensors") for run in ("a", "b"))
    assert sorted(a) == sorted(b) and all(np.array_equal(a[k], b[k]) for k in a)
    wider = tmp_path / "wider.toml"
    wider.write_text(second.read_text().replace("[8, 8]", "[8, 16]"))
    assert main(["train", "--config", str(wider), "--steps", "256", "--out", str(tmp_path / "c")]) == 2


def test_a_refused_init_policy_leaves_no_run_directory(tmp_path, capsys):
    config = tmp_path / "bad.toml"
    config.write_text(f'env = "{TRACKING}"\nalgo = "ppo"\ninit_policy = "{tmp_path / "nowhere"}"\n')
    assert main(["train", "--config", str(config), "--steps", "64", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "no such policy directory" in err[0]
    assert not (tmp_path / "run").exists()


def test_every_evaluation_runs_the_same_episodes(tmp_path, monkeypatch):
    """The kept policy is the best of evaluations on one set of episodes: each evaluation starts
    from the same first observations (the evaluation env is reseeded), not from the stream's next
    episodes, which would make the best evaluation the luckiest draw."""
    import stable_baselines3.common.evaluation as sb3_evaluation

    firsts = []

    def first_observations(model, env, n_eval_episodes, warn):
        env.reset()
        firsts.append(env.get_original_obs().copy())
        return 0.0, 0.0

    monkeypatch.setattr(sb3_evaluation, "evaluate_policy", first_observations)
    config = tmp_path / "c.toml"
    config.write_text(
        f'env = "{NOZZLE}"\nalgo = "ppo"\nnum_envs = 4\neval_freq = 256\neval_episodes = 3\n'
        "[hyperparameters]\nn_steps = 64\nbatch_size = 64\n[policy]\nnet_arch = [8, 8]\n"
    )
    assert main(["train", "--config", str(config), "--steps", "768", "--out", str(tmp_path / "run")]) == 0
    assert len(firsts) == 3 and all(np.array_equal(f, firsts[0]) for f in firsts)
    assert len({tuple(row) for row in firsts[0].round(6)}) == 3  # three different episodes


def test_train_out_is_staged_like_every_command(tmp_path, capsys, monkeypatch):
    """A directory holding other files is refused untouched; a run that fails leaves the earlier
    run whole (train wrote into --out directly, and overwrote a config.toml it found there)."""
    import agents.sb3

    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "config.toml").write_text("precious")
    argv = ["train", "--env", NOZZLE, "--algo", "ppo", "--steps", "64", "--out"]
    assert main([*argv, str(foreign)]) == 2
    assert "is not empty and was not written by ssme-envs" in capsys.readouterr().err
    assert [p.name for p in foreign.iterdir()] == ["config.toml"] and (
        foreign / "config.toml"
    ).read_text() == "precious"

    def failing(config, out, progress=True, source="config"):
        (out / "policy.json").write_text("{}")
        raise ValueError("the run failed")

    earlier = tmp_path / "run"
    earlier.mkdir()
    (earlier / MARKER).write_text("{}")
    (earlier / "policy.json").write_text("earlier")
    monkeypatch.setattr(agents.sb3, "train", failing)
    assert main([*argv, str(earlier)]) == 2
    assert capsys.readouterr().err == "error: the run failed\n"
    assert sorted(p.name for p in earlier.iterdir()) == [MARKER, "policy.json"]
    assert (earlier / "policy.json").read_text() == "earlier"
    assert not [p.name for p in tmp_path.iterdir() if ".new-" in p.name]  # the failed run's directory


def test_td3_explores_with_the_configured_action_noise(tmp_path):
    """``action_noise_std``: TD3 adds Gaussian noise of that std to its actions while it collects
    (SB3 adds none by default, so TD3 explored by nothing); the run records it and is repeatable."""
    base = (f'env = "{NOZZLE}"\nalgo = "td3"\nnum_envs = 4\neval_episodes = 2\naction_noise_std = 0.3\n'
            "[env_options]\nepisode_seconds = 0.4\n[policy]\nnet_arch = [8, 8]\n"
            "[hyperparameters]\nlearning_starts = 100\nbuffer_size = 1000\n")  # fmt: skip
    config = tmp_path / "td3.toml"
    config.write_text(base)
    runs = []
    for name in ("a", "b", "quiet"):
        if name == "quiet":
            config.write_text(base.replace("action_noise_std = 0.3", "action_noise_std = 0.0"))
        assert main(["train", "--config", str(config), "--steps", "200", "--out", str(tmp_path / name)]) == 0
        runs.append((tmp_path / name / "policy.safetensors").read_bytes())
    assert load_config(tmp_path / "a" / "config.toml")["action_noise_std"] == 0.3
    assert runs[0] == runs[1] and runs[0] != runs[2]  # the noise changed what was learned, repeatably
