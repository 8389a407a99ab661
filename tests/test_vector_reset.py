"""Partial resets, DISABLED autoreset and reset options: native vector env == SyncVectorEnv."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from conftest import SHORT_EPISODES
from gymnasium.vector import AutoresetMode

import ssme_envs  # noqa: F401  (registers the environments)
from ssme_envs.envs.tracking_env import EpisodeOverError

# short episodes: truncations within a few dozen steps
ENVS = SHORT_EPISODES
N = 4
BIAS = np.array([0.0, 0.1, 0.6, -1.0])[:, None]  # per sub-env: the last two leave the envelope


def _pair(env_id: str, mode: AutoresetMode, num_envs: int = N) -> tuple[gym.vector.VectorEnv, ...]:
    options = ENVS[env_id]
    sync = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": mode}, **options)  # fmt: skip
    native = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                          autoreset_mode=mode, **options)  # fmt: skip
    return sync, native


def _assert_same_info(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for key in a:
        if key == "final_obs":
            for i in np.flatnonzero(a["_final_obs"]):
                np.testing.assert_array_equal(a[key][i], b[key][i])
        elif isinstance(a[key], dict):
            _assert_same_info(a[key], b[key])
        else:
            np.testing.assert_array_equal(a[key], b[key])


@pytest.mark.parametrize("mode", list(AutoresetMode), ids=lambda m: m.name)
@pytest.mark.parametrize("env_id", list(ENVS))
def test_partial_resets_equal_sync_vector_env_over_600_steps(env_id, mode):
    """600 steps of random actions with random partial resets: every sub-env that ended (DISABLED
    mode: it must be reset) and random others (2 % a step), seeded with an int, per-env seeds
    with Nones, or none; observations, rewards, flags and infos of steps and resets equal bit
    for bit."""
    sync, native = _pair(env_id, mode)
    a, b = sync.reset(seed=7), native.reset(seed=7)
    np.testing.assert_array_equal(a[0], b[0])
    rng = np.random.default_rng(1)
    n_actions = native.single_action_space.shape[0]
    terminations = truncations = partial = 0
    for k in range(600):
        actions = (BIAS + rng.uniform(-0.2, 0.2, (N, n_actions))).astype(np.float32)
        ra, rb = sync.step(actions), native.step(actions)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated"), ra[:4], rb[:4], strict=True):
            assert np.array_equal(x, y) and x.dtype == y.dtype, f"{name} differs at step {k}"
        _assert_same_info(ra[4], rb[4])
        terminations += int(ra[2].sum())
        truncations += int(ra[3].sum())
        mask = rng.random(N) < 0.02
        if mode == AutoresetMode.DISABLED:
            mask |= ra[2] | ra[3]
        if not mask.any():
            continue
        partial += int(not mask.all())
        seed = [None, 100 + k, [int(s) if s % 3 else None for s in rng.integers(0, 1000, N)]][k % 3]
        before = rb[0]
        ra, rb = (env.reset(seed=seed, options={"reset_mask": mask.copy()}) for env in (sync, native))
        np.testing.assert_array_equal(ra[0], rb[0])
        np.testing.assert_array_equal(rb[0][~mask], before[~mask])  # the others keep their observations
        assert ra[1] == rb[1] == {}
        assert sync.np_random_seed == native.np_random_seed
    assert terminations > 0 and truncations > 0 and partial > 20


@pytest.mark.parametrize("env_id", list(ENVS))
def test_stepping_an_ended_episode_raises_in_every_env(env_id):
    """Scalar env after terminated or truncated, and a sub-env not reset in DISABLED mode: the
    native vector env and the scalar env raise EpisodeOverError (stepping nothing), which
    SyncVectorEnv's own AssertionError and ValueError also catch."""
    sync, native = _pair(env_id, AutoresetMode.DISABLED)
    with pytest.raises(EpisodeOverError, match="never reset"):
        native.step(np.zeros(native.action_space.shape, np.float32))
    sync.reset(seed=3)
    native.reset(seed=3)
    zeros = np.zeros(native.action_space.shape, np.float32)
    strong = np.ones(native.action_space.shape, np.float32)
    ended = np.zeros(N, bool)
    while not ended.any():
        ra, rb = sync.step(strong), native.step(strong)
        np.testing.assert_array_equal(ra[0], rb[0])
        ended = rb[2] | rb[3]
    state = [x.copy() for x in (native._t, native._obs)]
    for env in (sync, native):
        with pytest.raises(AssertionError):
            env.step(zeros)
    with pytest.raises(EpisodeOverError, match="reset_mask"):
        native.step(zeros)
    np.testing.assert_array_equal(native._t, state[0])  # nothing stepped
    np.testing.assert_array_equal(native._obs, state[1])
    # resetting the ended sub-envs lets both go on (SyncVectorEnv stepped its first sub-envs
    # before refusing: compare the native env with a fresh one instead)
    native.reset(options={"reset_mask": ended})
    assert native.step(zeros)[0].shape == native.observation_space.shape

    scalar = gym.make(env_id, **ENVS[env_id]).unwrapped
    with pytest.raises(EpisodeOverError, match="never reset"):
        scalar.step(zeros[0])
    scalar.reset(seed=0)
    while True:
        _, _, terminated, truncated, _ = scalar.step(strong[0])
        if terminated or truncated:
            break
    for error in (EpisodeOverError, AssertionError, ValueError, gym.error.ResetNeeded):
        with pytest.raises(error, match="call reset"):
            scalar.step(zeros[0])
    scalar.reset()
    scalar.step(zeros[0])


