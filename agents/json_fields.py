"""The checks every JSON file of a policy directory goes through: a bounded read of a regular
file, known and required fields, finite numbers, and short values in error lines."""

from __future__ import annotations

import errno
import math
import os
from pathlib import Path
from typing import Any

from ssme_envs.input_files import special_kind, spelled_kind
from ssme_envs.models.statespace_json import read_json


def load_object(path: Path) -> dict[str, Any]:
    """A JSON object from a regular file of at most the package's JSON limit (``read_json``: a FIFO,
    device, directory, oversized file, deep nesting or overlong number is a ValueError naming it)."""
    data = read_json(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object, got {type(data).__name__}")
    return data


def check_keys(data: dict[str, Any], known: set[str], required: set[str], where: str) -> None:
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{where}: unexpected field(s) {', '.join(unknown)}")
    missing = sorted(required - set(data))
    if missing:
        raise ValueError(f"{where}: missing field(s) {', '.join(missing)}")


def finite(value: Any) -> float | None:
    """``value`` as a float if it is a finite JSON number (not a bool, not an integer beyond float's
    range), else None."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        number = float(value)
    except OverflowError:  # an integer of more than 308 digits
        return None
    return number if math.isfinite(number) else None


def short(value: Any) -> str:
    """``repr(value)``, cut short (a 4000-digit integer in an error line helps nobody)."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:37]}..."


def numbers(value: Any, where: str) -> list[float]:
    """A JSON list of numbers (non-finite ones written "inf", "-inf")."""
    if not isinstance(value, list):
        raise ValueError(f"{where} must be a list of numbers")
    out = []
    for v in value:
        if isinstance(v, str) and v in ("inf", "-inf"):
            out.append(float(v))
        elif (number := finite(v)) is not None:
            out.append(number)
        else:
            raise ValueError(f"{where} must be a list of numbers, got {short(v)}")
    return out


def file_problem(path: Path) -> str | None:
    """None for a regular file (symlinks followed), "missing", or what ``path`` is instead (a
    directory, a FIFO, a symbolic link loop, ...); nothing is opened (a FIFO would block)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "a broken symbolic link" if os.path.islink(path) else "missing"
    except OSError as exc:  # other errors (permissions, ...) are named by the read that follows
        return "a symbolic link loop" if exc.errno == errno.ELOOP else None
    kind = special_kind(mode)
    return None if kind is None else spelled_kind(kind)
