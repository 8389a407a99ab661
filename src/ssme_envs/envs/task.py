"""The tracking-task protocol: what a task gives the scalar env and the native vector env.

A task owns its facts (observation layout, actions, horizon) and one ``step``, written once over
a :class:`Carrier`: :data:`FLOATS` steps one env on Python floats (an order of magnitude faster
than numpy on 1-element arrays), :data:`SYNCED` and :data:`GATHER` step N envs on (N,) rows. Both
carriers run the same IEEE operations in the same order, so an env gives the same bits alone
and in a batch (the tests hold the vector env to gymnasium's ``SyncVectorEnv`` bit for bit).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np

# ``shown``: a value cut short for a message, the one helper of the models' messages (a long
# integer by its size: ``reprlib.repr`` of an int past 4300 digits raised Python's own ValueError)
from ssme_envs.models.linear import describe as shown

Value = Any  # a Python float (one env) or an (N,) float64 row (a batch)


class Observation(NamedTuple):
    """The observation layout of a task: one entry per column, in order."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    high: tuple[float, ...]  # the bound is symmetric: low = -high

    def space(self) -> gym.spaces.Box:
        """The float32 Box of the observations, ``[-high, high]``."""
        high = np.array(self.high, dtype=np.float32)
        return gym.spaces.Box(-high, high, dtype=np.float32)

    def index(self, name: str) -> int:
        """The column of the observation called ``name``."""
        return self.names.index(name)


@dataclass(frozen=True)
class Schedule:
    """A per-step table (T + 1, ...) held for both carriers: as nested floats per step, and
    time last (..., T + 1), so that gathering every env's step is one cache-friendly ``take``."""

    floats: list
    time_last: np.ndarray

    @classmethod
    def of(cls, table: np.ndarray) -> Schedule:
        return cls(table.tolist(), np.ascontiguousarray(np.moveaxis(table, 0, -1)))


def _rows_synced(schedule: Schedule, t: np.ndarray) -> np.ndarray:
    return schedule.time_last[..., t[0] - 1, None]  # every env at the same step: a slice


def _rows_gathered(schedule: Schedule, t: np.ndarray) -> np.ndarray:
    return np.take(schedule.time_last, t - 1, axis=-1)


@dataclass(frozen=True)
class Carrier:
    """The few operations whose spelling differs between floats and arrays.

    ``where(cond, a, b)``, ``clip(x, lo, hi)``; ``at(schedule, t)``: the entries of a
    :class:`Schedule` acting on the step t - 1 -> t; ``any(cond)``: whether a condition holds
    anywhere (to skip the passes of a rare branch); ``charge(values, cond, cost, t)``: ``values
    - cost(t)`` where ``cond`` holds, the values elsewhere (arrays: in place, ``cost`` computed
    on those entries alone); ``batched``: True for arrays, where a plant core with two carriers
    of one arithmetic (``models``) picks its array one; ``restarting``: None, or (arrays, given
    only to a task that ``observes_restarts``) a bool (N,) row, True for the envs that restart at
    this step, whose ``ref`` and ``noise`` columns hold their new episodes' step 0 (see
    :class:`TrackingTask`)."""

    batched: bool
    where: Callable[[Any, Any, Any], Any]
    clip: Callable[[Any, float, float], Any]
    at: Callable[[Schedule, Any], Any]
    any: Callable[[Any], bool] = bool
    charge: Callable[[Any, Any, Callable[[Any], Any], Any], Any] = lambda values, cond, cost, t: (
        values - cost(t) if cond else values
    )
    restarting: np.ndarray | None = None

    def with_restarts(self, restarting: np.ndarray) -> Carrier:
        """This carrier with ``restarting`` set."""
        return dataclasses.replace(self, restarting=restarting)


def _array_charge(
    values: np.ndarray, cond: np.ndarray, cost: Callable[[Any], Any], t: np.ndarray
) -> np.ndarray:
    hit = cond.nonzero()[0]
    values[hit] -= cost(t[hit])
    return values


def _float_clip(x: float, lo: float, hi: float) -> float:
    """``min(max(x, lo), hi)`` as the builtins decide (each keeps its first argument unless the
    second lies strictly beyond it), NaN included, without their two calls."""
    x = lo if lo > x else x
    return hi if hi < x else x


