"""Residual policies (agents/residual.py): the action the env gets, the base controller kept in
step with each sub-env's episodes, the policy files and the config checks."""

import json

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents import make_controller, parse_controller
from agents.base import BatchController
from agents.residual import ResidualController, applied_action, residual_vec_env
from agents.sb3 import check_config
from agents.tvc import HysteresisCompensated
from ssme_envs.cli import main
from ssme_envs.envs.sb3_adapter import make_sb3_vec_env
from ssme_envs.evaluation import evaluate

NOZZLE = "ssme_envs/NozzleTVC-v0"
THROTTLE = "ssme_envs/EngineThrottle-v0"
LAUNCHER = "ssme_envs/LauncherPitch-v0"


class Constant(BatchController):
    """A stand-in for a learned policy: the same correction whatever it observes."""

    name = "constant"

    def __init__(self, value: float, size: int) -> None:
        super().__init__()
        self.value, self.size = value, size

    def compute(self, obs: np.ndarray) -> np.ndarray:
        return np.full((len(obs), self.size), self.value)


@pytest.mark.parametrize(
    ("env_id", "base", "scenario"),
    [
        (THROTTLE, "scheduled", "mission"),
        (NOZZLE, "hysteresis", "random_steps"),
        (LAUNCHER, "robust", "attitude"),
    ],
)
def test_a_zero_residual_acts_as_its_base(env_id, base, scenario):
    """Costs equal to the last bit: the composition resets and steps the base as the harness does."""
    n_actions = gym.make(env_id).action_space.shape[0]
    factories = {
        "base": lambda env: make_controller(base, env, env_id),
        "residual": lambda env: ResidualController(
            Constant(0.0, n_actions), make_controller(base, env, env_id), 0.5
        ),
    }
    results = evaluate(env_id, factories, [scenario], episodes=3)[scenario]
    assert results["residual"].cost_mean == results["base"].cost_mean


@settings(max_examples=50, deadline=None)
@given(
    base=st.floats(-1, 1, allow_nan=False),
    correction=st.floats(-5, 5, allow_nan=False),
    more=st.floats(0, 5, allow_nan=False),
    scale=st.floats(0.01, 2.0),
)
def test_the_applied_action_stays_in_range_and_moves_with_the_correction(base, correction, more, scale):
    """Invariants, not the formula: within [-1, 1]; a zero correction is the base; a larger
    correction never applies less; a correction beyond +-1 acts as +-1."""
    act = lambda c: float(applied_action(np.array([[base]]), np.array([[c]]), scale)[0, 0])  # noqa: E731
    assert -1.0 <= act(correction) <= 1.0
    assert act(0.0) == float(np.float32(base))
    assert act(correction + more) >= act(correction)
    assert act(7.0) == act(1.0) and act(-7.0) == act(-1.0)


class Recorder:
    """An SB3 VecEnv wrapper that keeps the actions its env receives."""

    def __new__(cls, venv):
        from stable_baselines3.common.vec_env import VecEnvWrapper

        class _Recorder(VecEnvWrapper):
            def __init__(self) -> None:
                super().__init__(venv)
                self.actions = []

            def reset(self):
                return self.venv.reset()

            def step_async(self, actions):
                self.actions.append(np.array(actions))
                self.venv.step_async(actions)

            def step_wait(self):
                return self.venv.step_wait()

        return _Recorder()


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**16), scale=st.floats(0.05, 1.0))
def test_the_env_gets_base_plus_scaled_correction_through_episode_ends(seed, scale):
    """Brute force beside the wrapper: a second base controller fed the observations the policy
    sees, reset where SB3 reports an episode's end, gives the base part of every applied action
    and of every observation, across episode ends."""
    env = gym.make(NOZZLE, episode_seconds=0.2)  # episodes of 25 steps: 120 steps cross several ends
    n = 3
    inner = Recorder(make_sb3_vec_env(NOZZLE, n, seed, episode_seconds=0.2))
    venv = residual_vec_env(inner, make_controller("lqi", env, NOZZLE), scale)
    twin = make_controller("lqi", env, NOZZLE)
    rng = np.random.default_rng(seed)
    obs = venv.reset()
    twin.reset(num_envs=n)
    size = env.observation_space.shape[0]
    ends = 0
    for _ in range(120):
        base = twin.act(obs[:, :size])
        assert np.array_equal(obs[:, size:], base)
        correction = rng.uniform(-2, 2, (n, 1)).astype(np.float32)
        obs, _, dones, infos = venv.step(correction)
        expected = np.clip(base.astype(np.float64) + scale * np.clip(correction, -1, 1), -1, 1)
        assert np.array_equal(inner.actions[-1], expected.astype(np.float32))
        for i in np.flatnonzero(dones):  # the episode's last observation, the last base action
            last = infos[i]["terminal_observation"]
            assert last.shape == (size + 1,) and last[size] == base[i, 0]
        if dones.any():
            ends += int(dones.sum())
            twin.reset(envs=np.flatnonzero(dones))
    assert ends >= 2 * n


def _run_config(tmp_path, extra: str = "") -> str:
    return (
        f'env = "{NOZZLE}"\nalgo = "ppo"\nnum_envs = 4\neval_freq = 256\neval_episodes = 2\n'
        f'residual = "hysteresis"\nresidual_scale = 0.25\n{extra}'
        "[hyperparameters]\nn_steps = 64\nbatch_size = 64\n[policy]\nnet_arch = [8, 8]\nlog_std_init = -2.0\n"
    )


