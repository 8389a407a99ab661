"""Output files and run directories: atomic writes, one run per directory, one run at a time.

Every file the package writes goes through :func:`atomic_write` (or :func:`write_text`,
:func:`save_figure`): the bytes go to a temporary file ``.<name>.<random>.tmp`` in the target's
directory, are flushed to disk and renamed over the target (``os.replace``), so that a reader, or
a run killed half-way, finds the old file or the new one, never a part of one.

A command's output directory is built by :func:`run_directory`. The run writes into a fresh
sibling ``.<name>.new-<random>``; only when it has succeeded is the previous directory (if any)
renamed aside, the new one renamed into its place and the previous one deleted. A failed,
interrupted or killed run leaves the previous directory as it was. A directory is replaced only
when it is empty or was written by ssme-envs (it holds :data:`MARKER`); anything else is refused.
A lock file ``.<name>.lock`` beside the directory (``fcntl.flock``, released by the kernel when
its holder dies, so a lock left by a killed run is stale and simply taken over) refuses a second
concurrent run into the same directory. Leftovers of a killed run (``.<name>.new-*``, and a
``.<name>.old-*`` when it died between the two renames) are cleaned up by the next run into the
directory, under the lock.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: runs are not locked
    fcntl = None  # type: ignore[assignment]

MARKER = ".ssme-envs-run"  # written into every run directory: such a directory may be replaced


class OutputError(ValueError):
    """An output directory that cannot be used (taken by a file, foreign contents, locked)."""


@contextmanager
def atomic_write(path: str | Path, mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path`` for writing; on success rename it over ``path``.

    Parameters
    ----------
    path : str or Path
        The file to (re)place; its directory must exist. A symlink is followed (its target is
        replaced); a device, FIFO or socket raises :class:`OutputError`.
    mode : {"w", "wb"}
        Text (UTF-8) or binary.

    Yields
    ------
    file object
        Write to it; on an exception (or a kill) ``path`` is left as it was and the temporary
        file is removed (after a kill it stays, as ``.<name>.<random>.tmp``).
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    path = _file_target(path)
    while True:
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:  # mode 0o666: the process umask applies, as for an ordinary open()
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:  # pragma: no cover - 32 random bits clashed
            continue
    try:
        with open(fd, mode, **({"encoding": "utf-8"} if mode == "w" else {})) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if exc.filename is None and exc.errno is not None:  # write, fsync: name the file
            raise OSError(exc.errno, exc.strerror, os.fspath(path)) from None
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _file_target(path: str | Path) -> Path:
    """The file :func:`atomic_write` replaces for ``path``: a symlink's target; OutputError for a
    device, FIFO or socket (renaming over one would replace it: as root, /dev/null too). A
    directory is left to the rename, which fails on it."""
    target = Path(os.path.realpath(path))
    if target.exists() and not target.is_file() and not target.is_dir():
        raise OutputError(f"{target} exists and is not a regular file: refusing to replace it")
    return target


def names_directory(path: str | Path) -> bool:
    """Whether ``path`` names a directory by its form: a trailing "/", "/." or "/.." (which
    ``Path()`` and ``realpath`` drop, so a file would take the directory's name)."""
    return os.path.basename(str(path)) in ("", ".", "..")


def check_file_target(path: str | Path, option: str = "--out") -> None:
    """OutputError unless :func:`atomic_write` can write ``path``: a file (not a directory or a
    special file) in an existing directory that takes a new file (tried, not guessed from
    permission bits, which neither root nor a read-only mount honour). For a command to check
    before its long work rather than fail at its end."""
    if names_directory(path):
        raise OutputError(f"{option} {path}: must be a file, and this names a directory")
    target = _file_target(path)
    if target.is_dir() or not target.parent.is_dir():
        raise OutputError(f"{option} {path}: must be a file in an existing directory")
    try:
        with tempfile.NamedTemporaryFile(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp"):
            pass
    except OSError as exc:
        raise OutputError(f"{option} {path}: cannot write in {target.parent} ({exc.strerror})") from None


def toml_value(value: Any) -> str:
    """A value as TOML writes it inline: a bool, a quoted string, a list, an inline table."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    return repr(value)


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_write(path) as fh:
        fh.write(text)


def save_figure(fig: Any, path: str | Path, **kwargs: Any) -> None:
    """``fig.savefig`` to ``path`` atomically; the format comes from the suffix (``.png``)."""
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format=kwargs.pop("format", path.suffix.lstrip(".") or "png"), **kwargs)


def write_with(path: str | Path, writer: Callable[[IO[str]], None]) -> None:
    """Call ``writer(file)`` on a text file that replaces ``path`` when ``writer`` returns."""
    with atomic_write(path) as fh:
        writer(fh)


def _lock_holder(path: Path) -> str:
    try:
        text = path.read_text().strip()
    except OSError:
        return "pid unknown"
    return f"pid {text}" if text.isdigit() else "pid unknown"


@contextmanager
def directory_lock(target: Path) -> Iterator[Path]:
    """Hold the lock of output directory ``target`` (the file ``.<name>.lock`` beside it).

    Raises
    ------
    OutputError
        When another process holds it; the message names the directory and the holder's pid.
    """
    path = target.parent / f".{target.name}.lock"
    if fcntl is None:  # pragma: no cover
        yield path
        return
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputError(
                f"{target} is in use by another ssme-envs run ({_lock_holder(path)}, lock file {path}); "
                "wait for it to end or choose another --out"
            ) from None
        except BaseException:
            os.close(fd)
            raise
        try:  # the holder we waited for may have removed the file: lock the one now there
            if os.path.samestat(os.fstat(fd), os.stat(path)):
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    try:  # a lock file left by a killed run holds its pid: the kernel released its lock
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield path
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)


def _siblings(target: Path, kind: str) -> list[Path]:
    prefix = f".{target.name}.{kind}-"
    return sorted(
        (p for p in target.parent.iterdir() if p.name.startswith(prefix) and p.is_dir()),
        key=lambda p: p.stat().st_mtime,
    )


def _recover(target: Path) -> None:
    """Remove what a killed run left beside ``target``; put back a directory it had renamed aside."""
    for work in _siblings(target, "new"):
        shutil.rmtree(work, ignore_errors=True)
    old = _siblings(target, "old")
    if old and not os.path.lexists(target):
        os.rename(old.pop(), target)
    for path in old:
        shutil.rmtree(path, ignore_errors=True)


def check_target(out: str | Path) -> Path:
    """The absolute output directory for ``out``; OutputError when it cannot be one."""
    target = Path(os.path.abspath(out))
    if target.is_symlink():
        if not target.exists():  # following it would create directories wherever it points
            raise OutputError(
                f"{out}: a symbolic link to {os.readlink(target)}, which does not exist: name a directory, "
                "or create the link's target first"
            )
        target = target.resolve()
    if not target.name or target == target.parent:
        raise OutputError(f"{out}: an output directory needs a name (not a file-system root)")
    if target.exists() and not target.is_dir():
        raise OutputError(f"{out}: exists and is not a directory")
    for parent in target.parents:  # the nearest existing ancestor must be a directory
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{out}: {parent} is a file, not a directory")
            break
    return target


def _check_replaceable(target: Path, shown: str | Path) -> None:
    if target.is_dir() and not (target / MARKER).is_file() and any(target.iterdir()):
        raise OutputError(
            f"{shown} is not empty and was not written by ssme-envs (no {MARKER} in it): "
            "choose a new or empty --out"
        )


def _swap(work: Path, target: Path) -> None:
    """Rename ``work`` to ``target``; a previous ``target`` is renamed aside first, then deleted."""
    if not os.path.lexists(target):
        os.rename(work, target)
        return
    old = target.with_name(f".{target.name}.old-{secrets.token_hex(4)}")
    os.rename(target, old)
    try:
        os.rename(work, target)
    except BaseException:
        os.rename(old, target)
        raise
    shutil.rmtree(old, ignore_errors=True)


def _make_parents(directory: Path) -> list[Path]:
    """Create ``directory`` and its missing parents; the ones created, innermost first."""
    created = []
    for path in (directory, *directory.parents):
        if os.path.lexists(path):
            break
        created.append(path)
    directory.mkdir(parents=True, exist_ok=True)
    return created


def _remove_empty(created: list[Path]) -> None:
    for path in created:
        try:
            path.rmdir()
        except OSError:
            return


def os_error_text(exc: OSError) -> str:
    """``path: reason`` of an OSError (both paths of a rename)."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    if exc.filename is not None and exc.filename2 is not None:
        return f"{exc.filename} -> {exc.filename2}: {reason}"
    if exc.filename is not None:
        return f"{exc.filename}: {reason}"
    return reason


def holds_run(out: str | Path) -> bool:
    """Whether ``out`` holds an earlier ssme-envs run (which a new run replaces)."""
    return (Path(out) / MARKER).is_file()


def check_inputs_outside(
    out: str | Path, inputs: Mapping[str, str | Path | None], out_name: str = "--out"
) -> None:
    """OutputError when an input file or directory lies in ``out``, which the run replaces (with
    every file in it) once it succeeds; ``inputs`` maps each input's name (the option or
    parameter) to its path (None: not given), ``out_name`` names ``out`` in the message."""
    if not holds_run(out):  # only an earlier run is replaced; other contents are refused as they are
        return
    target = os.path.realpath(out)
    for option, path in inputs.items():
        if path is None:
            continue
        where = os.path.realpath(path)
        if where == target or where.startswith(target.rstrip(os.sep) + os.sep):
            raise OutputError(
                f"{option} {path} lies in {out_name} {out}, which this run replaces with its own files: "
                f"choose another {out_name} or move the input out of it"
            )


@contextmanager
def run_directory(out: str | Path, stage: bool = True) -> Iterator[Path]:
    """The directory a command writes into, locked; swapped in for ``out`` when the block ends.

    Parameters
    ----------
    out : str or Path
        The output directory. Its parents are created (and removed again, if empty, when the
        run fails); it may be absent, empty, or an earlier ssme-envs run (replaced only once
        this run succeeds).
    stage : bool
        False: only hold the lock; the command creates and writes ``out`` itself.

    Yields
    ------
    Path
        A fresh directory beside ``out`` (``out`` itself when ``stage`` is False).

    Raises
    ------
    OutputError
        ``out`` is a file, holds foreign files, or is locked by another run.
    OSError
        From the file system (permissions, no space, ...).
    """
    target = check_target(out)
    created = _make_parents(target.parent)
    try:
        with directory_lock(target):
            _recover(target)
            if not stage:
                yield target
                return
            _check_replaceable(target, out)
            work = target.with_name(f".{target.name}.new-{secrets.token_hex(4)}")
            work.mkdir()
            try:
                started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
                write_text(
                    work / MARKER, json.dumps({"pid": os.getpid(), "argv": sys.argv, "started": started})
                )
                yield work
                _swap(work, target)
            except BaseException:
                shutil.rmtree(work, ignore_errors=True)
                raise
    except BaseException:
        _remove_empty(created)
        raise


@contextmanager
def output_directory(
    out: str | Path, inputs: Mapping[str, str | Path | None] | None = None
) -> Iterator[Path]:
    """:func:`run_directory` for a library function: file-system errors inside the block become
    ValueErrors naming ``out``, not the temporary directory the user never sees. ``inputs``: the
    files and directories the function reads, by parameter name, refused where they lie in an
    earlier run at ``out`` (:func:`check_inputs_outside`), which this run would delete."""
    check_inputs_outside(out, inputs or {}, "out_dir")
    with run_directory(out) as work:
        try:
            yield work
        except OSError as exc:
            raise ValueError(os_error_text(exc).replace(str(work), str(out))) from None


__all__ = [
    "MARKER",
    "OutputError",
    "atomic_write",
    "check_file_target",
    "check_inputs_outside",
    "check_target",
    "directory_lock",
    "holds_run",
    "names_directory",
    "os_error_text",
    "output_directory",
    "run_directory",
    "save_figure",
    "toml_value",
    "write_text",
    "write_with",
]
