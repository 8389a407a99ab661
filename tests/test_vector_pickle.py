"""Native vector envs and their SB3 adapter pickle and deep-copy mid-episode (the generators'
capsules, which do not pickle, are rebuilt), and the copies step on with the original's bits."""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest

import ssme_envs  # noqa: F401  (registers the ids)
from ssme_envs.envs import catalogue
from ssme_envs.envs.sb3_adapter import make_sb3_vec_env


@pytest.mark.parametrize("table", [False, True])
@pytest.mark.parametrize("env_id", list(catalogue.ENVS))
def test_a_vector_env_pickles_and_copies_mid_episode(env_id, table):
    """``table``: sub-env 0 given another bit generator, so the draws are held as a table (the
    form without the compiled kernel too), whose row views a copy must rebuild."""
    env = gym.make_vec(env_id, num_envs=6, vectorization_mode="vector_entry_point")
    env.reset(seed=3)
    if table:
        env.unwrapped.sub_env(0).np_random = np.random.Generator(np.random.MT19937(5))
        assert env.unwrapped._draws.form == "table"
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (60, *env.action_space.shape)).astype(np.float32)
    for a in actions[:5]:
        env.step(a)
    twins = (pickle.loads(pickle.dumps(env)), copy.deepcopy(env))
    for a in actions[5:]:  # random actions: episodes end and restart on the way
        want = env.step(a)
        for twin in twins:
            got = twin.step(a)
            for x, y in zip(want[:4], got[:4], strict=True):
                assert x.tobytes() == y.tobytes()
    assert twins[0].unwrapped.np_random[0] is not env.unwrapped.np_random[0]  # a copy, not shared


def test_the_sb3_adapter_pickles_with_its_sub_env_views():
    venv = make_sb3_vec_env("ssme_envs/NozzleTVC-v0", 4, seed=0)
    venv.reset()
    twin = pickle.loads(pickle.dumps(venv))
    actions = np.random.default_rng(1).uniform(-1, 1, (30, 4, 1)).astype(np.float32)
    for a in actions:
        venv.step_async(a)
        twin.step_async(a)
        for x, y in zip(venv.step_wait()[:3], twin.step_wait()[:3], strict=True):
            assert np.asarray(x).tobytes() == np.asarray(y).tobytes()
    assert twin.get_attr("np_random_seed") == venv.get_attr("np_random_seed")
