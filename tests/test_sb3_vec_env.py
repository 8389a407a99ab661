"""SB3's own VecEnv checks (its tests/test_vec_envs.py, adapted to our envs) on the SB3 adapter
of the native vector env beside SB3's DummyVecEnv of the scalar envs, and the two compared."""

from __future__ import annotations

import functools
import itertools
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from conftest import SHORT_EPISODES
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecFrameStack, VecNormalize

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs.envs.sb3_adapter import SB3VecEnv, make_sb3_vec_env

N_ENVS = 3
ENVS = SHORT_EPISODES
KINDS = ("adapter", "dummy")
VEC_ENV_WRAPPERS = [None, VecNormalize, VecFrameStack]
BIAS = np.array([0.0, 0.6, -1.0])[:, None]  # sub-env 0 runs to its time limit, 1 and 2 leave the envelope


def make(kind: str, env_id: str, n: int = N_ENVS) -> VecEnv:
    """The adapter of the native vector env, or SB3's DummyVecEnv of ``gymnasium.make``."""
    if kind == "adapter":
        return make_sb3_vec_env(env_id, n, **ENVS[env_id])
    return DummyVecEnv([functools.partial(gym.make, env_id, **ENVS[env_id]) for _ in range(n)])


def wrap(vec_env: VecEnv, wrapper: type | None) -> VecEnv:
    if wrapper is VecFrameStack:
        return VecFrameStack(vec_env, n_stack=2)
    return vec_env if wrapper is None else wrapper(vec_env)


# the adapter and DummyVecEnv, on each env
both = pytest.mark.parametrize("kind,env_id", list(itertools.product(KINDS, ENVS)))


@both
@pytest.mark.parametrize("wrapper", VEC_ENV_WRAPPERS, ids=lambda w: getattr(w, "__name__", "none"))
def test_vecenv_custom_calls(kind, env_id, wrapper):
    """SB3's test_vecenv_custom_calls: render, env_method with args and kwargs on all and on a
    subset, set_attr on one index at a time, on all, on a subset, with negative indices."""
    vec_env = wrap(make(kind, env_id), wrapper)
    assert vec_env.seed(0) == [0, 1, 2]
    with pytest.warns(UserWarning):  # no render_mode: both warn and draw nothing
        assert vec_env.render(mode="rgb_array") is None
    with pytest.warns(UserWarning):
        assert vec_env.render() is None

    seeds = vec_env.env_method("get_wrapper_attr", "np_random_seed", indices=None)  # positional args
    assert len(seeds) == N_ENVS
    resets = vec_env.env_method("reset", indices=[0, 2], seed=4)  # keyword args, a subset
    assert len(resets) == 2
    expected, _ = gym.make(env_id, **ENVS[env_id]).reset(seed=4)
    for obs, info in resets:
        np.testing.assert_array_equal(obs, expected)
        assert info == {}
    assert vec_env.env_method("get_wrapper_attr", "np_random_seed") == [4, seeds[1], 4]

    generators = [np.random.default_rng(i) for i in range(N_ENVS)]
    setattr_results = [vec_env.set_attr("np_random", generators[i], indices=i) for i in range(N_ENVS)]
    getattr_results = vec_env.get_attr("np_random")
    assert setattr_results == [None] * N_ENVS
    assert all(got is generators[i] for i, got in enumerate(getattr_results))
    assert vec_env.get_attr("np_random_seed") == [-1] * N_ENVS  # a generator set directly

    # to change the value for all the environments
    shared = np.random.default_rng(42)
    assert vec_env.set_attr("np_random", shared, indices=None) is None
    assert all(got is shared for got in vec_env.get_attr("np_random"))

    # set_attr that does not affect all the environments
    vec_env.reset()
    other = np.random.default_rng(12)
    assert vec_env.set_attr("np_random", other, indices=[0, 1]) is None
    assert [g is other for g in vec_env.get_attr("np_random")] == [True, True, False]
    assert [g is other for g in vec_env.get_attr("np_random", indices=[0, 1])] == [True, True]
    assert [g is other for g in vec_env.get_attr("np_random", indices=[0, 2])] == [True, False]

    vec_env.reset()
    last = np.random.default_rng(13)
    assert vec_env.set_attr("np_random", last, indices=[0, -1]) is None
    assert [g is last for g in vec_env.get_attr("np_random")] == [True, False, True]
    assert [g is last for g in vec_env.get_attr("np_random", indices=[-1])] == [True]
    vec_env.close()


