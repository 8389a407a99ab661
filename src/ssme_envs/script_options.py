"""Options of the scripts in experiments/, held to the command line's rule: a bad option is one
``error: ...`` line on stderr and exit code 2, before any work (:func:`script_parser` and the
``type=`` factories :func:`int_within`, :func:`float_within`, :func:`comma_choices`,
:func:`output_file` and :func:`episodes_within_memory`)."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import NoReturn

from ssme_envs.cli_checks import check_episodes, integer, number, one_line
from ssme_envs.outputs import OutputError, check_file_target, names_directory

_OUT = "--out"  # the option named in check_file_target's messages (removed from them here)


class _ScriptParser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        if message.startswith("argument "):  # "argument --rounds: must be ..." -> "--rounds must be ..."
            option, _, text = message.removeprefix("argument ").partition(": ")
            if text.startswith(f"{option} "):  # the check's own message names the option
                message = text
            else:
                message = f"{option} {text}" if text.startswith("must ") else f"{option}: {text}"
        print(f"error: {one_line(message)}", file=sys.stderr)
        raise SystemExit(2)


def script_parser(description: str) -> argparse.ArgumentParser:
    """An argument parser for a script in experiments/.

    Parameters
    ----------
    description : str
        The script's one-line description, for ``--help``.

    Returns
    -------
    argparse.ArgumentParser
        A parser whose errors (argparse's own, such as an unknown option or a missing value, the
        ``type=`` checks' and ``parser.error``'s) print one line ``error: OPTION ...`` on stderr
        and exit with code 2, without argparse's usage line.
    """
    return _ScriptParser(description=description)


def _number(value: float) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


def _bounds(low: float, high: float | None) -> str:
    return f"at least {_number(low)}" if high is None else f"within {_number(low)}-{_number(high)}"


def int_within(low: int, high: int | None = None) -> Callable[[str], int]:
    """An argparse ``type=`` for an integer option.

    Parameters
    ----------
    low, high : int
        Smallest and largest value taken (inclusive); no upper bound when ``high`` is None.

    Returns
    -------
    callable
        Text -> int; it raises ``argparse.ArgumentTypeError`` ("must be within LOW-HIGH, got V")
        for other text.
    """

    def convert(text: str) -> int:
        try:
            value = integer(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"must be an integer {_bounds(low, high)}, got {text!r}"
            ) from None
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be {_bounds(low, high)}, got {value}")
        return value

    return convert


def float_within(low: float, high: float | None = None, *, above: bool = False) -> Callable[[str], float]:
    """An argparse ``type=`` for a real option.

    Parameters
    ----------
    low, high : float
        Smallest and largest value taken (inclusive); no upper bound when ``high`` is None. NaN
        and infinities are refused.
    above : bool
        ``low`` itself is refused (a value must exceed it).

    Returns
    -------
    callable
        Text -> float; it raises ``argparse.ArgumentTypeError`` for other text.
    """
    bounds = _bounds(low, high)
    if above:
        bounds = f"above {_number(low)}" + ("" if high is None else f" and at most {_number(high)}")

    def convert(text: str) -> float:
        try:
            value = number(text)
        except ValueError:
            value = math.nan
        in_low = low < value if above else low <= value
        if not (math.isfinite(value) and in_low and (high is None or value <= high)):
            raise argparse.ArgumentTypeError(f"must be a number {bounds}, got {text!r}")
        return value

    return convert


def comma_choices(choices: Collection[str]) -> Callable[[str], str]:
    """An argparse ``type=`` for a comma-separated list option, such as ``--methods iv,ls``.

    Parameters
    ----------
    choices : collection of str
        The items allowed, in the order the error message lists them.

    Returns
    -------
    callable
        Text -> the same list with the spaces around its items removed; it raises
        ``argparse.ArgumentTypeError`` for an empty or unknown item.
    """

    def convert(text: str) -> str:
        items = [item.strip() for item in text.split(",")]
        if not all(item in choices for item in items):
            raise argparse.ArgumentTypeError(
                f"must be a comma-separated list of {', '.join(choices)}, got {text!r}"
            )
        return ",".join(items)

    return convert


def output_file(text: str) -> Path:
    """An argparse ``type=`` for a file a script writes when it ends.

    Parameters
    ----------
    text : str
        The path given.

    Returns
    -------
    Path
        The path; ``argparse.ArgumentTypeError`` when it names a directory (an existing one, or
        any path ending in ``/``, ``/.`` or ``/..``), its parent is not an existing directory, or
        :func:`~ssme_envs.outputs.check_file_target` refuses it (a FIFO, device or socket, or a
        directory that does not take a new file): refused before the work, not after it (a FIFO
        would hang the script's last write).
    """
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"must be a file, got the directory {text!r}")
    if names_directory(text):
        raise argparse.ArgumentTypeError(f"must be a file, got {text!r}, which names a directory")
    parent = path.parent
    if not parent.is_dir():
        why = "does not exist" if not parent.exists() else "is not a directory"
        raise argparse.ArgumentTypeError(f"must be in an existing directory, got {text!r} ({parent} {why})")
    try:
        check_file_target(text, option=_OUT)
    except OutputError as exc:  # "--out TEXT: why", or (a special file) "TARGET exists and is not ..."
        why = str(exc).removeprefix(f"{_OUT} {text}: ")
        raise argparse.ArgumentTypeError(
            f"must be a file this script can write, got {text!r} ({why})"
        ) from None
    return path


def episodes_within_memory(plan: Callable[[], Mapping[str, int]]) -> Callable[[str], int]:
    """An argparse ``type=`` for ``--episodes`` of an evaluation, held to the memory check of
    ``ssme-envs evaluate --episodes`` (:func:`~ssme_envs.cli_checks.check_episodes`).

    Parameters
    ----------
    plan : callable
        () -> ``{env id: scenario-controller pairs evaluated}``, called on a value given.

    Returns
    -------
    callable
        Text -> int (at least 1); it raises ``argparse.ArgumentTypeError`` for other text and
        for a count whose rollouts would not fit in memory (the message gives the largest that
        does).
    """
    count = int_within(1)

    def convert(text: str) -> int:
        episodes = count(text)
        try:
            check_episodes(episodes, dict(plan()))
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return episodes

    return convert


def max_workers() -> int:
    """The largest ``--workers`` (processes) a script takes: this machine's CPU count, at least 2
    (the scripts' default)."""
    return max(2, os.cpu_count() or 1)


__all__ = [
    "comma_choices",
    "episodes_within_memory",
    "float_within",
    "int_within",
    "max_workers",
    "output_file",
    "script_parser",
]
