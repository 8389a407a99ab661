"""Shared helpers for the tests: independent reference computations, never the code under test."""

from __future__ import annotations

import os

# One BLAS thread, set before numpy loads its BLAS: the tests' matrices are small, and two
# threads' synchronisation made some of them several times slower (a bootstrap test 71 s against
# 11 s). A value the caller set is kept.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from gymnasium.vector import AutoresetMode  # noqa: E402
from hypothesis import settings  # noqa: E402

# The same examples on every run and machine: several properties are statistical (an order chosen
# from a noisy record), and a run that draws afresh can meet a record outside them by chance.
# SSME_HYPOTHESIS_PROFILE=explore draws new examples, to look for such records.
settings.register_profile("deterministic", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("SSME_HYPOTHESIS_PROFILE", "deterministic"))


def markov(a: np.ndarray, b: np.ndarray, c: np.ndarray, count: int) -> np.ndarray:
    """C A^k B by explicit matrix powers."""
    return np.array([c @ np.linalg.matrix_power(a, k) @ b for k in range(count)])


def eq36(u: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Eq 36 of the paper written out branch by branch."""
    return np.where(u >= 0, lam * u, (2.0 - lam) * u)


def dlsim(a, b, c, u):
    """Zero-state response of x(k+1) = A x + B u, y = C x, by scipy.signal."""
    from scipy.signal import dlsim as _dlsim

    m, p = b.shape[1], c.shape[0]
    _, y, _ = _dlsim((a, b, c, np.zeros((p, m)), 1.0), u)
    return y.reshape(-1, p)


# Options of every env that make its episodes short: truncations within a few dozen steps.
SHORT_EPISODES = {
    "ssme_envs/EngineTracking-v0": {"episode_seconds": 2.0, "action_scale": 0.2},
    "ssme_envs/EngineThrottle-v0": {
        "profile": [(0.0, 100.0), (1.0, 100.0), (2.0, 90.0)],
        "action_scale": 0.2,
    },
    "ssme_envs/NozzleTVC-v0": {"episode_seconds": 0.4},
    "ssme_envs/LauncherPitch-v0": {"episode_seconds": 1.0},
}


def sync_equal(env_id, num_envs, steps, seed, action_scale_up, mode=AutoresetMode.NEXT_STEP, **kwargs):
    """Step gymnasium's SyncVectorEnv (scalar envs) and the native vector env on the same random
    actions (uniform within +-action_scale_up): observations, rewards, flags and final
    observations equal bit for bit; returns the number of episode ends."""
    sync = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": mode}, **kwargs)  # fmt: skip
    native = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                          autoreset_mode=mode, **kwargs)  # fmt: skip
    a, b = sync.reset(seed=seed), native.reset(seed=seed)
    np.testing.assert_array_equal(a[0], b[0])
    rng = np.random.default_rng(seed)
    ends = 0
    for k in range(steps):
        actions = rng.uniform(
            -action_scale_up, action_scale_up, (num_envs, native.single_action_space.shape[0])
        ).astype(np.float32)
        ra, rb = sync.step(actions), native.step(actions)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated"), ra[:4], rb[:4], strict=True):
            assert np.array_equal(x, y), f"{name} differs at step {k}"
        if mode == AutoresetMode.SAME_STEP and (ra[2] | ra[3]).any():
            assert sorted(ra[4]) == sorted(rb[4])
            np.testing.assert_array_equal(ra[4]["_final_obs"], rb[4]["_final_obs"])
            for i in np.flatnonzero(ra[2] | ra[3]):
                np.testing.assert_array_equal(ra[4]["final_obs"][i], rb[4]["final_obs"][i])
        ends += int((ra[2] | ra[3]).sum())
    return ends


def random_rollout(env_id: str, seed: int, batched: bool, steps: int, num_envs: int, **options) -> list:
    """Observations and rewards of ``steps`` uniform random float32 actions from a generator
    seeded ``seed``: one env (reset when its episode ends) or a native vector env of
    ``num_envs`` (autoresetting). Two runs compare bit for bit."""
    if batched:
        env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **options)
    else:
        env = gym.make(env_id, disable_env_checker=True, **options)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs]
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(
            rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        )
        out += [obs, np.asarray(reward)]
        if not batched and (terminated or truncated):
            out.append(env.reset()[0])
    env.close()
    return out


def random_system(order: int, n_inputs: int, n_outputs: int, rng: np.random.Generator):
    """A stable (A, B, C) from random real and complex pole blocks behind a random change of basis
    (no canonical form assumed)."""
    import scipy.linalg

    blocks, k = [], 0
    while k < order:
        radius = rng.uniform(0.3, 0.9)
        if order - k >= 2 and rng.random() < 0.5:
            angle = rng.uniform(0.1, 2.5)
            rotation = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
            blocks.append(radius * np.array(rotation))
            k += 2
        else:
            blocks.append(np.array([[radius * rng.choice([-1.0, 1.0])]]))
            k += 1
    basis = rng.standard_normal((order, order))
    a = basis @ scipy.linalg.block_diag(*blocks) @ np.linalg.inv(basis)
    return a, rng.standard_normal((order, n_inputs)), rng.standard_normal((n_outputs, order))