FLOATS = Carrier(
    batched=False,
    where=lambda cond, a, b: a if cond else b,
    clip=_float_clip,
    at=lambda schedule, t: schedule.floats[t - 1],
)
# numpy's clip ufunc: min(max(x, lo), hi) elementwise, NaN kept, as np.minimum(np.maximum())
# gives, in one pass instead of two slower ones (and without np.clip's Python wrapper)
CLIP_UFUNC: np.ufunc = (getattr(np, "_core", None) or np.core).umath.clip
_ARRAY_CLIP = CLIP_UFUNC
_ARRAY_ANY = np.ndarray.any
SYNCED = Carrier(
    batched=True, where=np.where, clip=_ARRAY_CLIP, at=_rows_synced, any=_ARRAY_ANY, charge=_array_charge
)  # every env at one step
GATHER = Carrier(
    batched=True, where=np.where, clip=_ARRAY_CLIP, at=_rows_gathered, any=_ARRAY_ANY, charge=_array_charge
)


class Uniforms(Protocol):
    """An episode draw as the tasks read it: (draw_size, k) float32 numbers, k episodes, read in
    row slices (``uniforms[lo:hi]``, an array). A numpy array is one; the vector env hands out
    :class:`~ssme_envs.envs.episode_draws.EpisodeUniforms`, which makes a slice when it is read."""

    @property
    def shape(self) -> tuple[int, ...]: ...

    def __getitem__(self, rows: slice) -> np.ndarray: ...


# where a task's ``episodes`` writes a block: references (None: shared, not written) and noise
Blocks = tuple[np.ndarray | None, np.ndarray]


@runtime_checkable
class TrackingTask(Protocol):
    """What the scalar env (:class:`~ssme_envs.envs.tracking_env.TrackingEnv`) and the vector env
    (:class:`~ssme_envs.envs.vector.TrackingVectorEnv`) need of a task.

    Episodes are drawn from ``draw_size`` uniform float32 numbers per episode (one generator call
    at reset), the last ``plant_draw_size`` of which (0: none) draw the episode's plant:
    ``initial_state(n, plants)`` gets them (plant_draw_size, n) and puts the drawn plant in the
    state. ``episodes(uniforms, start, stop)`` turns them (draw_size, k; a :class:`Uniforms`, read
    in row slices) into the references and unit sensor noise of steps [start, stop), (channels,
    stop - start, k) each, equal to the same steps of the whole episode, and returns them; given
    ``out``, a pair of such arrays (references None where they are shared), it writes them there
    (the vector env passes views of its tables, sparing a copy and the fresh memory of a block of
    every env). The envs ask for the steps as episodes reach them (:func:`next_stop`), so that a
    reset costs the same whatever the episode's length.
    ``step(state, action, t, ref, noise, ops)``: ``action``, ``ref`` and ``noise`` per channel
    (floats, or rows of N envs; noise float64), ``t`` the step index after the step; returns
    (state, observation values in the layout's order, reward, terminated). A task whose
    class sets ``scales_float32_noise = True`` gets the rows of noise float32, as drawn, and
    promises to scale them into float64 (the exact upcast's products), saving the vector env a
    conversion pass per step. A batched step may return its observation values as a fresh
    float32 (columns, N) array, already rounded: the vector env hands that table out as it is.
    A task whose ``stream_layout`` (optional) is a
    :class:`~ssme_envs.envs.references.StreamLayout` says where each step's noise and reference
    lie in its draw: the vector env then makes each step's alone
    (:mod:`~ssme_envs.envs.episode_streams`), the same values as its ``episodes`` gives.
    A task whose ``observes_restarts`` (optional) is True promises that its batched step, given a
    carrier whose ``restarting`` is set, returns its values as a float32 table whose restarting
    columns hold ``initial_observation`` of those columns' ``ref`` and ``noise``, with reward 0
    and not terminated there; what it makes of their state is discarded. Otherwise the vector env
    computes those first observations itself.
    """

    observation: Observation
    action_names: tuple[str, ...]
    n_actions: int
    n_channels: int
    horizon: int
    dt: float

    @property
    def draw_size(self) -> int: ...

    @property
    def plant_draw_size(self) -> int: ...

    @property
    def shared_references(self) -> np.ndarray | None: ...

    def episodes(
        self, uniforms: Uniforms, start: int, stop: int, out: Blocks | None = None
    ) -> tuple[np.ndarray, np.ndarray]: ...

    def initial_state(self, n: int | None = None, plants: np.ndarray | None = None) -> tuple: ...

    def initial_observation(self, ref: np.ndarray, noise: np.ndarray) -> np.ndarray: ...

    def step(
        self, state: Any, action: Sequence[Value], t: Any, ref: Sequence[Value], noise: Sequence[Value],
        ops: Carrier,
    ) -> tuple[Any, Sequence[Value], Value, Any]: ...  # fmt: skip

    def nonfinite_reward(self, t: Any) -> Any | None: ...

    def render_row(self, state: Any, obs: Sequence[float], ref: Sequence[float]) -> list[float]: ...


FIRST_STEPS = 16  # steps of an episode computed at its reset (early in training, most end sooner)


