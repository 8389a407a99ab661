"""What the envs take from their callers at reset and step, checked: seeds and actions.

Everything is checked before the env changes, and a bad input raises TypeError (the wrong kind
of thing) or ValueError (the right kind, out of range), naming what was expected.
"""

from __future__ import annotations

import operator
from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from ssme_envs.envs.task import real_number, shown
from ssme_envs.models.linear import holds_bool, masked_elements

REAL_KINDS = "fiu"  # numpy dtype kinds of real numbers: bool, complex, strings and objects are not


class ActionTypeError(TypeError, ValueError):
    """An action of the wrong kind (not real numbers): a dict, a string, bytes, a set, bools or
    complex numbers. A TypeError, and a ValueError too, what the envs raised for every bad action
    before (an ``except ValueError`` written then still catches it)."""


class SeedValueError(ValueError, gym.error.Error):
    """A negative seed: a ValueError, and the ``gymnasium.error.Error`` that gymnasium's seeding
    raised for it before (its words kept), so that callers catching either still do."""


class SeedTypeError(TypeError, gym.error.Error):
    """A seed that is not an integer (a bool included: gymnasium's seeding took ``True`` as 1): a
    TypeError, and gymnasium's error, as :class:`SeedValueError`."""


def check_seed(seed: Any, owner: str) -> int | None:
    """A reset's ``seed`` as a Python int (numpy integers converted), or None.

    Raises
    ------
    SeedTypeError
        ``seed`` is not an integer (a bool is refused: ``True`` is no seed); a TypeError.
    SeedValueError
        ``seed`` is negative; a ValueError.
    """
    if seed is None:
        return None
    takes = f"{owner}.reset takes an integer >= 0 or None"
    try:
        if isinstance(seed, bool | np.bool_):
            raise TypeError
        value = operator.index(seed)
    except TypeError:
        raise SeedTypeError(f"Seed must be an integer: {takes}, got {shown(seed)}") from None
    if value < 0:
        raise SeedValueError(f"Seed must be greater or equal to zero: {takes}, got {value}")
    return value


def check_seeds(seed: Any, num_envs: int, owner: str) -> list[int | None]:
    """A vector env's reset ``seed`` as one seed or None per sub-env: None, an int (sub-env ``i``
    gets ``seed + i``) or ``num_envs`` ints or Nones, every one checked (:func:`check_seed`)
    before any sub-env is seeded."""
    if seed is None:
        return [None] * num_envs
    if (isinstance(seed, Sequence) and not isinstance(seed, str | bytes)) or (
        isinstance(seed, np.ndarray) and seed.ndim == 1
    ):
        if len(seed) != num_envs:
            raise ValueError(f"seed must be an int or {num_envs} seeds, got {len(seed)}")
        return [check_seed(each, owner) for each in seed]
    first = check_seed(seed, owner)
    return [first + i for i in range(num_envs)]


def positive_int(name: str, value: Any) -> int:
    """``value`` as an int >= 1 (a Python or numpy integer, not a bool), else ValueError."""
    try:
        if isinstance(value, bool | np.bool_):
            raise TypeError
        number = operator.index(value)
    except TypeError:
        number = 0
    if number < 1:
        raise ValueError(f"{name} must be a positive integer, got {shown(value)}")
    return number


# what a sub-env holds beside its episodes' draws, references and noise: its generator (a Python
# object and PCG64's state), state columns, observation and bookkeeping rows, with room to spare
SUB_ENV_BYTES = 4096


def check_vector_memory(num_envs: int, episode_bytes: int) -> None:
    """ValueError when ``num_envs`` sub-envs would not fit in memory: per sub-env
    ``episode_bytes`` (what its episodes' source holds and computes,
    :func:`~ssme_envs.envs.episode_streams.episode_bytes`) and :data:`SUB_ENV_BYTES`."""
    from ssme_envs.cli_checks import check_memory

    check_memory("num_envs", num_envs, episode_bytes + SUB_ENV_BYTES, "each sub-env's episodes")


