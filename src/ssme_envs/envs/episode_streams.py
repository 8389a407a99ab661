"""Each step's noise and reference of a vector env's episodes, made as the step reaches it.

The tables of :mod:`ssme_envs.envs.episode_tables` compute an episode's references and noise a
block of steps at a time, so a reset computes a first block whatever the episode's length, and
each block is written across the (steps, envs) tables and read back a step later. Under random
actions, early in training, an eighth of the nozzle's sub-envs restart at every step, and that
block work costs more than the plant. Where a task's episode has a :class:`StreamLayout`
(one-channel Box-Muller noise and a random_steps reference, the nozzle's and the launcher's),
:class:`EpisodeStreams` makes each step's values alone instead: the compiled draw kernel keeps,
per sub-env, cursors on its draw that move one number a step and the reference's current hold,
and numpy's float32 ufuncs turn the step's uniforms into its normals, as
:func:`~ssme_envs.envs.references.normal_rows` does, so that every value has the bits the tables
(and the scalar env) give it. Without the kernel, or while the draws are a table, the same
values are read from the table with numpy (:func:`table_uniforms`).
"""

from __future__ import annotations

import copy
from typing import Any, Protocol

import numpy as np

from ssme_envs.envs.episode_draws import ORIGIN_WORDS, EpisodeDraws
from ssme_envs.envs.episode_tables import EpisodeTables
from ssme_envs.envs.references import StreamLayout
from ssme_envs.models.kernels import load_kernel

STREAM_WORDS = 10  # a sub-env's cursor words in the kernel (_draw_streams.h)
_AT, _HOLD = 0, 8  # the words of the step the cursors hold and of the reference's hold
_UNSET = np.uint64(2**64 - 2)  # a cursor's step before any: neither a step nor the one before one
TWO_PI = np.float32(2.0 * np.pi)


def table_uniforms(
    table: np.ndarray, envs: np.ndarray, t: np.ndarray, layout: StreamLayout,
    refs: np.ndarray, radius: np.ndarray, angle: np.ndarray,
) -> int:  # fmt: skip
    """The kernel's ``streams`` from whole draws ``table`` (N, size) float32: for sub-envs
    ``envs`` at steps ``t``, their references into ``refs`` (float64) and their noise's radius
    and angle uniforms into ``radius`` and ``angle`` (float32); how many steps are at or past
    ``layout.half`` (their noise is a sine)."""
    half = layout.half
    cosine = t < half
    radius[...] = table[envs, np.where(cosine, t, t - half)]
    angle[...] = table[envs, np.where(cosine, t + half, t)]
    lengths = table[envs, layout.refs_at : layout.refs_at + layout.holds].astype(np.float64)
    span = layout.longest - layout.shortest + 1
    ends = layout.shortest + np.floor(lengths * span).astype(np.intp)
    np.cumsum(ends, axis=1, out=ends)
    hold = np.minimum((ends <= t[:, None]).sum(axis=1), layout.holds - 1)
    level = 2.0 * table[envs, layout.refs_at + layout.holds + hold].astype(np.float64) - 1.0
    level *= layout.amplitude
    refs[...] = level
    return len(t) - int(cosine.sum())


def box_muller(radius: np.ndarray, angle: np.ndarray, sine: bool | np.ndarray) -> np.ndarray:
    """Unit normals from their uniforms, float32, in place into ``angle``: ``sqrt(-2 log(1 -
    radius)) wave(2 pi angle)``, the wave a sine where ``sine`` (a flag or a mask), else a
    cosine; the operations of :func:`~ssme_envs.envs.references.normal_rows`, and so its bits."""
    np.negative(radius, out=radius)
    np.log1p(radius, out=radius)
    radius *= -2.0
    np.sqrt(radius, out=radius)
    angle *= TWO_PI
    if isinstance(sine, np.ndarray):  # a few long episodes past half: their sines alone
        rows = sine.nonzero()[0]
        sines = np.sin(angle[rows])
        np.cos(angle, out=angle)
        angle[rows] = sines
    else:
        (np.sin if sine else np.cos)(angle, out=angle)
    angle *= radius
    return angle


