"""NozzleTVC-v0 (and LauncherPitch-v0 for the checkers and the vector env): checkers, native
vector == sync vector, hysteresis, RK4 accuracy, bad input."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check

import ssme_envs  # noqa: F401
from ssme_envs.models.nozzle import published_nozzle, simulate_nozzle

NOZZLE = "ssme_envs/NozzleTVC-v0"
LAUNCHER = "ssme_envs/LauncherPitch-v0"


@pytest.mark.parametrize("env_id", [NOZZLE, LAUNCHER])
def test_checkers_pass_without_warnings(env_id):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(env_id).unwrapped)
        sb3_check(gym.make(env_id).unwrapped)
    assert [str(w.message) for w in caught] == []


@pytest.mark.parametrize(
    ("env_id", "options"),
    [
        (NOZZLE, {}),
        (NOZZLE, {"actuator_lag": 0.02, "rate_limit": 2e5, "reference": "attitude",
                  "fault": {"kind": "gain_loss", "time": 1.0, "magnitude": 0.5}}),
        (NOZZLE, {"plant": "linear", "reference": "sine_sweep",
                  "fault": {"kind": "sensor_bias", "time": 0.0}}),
        (NOZZLE, {"reference": "mixed", "episode_seconds": 1.0}),
        (LAUNCHER, {}),
        (LAUNCHER, {"plant": "linear", "reference": "attitude",
                    "fault": {"kind": "gain_loss", "time": 2.0, "magnitude": 0.5}}),
        (LAUNCHER, {"plant": "identified", "reference": "sine_sweep", "episode_seconds": 4.0,
                    "fault": {"kind": "sensor_bias", "time": 1.0}}),
    ],
)  # fmt: skip
def test_native_vector_env_equals_sync_vector_env_over_600_steps(env_id, options):
    sync = gym.make_vec(env_id, num_envs=3, vectorization_mode="sync", **options)
    native = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **options)
    a, b = sync.reset(seed=4), native.reset(seed=4)
    np.testing.assert_array_equal(a[0], b[0])
    rng = np.random.default_rng(0)
    ends = 0
    for k in range(600):
        actions = rng.uniform(-0.6, 0.6, (3, 1)).astype(np.float32)
        ra, rb = sync.step(actions), native.step(actions)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated"), ra[:4], rb[:4], strict=True):
            assert np.array_equal(x, y), f"{name} differs at step {k}"
        ends += int((ra[2] | ra[3]).sum())
    assert ends >= 3  # every sub-env crossed an episode boundary


def _loop_area(plant: str, period: float) -> float:
    """Area (action x deg) of the (action, angle) loop over the second period of a slow sine
    reference of 3 deg tracked by a PD loop on the env's observations."""
    steps = round(2 * period / 0.008)
    env = gym.make(NOZZLE, plant=plant, reference="zero", sensor_noise=0.0, episode_seconds=2 * period,
                   max_episode_steps=steps)  # fmt: skip
    env.reset(seed=0)
    actions, angles = [], []
    angle = rate = 0.0
    for k in range(1, steps + 1):
        reference = 3.0 * np.sin(2 * np.pi * k * 0.008 / period)
        action = float(np.clip((1.0 * (reference - angle) - 0.01 * rate) / 12.0, -1, 1))
        obs, _, terminated, _, _ = env.step(np.array([action], dtype=np.float32))
        assert not terminated
        angle, rate = float(obs[0]), float(obs[1])
        actions.append(action)
        angles.append(angle)
    x, y = np.array(actions)[steps // 2 :], np.array(angles)[steps // 2 :]
    return 0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1)))  # shoelace


def test_hysteresis_opens_a_loop_that_the_linear_joint_does_not():
    # A rate-independent loop (hysteresis) keeps its area as the sweep slows; a linear joint's
    # loop comes only from its dynamic lag and shrinks in proportion to the frequency.
    bouc_wen = [_loop_area("bouc_wen", period) for period in (10.0, 20.0)]
    linear = [_loop_area("linear", period) for period in (10.0, 20.0)]
    assert bouc_wen[1] > 0.8 * bouc_wen[0] > 0.003
    assert linear[1] == pytest.approx(0.5 * linear[0], rel=0.15)
    assert linear[1] < 0.05 * bouc_wen[1]


def test_rk4_trajectory_agrees_with_a_fine_step_reference():
    env = gym.make(NOZZLE, reference="zero", sensor_noise=0.0)
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    actions = np.repeat(rng.uniform(-0.2, 0.2, 25), 20)  # torque steps every 0.16 s
    angles = []
    for a in actions:
        obs, _, terminated, _, _ = env.step(np.array([a], dtype=np.float32))
        assert not terminated
        angles.append(obs[0])
    fine = simulate_nozzle(published_nozzle("bouc_wen"), np.append(actions * 3.0e4, 0.0), substeps=256)[1:]
    error = np.max(np.abs(np.array(angles) - np.degrees(fine)))
    assert error < 1e-3  # deg (measured 5.8e-4 with 3 substeps): 0.03 % of the 3 deg working range


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"plant": "steel"}, "plant must be"),
        ({"reference": "chirp"}, "unknown reference 'chirp'"),
        ({"reference_amplitude_deg": 5.0}, "reference_amplitude_deg"),
        ({"fault": {"kind": "stuck_valve", "time": 1.0}}, "unknown fault kind 'stuck_valve'"),
        ({"fault": {"kind": "gain_loss", "time": 9.0}}, "beyond the episode"),
        ({"actuator_lag": -0.1}, "actuator_lag"),
        ({"rate_limit": 0.0}, "rate_limit"),
        ({"substeps": 0}, "substeps"),
        ({"sensor_noise": float("nan")}, "sensor_noise"),
    ],
)
def test_bad_options_name_the_option(options, message):
    with pytest.raises(ValueError, match=message):
        gym.make(NOZZLE, **options)


def test_bad_actions_and_malformed_model_file(tmp_path):
    env = gym.make(NOZZLE)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must be finite"):
        env.step(np.array([np.nan], dtype=np.float32))
    with pytest.raises(ValueError, match="action must be 1 number"):
        env.step(np.zeros(2, dtype=np.float32))
    clipped, _, _, _, _ = env.step(np.array([7.0], dtype=np.float32))
    assert clipped[5] == 1.0  # out of range: clipped, and the observation shows it
    venv = gym.make_vec(NOZZLE, num_envs=2, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="action of env 1 must be finite"):
        venv.step(np.array([[0.0], [np.inf]], dtype=np.float32))
    bad = tmp_path / "model.json"
    bad.write_text('{"schema": "ssme-envs/nozzle-model", "schema_version": 1, "linear": 3}')
    with pytest.raises(ValueError):
        gym.make(NOZZLE, plant=str(bad))