def _floats(values: Iterable[Any], action: Any, name: str = "action") -> list[float] | None:
    """``values`` as Python floats, None if one is not a real number; ValueError for an integer
    too large for a float (``float()`` raises OverflowError on it)."""
    floats = []
    for value in values:
        number = real_number(value)
        if number is None:
            return None
        if number in (np.inf, -np.inf) and isinstance(value, int | np.integer):
            raise ValueError(f"{name} must be finite, got {shown(action)}: an integer too large for a float")
        floats.append(number)
    return floats


def _unmasked(array: np.ma.MaskedArray, expected: str) -> np.ndarray:
    """A masked array's data, or ValueError if an element is masked: a masked element has no
    value (its ``tolist`` is None, its data whatever lies beneath), so no action can be read."""
    masked = masked_elements(array)
    if masked:
        raise ValueError(f"{expected}, got a masked array with {masked} masked element(s) of {array.size}")
    return array.data


def action_floats(action: Any, n: int, meaning: str) -> list[float]:
    """A scalar env's action, other than a float array of shape ``(n,)`` (the step's fast path),
    as ``n`` Python floats: a real (float or integer) array of shape ``(n,)``, or a list or tuple
    of ``n`` real numbers (Python's or numpy's, not bools).

    Raises
    ------
    ActionTypeError
        Not real numbers (a TypeError, and a ValueError).
    ValueError
        Not ``n`` of them, an integer too large for a float, or a masked array with a masked
        element (one whose mask is all False is its data).
    """
    expected = f"action must be {n} number{'s' if n > 1 else ''} ({meaning})"
    if isinstance(action, np.ma.MaskedArray):
        action = _unmasked(action, expected)
    if isinstance(action, np.ndarray):
        if action.dtype.kind not in REAL_KINDS:
            raise ActionTypeError(f"{expected}, a real array, got an array of dtype {action.dtype}")
        if action.shape != (n,):
            raise ValueError(f"{expected}, got an array of shape {action.shape}")
        return [float(a) for a in action.tolist()]
    if not isinstance(action, list | tuple):
        raise ActionTypeError(
            f"{expected}, a real array, list or tuple, got {type(action).__name__} {shown(action)}"
        )
    if len(action) != n:
        raise ValueError(f"{expected}, got {shown(action)}")
    floats = _floats(action, action)
    if floats is None:
        kinds = ", ".join(type(a).__name__ for a in action)
        raise ActionTypeError(f"{expected}, real numbers (not bools), got {shown(action)} ({kinds})")
    return floats


def batch_actions(actions: Any) -> np.ndarray:
    """A vector env's actions, other than a float32 or float64 array (the step's fast path), as
    float64: a real (float or integer) array, or nested lists of real numbers.

    Raises
    ------
    ActionTypeError
        Not real numbers: complex, bool (alone or among numbers), strings or other objects (numpy
        would drop an imaginary part, read "0.5" as 0.5, or True as 1).
    ValueError
        A ragged nesting, an integer too large for a float, or a masked array with a masked
        element (one whose mask is all False is its data).
    """
    if isinstance(actions, np.ma.MaskedArray):
        actions = _unmasked(actions, "actions must be a float array of shape (num_envs, actions)")
    try:
        array = actions if isinstance(actions, np.ndarray) else np.asarray(actions)
    except ValueError:
        raise ValueError(
            f"actions must be a rectangular array (num_envs, actions), got {shown(actions)}"
        ) from None
    what = f"{type(actions).__name__} of dtype {array.dtype}"
    if array.dtype.kind == "O":  # Python ints beyond int64 (or anything else): each checked
        floats = _floats(array.flat, actions, "actions")
        if floats is not None:
            return np.array(floats, dtype=np.float64).reshape(array.shape)
    elif array.dtype.kind in REAL_KINDS:
        if not isinstance(actions, list | tuple) or not holds_bool(actions):  # numpy reads bools as 0, 1
            return array.astype(np.float64)
        what = f"a {type(actions).__name__} holding bools"
    raise ActionTypeError(
        f"actions must be real numbers, a float array of shape (num_envs, actions), got {what}"
    )


__all__ = [
    "SUB_ENV_BYTES",
    "ActionTypeError",
    "SeedTypeError",
    "SeedValueError",
    "action_floats",
    "batch_actions",
    "check_seed",
    "check_seeds",
    "check_vector_memory",
    "positive_int",
]
