"""The one state-space type of the package: a discrete linear model ``x+ = A x + B u``, ``y = C x + D u``.

The identification results (:class:`~ssme_envs.models.statespace.AlphaCanonicalModel`,
:class:`~ssme_envs.identification.innovations_model.InnovationsModel`) convert to it with
``state_space()``, and the controllers' design models (:class:`agents.plants.LinearDesign`) hold
one, so that a controller designed on any of them reads the same four matrices.
"""

from __future__ import annotations

import math
import numbers
import reprlib
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np


class _Short(reprlib.Repr):
    """``reprlib.Repr`` bounded in depth and length (a file's value may be a deep or long list), with
    a long integer by its size, wherever it sits: ``repr`` of an int past 4300 digits raises."""

    def repr_int(self, x: int, level: int) -> str:
        if abs(x) >= 10**20:  # by bit length: str() of an integer past 4300 digits raises
            return f"an integer of about {int(x.bit_length() * math.log10(2)) + 1} digits"
        return super().repr_int(x, level)


_SHORT = _Short()
_SHORT.maxlevel, _SHORT.maxstring, _SHORT.maxother, _SHORT.maxlong = 3, 60, 60, 60


def describe(value: Any) -> str:
    """``value`` for an error message, kept short: a long integer by its size, others cut."""
    return _SHORT.repr(value)


def boolean_text(value: Any) -> str:
    """``"a boolean (true)"``: a JSON or TOML boolean as its file spells it, for a message."""
    return f"a boolean ({'true' if value else 'false'})"


_PLAIN_NUMBERS = frozenset((float, int))  # by exact type: bool is a subclass of int


def _not_number(item: Any) -> bool:
    # what numpy's float conversion takes that is no number of a file: a bool (an int to Python),
    # text ("1.5" converts), null (None converts to NaN)
    return item is None or isinstance(item, bool | np.bool_ | str | bytes | np.str_ | np.bytes_)


def non_number_at(value: Any) -> tuple[tuple[int, ...], Any] | None:
    """The index and entry of the first boolean, text or null in ``value`` (a number, a nested
    list or tuple, an array), or None: numpy converts ``True`` to 1.0, ``"1.5"`` to 1.5 and
    ``None`` to NaN, so a JSON ``true``, ``"1.5"`` or ``null`` in a matrix would pass as a number."""
    if _not_number(value):
        return (), value
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "bUS" and value.size:
            return (0,) * value.ndim, value.flat[0].item()
        if value.dtype != object:
            return None
        value = value.tolist()
    if isinstance(value, list | tuple):
        if all(type(item) in _PLAIN_NUMBERS for item in value):  # a row as JSON gives it: fast
            return None
        for i, item in enumerate(value):
            if _not_number(item):
                return (i,), item
            if isinstance(item, list | tuple | np.ndarray):
                found = non_number_at(item)
                if found is not None:
                    return (i, *found[0]), found[1]
    return None


def refuse_non_numbers(value: Any, name: str) -> None:
    """ValueError naming the first boolean, text or null entry of ``value``, e.g. ``"A[1][2] is a
    boolean (true), not a number"``; call it once ``value`` converted to a float array (its depth
    is then bounded)."""
    found = non_number_at(value)
    if found is not None:
        index, item = found
        if item is None:
            what = "null"
        elif isinstance(item, bool | np.bool_):
            what = boolean_text(item)
        else:
            what = f"text ({describe(item)})"
        raise ValueError(f"{name}{''.join(f'[{i}]' for i in index)} is {what}, not a number")


def refuse_unknown_keys(block: Any, known: Any, where: str, hint: str = "") -> None:
    """ValueError naming the keys of the file's object ``block`` outside ``known`` (a misspelt
    key would otherwise be dropped without a word): ``"{where}unknown key(s) 'x', 'y'{hint}"``."""
    unknown = sorted(map(str, set(block) - set(known)))
    if unknown:
        raise ValueError(f"{where}unknown key(s) {', '.join(map(describe, unknown))}{hint}")


def _file_value(value: Any) -> str:
    """A refused value for a message, as a file spells it: a boolean, null, else cut short."""
    if isinstance(value, bool | np.bool_):
        return boolean_text(value)
    return "null" if value is None else describe(value)


def finite_float(value: Any, name: str) -> float:
    """``value`` as a float, or ValueError naming ``name`` unless it is a finite real number.

    Booleans are refused (JSON's ``true`` is no number), and so are integers beyond a float's
    range, which JSON files can hold (``1e400`` reads as inf, ``1`` and 400 zeros as an int).
    """
    if isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_):
        try:
            result = float(value)
        except OverflowError:
            result = math.inf
        if math.isfinite(result):
            return result
    raise ValueError(f"{name} must be a finite number, got {_file_value(value)}")