@both
@pytest.mark.parametrize("wrapper", VEC_ENV_WRAPPERS, ids=lambda w: getattr(w, "__name__", "none"))
def test_vecenv_terminal_obs(kind, env_id, wrapper):
    """SB3's test_vecenv_terminal_obs: 'terminal_observation' in the info of the ending step
    only, the returned observation the first of the next episode."""
    vec_env = wrap(make(kind, env_id), wrapper)
    vec_env.seed(1)
    vec_env.reset()
    space = gym.make(env_id, **ENVS[env_id]).observation_space
    n_actions = vec_env.action_space.shape[0]
    ends = np.zeros(N_ENVS, int)
    truncations = np.zeros(N_ENVS, int)
    for _ in range(120):
        steps_before = np.array(vec_env.get_attr("elapsed_steps"))
        _, _, done_b, info_b = vec_env.step(np.broadcast_to(BIAS, (N_ENVS, n_actions)).astype(np.float32))
        assert len(done_b) == len(info_b) == N_ENVS
        steps_after = np.array(vec_env.get_attr("elapsed_steps"))
        for i, (done, info) in enumerate(zip(done_b, info_b, strict=True)):
            if not done:
                assert "terminal_observation" not in info
                assert steps_after[i] == steps_before[i] + 1
            else:
                ends[i] += 1
                truncations[i] += info["TimeLimit.truncated"]
                assert steps_after[i] == 0  # reset within the step
                if not isinstance(vec_env, VecNormalize | VecFrameStack):
                    assert space.contains(info["terminal_observation"])
    assert ends.min() >= 1
    assert truncations[0] == ends[0] and truncations[2] == 0  # time limit, envelope
    vec_env.close()


@both
def test_vecenv_single_space(kind, env_id):
    """SB3's check_vecenv_spaces: every observation in the observation space, to the first end."""
    vec_env = make(kind, env_id)
    space = vec_env.observation_space
    vec_env.action_space.seed(0)
    obs = vec_env.reset()
    dones = np.zeros(N_ENVS, bool)
    steps = 0
    while not dones.any():
        assert obs.shape[0] == N_ENVS and all(space.contains(value) for value in obs)
        actions = np.array([vec_env.action_space.sample() for _ in range(N_ENVS)])
        obs, _, dones, _ = vec_env.step(actions)
        steps += 1
    assert all(space.contains(value) for value in obs) and steps >= 1
    vec_env.close()


@pytest.mark.parametrize("env_id", list(ENVS))
def test_vec_env_is_wrapped(env_id):
    """SB3's test_vec_env_is_wrapped: DummyVecEnv with a Monitor on one env of two; the adapter
    answers for the gymnasium vector wrappers around the vector env (sub-envs have none)."""
    options = ENVS[env_id]
    vec_env = DummyVecEnv([lambda: gym.make(env_id, **options), lambda: Monitor(gym.make(env_id, **options))])
    assert vec_env.env_is_wrapped(Monitor) == [False, True]
    assert VecFrameStack(vec_env, n_stack=2).env_is_wrapped(Monitor) == [False, True]

    native = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                          autoreset_mode=AutoresetMode.SAME_STEP, **options)  # fmt: skip
    adapter = SB3VecEnv(gym.wrappers.vector.RecordEpisodeStatistics(native))
    assert adapter.env_is_wrapped(Monitor) == [False, False]
    assert adapter.env_is_wrapped(gym.wrappers.vector.RecordEpisodeStatistics) == [True, True]
    assert VecFrameStack(adapter, n_stack=2).env_is_wrapped(Monitor, indices=[1]) == [False]
    plain = make_sb3_vec_env(env_id, 2, **options)
    assert plain.env_is_wrapped(gym.wrappers.vector.RecordEpisodeStatistics) == [False, False]