@pytest.mark.parametrize("env_id", list(ENVS))
def test_unknown_or_ill_typed_reset_options_raise(env_id):
    """The same exception types from the native vector env, SyncVectorEnv and the scalar env,
    the native messages naming the option and what is accepted."""
    sync, native = _pair(env_id, AutoresetMode.NEXT_STEP)
    scalar = gym.make(env_id, **ENVS[env_id])
    for env in (sync, native, scalar):
        env.reset(seed=0)
    cases = [
        ("x", TypeError, "options must be a dict or None, got str"),
        ({"reset_msk": np.ones(N, bool)}, ValueError, r"unknown option\(s\) 'reset_msk'.*'reset_mask'"),
        ({"reset_mask": [True] * N}, TypeError, "must be a numpy array, got list"),
        ({"reset_mask": np.ones(N + 1, bool)}, ValueError, rf"must have shape \({N},\), got \({N + 1},\)"),
        ({"reset_mask": np.ones(N, int)}, TypeError, "must have dtype bool"),
        ({"reset_mask": np.zeros(N, bool)}, ValueError, "at least one True"),
        ({"reset_mask": np.ones(N, bool), "level": 1}, ValueError, r"unknown option\(s\) 'level'"),
    ]
    for options, error, message in cases:
        with pytest.raises(error, match=message):
            native.reset(options=options)
        with pytest.raises(error):
            sync.reset(options=dict(options) if isinstance(options, dict) else options)
    for options, error, message in [
        ("x", TypeError, "options must be a dict or None, got str"),
        ({"reset_mask": np.ones(N, bool)}, ValueError, r"unknown option\(s\) 'reset_mask'.*no options"),
        ({"level": 2}, ValueError, r"unknown option\(s\) 'level'"),
    ]:
        with pytest.raises(error, match=message):
            scalar.reset(options=options)
    # what is accepted: None, {}, a mask (with a seed: the masked sub-envs' entries only)
    for env in (sync, native, scalar):
        env.reset(options={})
        env.reset(options=None)
    mask = np.array([True, False, True, False])
    ra, rb = (env.reset(seed=5, options={"reset_mask": mask.copy()}) for env in (sync, native))
    np.testing.assert_array_equal(ra[0], rb[0])
    assert native.np_random_seed[0] == 5 and native.np_random_seed[2] == 7
    assert sync.np_random_seed == native.np_random_seed


def test_sub_env_views_and_partial_reset_before_a_full_one():
    native = gym.make_vec("ssme_envs/NozzleTVC-v0", num_envs=3, vectorization_mode="vector_entry_point",
                          autoreset_mode=AutoresetMode.DISABLED)  # fmt: skip
    obs, _ = native.reset(seed=1, options={"reset_mask": np.array([True, False, True])})
    assert not obs[1].any()  # never reset: zeros, and stepping waits for it
    with pytest.raises(EpisodeOverError, match=r"sub-env\(s\) \[1\] never reset"):
        native.step(np.zeros((3, 1), np.float32))
    view = native.sub_env(-2)
    first, info = view.reset(seed=2)
    assert info == {} and native.np_random_seed == (1, 2, 3)
    single = gym.make("ssme_envs/NozzleTVC-v0")
    np.testing.assert_array_equal(first, single.reset(seed=2)[0])
    native.step(np.zeros((3, 1), np.float32))
    assert [native.sub_env(i).elapsed_steps for i in range(3)] == [1, 1, 1]
    generator = np.random.default_rng(0)
    view.np_random = generator
    assert native.np_random[1] is generator and native.np_random_seed[1] == -1
    spec = view.spec
    assert spec.id == "ssme_envs/NozzleTVC-v0" and spec.kwargs == {} and spec.max_episode_steps == 500
    assert spec is not native.sub_env(0).spec
    with pytest.raises(IndexError):
        native.sub_env(3)
    with pytest.raises(AttributeError, match="cannot set 'task'"):
        view.task = None
    with pytest.raises(AttributeError, match="'step' does not exist per sub-env"):
        view.step(np.zeros(1))
    with pytest.raises(ValueError, match="unknown option"):
        view.reset(options={"reset_mask": np.ones(3, bool)})