def check_dt(dt: Any) -> float:
    """A sample time as a float, or ValueError unless it is a positive finite number of seconds."""
    try:
        value = finite_float(dt, "dt")
    except ValueError:
        value = math.nan
    if not value > 0:
        raise ValueError(f"dt must be a positive number of seconds, got {_file_value(dt)}")
    return value


def as_floats(value: Any, name: str, expected: str) -> np.ndarray:
    """``value`` as a float array; ValueError saying ``name`` must be ``expected`` when it holds
    anything but numbers (an object, text, an integer too large for a float), or naming the entry
    that is a boolean, text or null (``"A[1][2] is a boolean (true), not a number"``)."""
    try:
        result = np.asarray(value, dtype=float)
    except OverflowError:
        raise ValueError(f"{name} must be {expected}: it holds an integer too large for a float") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be {expected}: {exc}") from None
    refuse_non_numbers(value, name)  # after the conversion: ``value`` is a regular array, its depth bounded
    return result


def as_matrix(value: Any, name: str, shape: tuple[int | None, int | None]) -> np.ndarray:
    """``value`` as a finite float matrix of ``shape`` (None: any size); ValueError naming it."""
    arr = as_floats(value, name, "a numeric matrix (list of rows)")
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a matrix (list of rows), got {arr.ndim} dimension(s)")
    for axis, want in enumerate(shape):
        if want is not None and arr.shape[axis] != want:
            raise ValueError(f"{name} has shape {arr.shape}, expected {shape[0] or 'n'} x {shape[1] or 'n'}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


class Dimensions:
    """Sizes and poles read off ``A``, ``B``, ``C``: shared by every class holding the matrices."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A`` (discrete poles, dimensionless)."""
        return np.linalg.eigvals(self.A)


class PlantMatrices:
    """``A``, ``B``, ``C`` and ``dt`` of a design's ``plant`` (a :class:`StateSpace`) under the names
    the design methods read."""

    plant: StateSpace

    @property
    def A(self) -> np.ndarray:
        return self.plant.A

    @property
    def B(self) -> np.ndarray:
        return self.plant.B

    @property
    def C(self) -> np.ndarray:
        return self.plant.C

    @property
    def dt(self) -> float:
        return self.plant.dt


def spectral_radius(a: np.ndarray) -> float:
    """Largest eigenvalue modulus of the square matrix ``a`` (or of a stack of them: the largest
    over the stack)."""
    return float(np.max(np.abs(np.linalg.eigvals(a))))


@dataclass(frozen=True)
class StateSpace(Dimensions):
    """A discrete linear model ``x(k+1) = A x + B u``, ``y = C x + D u``.

    Parameters
    ----------
    A, B, C : ndarray
        Shapes (n, n), (n, m), (p, n).
    dt : float
        Sample time, s.
    D : ndarray, optional
        Shape (p, m); zeros when left out (the engine's and the nozzle's models are strictly proper).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    dt: float
    D: np.ndarray = field(default=None)  # type: ignore[assignment]  # zeros, filled in below

    def __post_init__(self) -> None:
        a = as_matrix(self.A, "A", (None, None))
        n = a.shape[0]
        if a.shape[1] != n:
            raise ValueError(f"A must be square, got shape {a.shape}")
        b = as_matrix(self.B, "B", (n, None))
        c = as_matrix(self.C, "C", (None, n))
        d = np.zeros((c.shape[0], b.shape[1])) if self.D is None else self.D
        d = as_matrix(d, "D", (c.shape[0], b.shape[1]))
        for name, value in (("A", a), ("B", b), ("C", c), ("D", d)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "dt", check_dt(self.dt))


def holds_bool(values: Iterable[Any]) -> bool:
    """Whether nested lists or tuples hold a bool (Python's or numpy's, or a bool array): numpy
    reads ``[True, 0.5]`` as ``[1.0, 0.5]``, so a check of numbers looks for them first."""
    for value in values:
        if isinstance(value, bool | np.bool_) or (isinstance(value, np.ndarray) and value.dtype.kind == "b"):
            return True
        if isinstance(value, list | tuple) and holds_bool(value):
            return True
    return False


def masked_elements(value: Any) -> int:
    """How many elements of ``value`` are masked (0 unless it is a masked array): a masked element
    has no value, and ``np.asarray`` would drop the mask and read whatever lies beneath it."""
    return int(np.ma.count_masked(value)) if isinstance(value, np.ma.MaskedArray) else 0


__all__ = [
    "Dimensions",
    "PlantMatrices",
    "StateSpace",
    "as_floats",
    "as_matrix",
    "boolean_text",
    "check_dt",
    "describe",
    "finite_float",
    "holds_bool",
    "masked_elements",
    "non_number_at",
    "refuse_non_numbers",
    "refuse_unknown_keys",
    "spectral_radius",
]
