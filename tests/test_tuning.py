"""Hyperparameter tuning on a shared Optuna study: two worker processes on one journal file, one
in-process trial reproduced by `ssme-envs train` from the written config, the search spaces, and
the command's errors."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

optuna = pytest.importorskip("optuna")
pytest.importorskip("stable_baselines3")

from agents.sb3 import PolicyController, check_config, load_config, train  # noqa: E402
from ssme_envs.cli import main  # noqa: E402
from ssme_envs.evaluation import SCENARIOS, evaluate  # noqa: E402
from ssme_envs.tuning import EVAL_SEED, SPACES, Budget, tune, write_best_config  # noqa: E402

ENV = "ssme_envs/EngineTracking-v0"
TINY = ["--timesteps", "256", "--num-envs", "4", "--evaluations", "2", "--eval-episodes", "4"]


def _journal(path: Path):
    """The study's storage opened with Optuna's own classes (not the code under test)."""
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    return JournalStorage(JournalFileBackend(str(path)))


def _trial_of(config_file: Path, trials: list) -> object:
    number = int(re.match(r"# Best trial (\d+) ", config_file.read_text()).group(1))
    return next(t for t in trials if t.number == number)


@pytest.mark.slow
def test_two_worker_processes_share_one_study(tmp_path):
    journal = tmp_path / "study.log"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    command = [sys.executable, "-m", "ssme_envs.cli", "tune", "--env", ENV, "--algo", "ppo",
               "--storage", f"journal:{journal}", "--study", "shared", "--trials", "2", *TINY]  # fmt: skip
    workers = [
        subprocess.Popen(
            [*command, "--seed", str(i), "--out", str(tmp_path / f"best{i}.toml")],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for i in range(2)
    ]
    try:
        outputs = [worker.communicate(timeout=120) for worker in workers]
    finally:
        for worker in workers:
            if worker.poll() is None:
                worker.kill()
    for worker, (out, err) in zip(workers, outputs, strict=True):
        assert worker.returncode == 0, err
        assert "wrote" in out
    trials = optuna.load_study(study_name="shared", storage=_journal(journal)).get_trials()
    assert sorted(t.number for t in trials) == [0, 1, 2, 3]
    pids = [t.user_attrs["pid"] for t in trials]
    assert sorted(pids) == sorted([w.pid for w in workers] * 2)  # two trials from each worker
    finished = [t for t in trials if t.state == optuna.trial.TrialState.COMPLETE]
    for t in trials:  # a pruned trial holds its last evaluation's cost
        assert t.state in (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)
        assert math.isfinite(t.value) and t.value > 0
    best = min(finished, key=lambda t: t.value)
    # each worker writes the best of the trials finished when its own were: its own among them;
    # the worker finishing last saw all four
    picked = []
    for worker, i in zip(workers, range(2), strict=True):
        path = tmp_path / f"best{i}.toml"
        config = check_config(load_config(path))
        trial = _trial_of(path, trials)
        assert config == check_config(trial.user_attrs["config"])
        own = [t.value for t in finished if t.user_attrs["pid"] == worker.pid]
        assert trial.value <= min(own)
        picked.append(trial.number)
    assert best.number in picked


def test_one_trial_is_reproduced_by_training_its_config(tmp_path):
    study = tune(ENV, "ppo", f"sqlite:///{tmp_path / 'study.db'}", "one", trials=1, timesteps=64, seed=3,
                 num_envs=2, evaluations=2, eval_episodes=2, progress=False)  # fmt: skip
    (trial,) = study.get_trials()
    assert trial.state == optuna.trial.TrialState.COMPLETE
    assert sorted(trial.intermediate_values) == [1, 2]
    assert trial.value == trial.intermediate_values[2]
    config = check_config(load_config(write_best_config(study, tmp_path / "best.toml")))
    assert config["hyperparameters"]["n_steps"] * 2 <= 64 // 2  # two evaluations' worth
    train(config, tmp_path / "run", progress=False)
    # the trial's cost recomputed from the saved run by the evaluation harness
    scenario = next(name for name, options in SCENARIOS[ENV].items() if not options)
    result = evaluate(ENV, {"run": lambda env: PolicyController(tmp_path / "run")}, [scenario], 2, EVAL_SEED)
    assert result[scenario]["run"].cost_mean == pytest.approx(trial.value, rel=1e-6)


@settings(max_examples=30, deadline=None)
@given(
    algo=st.sampled_from(sorted(SPACES)),
    timesteps=st.integers(1, 10**7),
    num_envs=st.integers(1, 256),
    evaluations=st.integers(1, 20),
    seed=st.integers(0, 2**31),
)
def test_every_sample_is_a_valid_training_config(algo, timesteps, num_envs, evaluations, seed):
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=seed))
    budget = Budget(timesteps, num_envs, max(1, min(evaluations, timesteps)))
    hyper, net_arch = SPACES[algo](study.ask(), budget)
    config = check_config({"env": ENV, "algo": algo, "steps": timesteps, "num_envs": num_envs,
                           "hyperparameters": hyper, "policy": {"net_arch": net_arch}})  # fmt: skip
    if algo == "ppo":
        rollout = hyper["n_steps"] * num_envs
        assert 2 <= hyper["batch_size"] <= max(rollout, 2)
        assert rollout <= timesteps // budget.evaluations or hyper["n_steps"] == 8  # the smallest
    else:
        assert hyper["learning_starts"] <= timesteps // 4
        assert config["hyperparameters"]["buffer_size"] <= timesteps


def _error(capsys, *args: str) -> str:
    code = main(["tune", "--env", ENV, "--algo", "ppo", "--study", "s", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 or (len(err) == 2 and "existing study" in err[0])
    assert err[-1].startswith("error: ")
    return err[-1]


def test_bad_input_exits_2_with_one_error_line(tmp_path, capsys):
    journal = f"journal:{tmp_path / 'j.log'}"
    assert "unknown env" in _error(capsys, "--storage", journal, "--env", "nope")
    assert "unknown algo" in _error(capsys, "--storage", journal, "--algo", "dqn")
    assert "--trials" in _error(capsys, "--storage", journal, "--trials", "0")
    assert "--timesteps" in _error(capsys, "--storage", journal, "--timesteps", "-5")
    assert "--storage" in _error(capsys, "--storage", "not a url")
    assert "does not exist" in _error(capsys, "--storage", f"journal:{tmp_path / 'no' / 'j.log'}")
    assert "cannot open" in _error(capsys, "--storage", f"sqlite:///{tmp_path / 'no' / 's.db'}")
    assert "--out" in _error(capsys, "--storage", journal, "--out", str(tmp_path))
    assert not (tmp_path / "j.log").exists() or not optuna.get_all_study_names(_journal(tmp_path / "j.log"))


def test_a_worker_with_another_budget_is_refused(tmp_path, capsys):
    journal = tmp_path / "j.log"
    study = optuna.create_study(study_name="s", storage=_journal(journal))
    for key, value in {"env": ENV, "algo": "ppo", "timesteps": 256, "num_envs": 4, "evaluations": 2,
                       "eval_episodes": 4}.items():  # fmt: skip
        study.set_user_attr(key, value)
    line = _error(capsys, "--storage", f"journal:{journal}", *TINY[:2], "--num-envs", "8", *TINY[4:])
    assert "num_envs 4 (asked 8)" in line
    assert not study.get_trials()
