"""Per-step episode streams (``envs.episode_streams``) against whole episodes computed in one go.

The expected values are the task's own ``episodes`` over each episode's whole draw, drawn by a twin
generator with ``rng.random(draw_size, dtype=np.float32)``: the Box-Muller rows of
``normal_rows`` and the references of ``reference_signals``, computed a block at a time over
every step, not from cursors or holds one step at a time.
"""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ssme_envs  # noqa: F401
from ssme_envs.envs import episode_streams
from ssme_envs.envs.episode_draws import ORIGIN_WORDS, EpisodeDraws
from ssme_envs.envs.episode_streams import (
    STREAM_WORDS,
    EpisodeStreams,
    EpisodeTables,
    episode_source,
    table_uniforms,
)
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_task import NozzleTask
from ssme_envs.envs.references import StreamLayout

needs_kernel = pytest.mark.skipif(episode_streams.KERNEL != "compiled", reason="the draw kernel is not built")

# a step's move: on by one (most), repeated, skipped ahead, a jump anywhere, a restart, and a
# restart begun for the next read (the vector env's NEXT_STEP restarts)
MOVES = st.lists(
    st.tuples(
        st.sampled_from(["next", "next", "next", "same", "skip", "jump", "restart", "begin"]),
        st.integers(0, 10**6),
    ),
    min_size=1,
    max_size=60,
)


def whole_episodes(task, rngs):
    """Each generator's next episode drawn whole by a twin, and the task's references and unit
    noise over all its steps, (steps, n) each."""
    twins = copy.deepcopy(rngs)
    uniforms = np.stack([twin.random(task.draw_size, dtype=np.float32) for twin in twins], axis=1)
    refs, noise = task.episodes(uniforms, 0, task.horizon + 1)
    return refs[0], noise[0]


@given(
    st.sampled_from(["nozzle", "launcher"]),
    st.floats(0.1, 12.0),
    st.lists(st.integers(0, 2**64 - 1), min_size=1, max_size=6),
    MOVES,
    st.booleans(),
)
@settings(max_examples=60, deadline=None)
def test_every_step_is_the_whole_episodes_step(kind, seconds, seeds, moves, to_table):
    task = (NozzleTask.build if kind == "nozzle" else LauncherTask.build_launcher)(episode_seconds=seconds)
    length, n = task.horizon + 1, len(seeds)
    rngs = [np.random.Generator(np.random.PCG64(seed)) for seed in seeds]
    for i, rng in enumerate(rngs):
        rng.random(i % 2, dtype=np.float32)  # odd envs' generators keep a half
    draws = EpisodeDraws(task.draw_size, rngs)
    streams = EpisodeStreams(draws, task.stream_layout)
    envs = np.arange(n)
    refs, noise = whole_episodes(task, rngs)
    draws.start(envs)
    ref0, noise0 = streams.restart(envs)
    assert ref0.tobytes() == refs[0].tobytes() and noise0.tobytes() == noise[0].tobytes()
    t = np.zeros(n, dtype=np.int64)
    for step, (move, value) in enumerate(moves):
        if to_table and step == len(moves) // 2:  # a sub-env given another bit generator: a table
            draws.set_generator(0, np.random.Generator(np.random.MT19937(value)))
        if move in ("restart", "begin"):
            restart = np.arange(value % n, n)[:: 1 + value % 2].copy()  # C-contiguous, as flatnonzero gives
            fresh_refs, fresh_noise = whole_episodes(task, [draws.generators[i] for i in restart])
            draws.start(restart)
            refs[:, restart], noise[:, restart] = fresh_refs, fresh_noise
            t[restart] = 0
            if move == "restart":
                ref0, noise0 = streams.restart(restart)
                assert ref0.tobytes() == fresh_refs[0].tobytes()
                assert noise0.tobytes() == fresh_noise[0].tobytes()
                continue
            streams.begin(restart)  # the read below gives their step 0 beside the others' steps
        else:
            t = {
                "next": t + 1,
                "same": t,
                "skip": t + 1 + value % 7,
                "jump": (t * 0 + value + np.arange(n) * 131) % length,
            }[move]
        t = np.minimum(t, length - 1)
        got_refs, got_noise, _ = streams.at(t, int(t.max()), False)
        assert got_refs[0].tobytes() == refs[t, envs].tobytes()
        assert got_noise[0].tobytes() == noise[t, envs].tobytes()


# a layout with room for many steps on, a few holds, a turn to sines, and an odd half (the two
# cursors then take new outputs at alternate steps)
WIDE_LAYOUT = StreamLayout(half=41, refs_at=82, holds=5, shortest=3, longest=20, amplitude=0.05)
CALLS = st.lists(
    st.tuples(
        st.sampled_from(["all", "all", "all", "ascending", "any"]),  # which envs a call reads
        st.sampled_from(["next", "next", "next", "same", "jump"]),  # where their steps go
        st.booleans(),  # sought from their origins (fresh)
    ),
    min_size=1,
    max_size=40,
)