def _kernel_agrees(kernel: object) -> bool:
    """Whether the kernel's ``streams`` gives :func:`table_uniforms`' numbers on seeded draws
    (with and without a kept half), through restarts (a reset's, and a vector env's at step 0
    beside envs stepping on: eight a vector where the wide path runs), steps one at a time,
    repeated and skipped steps, the noise's turn to sines and the reference's holds."""
    layout = StreamLayout(half=7, refs_at=14, holds=4, shortest=3, longest=9, amplitude=0.05)
    size, n = 22, 12
    rngs = [np.random.Generator(np.random.PCG64(seed)) for seed in (0, 1, 2**63 + 5, 12345, *range(8))]
    for i, rng in enumerate(rngs):
        rng.random(i % 2, dtype=np.float32)  # the odd envs hold a kept half
    twins = copy.deepcopy(rngs)
    table = np.stack([twin.random(size, dtype=np.float32) for twin in twins])
    origins = np.zeros((n, ORIGIN_WORDS), dtype=np.uint64)
    envs = np.arange(n)
    capsules = [rng.bit_generator.capsule for rng in rngs]
    kernel.start(capsules, envs, size, origins)
    cursors = np.zeros((STREAM_WORDS, n), dtype=np.uint64)
    cursors[_AT] = _UNSET
    codes = np.array(layout[:5], dtype=np.int64)
    # a reset, a step on by one of all envs at one step, steps on by one, repeated, skipped,
    # past half (sines) and across holds (four envs' steps, for each four envs); then new
    # episodes for nine envs at step 0 beside the others' next steps, and on through their
    # first hold's end, a step at a time
    steps = [
        (0, 0, 0, 0), (1, 1, 1, 1), (1, 0, 2, 5), (2, 1, 3, 6), (3, 9, 3, 7), (13, 10, 4, 8), (6, 11, 12, 13)
    ]  # fmt: skip
    at = [np.array(row * (n // 4), dtype=np.int64) for row in steps]
    restarted = np.array([0, 2, 3, 5, 6, 7, 8, 9, 11])
    t = np.minimum(at[-1] + 1, 2 * layout.half - 1)
    t[restarted] = 0
    at += [np.minimum(t + k, 2 * layout.half - 1) for k in range(layout.longest + 1)]
    for row, t in enumerate(at):
        if row == len(steps):  # the vector env's restart: new origins, cursors at no step
            kernel.start(capsules, restarted, size, origins)
            table[restarted] = [twins[i].random(size, dtype=np.float32) for i in restarted]
            cursors[_AT, restarted] = _UNSET
            cursors[_HOLD, restarted] = 0
        got = np.empty(n), np.empty(n, np.float32), np.empty(n, np.float32)
        want = np.empty(n), np.empty(n, np.float32), np.empty(n, np.float32)
        sines = kernel.streams(origins, envs, t, cursors, codes, layout.amplitude, row == 0, *got)
        if sines != table_uniforms(table, envs, t, layout, *want):
            return False
        if any(a.tobytes() != b.tobytes() for a, b in zip(got, want, strict=True)):
            return False
    return True


_KERNEL = load_kernel("_draw_kernel", _kernel_agrees, "episode stream")
KERNEL = "python" if _KERNEL is None else "compiled"  # how the streams read their uniforms


class EpisodeStreams:
    """Each step's references (1, N) float64 and unit noise (1, N) float32 of N sub-envs whose
    episodes ``draws`` holds, laid out as ``layout`` says; the values the task's ``episodes``
    gives those steps. :meth:`restart` after ``draws.start``; :meth:`at` at every step."""

    def __init__(self, draws: EpisodeDraws, layout: StreamLayout) -> None:
        self._draws = draws
        self._layout = layout
        self._codes = np.array(layout[:5], dtype=np.int64)
        n = len(draws.generators)
        self._all = np.arange(n)
        self._cursors = np.zeros((STREAM_WORDS, n), dtype=np.uint64)  # a row per word
        self._cursors[_AT] = _UNSET

    @staticmethod
    def bytes_per_env(layout: StreamLayout) -> int:
        """Bytes per sub-env: its cursors, a step's reference, uniforms and normals, and (read
        from a table, without the kernel) the step's hold lengths and ends."""
        return 8 * STREAM_WORDS + 32 + 24 * layout.holds

    def restart(self, envs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Step 0 of the new episodes of ``envs`` (int64 indices): references and noise (1, k)."""
        return self._values(envs, np.zeros(len(envs), dtype=np.int64), True)

    def begin(self, envs: np.ndarray) -> None:
        """Make the next :meth:`at` read the new episodes of ``envs`` (after ``draws.start``) from
        their origins, as :meth:`restart` does: cursors at no step and on no hold."""
        self._cursors[_AT, envs] = _UNSET
        self._cursors[_HOLD, envs] = 0  # a hold that ends at step 0: sought again at any step

    def at(self, t: np.ndarray, t_bound: int, synced: bool) -> tuple[np.ndarray, np.ndarray, int]:
        """Step ``t`` (int64, per sub-env) of every episode: references, noise, and ``t_bound``
        as it came (the tables' signature, :class:`~ssme_envs.envs.episode_tables.EpisodeTables`)."""
        return (*self._values(self._all, t, False), t_bound)

    def _values(self, envs: np.ndarray, t: np.ndarray, fresh: bool) -> tuple[np.ndarray, np.ndarray]:
        k = len(envs)
        refs = np.empty((1, k))
        radius, angle = np.empty(k, dtype=np.float32), np.empty(k, dtype=np.float32)
        origins = self._draws.origins
        if origins is not None and _KERNEL is not None:
            args = (self._codes, self._layout.amplitude, fresh, refs[0], radius, angle)
            sines = _KERNEL.streams(origins, envs, t, self._cursors, *args)
        else:  # the cursors are sought afresh once the draws are origins again (a reset of all)
            table = self._draws.table
            if table is None:  # origins without the stream kernel (episode_source picks tables then)
                table = np.ascontiguousarray(self._draws.rows(self._all, 0, self._draws.size).T)
            sines = table_uniforms(table, envs, t, self._layout, refs[0], radius, angle)
        sine = sines == k if sines in (0, k) else t >= self._layout.half
        return refs, box_muller(radius, angle, sine)[None]


class EpisodeSource(Protocol):
    """What a vector env reads its episodes' references and unit noise from: :class:`EpisodeStreams`
    or :class:`~ssme_envs.envs.episode_tables.EpisodeTables`, which give the same values."""

    def restart(self, envs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Step 0 of the new episodes of ``envs`` (after ``draws.start``): references, noise (channels, k)."""
        ...

    def begin(self, envs: np.ndarray) -> None:
        """Ready the new episodes of ``envs`` (after ``draws.start``) for an :meth:`at` at their step 0."""
        ...

    def at(self, t: np.ndarray, t_bound: int, synced: bool) -> tuple[np.ndarray, np.ndarray, int]:
        """Step ``t[i]`` of every episode i: references, noise, and the bound on t."""
        ...


def _streamed(task: Any, form: str) -> StreamLayout | None:
    """The task's stream layout (its ``stream_layout``, optional) where its episodes can be read
    as streams from draws held in ``form`` (the kernel, or a table), else None."""
    layout = getattr(task, "stream_layout", None)
    return layout if layout is not None and (KERNEL == "compiled" or form == "table") else None


def episode_source(task: Any, draws: EpisodeDraws) -> EpisodeSource:
    """Streams where the task's episodes have a layout and they can be read (:func:`_streamed`),
    tables otherwise."""
    layout = _streamed(task, draws.form)
    return EpisodeTables(task, draws) if layout is None else EpisodeStreams(draws, layout)


def episode_bytes(task: Any) -> int:
    """Bytes per sub-env of a new vector env's episodes of ``task``: its draws and the source
    :func:`episode_source` picks for them (the vector env checks memory with it before making
    either)."""
    form = EpisodeDraws.pcg64_form()
    layout = _streamed(task, form)
    source = EpisodeTables.bytes_per_env(task) if layout is None else EpisodeStreams.bytes_per_env(layout)
    return source + EpisodeDraws.bytes_per_env(task.draw_size, form)


__all__ = [
    "KERNEL",
    "STREAM_WORDS",
    "EpisodeSource",
    "EpisodeStreams",
    "box_muller",
    "episode_bytes",
    "episode_source",
    "table_uniforms",
]