def next_stop(ready: int, length: int) -> int:
    """Where the next block of an episode ends when its first ``ready`` steps are computed: the
    first FIRST_STEPS, then doubling (a whole episode costs at most twice its references, the
    prefix of which each block recomputes), up to the episode's ``length`` steps."""
    return min(length, max(FIRST_STEPS, 2 * ready))


def envelope_penalty(task: Any, t: Any) -> Any:
    """What leaving the envelope at step t costs a task (its ``step_cost_bound`` and ``horizon``):
    the worst reward of the steps it skips."""
    return task.step_cost_bound * (task.horizon - t + 1)


def set_columns(state: Any, fresh: Any, envs: np.ndarray) -> None:
    """Write the columns (last axis) ``envs`` of every array of a nested state tuple (entries
    that are not arrays, such as None or a flag, are the same for every env)."""
    for block, new in zip(state, fresh, strict=True):
        if isinstance(block, tuple):
            set_columns(block, new, envs)
        elif isinstance(block, np.ndarray) and block.ndim == 1:
            block[envs] = new  # numpy's fast path of one index (``[..., envs]`` takes its general one)
        elif isinstance(block, np.ndarray) and block.ndim == 2:  # row by row: that fast path again
            shape = (len(block), len(envs))
            rows = new if np.shape(new) == shape else np.broadcast_to(new, shape)
            for row, new_row in zip(block, rows, strict=True):
                row[envs] = new_row
        elif isinstance(block, np.ndarray):
            block[..., envs] = new


def transpose_into(table: np.ndarray, out: np.ndarray, tile: int = 256) -> np.ndarray:
    """A C-contiguous transpose copied tile by tile into ``out``: numpy's one-pass copy of a
    transposed view strides through memory, several times slower on tens of MB."""
    rows, cols = table.shape
    for i in range(0, rows, tile):
        for j in range(0, cols, tile):
            out[j : j + tile, i : i + tile] = table[i : i + tile, j : j + tile].T
    return out


MAX_EPISODE_SECONDS = 3600.0  # the longest episode any env takes (and so the latest fault time)


def real_number(value: Any) -> float | None:
    """``value`` as a float if it is a real number (a Python or numpy int or float, not a bool),
    else None; an int too large for a float is +-inf, so that the callers' finite checks refuse it
    (``float()`` raises OverflowError)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.integer | np.floating):
        return None
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def check_keys(name: str, spec: Mapping[Any, Any], accepted: Sequence[str], noun: str = "key") -> None:
    """ValueError when the dict option ``name`` has keys outside ``accepted``, naming them.

    Keys of any type are shown by their repr, in the dict's order (a dict may mix ints and
    strings, which neither sort together nor join as text); only strings are accepted.
    """
    unknown = [key for key in spec if not (isinstance(key, str) and key in accepted)]
    if unknown:
        raise ValueError(
            f"{name}: unknown {noun}(s) {', '.join(map(shown, unknown))}; "
            f"it takes {', '.join(map(repr, accepted))}"
        )


def check_number(name: str, value: Any, low: float, high: float, low_open: bool = False) -> float:
    """``value`` as a float, or ValueError unless a finite real number (numpy's included, not a
    bool) within [low, high] (or (low, high])."""
    number = real_number(value)
    if (
        number is None
        or not math.isfinite(number)
        or not low <= number <= high
        or (low_open and number == low)
    ):
        bracket = "(" if low_open else "["
        raise ValueError(f"{name} must be a number in {bracket}{low:g}, {high:g}], got {shown(value)}")
    return number


def check_numbers(name: str, value: Any, count: int, low: float, high: float) -> np.ndarray:
    """One number for every channel, or ``count`` numbers (a list, tuple or array), each checked
    by :func:`check_number`: a float array of ``count``, or ValueError naming ``name``."""
    if isinstance(value, np.ndarray):
        value = value.tolist()  # Python numbers (bools stay bools: refused)
    values = list(value) if isinstance(value, list | tuple) else [value]
    if len(values) not in (1, count):
        raise ValueError(f"{name} must be one number or {count}, got {shown(value)}")
    numbers = [check_number(name, each, low, high) for each in values]
    return np.array(numbers * (count // len(numbers)), dtype=float)


__all__ = [
    "CLIP_UFUNC",
    "FIRST_STEPS",
    "FLOATS",
    "GATHER",
    "MAX_EPISODE_SECONDS",
    "SYNCED",
    "Blocks",
    "Carrier",
    "Observation",
    "Schedule",
    "TrackingTask",
    "Uniforms",
    "check_keys",
    "check_number",
    "check_numbers",
    "envelope_penalty",
    "next_stop",
    "real_number",
    "set_columns",
    "shown",
    "transpose_into",
]
