"""The arguments of :func:`~ssme_envs.identification.alpha_canonical.identify`, checked before any work.

A bad argument raises :class:`ArgumentTypeError` (the wrong kind of thing: a TypeError, and a
ValueError) or ValueError (the right kind, out of range), naming the argument and its value, in the
words the envs use for a bad action (:mod:`ssme_envs.envs.inputs`). Unchecked, a string of names
would be split into letters, ``"no"`` taken as true, a complex record cut to its real part and a
record without input columns divide by zero deep inside the structure search.
"""

from __future__ import annotations

import numbers
import operator
from collections.abc import Iterable, Mapping, Set
from typing import Any, NamedTuple

import numpy as np

from ssme_envs.identification.structure import check_search_length
from ssme_envs.models.linear import check_dt, describe, holds_bool, masked_elements

REAL_KINDS = "fiu"  # numpy dtype kinds of real numbers: bool, complex, strings and objects are not
METHODS = ("iv", "ls", "oe")  # identify()'s estimators, described there
MAX_SEED = 2**32 - 1  # numpy's legacy seeding (scipy's searches, SB3's set_random_seed) takes 32 bits


class ArgumentTypeError(TypeError, ValueError):
    """An argument of the wrong kind (a complex record, a string of names, ``"no"`` for a flag): a
    TypeError, and a ValueError too, so that an ``except ValueError`` (the command line's) catches
    it with the range errors."""


class Arguments(NamedTuple):
    """What :func:`check_arguments` passes on: the record as arrays (converted to float by
    :func:`~ssme_envs.identification.alpha_canonical.check_record`, as before), the sample time,
    the indices as a tuple (an iterator given is read once, here) and the channel names."""

    u: np.ndarray
    y: np.ndarray
    dt: float
    indices: tuple[int, ...] | None
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]


def _shown(value: Any) -> str:
    """``value`` for a message: its type, then its (shortened) repr."""
    return f"{type(value).__name__} {describe(value)}"


def _is_real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def real_record(value: Any, name: str, channels: str) -> np.ndarray:
    """``value`` as an array of real numbers, shape (T,) or (T, k) with k >= 1, else an error
    naming ``name``; ``channels`` ("inputs", "outputs") says what its columns are."""
    expected = f"{name} must be real numbers (an int or float array of shape (samples, {channels}))"
    masked = masked_elements(value)
    if masked:
        raise ValueError(
            f"{name} has {masked} masked value{'s' if masked > 1 else ''} of {value.size}: fill or "
            "cut out the masked samples first (the identifiers do not read a mask)"
        )
    try:
        array = np.asarray(value)
    except ValueError:  # a ragged nesting
        raise ValueError(f"{expected}, got a ragged {type(value).__name__}") from None
    what = (
        str(array.dtype)
        if isinstance(value, np.ndarray)
        else f"{type(value).__name__} of dtype {array.dtype}"
    )
    if array.dtype.kind == "O" and all(_is_real(v) for v in array.flat):
        try:  # Python ints beyond int64, Fractions and the like: numbers still
            array = array.astype(float)
        except OverflowError:
            raise ValueError(f"{expected}, got {what}: an integer too large for a float") from None
    elif array.dtype.kind not in REAL_KINDS:
        raise ArgumentTypeError(f"{expected}, got {what}")
    elif isinstance(value, list | tuple) and holds_bool(value):
        raise ArgumentTypeError(f"{expected}, got a {type(value).__name__} holding bools")
    if array.ndim not in (1, 2):
        raise ValueError(
            f"{name} must be an array of shape (samples, {channels}) or (samples,), got shape {array.shape}"
        )
    if array.ndim == 2 and array.shape[1] == 0:
        raise ValueError(f"{name} needs at least one {channels[:-1]} column, got shape {array.shape}")
    return array


def _listed(value: Any) -> tuple[Any, ...] | None:
    """``value``'s items in order if it is a list-like (a list, tuple, 1-D array, iterator), else
    None: a string is one value, not its letters, and a set or mapping has no order."""
    if isinstance(value, str | bytes | Mapping | Set) or not isinstance(value, Iterable):
        return None
    if isinstance(value, np.ndarray) and value.ndim != 1:
        return None
    return tuple(value)


def _names(value: Any, name: str, count: int, of: str, prefix: str) -> tuple[str, ...]:
    """``count`` distinct names (strings) from ``value``, or ``prefix0``, ... for None."""
    if value is None:
        return tuple(f"{prefix}{i}" for i in range(count))
    expected = f"{name} must be {count} distinct str, one per column of {of}"
    names = _listed(value)
    if names is None or not all(isinstance(v, str) for v in names):
        raise ArgumentTypeError(f"{expected}, got {_shown(value)}")
    if len(names) != count:
        raise ValueError(f"{expected}, got {len(names)}: {describe(names)}")
    if len(set(names)) != count:
        raise ValueError(f"{expected}, got {describe(names)} (a name repeated)")
    return names


