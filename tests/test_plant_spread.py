"""Plants drawn per episode (``plant_spread``): the same bits alone and batched, the stated
distribution (checked against scipy's truncated normal), the substep rule over every draw, and
clear errors."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import scipy.stats
from conftest import SHORT_EPISODES
from gymnasium.vector import AutoresetMode
from hypothesis import given, settings
from hypothesis import strategies as st

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs.models.nozzle import NozzleParameters, identified_nozzle, integration_substeps

SPREAD_ENVS = ["ssme_envs/NozzleTVC-v0", "ssme_envs/LauncherPitch-v0"]
N = 4


def _pair(env_id: str, **options):
    options = {**SHORT_EPISODES[env_id], **options}
    mode = {"autoreset_mode": AutoresetMode.NEXT_STEP}
    sync = gym.make_vec(env_id, num_envs=N, vectorization_mode="sync", vector_kwargs=mode, **options)
    native = gym.make_vec(env_id, num_envs=N, vectorization_mode="vector_entry_point", **mode, **options)
    return sync, native


@settings(max_examples=6, deadline=None)
@given(
    env_id=st.sampled_from(SPREAD_ENVS),
    spread=st.one_of(st.floats(0.01, 0.5), st.just("uncertainty")),
    seed=st.integers(0, 2**31 - 1),
)
def test_drawn_plants_equal_sync_vector_env_bit_for_bit(env_id, spread, seed):
    """With plants drawn per episode, the native vector env and SyncVectorEnv give the same
    observations, rewards and flags over 150 steps with partial resets (random actions, episodes
    ending early and truncating)."""
    plant = "strong_identified" if spread == "uncertainty" else "bouc_wen"
    sync, native = _pair(env_id, plant=plant, plant_spread=spread, uncertainty_scale=20.0)
    a, b = sync.reset(seed=seed), native.reset(seed=seed)
    np.testing.assert_array_equal(a[0], b[0])
    rng = np.random.default_rng(seed)
    ends = 0
    for k in range(150):
        actions = rng.uniform(-1, 1, (N, 1)).astype(np.float32)
        ra, rb = sync.step(actions), native.step(actions)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated"), ra[:4], rb[:4], strict=True):
            assert np.array_equal(x, y), f"{name} differs at step {k}"
        ends += int((ra[2] | ra[3]).sum())
        mask = rng.random(N) < 0.05
        mask[0] = False  # sub-env 0 runs its episodes to their end: truncations are covered
        if mask.any():
            seeds = [int(s) for s in rng.integers(0, 1000, N)]
            ra, rb = (env.reset(seed=seeds, options={"reset_mask": mask}) for env in (sync, native))
            np.testing.assert_array_equal(ra[0], rb[0])
    assert ends > 0


def _joints(env_id: str, count: int, seed: int, **options) -> dict[str, np.ndarray]:
    """The normalized joint parameters drawn for ``count`` episodes, read back from the state."""
    env = gym.make_vec(env_id, num_envs=count, vectorization_mode="vector_entry_point", **options)
    env.reset(seed=seed)
    p = env.unwrapped._state.joint
    J = 1.0 / p.inv_j
    return {"J": J, "b": p.b_j * J, "k_el": p.k_el_j * J, "k_hys": p.k_hys_j * J, "beta_n": p.beta,
            "gamma_n": p.gamma, "n": p.n}  # fmt: skip


def test_relative_spread_is_a_truncated_log_normal_per_parameter():
    """log(theta / theta_0) / s of 4,000 drawn joints follows the normal truncated at +-3
    (scipy's truncnorm, Kolmogorov-Smirnov) for each of J, b, k_el, k_hys, beta_n, gamma_n,
    independently (correlations within sampling error); n is kept."""
    spread = 0.15
    nominal = NozzleParameters(J=20.0, b=250.0, k=1.6e5, a=0.15, A=1.0, beta=120.0, gamma=80.0, n=1.5)
    drawn = _joints("ssme_envs/NozzleTVC-v0", 4000, 11, plant="strong", plant_spread=spread)
    norm = nominal.normalized()
    z = []
    for name in ("J", "b", "k_el", "k_hys", "beta_n", "gamma_n"):
        scaled = np.log(drawn[name] / norm[name]) / spread
        assert np.abs(scaled).max() <= 3.0 + 1e-9
        assert scipy.stats.kstest(scaled, scipy.stats.truncnorm(-3, 3).cdf).pvalue > 1e-3, name
        z.append(scaled)
    corr = np.corrcoef(z)
    assert np.abs(corr - np.eye(6)).max() < 4.5 / math.sqrt(4000)
    np.testing.assert_allclose(drawn["n"], norm["n"], rtol=1e-12)


def test_uncertainty_spread_has_the_model_covariance():
    """Drawn from the packaged strong-nozzle model's covariance (x 20): the sample mean is the
    model's parameters and the sample covariance the model's times 20^2 times the variance of the
    normal truncated at +-3 (scipy), within sampling error."""
    model = identified_nozzle("strong")
    block = model.bouc_wen_uncertainty
    scale = 20.0
    drawn = _joints("ssme_envs/NozzleTVC-v0", 6000, 5, plant="strong_identified", plant_spread="uncertainty",
                    uncertainty_scale=scale)  # fmt: skip
    samples = np.stack([drawn[name] for name in block.parameters])
    norm = model.bouc_wen.normalized()
    mean = np.array([norm[name] for name in block.parameters])
    expected = block.covariance * scale**2 * scipy.stats.truncnorm(-3, 3).var()
    sd = np.sqrt(np.diag(expected))
    assert np.all(np.abs(samples.mean(axis=1) - mean) < 5 * sd / math.sqrt(6000))
    np.testing.assert_allclose(np.sqrt(np.diag(np.cov(samples))), sd, rtol=0.06)
    corr_drawn = np.corrcoef(samples)
    corr_model = expected / np.outer(sd, sd)
    assert np.abs(corr_drawn - corr_model).max() < 0.08


@pytest.mark.parametrize("env_id", SPREAD_ENVS)
def test_every_drawn_joint_gets_enough_substeps(env_id):
    """The RK4 substep count is sized on the spread's corners: no drawn joint needs more."""
    env = gym.make_vec(env_id, num_envs=300, vectorization_mode="vector_entry_point", plant="strong",
                       plant_spread=0.3)  # fmt: skip
    env.reset(seed=3)
    task = env.unwrapped.task
    p = env.unwrapped._state.joint
    J = 1.0 / p.inv_j
    if env_id.endswith("NozzleTVC-v0"):
        h, amplitude, count, limit = task.dt, task.envelope, task.substeps, 10_000
    else:
        h, amplitude, count, limit = task.dt / task.substeps, 2 * task.max_deflection, task.rk4_substeps, 1000
    needed = []
    for i in range(0, 300, 10):
        joint = NozzleParameters.from_normalized(
            J[i],
            p.b_j[i] * J[i],
            p.k_el_j[i] * J[i],
            p.k_hys_j[i] * J[i],
            p.beta[i],
            p.gamma[i],
            p.n[i],
            A=1.0,
        )
        needed.append(integration_substeps(joint, h, amplitude, task.torque_limit, 0.25, limit))
    assert max(needed) <= count
    assert len(set(np.round(J, 9))) == 300  # a joint per episode


def test_same_seed_same_plant_and_the_scalar_env_draws_it_too():
    """An episode's joint depends on its seed only: the scalar env reset with sub-env 2's seed
    steps sub-env 2's joint; the next episode draws another."""
    options = {"plant_spread": 0.2, "episode_seconds": 0.4}
    vector = gym.make_vec("ssme_envs/NozzleTVC-v0", num_envs=3, vectorization_mode="vector_entry_point",
                          **options)  # fmt: skip
    vector.reset(seed=40)
    single = gym.make("ssme_envs/NozzleTVC-v0", **options)
    single.reset(seed=42)
    joint = single.unwrapped._state.joint
    assert joint.k_el_j == vector.unwrapped._state.joint.k_el_j[2]
    single.reset()
    assert single.unwrapped._state.joint.k_el_j != joint.k_el_j


def test_without_a_spread_the_episode_draws_are_unchanged():
    """A spread appends its draws after the noise and references: those stay the same."""
    a = gym.make("ssme_envs/NozzleTVC-v0")
    b = gym.make("ssme_envs/NozzleTVC-v0", plant_spread=0.1)
    oa, _ = a.reset(seed=9)
    ob, _ = b.reset(seed=9)
    np.testing.assert_array_equal(oa, ob)
    assert b.unwrapped.task.draw_size == a.unwrapped.task.draw_size + 6


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"plant_spread": -0.1}, "plant_spread must be in"),
        ({"plant_spread": 0.6}, "plant_spread must be in"),
        ({"plant_spread": "wide"}, "plant_spread must be a number or 'uncertainty'"),
        ({"plant_spread": True}, "plant_spread must be a number"),
        ({"plant_spread": float("nan")}, "plant_spread must be a number"),
        ({"plant_spread": "uncertainty"}, "needs plant='identified'"),
        ({"plant": "linear", "plant_spread": "uncertainty"}, "needs plant='identified'"),
        ({"plant": "identified", "plant_spread": "uncertainty", "uncertainty_scale": 0}, "uncertainty_scale"),
        ({"plant": "identified", "plant_spread": "uncertainty", "uncertainty_scale": 100}, "too wide"),
    ],
)
@pytest.mark.parametrize("env_id", SPREAD_ENVS)
def test_bad_spreads_are_refused_by_name(env_id, options, message):
    with pytest.raises(ValueError, match=message):
        gym.make(env_id, **options)
