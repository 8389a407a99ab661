"""A vector env's episode references and noise as (channels, steps, envs) tables, a block at a time.

Each episode's steps are computed as it reaches them (:func:`~ssme_envs.envs.task.next_stop`:
the first FIRST_STEPS at its reset, then doubling) by its task's ``episodes``, written into the
tables with the env axis last, so that one step of every env is a contiguous row where the
envs are synced and a gather where they are not. The form every task can use; tasks whose
episodes have a :class:`~ssme_envs.envs.references.StreamLayout` use
:class:`~ssme_envs.envs.episode_streams.EpisodeStreams` instead.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ssme_envs.envs.episode_draws import EpisodeDraws
from ssme_envs.envs.task import next_stop


class EpisodeTables:
    """The references and unit noise of N sub-envs' episodes, drawn by ``draws``, from the
    task's ``episodes`` a block at a time. :meth:`restart` after ``draws.start``; :meth:`at` at
    every step."""

    def __init__(self, task: Any, draws: EpisodeDraws) -> None:
        self.task = task
        self._draws = draws
        n, length, channels = len(draws.generators), task.horizon + 1, task.n_channels
        self._n = n
        self._rows = np.arange(n)
        # References common to every episode (the throttle profile) are not stored per env.
        shared = task.shared_references
        self._shared_refs = None if shared is None else np.ascontiguousarray(shared.T)  # (channels, T + 1)
        self._refs = None if shared is not None else np.zeros((channels, length, n))
        self._noise = np.zeros((channels, length, n), dtype=np.float32)  # unit draws, scaled at each step
        # how many of each episode's steps are computed into the tables: they are as the episode
        # reaches them
        self._ready = np.zeros(n, dtype=np.int64)
        # no step reaches an uncomputed block while the largest t (bounded above) is below the
        # smallest _ready: that spares most steps the (N,) comparison of t with _ready
        self._ready_min = 0

    @staticmethod
    def bytes_per_env(task: Any) -> int:
        """Bytes per sub-env: its episode's unit noise (float32) and references (float64, unless
        every episode shares them) per channel and step, with the temporaries of computing a
        block (``TRANSIENT_COPIES``), and a block of its draw (float32) read at once."""
        from ssme_envs.cli_checks import TRANSIENT_COPIES

        per_step = 4 if task.shared_references is not None else 12
        return per_step * task.n_channels * (task.horizon + 1) * (1 + TRANSIENT_COPIES) + 4 * task.draw_size

    def restart(self, envs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Step 0 of the new episodes of ``envs`` (int64 indices): references and noise
        (channels, k), their first block written into the tables."""
        self._ready[envs] = 0
        refs, noise = self._compute(envs, 0)
        return refs[:, 0], noise[:, 0]

    def begin(self, envs: np.ndarray) -> None:
        """Step 0 of the new episodes of ``envs`` for the next :meth:`at`: their first block."""
        self.restart(envs)

    def at(self, t: np.ndarray, t_bound: int, synced: bool) -> tuple[np.ndarray, np.ndarray, int]:
        """Step ``t`` (int64, per sub-env; every t at most ``t_bound``) of every episode:
        references (channels, N, or (channels, 1) where shared and synced), noise (channels, N)
        float32, and the bound on t, tightened where blocks were computed."""
        if t_bound >= self._ready_min and (t >= self._ready).any():
            t_bound = self._extend(t)
        if synced:  # contiguous slices
            noise = self._noise[:, t[0]]
            refs = self._refs[:, t[0]] if self._refs is not None else self._shared_refs[:, t[0], None]
            return refs, noise, t_bound
        flat = t * self._n + self._rows  # one flat index for both tables: take beats fancy indexing
        noise = np.take(self._noise.reshape(len(self._noise), -1), flat, axis=1)
        if self._refs is None:
            refs = np.take(self._shared_refs, t, axis=1)
        else:
            refs = np.take(self._refs.reshape(len(self._refs), -1), flat, axis=1)
        return refs, noise, t_bound

    def _extend(self, t: np.ndarray) -> int:
        """Compute the next block of the episodes that reach their uncomputed steps at ``t``, and
        of those of the same position within half a block of it: unsynced episodes (random
        actions) reach a position a few at a step, and a block's numpy calls cost more than its
        numbers, so that one call serves the next steps' arrivals too. Returns ``t.max()``."""
        late = np.flatnonzero(t >= self._ready)
        starts = self._ready[late]
        if starts[0] == starts[-1] and len(late) == self._n:  # synced: every episode
            self._compute(late, int(starts[0]))
        else:
            for start in np.unique(starts).tolist():
                ahead = (next_stop(start, self.task.horizon + 1) - start) // 2
                self._compute(np.flatnonzero((self._ready == start) & (t >= start - ahead)), start)
        return int(t.max())

    def _compute(self, envs: np.ndarray, start: int) -> tuple[np.ndarray, np.ndarray]:
        """The references and noise of the next block (:func:`next_stop`) of the episodes
        ``envs``, whose first ``start`` steps are computed, written into the tables; returned
        (channels, steps, len(envs))."""
        stop = next_stop(start, self.task.horizon + 1)
        uniforms = self._draws.uniforms(envs)
        if len(envs) == self._n:  # every episode (envs is then 0..N-1): into the tables
            out = (None if self._refs is None else self._refs[:, start:stop], self._noise[:, start:stop])
            refs, noise = self.task.episodes(uniforms, start, stop, out)
            for table, block in zip(out, (refs, noise), strict=True):  # a task that made its own
                if table is not None and not np.may_share_memory(table, block):
                    table[...] = block
        else:  # written through one flat index per channel: numpy's fast path ([:, slice, envs]: slow)
            refs, noise = self.task.episodes(uniforms, start, stop)
            flat = np.arange(start * self._n, stop * self._n, self._n)[:, None] + envs
            for table, block in ((self._noise, noise), (self._refs, refs)):
                if table is not None:
                    for channel, values in zip(table, block, strict=True):
                        channel.reshape(-1)[flat] = values
        self._ready[envs] = stop
        self._ready_min = int(self._ready.min())
        return refs, noise


__all__ = ["EpisodeTables"]
