"""The episode draws of a vector env's sub-envs: each as the scalar env draws it, read in blocks.

A sub-env's episode is ``draw_size`` uniform float32 numbers from its own generator at reset,
``rng.random(draw_size, dtype=np.float32)``, which the task turns into references, noise and
plant as the episode reaches its steps (:func:`~ssme_envs.envs.task.next_stop`). Most of an
episode that ends early is never read. :class:`EpisodeDraws` holds the draws of N sub-envs
in one of two forms, with the same bits:

- **Origins**, where the compiled kernel is built and every sub-env's generator is numpy's
  PCG64 (gymnasium's): each episode is the generator's state at its reset, and the generator is
  moved past the whole draw at once (PCG64 jumps ahead in log2 steps); any block of numbers is
  then made from the origin when it is read. A reset costs the same whatever the episode's
  length, and no Python call per sub-env.
- **A table** of every sub-env's whole draw, drawn by its generator, otherwise: without the
  kernel, or once a sub-env is given another bit generator (until every sub-env is again PCG64
  at a reset of all of them).

The kernel is used only where it gives numpy's bits on a check set at import
(:func:`_kernel_agrees`), as the package's other kernels are.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import numpy as np

from ssme_envs.envs.task import transpose_into
from ssme_envs.models.kernels import load_kernel

ORIGIN_WORDS = 6  # an episode's origin: PCG64 state (2 words), increment (2), has_uint32, uinteger


def _kernel_agrees(kernel: object) -> bool:
    """Whether the kernel moves PCG64 generators and makes their numbers as numpy does: states
    after a draw (the kept half included) and every block of a draw, on seeded generators with and
    without a kept half, for draws of 0 to 41 numbers."""
    for seed, ahead in ((0, 0), (1, 1), (2**63 + 5, 2), (12345, 3)):
        for count in (0, 1, 2, 3, 8, 41):
            rng = np.random.Generator(np.random.PCG64(seed))
            rng.random(ahead, dtype=np.float32)
            twin = copy.deepcopy(rng)
            origins = np.zeros((1, ORIGIN_WORDS), dtype=np.uint64)
            kernel.start([rng.bit_generator.capsule], np.zeros(1, dtype=np.int64), count, origins)
            drawn = twin.random(count, dtype=np.float32)
            if rng.bit_generator.state != twin.bit_generator.state:
                return False
            for lo, hi in ((0, count), (1, count), (count // 2, count), (count // 3, 2 * count // 3)):
                lo, hi = min(lo, count), max(min(hi, count), min(lo, count))
                out = np.empty((hi - lo, 1), dtype=np.float32)
                kernel.rows(origins, np.zeros(1, dtype=np.int64), lo, hi, out)
                if out[:, 0].tobytes() != drawn[lo:hi].tobytes():
                    return False
    return True


_KERNEL = load_kernel("_draw_kernel", _kernel_agrees, "episode draw")
KERNEL = "python" if _KERNEL is None else "compiled"  # how vector envs hold their episode draws


def _is_pcg64(rng: np.random.Generator) -> bool:
    return type(rng.bit_generator) is np.random.PCG64


class EpisodeDraws:
    """The current episode draws of N sub-envs, ``size`` uniform float32 numbers each.

    ``generators`` is the sub-envs' list of generators; set one with :meth:`set_generator`.
    :meth:`start` draws the next episodes of some sub-envs (each generator moves on as
    ``rng.random(size, dtype=np.float32)`` moves it), :meth:`rows` reads a block of their numbers
    and :meth:`uniforms` gives them as the tasks read them.
    """

    def __init__(self, size: int, generators: Sequence[np.random.Generator]) -> None:
        self.size = size
        self.generators = list(generators)
        n = len(self.generators)
        self._all = np.arange(n)
        self._capsules = [rng.bit_generator.capsule for rng in self.generators]
        self._origins: np.ndarray | None = None
        self._table: np.ndarray | None = None
        self._table_rows: list[np.ndarray] = []
        if self.pcg64_form() == "origins" and all(map(_is_pcg64, self.generators)):
            self._origins = np.zeros((n, ORIGIN_WORDS), dtype=np.uint64)
        else:
            self._use_table(np.zeros((n, size), dtype=np.float32))

    def __getstate__(self) -> dict:
        """The state without what is made from the rest: the generators' capsules (which do not
        pickle) and the table's row views (which a copy would cut loose from the table), so that a
        vector env pickles and deep-copies."""
        return {key: value for key, value in self.__dict__.items() if key not in ("_capsules", "_table_rows")}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._capsules = [rng.bit_generator.capsule for rng in self.generators]
        self._table_rows = [] if self._table is None else list(self._table)

    @property
    def form(self) -> str:
        """``"origins"`` or ``"table"`` (see the module docs)."""
        return "table" if self._origins is None else "origins"

    @property
    def origins(self) -> np.ndarray | None:
        """The episodes' origins, (N, ORIGIN_WORDS) uint64, in the origins form (else None)."""
        return self._origins

    @property
    def table(self) -> np.ndarray | None:
        """The episodes' whole draws, (N, size) float32, in the table form (else None)."""
        return self._table

    def _use_table(self, table: np.ndarray) -> None:
        self._origins = None
        self._table = table
        self._table_rows = list(table)  # views made once: a reset draws into them by the thousand

    def set_generator(self, index: int, rng: np.random.Generator) -> None:
        """Give sub-env ``index`` the generator ``rng`` (its current episode is kept)."""
        self.generators[index] = rng
        self._capsules[index] = rng.bit_generator.capsule
        if self._origins is not None and not _is_pcg64(rng):  # the episodes in flight, drawn out
            self._use_table(np.ascontiguousarray(self.rows(self._all, 0, self.size).T))

    def start(self, envs: np.ndarray) -> None:
        """Draw the next episode of each sub-env of ``envs`` (int64 indices, in order) from its
        generator."""
        if self._origins is None and len(envs) == len(self._all) and _KERNEL is not None:
            if all(map(_is_pcg64, self.generators)):  # no episode left in flight: origins again
                self._origins = np.zeros((len(envs), ORIGIN_WORDS), dtype=np.uint64)
                self._table, self._table_rows = None, []
        if self._origins is not None:
            _KERNEL.start(self._capsules, envs, self.size, self._origins)
            return
        rngs, rows, single = self.generators, self._table_rows, np.float32
        for i in envs.tolist():  # positional arguments: half the cost of the keywords per call
            rngs[i].random(None, single, rows[i])

    def rows(self, envs: np.ndarray, lo: int, hi: int) -> np.ndarray:
        """Numbers [lo, hi) of the episodes of ``envs`` (int64 indices), (hi - lo, len(envs))
        float32, C-contiguous."""
        out = np.empty((hi - lo, len(envs)), dtype=np.float32)
        if self._origins is not None:
            _KERNEL.rows(self._origins, envs, lo, hi, out)
        elif len(envs) == len(self._all):  # every sub-env: a tiled transpose of the table's slab
            transpose_into(self._table[:, lo:hi], out)
        else:
            out[...] = np.take(self._table[:, lo:hi], envs, axis=0).T
        return out

    @staticmethod
    def pcg64_form() -> str:
        """The form of new draws of PCG64 generators (a new vector env's)."""
        return "table" if _KERNEL is None else "origins"

    @staticmethod
    def bytes_per_env(size: int, form: str) -> int:
        """Bytes per sub-env of draws of ``size`` numbers held in ``form``: an origin, or the whole
        draw in the table."""
        return 8 * ORIGIN_WORDS if form == "origins" else 4 * size

    def uniforms(self, envs: np.ndarray) -> EpisodeUniforms:
        """The draws of the episodes of ``envs`` as the tasks read them (``draw_size`` rows)."""
        return EpisodeUniforms(self, envs)


class EpisodeUniforms:
    """The draws of k episodes as a (draw_size, k) float32 table whose rows are read in slices
    (``uniforms[lo:hi]``, what the tasks' ``episodes`` take): each slice is made when read, so
    rows no step reaches are never made (:class:`~ssme_envs.envs.task.Uniforms`)."""

    def __init__(self, draws: EpisodeDraws, envs: np.ndarray) -> None:
        self._draws = draws
        self._envs = np.asarray(envs, dtype=np.int64)
        self.shape = (draws.size, len(self._envs))

    def __getitem__(self, rows: slice) -> np.ndarray:
        if not isinstance(rows, slice):
            raise TypeError(f"episode draws are read in row slices, got {type(rows).__name__}")
        lo, hi, step = rows.indices(self.shape[0])
        if step != 1:
            raise ValueError("episode draws are read in contiguous row slices")
        return self._draws.rows(self._envs, lo, max(lo, hi))


__all__ = ["KERNEL", "EpisodeDraws", "EpisodeUniforms"]