def test_a_trained_residual_records_its_base_and_loads_with_it(tmp_path):
    config = tmp_path / "residual.toml"
    config.write_text(_run_config(tmp_path))
    out = tmp_path / "run"
    assert main(["train", "--config", str(config), "--steps", "256", "--out", str(out)]) == 0
    meta = json.loads((out / "policy.json").read_text())
    assert meta["residual"] == {"base": "hysteresis", "scale": 0.25}
    assert meta["observation_space"]["shape"] == [7]  # the 6 observations and the base action
    env = gym.make(NOZZLE)
    controller = parse_controller(f"ppo:{out}", NOZZLE)(env)
    assert isinstance(controller, ResidualController) and isinstance(controller.base, HysteresisCompensated)
    results = evaluate(NOZZLE, {"residual": parse_controller(f"ppo:{out}", NOZZLE)}, ["step"], episodes=2)
    assert np.isfinite(results["step"]["residual"].cost_mean)
    for bad, message in [
        ({"base": "ppo", "scale": 0.25}, "not a classical controller"),
        ({"base": "hysteresis", "scale": 5.0}, r"scale must be a number in \(0, 2\]"),
        ({"base": "hysteresis"}, "residual must be an object with base, scale"),
    ]:
        meta["residual"] = bad
        (out / "policy.json").write_text(json.dumps(meta))
        with pytest.raises(ValueError, match=message):
            parse_controller(f"ppo:{out}", NOZZLE)


@pytest.mark.parametrize(
    ("config", "message"),
    [
        ({"residual": "pi"}, "base 'pi' is not a classical controller of ssme_envs/NozzleTVC-v0"),
        ({"residual": "ppo"}, "base 'ppo' is not a classical controller"),
        ({"residual": "lqi", "residual_scale": 0.0}, r"scale must be a number in \(0, 2\]"),
        ({"residual_scale": 0.5}, "residual_scale without residual"),
        ({"residual_penalty": 0.1}, "residual_penalty without residual"),
        ({"residual": "lqi", "residual_penalty": -1.0}, "residual_penalty must be a number >= 0"),
        ({"policy": {"log_std_init": 9.0}}, r"log_std_init must be a number in \[-5, 2\]"),
        (
            {"algo": "td3", "policy": {"log_std_init": -2.0}},
            "log_std_init sets PPO's initial noise, not td3's",
        ),
        ({"residual": "lqi:bogus"}, "names no design model; after the colon write identified or truth"),
        ({"residual": "zero:truth"}, "base 'zero:truth': the zero controller is designed on no model"),
        ({"residual": "lqi", "residual_scale": 10**400}, "residual_scale must be a float, got an integer"),
        ({"env": "ssme_envs/Nope-v0", "residual": "lqi"}, "unknown env 'ssme_envs/Nope-v0'"),
    ],
)
def test_bad_residual_configs_name_the_problem(config, message):
    with pytest.raises(ValueError, match=message):
        check_config({"env": NOZZLE, "algo": "ppo", **config})


def test_a_residual_policy_alone_names_its_base_when_given_the_env_observations():
    from agents.sb3 import PolicyController, shipped_policy

    alone = PolicyController(shipped_policy(NOZZLE, "residual"))
    assert alone.act(np.zeros((1, 7))).shape == (1, 1)  # the env's 6 observations and the base action
    with pytest.raises(
        ValueError, match=r"a residual policy over hysteresis: .* through the spec ppo:RUN_DIR"
    ):
        alone.act(np.zeros((1, 6)))


def test_init_policy_names_a_residual_mismatch(tmp_path, capsys):
    from agents.sb3 import shipped_policy

    config = tmp_path / "c.toml"
    start = f'init_policy = "{shipped_policy(NOZZLE, "residual")}"\n'
    config.write_text(start + _run_config(tmp_path).replace('"hysteresis"', '"lqi"'))
    assert main(["train", "--config", str(config), "--steps", "64", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert "a residual over hysteresis (scale 0.1), this config a residual over lqi (scale 0.25)" in err


def test_a_residual_config_fills_its_scale():
    full = check_config({"env": NOZZLE, "algo": "ppo", "residual": "lqi", "residual_scale": 1})
    assert full["residual_scale"] == 1.0 and isinstance(full["residual_scale"], float)
    assert check_config({"env": NOZZLE, "algo": "ppo", "residual": "lqi"})["residual_scale"] == 0.5


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**16), penalty=st.floats(0.001, 10.0), scale=st.floats(0.05, 1.0))
def test_the_training_penalty_takes_the_squared_correction_off_the_reward(seed, penalty, scale):
    """Two wrappers on the same episodes and corrections, with and without the penalty: the
    rewards differ by penalty * |scale * clip(correction)|^2, step by step."""
    env = gym.make(NOZZLE, episode_seconds=0.2)
    plain = residual_vec_env(
        make_sb3_vec_env(NOZZLE, 2, seed, episode_seconds=0.2), make_controller("lqi", env, NOZZLE), scale
    )
    taxed = residual_vec_env(
        make_sb3_vec_env(NOZZLE, 2, seed, episode_seconds=0.2),
        make_controller("lqi", env, NOZZLE),
        scale,
        penalty,
    )
    plain.reset(), taxed.reset()
    rng = np.random.default_rng(seed)
    for _ in range(40):
        correction = rng.uniform(-1.5, 1.5, (2, 1)).astype(np.float32)
        _, r_plain, _, _ = plain.step(correction)
        _, r_taxed, _, _ = taxed.step(correction)
        expected = penalty * (scale * np.clip(correction, -1, 1)[:, 0]) ** 2
        # the rewards are float32: their difference carries its rounding (a few 1e-6 at most)
        np.testing.assert_allclose(r_plain - r_taxed, expected, rtol=1e-4, atol=2e-5)