def test_episode_statistics_reach_the_ending_steps_info():
    """gymnasium's RecordEpisodeStatistics puts an ended episode's statistics at the top of a
    SAME_STEP info, which the adapter filed with the reset's entries: SB3 (ep_info_buffer) reads
    ``info["episode"]`` from the ending step's info, where DummyVecEnv with a Monitor puts it."""
    env_id = "ssme_envs/NozzleTVC-v0"
    native = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                          autoreset_mode=AutoresetMode.SAME_STEP, max_episode_steps=5)  # fmt: skip
    adapter = SB3VecEnv(gym.wrappers.vector.RecordEpisodeStatistics(native), seed=0)
    dummy = DummyVecEnv([lambda: Monitor(gym.make(env_id, max_episode_steps=5)) for _ in range(2)])
    dummy.seed(0)
    for vec_env in (adapter, dummy):
        vec_env.reset()
        for _ in range(5):
            _, _, dones, infos = vec_env.step(np.zeros((2, 1), dtype=np.float32))
        assert dones.all()
        assert [info["episode"]["l"] for info in infos] == [5, 5]
        assert all("episode" not in info for info in vec_env.reset_infos)
    adapter.close()
    dummy.close()


@both
def test_vec_seeding(kind, env_id):
    """SB3's test_vec_seeding: seed() without a seed still seeds every env differently."""
    vec_env = make(kind, env_id)
    seeds = vec_env.seed()
    assert len(set(seeds)) == N_ENVS
    obs = vec_env.reset()
    assert vec_env.get_attr("np_random_seed") == seeds
    _, rewards, _, _ = vec_env.step(np.zeros((N_ENVS, *vec_env.action_space.shape), np.float32))
    for i in range(N_ENVS - 1):
        assert not np.allclose(obs[i], obs[i + 1])
        assert not np.allclose(rewards[i], rewards[i + 1])
    vec_env.close()


@both
def test_vec_deterministic(kind, env_id):
    """SB3's test_vec_deterministic: the seeds of seed() make the next reset reproducible, also
    through VecNormalize; they are used once (the next reset continues the streams)."""
    vec_env = make(kind, env_id)
    vec_env.seed(3)
    obs = vec_env.reset()
    assert vec_env.get_attr("np_random_seed") == [3, 4, 5]
    following = vec_env.reset()
    assert not np.array_equal(following, obs)
    vec_env.seed(3)
    np.testing.assert_array_equal(vec_env.reset(), obs)
    vec_normalize = VecNormalize(vec_env)
    vec_normalize.seed(3)
    obs = vec_env.reset()
    vec_normalize.seed(3)
    np.testing.assert_array_equal(vec_env.reset(), obs)


class CustomWrapperA(VecNormalize):
    def __init__(self, venv: VecEnv) -> None:
        VecNormalize.__init__(self, venv)
        self.var_a = "a"


class CustomWrapperB(VecNormalize):
    def __init__(self, venv: VecEnv) -> None:
        VecNormalize.__init__(self, venv)
        self.var_b = "b"

    def func_b(self) -> str:
        return self.var_b

    def name_test(self) -> type:
        return self.__class__


class CustomWrapperBB(CustomWrapperB):
    def __init__(self, venv: VecEnv) -> None:
        CustomWrapperB.__init__(self, venv)
        self.var_bb = "bb"


@both
def test_vecenv_wrapper_getattr(kind, env_id):
    """SB3's test_vecenv_wrapper_getattr: attributes through stacked VecEnv wrappers."""
    wrapped = CustomWrapperA(CustomWrapperBB(make(kind, env_id)))
    assert (wrapped.var_a, wrapped.var_b, wrapped.var_bb, wrapped.func_b()) == ("a", "b", "bb", "b")
    assert wrapped.name_test() == CustomWrapperBB
    double_wrapped = CustomWrapperA(CustomWrapperB(wrapped))
    assert double_wrapped.var_a == "a"  # defined here
    with pytest.raises(AttributeError):  # ambiguous
        _ = double_wrapped.var_b
    with pytest.raises(AttributeError):  # nowhere
        _ = double_wrapped.nonexistent_attribute