def _flag(value: Any, name: str) -> None:
    # ``if "no":`` is true: only a bool says yes or no here
    if not isinstance(value, bool | np.bool_):
        raise ArgumentTypeError(f"{name} must be True or False, got {_shown(value)}")


def _max_index(value: Any) -> None:
    try:
        if isinstance(value, bool | np.bool_):  # True is no index
            raise TypeError
        number = operator.index(value)
    except TypeError:
        raise ArgumentTypeError(
            f"max_index must be a positive integer (the largest observability index searched), "
            f"got {_shown(value)}"
        ) from None
    if number < 1:  # the words the command line's tests look for
        raise ValueError(f"max_index must be >= 1, got {number}")


def _rank_tol(value: Any) -> None:
    expected = "rank_tol must be in (0, 1), a finite real number"
    if not _is_real(value):
        raise ArgumentTypeError(f"{expected}, got {_shown(value)}")
    if not 0 < float(value) < 1:  # NaN fails too
        raise ValueError(f"{expected}, got {describe(value)}")


def _indices(value: Any, p: int) -> tuple[int, ...]:
    """``value`` as ``p`` observability indices, positive integers (numpy's too, not bools)."""
    idx = _listed(value)
    if idx is None:
        raise ArgumentTypeError(
            f"indices must be {p} observability indices (positive integers, one per output), "
            f"got {_shown(value)}"
        )
    if len(idx) != p:
        raise ValueError(f"indices: {len(idx)} observability indices given for {p} outputs: {describe(idx)}")
    if not all(isinstance(v, int | np.integer) and not isinstance(v, bool | np.bool_) for v in idx):
        raise ArgumentTypeError(
            f"indices must be positive integers (observability indices), got {describe(idx)}"
        )
    if min(idx) < 1:
        raise ValueError(f"indices must be positive integers (observability indices), got {describe(idx)}")
    return tuple(int(v) for v in idx)


def check_arguments(
    u: Any,
    y: Any,
    dt: Any,
    *,
    indices: Any,
    method: Any,
    asymmetric: Any,
    max_index: Any,
    rank_tol: Any,
    input_names: Any,
    output_names: Any,
    uncertainty: Any,
) -> Arguments:
    """Check every argument of :func:`identify` (see it for their meaning), cheapest first, and
    that the record is long enough for what is asked of it, before any work.

    Raises
    ------
    ArgumentTypeError
        An argument of the wrong kind (a TypeError, and a ValueError): a record that is not real
        numbers (complex, bool, strings, objects), a flag that is not a bool, names that are not a
        sequence of str, a ``max_index`` or ``indices`` that are not integers, a ``rank_tol`` that
        is not a real number.
    ValueError
        Out of range: a masked record, a record of the wrong shape or without columns, ``u`` and
        ``y`` of different lengths, names of the wrong count or repeated, ``max_index < 1``,
        ``rank_tol`` outside (0, 1), indices of the wrong count or below 1, a record too short for
        the indices or the structure search.
    """
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}, got {describe(method)}")
    dt = check_dt(dt)
    _flag(asymmetric, "asymmetric")
    _flag(uncertainty, "uncertainty")
    _max_index(max_index)
    _rank_tol(rank_tol)
    u = real_record(u, "u", "inputs")
    y = real_record(y, "y", "outputs")
    if u.shape[0] != y.shape[0]:  # check_record's words, kept
        raise ValueError(
            f"u and y must have a row per sample: inputs have {u.shape[0]} samples but outputs "
            f"have {y.shape[0]}"
        )
    samples = u.shape[0]
    m = u.shape[1] if u.ndim == 2 else 1
    p = y.shape[1] if y.ndim == 2 else 1
    in_names = _names(input_names, "input_names", m, "u", "u")
    out_names = _names(output_names, "output_names", p, "y", "y")
    # the record's length before its values (check_record's reductions fail on an empty one)
    if indices is None:
        check_search_length(samples, p, m, operator.index(max_index))
    else:
        indices = _indices(indices, p)
        if max(indices) >= samples:
            raise ValueError(
                f"the record has {samples} samples, observability indices {list(indices)} need more"
            )
    return Arguments(u, y, dt, indices, in_names, out_names)


__all__ = ["ArgumentTypeError", "Arguments", "check_arguments", "real_record"]
