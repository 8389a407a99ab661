"""Reading a file the user names, bounded: a regular file only, at most so many bytes.

A FIFO named like a record blocks its reader for ever, a device such as /dev/zero never ends,
and a wrong path (a disk image, a log) would be read whole before any check could refuse it:
:func:`read_bounded` opens without blocking, checks the opened file itself (symlinks followed,
no race with a swap) and stops reading past the limit. Callers word the errors for their files.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


class NotRegularFile(ValueError):
    """The path names something else than a regular file; ``kind`` says what ("a FIFO", ...)."""

    def __init__(self, kind: str) -> None:
        super().__init__(kind)
        self.kind = kind


class FileTooLarge(ValueError):
    """The file holds more than the limit the caller gave."""


def read_bounded(path: str | Path, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path`` (symlinks followed).

    Raises
    ------
    FileNotFoundError, OSError
        As ``open`` and ``read`` raise them.
    NotRegularFile
        A directory, FIFO, device or socket.
    FileTooLarge
        More than ``max_bytes`` bytes (checked before reading, and again while reading: the file
        may grow meanwhile).
    """
    # O_NONBLOCK: opening a FIFO would otherwise wait for a writer before fstat could refuse it
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    try:
        info = os.fstat(fd)  # before open(): it refuses a directory with an error of its own
        kind = special_kind(info.st_mode)
        if kind is not None:
            raise NotRegularFile(kind)
        if info.st_size > max_bytes:
            raise FileTooLarge(path)
        with open(fd, "rb", closefd=False) as file:
            data = file.read(max_bytes + 1)
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise FileTooLarge(path)
    return data


def special_kind(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is when it is not a regular file ("a FIFO", ...)."""
    if stat.S_ISREG(mode):
        return None
    return next((kind for test, kind in _KINDS if test(mode)), "a special file")


def spelled_kind(kind: str) -> str:
    """A :class:`NotRegularFile` kind as the file readers' messages write it ("a FIFO (named pipe)")."""
    return "a FIFO (named pipe)" if kind == "a FIFO" else kind


def read_or_refuse(path: str | Path, max_bytes: int, kind: str, too_large: str) -> bytes:
    """:func:`read_bounded`, its errors a ValueError naming ``path``: "not {kind}: it is a FIFO
    (named pipe), not a regular file", "larger than N MiB, too large for {too_large}", ..."""
    try:
        return read_bounded(path, max_bytes)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except NotRegularFile as exc:
        raise ValueError(f"{path}: not {kind}: it is {spelled_kind(exc.kind)}, not a regular file") from None
    except FileTooLarge:
        raise ValueError(f"{path}: larger than {max_bytes // 2**20} MiB, too large for {too_large}") from None
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.strerror or exc})") from None


__all__ = ["FileTooLarge", "NotRegularFile", "read_bounded", "read_or_refuse", "special_kind", "spelled_kind"]
