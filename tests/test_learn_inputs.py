"""Bad input to training, tuning and trained policies: refused up front with one `error:` line (the
CLI, exit code 2) or a ValueError/TypeError naming the problem, never a traceback or a quietly
wrong result."""

from __future__ import annotations

import hashlib
import inspect
import json
import os
import re
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("stable_baselines3")

from agents import parse_controller
from agents.hyperparameters import HYPERPARAMETERS
from agents.policy_files import algorithm_class, load_policy
from agents.sb3 import check_config, load_config, shipped_policy
from ssme_envs.cli import main

NOZZLE = "ssme_envs/NozzleTVC-v0"
ROOT = Path(__file__).resolve().parents[1]


def _config(tmp_path: Path, algo: str, body: str, name: str = "c.toml") -> Path:
    path = tmp_path / name
    path.write_text(f'env = "{NOZZLE}"\nalgo = "{algo}"\nnum_envs = 2\n{body}\n')
    return path


def _cli(*argvs: list[str]) -> list[subprocess.CompletedProcess]:
    """Run ``python -m ssme_envs.cli ARGV`` for each argv, a few at once (each pays the imports)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}

    def run(argv: list[str]) -> subprocess.CompletedProcess:
        command = [sys.executable, "-m", "ssme_envs.cli", *argv]
        return subprocess.run(command, capture_output=True, text=True, env=env, timeout=300, check=False)

    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        return list(pool.map(run, argvs))


def _one_error(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


HYPER = "[hyperparameters]\n"
# (algo, config body, what the error line names): the audit's cases, each refused before training
BAD_TRAINING = [
    ("ppo", HYPER + "batch_size = 0", "hyperparameters.batch_size must be an integer >= 1, got 0"),
    ("ppo", HYPER + "n_epochs = 0", "hyperparameters.n_epochs must be an integer >= 1, got 0"),
    ("ppo", HYPER + 'target_kl = "x"', "hyperparameters.target_kl must be a number > 0, got 'x'"),
    ("sac", HYPER + "train_freq = 0", "hyperparameters.train_freq must be an integer >= 1, got 0"),
    ("sac", HYPER + 'action_noise = "x"', "hyperparameters.action_noise is not a sac hyperparameter"),
    ("td3", HYPER + "policy_delay = 0", "hyperparameters.policy_delay must be an integer >= 1, got 0"),
    ("ppo", HYPER + "_init_setup_model = false", "hyperparameters._init_setup_model is not a ppo"),
    ("ppo", "[policy]\nnet_arch = [200000, 200000]", "each 1 to 4096 units, got [200000, 200000]"),
    ("ppo", HYPER + "gamma = 2.0", "hyperparameters.gamma must be a number in [0, 1], got 2.0"),
    ("ppo", HYPER + "gae_lambda = 5.0", "hyperparameters.gae_lambda must be a number in [0, 1], got 5.0"),
    ("ppo", HYPER + "clip_range = -1.0", "hyperparameters.clip_range must be a number > 0, got -1.0"),
    ("sac", HYPER + "learning_starts = -5", "hyperparameters.learning_starts must be an integer >= 0"),
    ("td3", HYPER + "target_noise_clip = -1.0", "hyperparameters.target_noise_clip must be a number >= 0"),
    (
        "ppo",
        HYPER + "n_steps = 8\nbatch_size = 1024",
        "hyperparameters.batch_size 1024 is more than a rollout",
    ),
]


@pytest.mark.parametrize(("algo", "body", "message"), BAD_TRAINING)
def test_bad_training_configs_exit_2_with_one_error_line_before_training(
    tmp_path, capsys, algo, body, message
):
    config = _config(tmp_path, algo, body)
    assert main(["train", "--config", str(config), "--steps", "64", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: config {config}: ") and message in err, err
    assert not (tmp_path / "run").exists()  # refused before the run directory was made


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("[env_options]\nsensor_noise = -1.0", "sensor_noise must be a number in [0, "),
        ('[env_options]\nplant = "steel"', "plant must be one of"),
        ("[env_options]\nwobble = 1", "env_options: "),
    ],
)
def test_bad_env_options_name_the_config_file_and_leave_no_run(tmp_path, capsys, body, message):
    """A value the env refuses reaches the user as one line naming the config file; nothing of
    the run is written."""
    config = _config(tmp_path, "ppo", body)
    assert main(["train", "--config", str(config), "--steps", "64", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: config {config}: ") and message in err, err
    assert not (tmp_path / "run").exists()


def test_the_command_itself_prints_one_line_not_a_traceback(tmp_path):
    """Through ``python -m ssme_envs.cli``: cases that ended in tracebacks deep inside SB3 or torch."""
    cases = [BAD_TRAINING[0], BAD_TRAINING[6], BAD_TRAINING[7]]  # batch_size 0, _init_setup_model, net_arch
    argvs = []
    for i, (algo, body, _) in enumerate(cases):
        config = _config(tmp_path, algo, body, f"c{i}.toml")
        argvs.append(["train", "--config", str(config), "--steps", "64", "--out", str(tmp_path / f"run{i}")])
    for i, ((_, _, message), result) in enumerate(zip(cases, _cli(*argvs), strict=True)):
        line = _one_error(result)
        assert line.startswith(f"error: config {tmp_path / f'c{i}.toml'}: ") and message in line, line
        assert not (tmp_path / f"run{i}").exists()


@pytest.mark.parametrize(
    ("algo", "hyper", "message"),
    [
        ("ppo", {"learning_rate": -1e-4}, r"learning_rate must be a number >= 0"),
        ("ppo", {"learning_rate": float("nan")}, r"learning_rate must be a number >= 0, got nan"),
        ("ppo", {"n_steps": 64.0}, r"n_steps must be an integer, got 64.0"),
        ("ppo", {"clip_range_vf": 0.0}, r"clip_range_vf must be a number > 0"),
        ("ppo", {"max_grad_norm": 0}, r"max_grad_norm must be a number > 0"),
        ("ppo", {"vf_coef": -0.5}, r"vf_coef must be a number >= 0"),
        ("ppo", {"normalize_advantage": 1}, r"normalize_advantage must be true or false"),
        ("ppo", {"sde_sample_freq": -2}, r"sde_sample_freq must be an integer >= -1"),
        ("ppo", {"rollout_buffer_kwargs": {}}, r"rollout_buffer_kwargs is not a ppo hyperparameter"),
        ("ppo", {"policy_delay": 2}, r"policy_delay is not a ppo hyperparameter"),
        ("sac", {"tau": 0.0}, r"tau must be a number in \(0, 1\]"),
        ("sac", {"tau": 1.5}, r"tau must be a number in \(0, 1\]"),
        ("sac", {"gradient_steps": 0}, r"gradient_steps must be an integer >= 1, or -1"),
        ("sac", {"buffer_size": 0}, r"buffer_size must be an integer >= 1"),
        ("sac", {"ent_coef": "auto_-1"}, r"ent_coef must be \"auto\", \"auto_<initial value > 0>\""),
        ("sac", {"ent_coef": -0.1}, r"ent_coef must be \"auto\""),
        ("sac", {"target_entropy": "high"}, r"target_entropy must be \"auto\" or a number"),
        ("sac", {"replay_buffer_class": "x"}, r"replay_buffer_class is not a sac hyperparameter"),
        ("sac", {"optimize_memory_usage": True}, r"optimize_memory_usage is not a sac hyperparameter"),
        ("td3", {"target_policy_noise": -0.1}, r"target_policy_noise must be a number >= 0"),
        ("td3", {"n_steps": 0}, r"n_steps must be an integer >= 1"),
        ("td3", {"use_sde": True}, r"use_sde is not a td3 hyperparameter"),
    ],
)
def test_check_config_names_each_bad_hyperparameter(algo, hyper, message):
    with pytest.raises(ValueError, match=rf"^src\.toml: hyperparameters\.{message}"):
        check_config({"env": NOZZLE, "algo": algo, "hyperparameters": hyper}, "src.toml")


def test_learning_starts_beyond_the_steps_is_refused():
    config = {"env": NOZZLE, "algo": "td3", "steps": 5000, "hyperparameters": {"learning_starts": 5000}}
    with pytest.raises(ValueError, match="learning_starts 5000 leaves none of the 5000 steps to learn from"):
        check_config(config)
    check_config({**config, "steps": 5001})


@pytest.mark.parametrize("net_arch", [[4097], [64] * 17, [64, True], [64, 64.0], []])
def test_net_arch_is_bounded(net_arch):
    with pytest.raises(ValueError, match=r"policy\.net_arch must be a list of 1 to 16 layer sizes"):
        check_config({"env": NOZZLE, "algo": "ppo", "policy": {"net_arch": net_arch}})


def test_good_values_and_every_shipped_and_example_config_pass():
    good = {
        "ppo": {"learning_rate": 0.0, "gamma": 1.0, "gae_lambda": 0.0, "target_kl": 0.01, "n_epochs": 1,
                "use_sde": True, "sde_sample_freq": -1, "clip_range_vf": 0.2},
        "sac": {"ent_coef": "auto_0.1", "target_entropy": -2, "gradient_steps": -1, "learning_starts": 0,
                "tau": 1.0, "n_steps": 3},
        "td3": {"policy_delay": 1, "target_policy_noise": 0.0, "target_noise_clip": 0.0, "train_freq": 4},
    }  # fmt: skip
    for algo, hyper in good.items():
        check_config({"env": NOZZLE, "algo": algo, "hyperparameters": hyper, "policy": {"net_arch": [4096]}})
    paths = sorted((ROOT / "experiments" / "configs").glob("*.toml"))
    paths += sorted((ROOT / "agents" / "policies").glob("*/config.toml"))
    assert paths
    for path in paths:
        check_config(load_config(path), str(path))


@pytest.mark.parametrize("algo", sorted(HYPERPARAMETERS))
def test_the_settable_hyperparameters_are_public_arguments_of_sb3(algo):
    accepted = inspect.signature(algorithm_class(algo).__init__).parameters
    for name in HYPERPARAMETERS[algo]:
        assert name in accepted and not name.startswith("_"), name


def test_an_error_building_the_model_is_one_config_line(tmp_path, capsys, monkeypatch):
    """What the checks let through and SB3 or torch refuse while building (here a stand-in for
    a network too large to allocate) is the config's fault: one line naming the config."""
    import stable_baselines3

    class Unbuildable(stable_baselines3.PPO):
        def _setup_model(self) -> None:
            raise RuntimeError("cannot allocate 160 GB")

    monkeypatch.setattr(stable_baselines3, "PPO", Unbuildable)
    config = _config(tmp_path, "ppo", HYPER + "n_steps = 64\nbatch_size = 64")
    assert main(["train", "--config", str(config), "--steps", "64", "--out", str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err == (
        f"error: config {config}: hyperparameters or policy: cannot build the ppo model "
        "(RuntimeError: cannot allocate 160 GB)\n"
    )
    assert not (tmp_path / "run").exists()


TUNE = ["tune", "--env", NOZZLE, "--algo", "ppo", "--study", "s", "--trials", "1", "--timesteps", "64",
        "--num-envs", "2", "--evaluations", "1", "--eval-episodes", "1"]  # fmt: skip


@pytest.mark.parametrize(
    "text",
    [
        '{"op_code": 0, "worker_id": "x"}\n',  # Optuna's replay: KeyError
        "garbage\n",  # Optuna: a JSONDecodeError, only once something follows it
        "\x00\x81 not text",
        "[1, 2]\n",
    ],
)
def test_a_corrupt_journal_is_named_and_left_alone(tmp_path, capsys, text):
    journal = tmp_path / "j.log"
    journal.write_text(text, encoding="latin-1")
    assert main([*TUNE, "--storage", f"journal:{journal}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: --storage journal:{journal}: "), err
    assert f"{journal} is not a readable Optuna journal" in err
    assert journal.read_text(encoding="latin-1") == text  # nothing appended


def test_an_unwritable_tune_out_is_refused_before_any_trial(tmp_path):
    journal = tmp_path / "j.log"
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    # root writes through permission bits: /proc takes no new file from anyone
    target = Path("/proc/best.toml") if os.geteuid() == 0 else locked / "best.toml"
    try:
        (result,) = _cli([*TUNE, "--storage", f"journal:{journal}", "--out", str(target)])
    finally:
        locked.chmod(0o755)
    line = _one_error(result)
    assert line.startswith(f"error: --out {target}: cannot write in {target.parent}"), line
    assert not journal.exists()  # no study, no trial


def _nozzle_copy(tmp_path: Path) -> Path:
    return Path(shutil.copytree(shipped_policy(NOZZLE), tmp_path / "policy"))


def _edit_json(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    ("space", "bound", "value"),
    [("action_space", "high", [-1.0]), ("action_space", "low", [0.0]), ("observation_space", "high", None)],
)
def test_a_policy_whose_spaces_are_not_the_envs_is_refused(tmp_path, space, bound, value):
    import gymnasium as gym

    directory = _nozzle_copy(tmp_path)
    env = gym.make(NOZZLE)
    parse_controller(f"ppo:{directory}", NOZZLE)(env)  # the shipped files act as they are

    def change(data):
        if value is None:  # one observation bound moved
            data[space][bound][0] = 123.0
        else:
            data[space][bound] = value

    _edit_json(directory / "policy.json", change)
    what = space.removesuffix("_space")
    with pytest.raises(
        ValueError, match=rf"policy: the policy's {what} space Box\(.* is not {re.escape(NOZZLE)}'s Box\("
    ):
        parse_controller(f"ppo:{directory}", NOZZLE)(env)
    env.close()


def test_evaluate_refuses_a_policy_with_a_moved_action_bound(tmp_path):
    directory = _nozzle_copy(tmp_path)
    _edit_json(directory / "policy.json", lambda d: d["action_space"].update(high=[-1.0]))
    argv = ["evaluate", "--env", NOZZLE, "--controllers", f"ppo:{directory}", "--scenario", "step",
            "--episodes", "1", "--out", str(tmp_path / "eval")]  # fmt: skip
    (result,) = _cli(argv)
    line = _one_error(result)
    assert f"{directory}: the policy's action space" in line and f"is not {NOZZLE}'s" in line, line


def test_init_policy_with_other_spaces_is_refused(tmp_path, capsys):
    directory = _nozzle_copy(tmp_path)
    _edit_json(directory / "policy.json", lambda d: d["action_space"].update(low=[0.0]))
    body = (
        f'init_policy = "{directory}"\n'
        + HYPER
        + "n_steps = 64\nbatch_size = 64\n[policy]\nnet_arch = [64, 64]"
    )
    config = _config(tmp_path, "ppo", body)
    assert main(["train", "--config", str(config), "--steps", "128", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"error: {directory}: the policy's action space" in err


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_weights_are_refused_naming_the_file(tmp_path, bad):
    import safetensors.torch

    directory = _nozzle_copy(tmp_path)
    weights = directory / "policy.safetensors"
    tensors = safetensors.torch.load(weights.read_bytes())
    key = sorted(tensors)[0]
    tensors[key].view(-1)[0] = bad
    raw = safetensors.torch.save(tensors)
    weights.write_bytes(raw)
    _edit_json(directory / "policy.json", lambda d: d.update(weights_sha256=hashlib.sha256(raw).hexdigest()))
    with pytest.raises(ValueError, match=rf"{re.escape(str(weights))}: {key} holds non-finite weights"):
        load_policy(directory)


def test_a_controller_spec_that_is_not_a_string_is_a_type_error(tmp_path):
    from ssme_envs.pipelines import evaluate_to

    with pytest.raises(TypeError, match=r"a controller spec is a string .* got None"):
        parse_controller(None, NOZZLE)
    with pytest.raises(TypeError, match="a controller spec is a string"):
        evaluate_to(tmp_path / "e", NOZZLE, controllers=[None], episodes=1)
    assert not (tmp_path / "e").exists()


@pytest.mark.parametrize("controllers", [["zero"], {"zero": None}, {3: lambda env: None}])
def test_evaluate_refuses_controllers_that_are_not_named_factories(controllers):
    from ssme_envs.evaluation import evaluate

    with pytest.raises(TypeError, match="controllers"):
        evaluate("ssme_envs/EngineTracking-v0", controllers, episodes=1)


def test_evaluate_to_refuses_one_spec_given_as_a_string(tmp_path):
    from ssme_envs.pipelines import evaluate_to

    with pytest.raises(TypeError, match="list of controller specs"):
        evaluate_to(tmp_path / "out", "ssme_envs/EngineTracking-v0", controllers="lqi", episodes=1)


def test_a_default_minibatch_above_the_rollout_is_the_rollout_and_trains_the_same_bits():
    """A short run fits n_steps below PPO's default batch_size of 64: SB3 then trains on the whole
    rollout as one minibatch (with a warning). The plan sets batch_size to the rollout, which SB3
    trains on identically, silently."""
    import gymnasium as gym
    import stable_baselines3
    import torch

    from agents.run_config import check_config, plan_steps

    config = check_config({"algo": "ppo", "env": NOZZLE, "steps": 10, "num_envs": 1, "hyperparameters": {}})
    steps, hyper, note = plan_steps(config)
    assert (steps, hyper["n_steps"], hyper["batch_size"]) == (
        10,
        10,
        10,
    ) and "batch_size 10: one rollout" in note

    def trained(batch_size: int) -> list:
        model = stable_baselines3.PPO("MlpPolicy", gym.make(NOZZLE), n_steps=10, batch_size=batch_size,
                                      n_epochs=2, seed=3, device="cpu")  # fmt: skip
        model.learn(10)
        return [p.detach().clone() for p in model.policy.parameters()]

    with pytest.warns(UserWarning, match="mini-batch size of 64"):
        by_sb3 = trained(64)
    assert all(torch.equal(a, b) for a, b in zip(by_sb3, trained(10), strict=True))


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ('{"schema": 2, "dt": 0.04, "A": [[0.5]]}', "line 1: not an Optuna journal record"),  # a model.json
        ('{"schema": 2, "dt": 0.04}\n', "line 1: not an Optuna journal record"),
        (
            '{"op_code": 0, "worker_id": "x", "study_name": "s", "directions": [1]}\n{"op_code": 0, "wor',
            r"line 2: its last line is cut off \(an interrupted write\?\): remove that line",
        ),
        (  # cut before its key is whole: read as a record begun, not as another kind of file
            '{"op_code": 0, "worker_id": "x", "study_name": "s", "directions": [1]}\n{"op_',
            r"line 2: its last line is cut off \(an interrupted write\?\): remove that line",
        ),
    ],
    ids=["json-file-without-newline", "json-file", "cut-off-last-line", "cut-off-in-its-key"],
)
def test_a_file_that_is_not_a_whole_journal_is_refused_and_left_alone(tmp_path, capsys, text, problem):
    """Another kind of JSON file named as the journal, or a journal whose last record was cut off:
    Optuna appended its records to the file (a model.json was corrupted, then a traceback; the cut
    record had the next one glued on), now both are refused by name with nothing written."""
    journal = tmp_path / "j.log"
    journal.write_text(text, encoding="utf-8")
    assert main([*TUNE, "--storage", f"journal:{journal}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert re.fullmatch(
        rf"error: --storage journal:{re.escape(str(journal))}: .* journal \({problem}\)\n", err
    )
    assert journal.read_text(encoding="utf-8") == text


def test_tune_keeps_stderr_for_errors(tmp_path, capsys):
    """Optuna's log lines ("A new study created ...", each trial) go to stdout with the rest of the
    progress: stderr holds nothing on success, and only the error line otherwise."""
    journal = tmp_path / "j.log"
    assert main([*TUNE, "--storage", f"journal:{journal}"]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert "A new study created in Journal with name: s" in captured.out


@settings(max_examples=60, deadline=None)
@given(
    asked=st.one_of(st.integers(1, 10**12), st.integers(10**12 - 10**6, 10**12)),
    num_envs=st.integers(1, 256),
    algo=st.sampled_from(["ppo", "sac"]),
    n_steps=st.one_of(st.none(), st.integers(2, 4096)),
)
def test_the_steps_are_rounded_up_to_whole_collections_exactly(asked, num_envs, algo, n_steps):
    """Any steps up to MAX_STEPS: the plan trains at least the steps asked, in whole collections,
    less than one collection more (integer arithmetic here; 1e23 steps came out rounded down
    through floats, to 99,999,999,999,999,991,611,392)."""
    from agents.run_config import MAX_STEPS, check_config, plan_steps

    hyper = {} if n_steps is None or algo != "ppo" else {"n_steps": n_steps, "batch_size": 2}
    config = check_config({"algo": algo, "env": NOZZLE, "steps": asked, "num_envs": num_envs,
                           "hyperparameters": hyper})  # fmt: skip
    steps, planned, _ = plan_steps(config)
    unit = planned["n_steps"] * num_envs if algo == "ppo" else planned.get("train_freq", 1) * num_envs
    assert asked <= steps < asked + unit and steps % unit == 0 and asked <= MAX_STEPS


@pytest.mark.parametrize("steps", [10**12 + 1, 10**23])
def test_steps_beyond_the_cap_are_refused(tmp_path, capsys, steps):
    """Beyond 1e12 steps (months of training) a run never ends: refused before any work."""
    code = main(
        ["train", "--env", NOZZLE, "--algo", "ppo", "--steps", str(steps), "--out", str(tmp_path / "t")]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert err == f"error: options: steps must be at most 1,000,000,000,000, got {steps:,}\n", err
    assert not (tmp_path / "t").exists()