@both
def test_framestack_vecenv(kind, env_id):
    """SB3's test_framestack_vecenv for a non-image env: frames stacked on the last axis."""
    vec_env = VecFrameStack(make(kind, env_id), n_stack=2)
    obs = vec_env.reset()
    size = vec_env.venv.observation_space.shape[0]
    assert obs.shape == (N_ENVS, 2 * size) and not obs[:, :size].any()
    obs, *_ = vec_env.step(np.zeros((N_ENVS, *vec_env.action_space.shape), np.float32))
    assert obs.shape == (N_ENVS, 2 * size)


class OptionProbe(gym.Wrapper):
    """Records the options of each reset and takes away its own key, ``probe``."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.seen: list[dict | None] = []

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple:
        self.seen.append(None if options is None else dict(options))
        rest = None if options is None else {k: v for k, v in options.items() if k != "probe"}
        return self.env.reset(seed=seed, options=rest)


class VectorOptionProbe(gym.vector.VectorWrapper):
    """OptionProbe for a vector env: the options each sub-env's reset got (``reset_mask`` aside)."""

    def __init__(self, env: gym.vector.VectorEnv) -> None:
        super().__init__(env)
        self.seen: list[list[dict | None]] = [[] for _ in range(env.num_envs)]

    def reset(self, *, seed: Any = None, options: dict | None = None) -> tuple:
        mask = (options or {}).get("reset_mask", np.ones(self.num_envs, bool))
        own = None if options is None else {k: v for k, v in options.items() if k != "reset_mask"}
        for i in np.flatnonzero(mask):
            self.seen[i].append(own or None)
        rest = None if options is None else {k: v for k, v in options.items() if k != "probe"}
        return self.env.reset(seed=seed, options=rest)


@pytest.mark.parametrize("env_id", list(ENVS))
def test_set_options_reach_the_next_reset_only(env_id):
    """SB3's options checks: set_options acts at the next reset only, the same options for all
    or a list per env; DummyVecEnv and the adapter pass each env the same options (the adapter
    in partial resets, one per set of equal options, each env with its own seed)."""
    options = ENVS[env_id]
    dummy = DummyVecEnv([lambda: OptionProbe(gym.make(env_id, **options)) for _ in range(N_ENVS)])
    native = gym.make_vec(env_id, num_envs=N_ENVS, vectorization_mode="vector_entry_point",
                          autoreset_mode=AutoresetMode.SAME_STEP, **options)  # fmt: skip
    probe = VectorOptionProbe(native)
    adapter = SB3VecEnv(probe)
    observations = []
    for vec_env in (dummy, adapter):
        vec_env.reset()
        vec_env.set_options({"probe": 1})
        vec_env.reset()
        vec_env.reset()  # options used once
        vec_env.set_options([{"probe": i % 2} for i in range(N_ENVS)])
        vec_env.seed(9)
        observations.append(vec_env.reset())
    expected = [[None, {"probe": 1}, None, {"probe": i % 2}] for i in range(N_ENVS)]
    assert dummy.get_attr("seen") == expected
    assert probe.seen == expected
    np.testing.assert_array_equal(observations[0], observations[1])
    for vec_env in (dummy, adapter):  # options our envs do not take fail at the reset
        vec_env.set_options({"bogus": 1})
        with pytest.raises(ValueError, match=r"unknown option.*'bogus'"):
            vec_env.reset()


