"""Engine environments: checkers, native vector env == SyncVectorEnv, linked model, bad input."""

from __future__ import annotations

import json
import warnings

import gymnasium as gym
import numpy as np
import pytest
from conftest import sync_equal
from gymnasium.vector import AutoresetMode

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs.cli import main
from ssme_envs.models import POWER_LEVELS, published_model
from ssme_envs.models.linked import LinkedEngineModel

TRACKING, THROTTLE = "ssme_envs/EngineTracking-v0", "ssme_envs/EngineThrottle-v0"
SHORT_PROFILE = [(0.0, 100.0), (3.0, 100.0), (6.0, 80.0), (10.0, 80.0)]  # 250 steps


@pytest.mark.parametrize("env_id", [TRACKING, THROTTLE])
def test_gymnasium_and_sb3_checkers_pass_without_warnings(env_id):
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym_check(gym.make(env_id).unwrapped)
        sb3_check(gym.make(env_id).unwrapped)
    assert [str(w.message) for w in caught] == []


def test_native_vector_env_equals_sync_vector_env_over_600_steps():
    ends = sync_equal(TRACKING, 3, 600, seed=11, action_scale_up=1.3)
    assert ends >= 6  # every sub-env crossed two episode boundaries
    # a batch wider than the transpose tiles (256), with envs restarting at different steps
    assert sync_equal(TRACKING, 300, 260, seed=4, action_scale_up=2.0, action_scale=0.2) >= 300


def test_equality_with_faults_same_step_autoreset_and_terminations():
    fault = {"kind": "stuck_valve", "time": 2.0, "index": 1}
    assert (
        sync_equal(TRACKING, 2, 300, seed=3, action_scale_up=1.0, mode=AutoresetMode.SAME_STEP, fault=fault)
        >= 2
    )
    # large valve moves leave the envelope at different times: the envs fall out of step
    ends = sync_equal(THROTTLE, 4, 600, seed=5, action_scale_up=1.0, profile=SHORT_PROFILE, action_scale=0.2,
                    truth={"sensor_noise": 2e-4})  # fmt: skip
    assert ends >= 8


@pytest.mark.parametrize("kind", ["sensor_bias", "gain_loss"])
def test_equality_with_other_faults(kind):
    fault = {"kind": kind, "time": 1.0, "index": 0}
    assert sync_equal(TRACKING, 2, 260, seed=2, action_scale_up=1.0, fault=fault, reference="prbs") >= 2


def test_registration_and_limits():
    assert gym.spec(TRACKING).max_episode_steps == 250
    assert gym.spec(THROTTLE).max_episode_steps == 1500
    assert gym.spec(TRACKING).vector_entry_point and gym.spec(THROTTLE).vector_entry_point
    env = gym.make(TRACKING)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (10,) and obs.dtype == np.float32
    steps = 0
    while True:
        _, _, terminated, truncated, _ = env.step(np.zeros(2, np.float32))
        steps += 1
        if terminated or truncated:
            break
    assert (steps, truncated, terminated) == (250, True, False)


def test_point_model_env_responds_like_the_published_model():
    """With every truth effect off, the env's outputs are the published model's response."""
    env = gym.make(TRACKING, power=90, truth={"asymmetric_gains": False, "backlash": 0.0, "stiction": 0.0,
                                             "sensor_noise": 0.0}, reference="zero")  # fmt: skip
    env.reset(seed=0)
    model = published_model(90)
    x, got, expected = np.zeros(4), [], []
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = rng.uniform(-1, 1, 2)
        obs, *_ = env.step(a.astype(np.float32))
        x = model.A @ x + model.B @ (0.02 * a.astype(np.float32).astype(float))
        got.append(obs[:2] / 100.0)
        expected.append(model.C @ x)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-8)  # float32 observations


def test_linked_model_equals_the_point_models_and_varies_smoothly():
    linked = LinkedEngineModel()
    for power in POWER_LEVELS[:-1]:
        local, published = linked.local_model(power), published_model(power)
        np.testing.assert_array_equal(local.A, published.A)
        np.testing.assert_array_equal(local.B, published.B)
        np.testing.assert_array_equal(local.lam, published.lam)
    grid = np.arange(65.0, 109.01, 0.25)
    gains = np.array([linked.dc_gain(p) for p in grid])
    steps = np.abs(np.diff(gains, axis=0)).max(axis=(1, 2))
    assert steps.max() < 0.02 * np.abs(gains).max()  # no jumps between neighbouring 0.25 % points
    # the nominal schedule is consistent with the DC gains: dy_eq/dP = G du_eq/dP (finite differences)
    for power in (68.0, 75.0, 95.0, 105.0):
        h = 0.05
        du = (linked.nominal_valves(power + h) - linked.nominal_valves(power - h)) / (2 * h)
        dy = (linked.nominal_outputs(power + h) - linked.nominal_outputs(power - h)) / (2 * h)
        np.testing.assert_allclose(linked.dc_gain(power) @ du, dy, atol=2e-5)


