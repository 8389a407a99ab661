"""Episode draws read in blocks (``envs.episode_draws``) against numpy drawing whole episodes.

The expected numbers and generator states are numpy's own: a twin of each generator draws
``rng.random(size, dtype=np.float32)``, what the scalar env does at reset.
"""

from __future__ import annotations

import copy
import importlib

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ssme_envs  # noqa: F401
from ssme_envs.envs import episode_draws
from ssme_envs.envs.episode_draws import ORIGIN_WORDS, EpisodeDraws
from ssme_envs.models.kernels import NO_KERNEL, references_requested

needs_kernel = pytest.mark.skipif(episode_draws.KERNEL != "compiled", reason="the draw kernel is not built")


def generators(seeds: list[int], ahead: list[int]) -> list[np.random.Generator]:
    """PCG64 generators, each moved on by a few float32 draws (an odd count keeps a half)."""
    rngs = [np.random.Generator(np.random.PCG64(seed)) for seed in seeds]
    for rng, count in zip(rngs, ahead, strict=True):
        rng.random(count, dtype=np.float32)
    return rngs


draw_case = st.integers(1, 5).flatmap(
    lambda n: st.tuples(
        st.lists(st.integers(0, 2**64 - 1), min_size=n, max_size=n),
        st.lists(st.integers(0, 3), min_size=n, max_size=n),
        st.lists(st.integers(0, n - 1), min_size=1, max_size=2 * n),  # repeats: one generator twice
        st.integers(0, 700),
        st.integers(1, 3),
    )
)


@given(draw_case, st.data())
@settings(max_examples=80, deadline=None)
def test_blocks_and_generator_states_are_numpys_whole_draws(case, data):
    seeds, ahead, picks, size, episodes = case
    rngs = generators(seeds, ahead)
    twins = copy.deepcopy(rngs)
    draws = EpisodeDraws(size, rngs)
    envs = np.unique(np.array(picks, dtype=np.int64))
    for _ in range(episodes):
        draws.start(envs)
        expected = {int(i): twins[i].random(size, dtype=np.float32) for i in envs}
        for i in envs:
            assert rngs[i].bit_generator.state == twins[i].bit_generator.state
        lo = data.draw(st.integers(0, size))
        hi = data.draw(st.integers(lo, size))
        block = draws.rows(envs, lo, hi)
        assert block.shape == (hi - lo, len(envs)) and block.dtype == np.float32 and block.flags.c_contiguous
        for column, i in enumerate(envs):
            assert block[:, column].tobytes() == expected[int(i)][lo:hi].tobytes()
        whole = draws.uniforms(envs)
        assert whole.shape == (size, len(envs))
        np.testing.assert_array_equal(whole[lo:hi], block)
        np.testing.assert_array_equal(whole[-3:], np.stack([expected[int(i)][-3:] for i in envs], axis=1))


def test_without_the_kernel_the_table_gives_numpys_numbers(monkeypatch):
    monkeypatch.setattr(episode_draws, "_KERNEL", None)
    rngs = generators([3, 4, 5], [0, 1, 2])
    twins = copy.deepcopy(rngs)
    table = EpisodeDraws(41, rngs)
    assert table.form == "table"
    for envs in (np.arange(3), np.array([2, 0])):
        table.start(envs)
        expected = np.stack([twins[i].random(41, dtype=np.float32) for i in envs], axis=1)
        for lo, hi in ((0, 41), (7, 20), (40, 41)):
            np.testing.assert_array_equal(table.rows(envs, lo, hi), expected[lo:hi])
    assert table.form == "table"  # a full start keeps the table without the kernel


@needs_kernel
def test_another_bit_generator_switches_to_the_table_and_keeps_the_episodes():
    rngs = generators([1, 2, 3], [0, 1, 0])
    twins = copy.deepcopy(rngs)
    draws = EpisodeDraws(9, rngs)
    assert draws.form == "origins"
    envs = np.arange(3)
    draws.start(envs)
    first = np.stack([twin.random(9, dtype=np.float32) for twin in twins], axis=1)
    mt = np.random.Generator(np.random.MT19937(7))
    draws.set_generator(1, mt)
    assert draws.form == "table" and draws.generators[1] is mt
    np.testing.assert_array_equal(draws.rows(envs, 0, 9), first)  # episodes in flight kept
    twin_mt = np.random.Generator(np.random.MT19937(7))
    draws.start(np.array([1]))
    np.testing.assert_array_equal(draws.rows(np.array([1]), 0, 9)[:, 0], twin_mt.random(9, dtype=np.float32))
    draws.set_generator(1, np.random.Generator(np.random.PCG64(9)))
    draws.start(np.array([0]))  # a partial start: the table stays
    assert draws.form == "table"
    draws.start(envs)  # every sub-env restarts, all PCG64: origins again
    assert draws.form == "origins"