@pytest.mark.parametrize("env_id", list(ENVS))
def test_adapter_equals_dummy_vec_env(env_id):
    """Episodes through the adapter and through DummyVecEnv of the scalar env, bit for bit:
    observations, rewards, dones, terminal observations, truncation marks, per-env attributes."""
    adapter, dummy = make("adapter", env_id), make("dummy", env_id)
    for vec_env in (adapter, dummy):
        vec_env.seed(5)
    np.testing.assert_array_equal(adapter.reset(), dummy.reset())
    assert adapter.reset_infos == dummy.reset_infos == [{}] * N_ENVS
    rng = np.random.default_rng(0)
    n_actions = adapter.action_space.shape[0]
    ends = 0
    for k in range(150):
        actions = (BIAS + rng.uniform(-0.2, 0.2, (N_ENVS, n_actions))).astype(np.float32)
        a, b = adapter.step(actions), dummy.step(actions)
        for name, x, y in zip(("obs", "rewards", "dones"), a[:3], b[:3], strict=True):
            assert np.array_equal(x, y) and x.dtype == y.dtype, f"{name} differs at step {k}"
        for info_a, info_b, done in zip(a[3], b[3], a[2], strict=True):
            if done:
                np.testing.assert_array_equal(
                    info_a.pop("terminal_observation"), info_b.pop("terminal_observation")
                )
                assert info_a == info_b
        ends += int(a[2].sum())
        assert adapter.get_attr("elapsed_steps") == dummy.get_attr("elapsed_steps")
    assert ends >= N_ENVS
    assert adapter.get_attr("np_random_seed") == dummy.get_attr("np_random_seed") == [5, 6, 7]
    specs = adapter.get_attr("spec")
    for spec, reference in zip(specs, dummy.get_attr("spec"), strict=True):
        assert (spec.id, spec.kwargs, spec.max_episode_steps) == (
            reference.id,
            reference.kwargs,
            reference.max_episode_steps,
        )
    assert specs[0] is not specs[1]  # per sub-env objects
    np.testing.assert_array_equal(gym.make(specs[0]).reset(seed=1)[0], dummy.envs[0].reset(seed=1)[0])


@pytest.mark.parametrize("env_id", list(ENVS))
def test_adapter_refuses_what_is_not_per_sub_env(env_id):
    adapter = make("adapter", env_id)
    adapter.reset()
    tasks = adapter.get_attr("task", indices=[1, 2])
    assert len(tasks) == 2 and tasks[0].horizon == tasks[1].horizon  # shared, read-only
    for name, value in [("task", None), ("elapsed_steps", 3), ("new_attribute", 1)]:
        with pytest.raises(AttributeError, match=f"cannot set '{name}' on one sub-env"):
            adapter.set_attr(name, value, indices=[0])
    for method in ("step", "close", "render"):
        with pytest.raises(AttributeError, match=f"'{method}' does not exist per sub-env"):
            adapter.env_method(method, indices=[0])
    assert adapter.has_attr("np_random") and not adapter.has_attr("nonexistent")
    with pytest.raises(IndexError):
        adapter.get_attr("np_random", indices=[N_ENVS])
    same_step = {"autoreset_mode": AutoresetMode.SAME_STEP}
    sync = gym.make_vec(env_id, N_ENVS, vectorization_mode="sync", vector_kwargs=same_step, **ENVS[env_id])
    over_sync = SB3VecEnv(sync, seed=2)  # a SyncVectorEnv's sub-envs are objects: per-env values as they are
    over_sync.reset()
    assert over_sync.get_attr("np_random_seed") == [2, 3, 4]
    with pytest.raises(ValueError, match="SAME_STEP"):
        SB3VecEnv(gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **ENVS[env_id]))


def test_sub_env_indices_generators_and_seeds_are_checked():
    """Out-of-range indices gave a bare IndexError, True picked sub-env 1, an int as np_random
    broke the next reset, and a string seed gave numpy's concatenation error."""
    from ssme_envs.envs.sb3_adapter import make_sb3_vec_env

    venv = make_sb3_vec_env("ssme_envs/EngineTracking-v0", 2, seed=0)
    with pytest.raises(IndexError, match="sub-env index 5 out of range for 2"):
        venv.get_attr("np_random_seed", [5])
    with pytest.raises(TypeError, match="indices must be sub-env numbers"):
        venv.get_attr("np_random_seed", True)
    with pytest.raises(TypeError, match="np_random must be a numpy Generator"):
        venv.set_attr("np_random", 5)
    venv.reset()  # still resets: nothing was set
    assert venv.get_attr("np_random_seed", [1]) == [1]
    with pytest.raises(TypeError, match="Seed must be an integer"):
        make_sb3_vec_env("ssme_envs/EngineTracking-v0", 2, seed="x")