@pytest.mark.parametrize("env_id", list(ENVS))
@pytest.mark.parametrize("value", [1.7e308, -1.7e308])
def test_huge_finite_actions_are_clipped_without_warnings(env_id, value):
    """Actions near the float64 limit are legal (clipped to [-1, 1]): the native vector env steps
    as gymnasium's SyncVectorEnv does, without the overflow warning its finiteness check (a sum)
    used to raise, which under -W error refused a legal action."""
    import warnings

    sync, native = _pair(env_id, AutoresetMode.NEXT_STEP)
    action = np.full((N, *native.single_action_space.shape), value)
    sync.reset(seed=3)
    native.reset(seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = native.step(action)
    want = sync.step(action)
    for a, b in zip(got[:4], want[:4], strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("env_id", ["ssme_envs/EngineTracking-v0", "ssme_envs/NozzleTVC-v0"])
def test_max_episode_steps_minus_one_is_no_limit_as_gymnasium_reads_it(env_id):
    """``gymnasium.make`` reads max_episode_steps=-1 as no TimeLimit (the env's own end); the
    native vector env refused it as not a positive integer."""
    options = {**ENVS[env_id], "episode_seconds": 2 * ENVS[env_id]["episode_seconds"]}
    sync = gym.make_vec(env_id, num_envs=2, vectorization_mode="sync", max_episode_steps=-1, **options)
    native = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=-1,
                          **options)  # fmt: skip
    ends = []
    for env in (sync, native):
        env.reset(seed=0)
        steps, truncated = 0, np.zeros(2, bool)
        while not truncated.any():
            _, _, _, truncated, _ = env.step(np.zeros(env.action_space.shape, np.float32))
            steps += 1
        ends.append(steps)
        env.close()
    horizon = round(options["episode_seconds"] / gym.make(env_id, **options).unwrapped.task.dt)
    assert ends == [horizon, horizon]  # the env's own end, twice the short episodes


@pytest.mark.parametrize(
    ("env_id", "option", "value"),
    [
        ("ssme_envs/EngineTracking-v0", "reference", np.array(["step", "zero"])),
        ("ssme_envs/EngineTracking-v0", "reference", np.array("step")),
        ("ssme_envs/NozzleTVC-v0", "reference", np.array(["step"])),
        ("ssme_envs/EngineTracking-v0", "plant", np.array(["truth", "identified"])),
        ("ssme_envs/EngineTracking-v0", "plant", 3),
    ],
)
def test_a_name_option_given_as_an_array_is_refused_naming_the_option(env_id, option, value):
    """reference and plant were compared with their names as they came: a numpy array raised
    numpy's "truth value of an array is ambiguous", or passed as its one element."""
    for make in (
        gym.make,
        lambda i, **o: gym.make_vec(i, num_envs=2, vectorization_mode="vector_entry_point", **o),
    ):
        with pytest.raises(TypeError, match=rf"^{option} must be .*got (ndarray|int)\b"):
            make(env_id, **{option: value})


@pytest.mark.parametrize(("env_id", "time", "accepted"), [
    ("ssme_envs/EngineTracking-v0", 9.97, True), ("ssme_envs/EngineTracking-v0", 9.98, False),
    ("ssme_envs/NozzleTVC-v0", 3.99, True), ("ssme_envs/NozzleTVC-v0", 3.996, False),
])  # fmt: skip
def test_a_fault_time_inside_the_episode_that_rounds_to_its_last_step_is_told_so(env_id, time, accepted):
    """9.98 s on a 10 s episode rounds to its last step (250 of 0.04 s); the message said it was
    beyond the episode."""
    fault = {"kind": "sensor_bias", "time": time}
    if accepted:
        gym.make(env_id, fault=fault).close()
        return
    with pytest.raises(
        ValueError,
        match=rf"fault time {time:g} s is beyond the episode .* or at its last step \(it rounds to step",
    ):
        gym.make(env_id, fault=fault)