def test_open_loop_on_the_nominal_schedule_follows_the_throttle_profile():
    env = gym.make(THROTTLE, truth={"sensor_noise": 0.0})
    env.reset(seed=0)
    task = env.unwrapped.task
    pcs, refs = [], []
    for _ in range(task.horizon):
        obs, *_ = env.step(np.zeros(2, np.float32))
        pcs.append(obs[0])
        refs.append(obs[2])
    pcs, refs = np.array(pcs), np.array(refs)
    assert refs.min() == pytest.approx(-33.0, abs=0.01) and refs.max() == pytest.approx(4.0, abs=0.01)
    holds = [int(t / 0.04) - 2 for t in (15.0, 29.0, 45.0)]  # ends of the 104 %, 67 %, 104 % holds
    assert np.abs(pcs[holds] - refs[holds]).max() < 0.3  # % of rated Pc: valve backlash and stiction
    assert np.abs(pcs - refs).max() < 3.0  # and the engine's lag while throttling


def test_leaving_the_envelope_never_pays():
    env = gym.make(TRACKING, action_scale=0.2, reference="zero")
    env.reset(seed=1)
    bound = env.unwrapped.task.step_cost_bound
    worst, t = 0.0, 0
    while True:
        _, reward, terminated, truncated, _ = env.step(np.ones(2, np.float32))
        t += 1
        if terminated:
            assert reward <= -bound * (250 - t + 1)
            break
        worst = max(worst, -reward)
        assert not truncated
    assert worst < bound


def test_bad_actions_and_options():
    env = gym.make(TRACKING)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must be finite"):
        env.step(np.array([np.nan, 0.0], np.float32))
    for bad_shape in ([1.0], [1.0, 2.0, 3.0], "ab"):
        with pytest.raises(ValueError, match="action must be 2 numbers"):
            env.step(bad_shape)
    obs, *_ = env.step(np.array([5.0, -7.0], np.float32))
    assert obs[8:].tolist() == [1.0, -1.0]  # clipped, and reported as applied
    raw = gym.make(TRACKING, episode_seconds=1.0).unwrapped
    raw.reset(seed=0)
    for _ in range(25):
        raw.step(np.zeros(2, np.float32))
    with pytest.raises(ValueError, match="call reset"):
        raw.step(np.zeros(2, np.float32))
    venv = gym.make_vec(TRACKING, num_envs=3, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    bad = np.zeros((3, 2), np.float32)
    bad[2, 1] = np.inf
    with pytest.raises(ValueError, match="action of env 2 must be finite"):
        venv.step(bad)
    for kwargs, message in [
        ({"power": 120}, "power must be within 65-109"),
        ({"power": "high"}, "power must be a number"),
        ({"reference": "sine"}, "unknown reference 'sine'"),
        ({"fault": {"kind": "explode", "time": 1.0}}, "unknown fault kind 'explode'"),
        ({"fault": {"kind": "sensor_bias", "time": -1.0}}, "fault time"),
        ({"fault": {"kind": "gain_loss", "time": 1.0, "index": 5}}, "fault index"),
        ({"truth": {"bogus": 1}}, "unknown option"),
        ({"plant": "identified", "power": 95}, "plant='identified' exists at power"),
        ({"plant": "nonsense"}, "plant must be"),
        ({"reference_amplitude": 0.5}, "reference_amplitude"),
    ]:
        with pytest.raises(ValueError, match=message):
            gym.make(TRACKING, **kwargs)
    with pytest.raises(ValueError, match="profile power must stay within"):
        gym.make(THROTTLE, profile=[(0.0, 100.0), (5.0, 120.0)])
    for kwargs, message in [
        ({"profile": [(0.0, 100.0), (0.01, 100.0)]}, "shorter than one"),
        ({"fault": {"kind": "stuck_valve", "time": 100.0}}, "beyond the episode"),
        ({"fault": {"kind": "sensor_bias", "time": 1.0, "magnitude": 1.0}}, "within \\+-0.05"),
        ({"fault": {"kind": "gain_loss", "time": 1.0, "magnitude": 3.0}}, "within 0-1"),
        ({"truth": {"backlash": "a"}}, "backlash"),
        ({"truth": {"asymmetric_gains": "no"}}, "asymmetric_gains"),
        ({"truth": {"sensor_noise": [1e-4, 1e-4, 1e-4]}}, "sensor_noise"),
    ]:
        with pytest.raises(ValueError, match=message):
            gym.make(THROTTLE, **kwargs)
    with pytest.raises(ValueError, match="max_episode_steps must be a positive integer"):
        gym.make_vec(TRACKING, num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=0)


def test_faults_act_as_documented():
    stuck = gym.make(
        THROTTLE, truth={"sensor_noise": 0.0}, fault={"kind": "stuck_valve", "time": 4.0, "index": 0}
    )
    stuck.reset(seed=0)
    positions, terminated = [], False
    while not terminated:  # the held valve takes the engine out of the envelope (at 16.4 s)
        _, _, terminated, truncated, _ = stuck.step(np.zeros(2, np.float32))
        plant = stuck.unwrapped._state[0]
        positions.append(stuck.unwrapped.task.valve_positions(plant))
        assert not truncated
    positions = np.array(positions)
    assert np.ptp(positions[100:, 0]) == 0.0 and np.ptp(positions[100:, 1]) > 0.05  # OPOV held, FPOV follows
    biased = gym.make(TRACKING, truth={"sensor_noise": 0.0}, reference="zero",
                      fault={"kind": "sensor_bias", "time": 0.0, "index": 0, "magnitude": 0.01})  # fmt: skip
    obs, _ = biased.reset(seed=0)
    assert obs[:2].tolist() == [1.0, 0.0]  # the bias is there from the first measurement


def test_plant_from_a_model_file_and_malformed_file(tmp_path):
    path = tmp_path / "model.json"
    published_model(80).save(path)
    env = gym.make(TRACKING, plant=str(path), power=80)
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))
    doc = json.loads(path.read_text())
    doc["B"] = doc["B"][:2]
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="B has shape"):
        gym.make(TRACKING, plant=str(path))