@needs_kernel
def test_the_kernel_refuses_bad_arguments_before_moving_a_generator():
    kernel = episode_draws._KERNEL
    rngs = generators([1, 2], [0, 1])
    capsules = [rng.bit_generator.capsule for rng in rngs]
    before = [rng.bit_generator.state for rng in rngs]
    origins = np.zeros((2, ORIGIN_WORDS), dtype=np.uint64)
    envs = np.arange(2, dtype=np.int64)
    bad_starts = [
        ((capsules, np.array([0, 2]), 5, origins), ValueError, "outside"),
        ((capsules, np.array([-1]), 5, origins), ValueError, "outside"),
        ((capsules, envs.astype(np.int32), 5, origins), ValueError, "envs"),
        ((capsules, envs, -1, origins), ValueError, "count"),
        ((tuple(capsules), envs, 5, origins), ValueError, "list"),
        ((capsules, envs, 5, np.zeros((2, 5), np.uint64)), ValueError, "words"),
        ((capsules, envs, 5, origins.astype(np.int64)), ValueError, "origins"),
        ((capsules, envs, 5, origins[:, ::2]), ValueError, "contiguous"),
        (([capsules[0], object()], envs, 5, origins), TypeError, "capsule"),
        ((capsules, envs, 5), TypeError, "start"),
    ]
    for args, error, words in bad_starts:
        with pytest.raises(error, match=words):
            kernel.start(*args)
    assert [rng.bit_generator.state for rng in rngs] == before
    kernel.start(capsules, envs, 5, origins)
    out = np.empty((3, 2), dtype=np.float32)
    bad_rows = [
        ((origins, envs, 0, 4, out), "hi - lo"),
        ((origins, envs, 2, 1, out), "lo <= hi"),
        ((origins, envs, -1, 2, out), "lo <= hi"),
        ((origins, np.array([3]), 0, 3, out[:, :1].copy()), "outside"),
        ((origins, envs, 0, 3, out.astype(np.float64)), "out"),
        ((origins[:, :5].copy(), envs, 0, 3, out), "6 words"),
    ]
    for args, words in bad_rows:
        with pytest.raises(ValueError, match=words):
            kernel.rows(*args)


@needs_kernel
def test_a_block_is_made_from_its_origin_not_from_the_generator_now():
    rng = generators([11], [1])[0]
    twin = copy.deepcopy(rng)
    draws = EpisodeDraws(30, [rng])
    draws.start(np.array([0]))
    rng.random(5)  # the caller draws from the generator mid-episode
    np.testing.assert_array_equal(draws.rows(np.array([0]), 10, 30)[:, 0], twin.random(30, np.float32)[10:])


def test_uniforms_are_read_in_contiguous_row_slices():
    draws = EpisodeDraws(8, generators([1], [0]))
    draws.start(np.array([0]))
    view = draws.uniforms(np.array([0]))
    assert view[5:100].shape == (3, 1) and view[6:2].shape == (0, 1)
    with pytest.raises(TypeError, match="row slices"):
        view[0]
    with pytest.raises(ValueError, match="contiguous"):
        view[::2]


def give(env: gym.vector.VectorEnv, index: int, rng: np.random.Generator) -> None:
    """Set sub-env ``index``'s generator, in a native vector env or a SyncVectorEnv."""
    if hasattr(env.unwrapped, "sub_env"):
        env.unwrapped.sub_env(index).np_random = rng
    else:
        env.envs[index].unwrapped.np_random = rng


@pytest.mark.parametrize("env_id", ["ssme_envs/NozzleTVC-v0", "ssme_envs/EngineTracking-v0"])
def test_vector_env_with_other_bit_generators_equals_sync(env_id):
    """Sub-envs given MT19937 and shared PCG64 generators mid-run step as SyncVectorEnv's."""
    native = gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point")
    sync = gym.make_vec(env_id, num_envs=4, vectorization_mode="sync")
    actions = np.random.default_rng(5)
    for env in (native, sync):
        env.reset(seed=3)
    for step in range(400):
        if step in (40, 200):
            for env in (native, sync):
                give(env, 1, np.random.Generator(np.random.MT19937(step)))
                shared = np.random.default_rng(step)  # one generator for two sub-envs
                give(env, 2, shared)
                give(env, 3, shared)
        action = (2.0 * actions.random(native.action_space.shape) - 1.0).astype(np.float32)
        for got, want in zip(native.step(action)[:4], sync.step(action)[:4], strict=True):
            np.testing.assert_array_equal(got, want)
    assert native.unwrapped._draws.form == "table"
    native.reset(seed=1)
    assert native.unwrapped._draws.form == ("origins" if episode_draws.KERNEL == "compiled" else "table")


def test_a_built_kernel_is_used():
    """A build that the import check refused would leave the kernel's tests skipped: where the
    extension is built (and the references are not asked for), it must be the one in use."""
    if references_requested():
        pytest.skip(f"{NO_KERNEL} asks for the references")
    try:
        importlib.import_module("ssme_envs.models._draw_kernel")
    except ImportError:
        pytest.skip("the draw kernel is not built here")
    assert episode_draws.KERNEL == "compiled"