@needs_kernel
@given(st.integers(1, 1100), st.integers(0, 2**64 - 1), CALLS)
@settings(max_examples=40, deadline=None)
def test_the_kernel_gives_the_whole_draws_numbers_for_any_envs(n, seed, calls):
    """The kernel's ``streams`` against ``table_uniforms`` (numpy over whole draws) for calls on
    every env (consecutive: eight at a time where AVX-512 runs), on an ascending subset (env by
    env), and on any envs in any order with repeats (each in its order)."""
    layout, size = WIDE_LAYOUT, 2 * WIDE_LAYOUT.refs_at
    rng = np.random.default_rng(seed % 2**32)
    gens = [np.random.Generator(np.random.PCG64(seed + i)) for i in range(n)]
    for i, gen in enumerate(gens):
        gen.random(i % 2, dtype=np.float32)  # odd envs' generators keep a half
    table = np.stack([twin.random(size, dtype=np.float32) for twin in copy.deepcopy(gens)])
    origins = np.zeros((n, ORIGIN_WORDS), dtype=np.uint64)
    episode_streams._KERNEL.start([gen.bit_generator.capsule for gen in gens], np.arange(n), size, origins)
    cursors = np.zeros((STREAM_WORDS, n), dtype=np.uint64)
    cursors[0] = episode_streams._UNSET
    codes = np.array(layout[:5], dtype=np.int64)
    last = np.zeros(n, dtype=np.int64)
    for which, move, fresh in calls:
        if which == "all":
            envs = np.arange(n)
        elif which == "ascending":
            envs = np.flatnonzero(rng.random(n) < 0.7)
        else:
            envs = rng.integers(0, n, size=rng.integers(1, 2 * n + 1))
        jump = rng.integers(0, 2 * layout.half, len(envs))
        t = np.minimum({"next": last[envs] + 1, "same": last[envs], "jump": jump}[move], 2 * layout.half - 1)
        restarted = rng.random(len(envs)) < 0.1  # some start again from step 0
        t[restarted] = 0
        got = np.empty(len(envs)), np.empty(len(envs), np.float32), np.empty(len(envs), np.float32)
        want = np.empty(len(envs)), np.empty(len(envs), np.float32), np.empty(len(envs), np.float32)
        kernel = episode_streams._KERNEL
        sines = kernel.streams(origins, envs, t, cursors, codes, layout.amplitude, fresh, *got)
        assert sines == table_uniforms(table, envs, t, layout, *want)
        for a, b in zip(got, want, strict=True):
            assert a.tobytes() == b.tobytes()
        last[envs] = t


@needs_kernel
def test_the_kernel_agrees_at_import():
    assert episode_streams._kernel_agrees(episode_streams._KERNEL)


@needs_kernel
@pytest.mark.parametrize(
    "change, message",
    [
        ({"t": np.array([-1], dtype=np.int64)}, "step -1 outside"),
        ({"t": np.array([14], dtype=np.int64)}, "step 14 outside"),
        ({"layout": np.array([7, 3, 4, 3, 9], dtype=np.int64)}, "layout"),
        ({"layout": np.array([7, 14, 4, 9, 3], dtype=np.int64)}, "layout"),
        ({"cursors": np.zeros((1, STREAM_WORDS - 1), dtype=np.uint64)}, "cursors"),
        ({"envs": np.array([1], dtype=np.int64)}, "envs: index 1"),
        ({"refs": np.empty(2)}, "refs"),
    ],
)
def test_the_kernel_refuses_bad_arguments(change, message):
    args = {
        "origins": np.zeros((1, ORIGIN_WORDS), dtype=np.uint64),
        "envs": np.zeros(1, dtype=np.int64),
        "t": np.zeros(1, dtype=np.int64),
        "cursors": np.zeros((1, STREAM_WORDS), dtype=np.uint64),
        "layout": np.array([7, 14, 4, 3, 9], dtype=np.int64),
        "amplitude": 0.05,
        "fresh": True,
        "refs": np.empty(1),
        "radius": np.empty(1, dtype=np.float32),
        "angle": np.empty(1, dtype=np.float32),
    }
    args.update(change)
    with pytest.raises(ValueError, match=message):
        episode_streams._KERNEL.streams(*args.values())


def test_streams_serve_random_steps_tasks_and_tables_the_rest():
    rngs = [np.random.default_rng(0)]
    for task in (NozzleTask.build(), LauncherTask.build_launcher()):
        draws = EpisodeDraws(task.draw_size, rngs)  # a table without the draw kernel: streams read it
        readable = episode_streams.KERNEL == "compiled" or draws.form == "table"
        assert isinstance(episode_source(task, draws), EpisodeStreams if readable else EpisodeTables)
    for task in (NozzleTask.build(reference="sine_sweep"), LauncherTask.build_launcher(reference="attitude")):
        assert task.stream_layout is None
        assert isinstance(episode_source(task, EpisodeDraws(task.draw_size, rngs)), EpisodeTables)


@needs_kernel
@pytest.mark.parametrize("env_id", ["ssme_envs/NozzleTVC-v0", "ssme_envs/LauncherPitch-v0"])
def test_vector_env_with_streams_equals_the_one_with_tables(env_id, monkeypatch):
    """Random actions (episodes end and restart every few steps) through both sources."""
    runs = []
    for source in (EpisodeStreams, EpisodeTables):
        if source is EpisodeTables:
            monkeypatch.setattr(episode_streams, "KERNEL", "python")  # origins without streams: tables
        env = gym.make_vec(env_id, num_envs=64, vectorization_mode="vector_entry_point")
        assert isinstance(env.unwrapped._episodes, source)
        obs, _ = env.reset(seed=3)
        rng = np.random.default_rng(0)
        out = [obs]
        for _ in range(80):
            obs, reward, terminated, truncated, _ = env.step(rng.uniform(-1, 1, (64, 1)))
            out += [obs, reward, terminated, truncated]
        runs.append(b"".join(np.ascontiguousarray(a).tobytes() for a in out))
        env.close()
    assert runs[0] == runs[1]