def test_render_rgb_array():
    env = gym.make(TRACKING, render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(20):
        env.step(env.action_space.sample())
    image = env.render()
    assert image.ndim == 3 and image.shape[2] == 3 and image.dtype == np.uint8
    assert image.std() > 0  # something was drawn
    env.close()


@pytest.mark.parametrize(
    "env_id", ["ssme_envs/EngineTracking-v0", "ssme_envs/NozzleTVC-v0", "ssme_envs/LauncherPitch-v0"]
)
def test_render_before_the_first_reset_says_so(env_id):
    """The env class itself (no OrderEnforcing) failed inside the renderer with an IndexError."""
    from ssme_envs.envs.tracking_env import EpisodeOverError

    env = gym.make(env_id, render_mode="rgb_array").unwrapped
    with pytest.raises(EpisodeOverError, match=r"render\(\) before the first reset"):
        env.render()
    env.reset(seed=0)
    assert env.render().dtype == np.uint8
    env.close()


def test_render_human_draws_each_step():
    import matplotlib

    matplotlib.use("Agg")  # no display here: the same drawing, shown nowhere
    env = gym.make(TRACKING, render_mode="human")
    env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample())
    assert env.render() is None
    figure = env.unwrapped._figure
    pc_axis, _, valve_axis = figure.axes
    assert [len(line.get_xdata()) for line in pc_axis.lines] == [4, 4]  # Pc and its reference
    assert len(valve_axis.lines) == 2
    env.close()


def test_sb3_trains_on_the_native_vector_env():
    from stable_baselines3 import PPO

    from ssme_envs.envs.sb3_adapter import make_sb3_vec_env

    venv = make_sb3_vec_env(TRACKING, num_envs=8, seed=0)
    obs = venv.reset()
    assert obs.shape == (8, 10)
    dones = np.zeros(8, bool)
    infos = []
    for _ in range(250):
        obs, _, dones, infos = venv.step(np.zeros((8, 2), np.float32))
    assert dones.all() and "terminal_observation" in infos[0] and infos[0]["TimeLimit.truncated"]
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)


def test_bench_command_prints_ratios(capsys):
    assert main(["bench", "--rounds", "1", "--sizes", "2", "--env", TRACKING]) == 0
    out = capsys.readouterr().out
    # one single and one vector row for each of the zero and the random actions
    assert "Pendulum-v1" in out and "CartPole-v1 vector" in out and out.count("x |") == 4
    assert main(["bench", "--sizes", "0"]) == 2


@pytest.mark.parametrize("env_id", ["ssme_envs/NozzleTVC-v0", "ssme_envs/LauncherPitch-v0"])
def test_render_fps_plays_an_episode_in_real_time(env_id):
    """A frame per step: RecordVideo's clip of a 0.008 s-step episode lasted five times the
    episode at the class's 25 fps."""
    env = gym.make(env_id)
    assert env.metadata["render_fps"] == round(1 / env.unwrapped.task.dt)
