"""Where tuning studies live: the Optuna storage of ``journal:PATH`` or a database URL, checked
before any trial (a file that is not a whole Optuna journal is refused, not appended to), and
Optuna's log lines on stdout."""

from __future__ import annotations

import json
import logging
import sys
import time
from pathlib import Path
from typing import Any

# A journal line opens as Optuna writes its records (json.dumps, compact or spaced); an unfinished
# last line (one that opens so, or is cut inside the opening) still unfinished after UNFINISHED_WAIT s
# (Optuna appends a batch in one locked write) was cut off.
RECORD_OPENING = b'{"op_code":'
UNFINISHED_WAIT = 0.2


def open_storage(url: str) -> Any:
    """The Optuna storage of ``journal:PATH`` (a journal file) or of an RDB URL; ValueError
    naming the problem (unknown form, missing directory, a file that is not an Optuna journal,
    database unreachable or its driver not installed)."""
    import optuna

    if not isinstance(url, str) or not url:
        raise ValueError("--storage must be journal:PATH or a database URL such as sqlite:///study.db")
    if url.startswith("journal:"):
        path = Path(url.removeprefix("journal:"))
        if not path.name or path.is_dir():
            raise ValueError(f"--storage {url}: journal:PATH needs a file path")
        if not path.parent.is_dir():
            raise ValueError(f"--storage {url}: directory {path.parent} does not exist")
        if path.exists() and not path.is_file():  # a FIFO blocks Optuna's read, a device never ends it
            raise ValueError(f"--storage {url}: {path} is not a regular file")
        from optuna.storages.journal import JournalFileBackend

        _check_journal_lines(path, url)
        try:  # Optuna replays the records at once, trusting their fields
            return optuna.storages.JournalStorage(JournalFileBackend(str(path)))
        except OSError:
            raise  # the CLI names the file and the reason
        except Exception as exc:
            raise ValueError(f"--storage {url}: {path} is not a readable Optuna journal (replaying it "
                             f"failed: {type(exc).__name__}: {exc})") from None  # fmt: skip
    import sqlalchemy

    try:
        sqlalchemy.engine.make_url(url)
    except sqlalchemy.exc.ArgumentError:
        raise ValueError(
            f"--storage {url!r}: not journal:PATH nor a database URL (sqlite:///study.db, "
            "postgresql://user:password@host/db, mysql+pymysql://...)"
        ) from None
    try:
        return optuna.storages.RDBStorage(url)
    except ImportError as exc:  # the database's driver (psycopg2, pymysql, ...)
        raise ValueError(f"--storage {url}: the database driver is not installed ({exc})") from None
    except (sqlalchemy.exc.SQLAlchemyError, ValueError) as exc:
        raise ValueError(f"--storage {url}: cannot open the database ({str(exc).splitlines()[0]})") from None


def _check_journal_lines(path: Path, url: str) -> None:
    """ValueError unless every line of the journal at ``path`` (if any) is an Optuna journal record
    (a JSON object with an ``op_code``), so that nothing is appended to another kind of file.
    An unfinished last line may be another worker's record being appended (Optuna writes each
    batch in one call under a lock): it must start as a record does, and a last line still
    unfinished after ``UNFINISHED_WAIT`` s was cut off (an interrupted write), which Optuna would
    glue the next record onto."""
    if not path.is_file():
        return
    size = path.stat().st_size
    with path.open("rb") as fh:
        for number, line in enumerate(fh, start=1):
            if not line.endswith(b"\n"):
                opens = line.startswith(RECORD_OPENING) or RECORD_OPENING.startswith(line)
                problem = None if opens else "not an Optuna journal record"
                if problem is None:
                    time.sleep(UNFINISHED_WAIT)
                    if path.stat().st_size == size:
                        problem = "its last line is cut off (an interrupted write?): remove that line"
            else:
                try:
                    record = json.loads(line)
                    problem = (
                        None
                        if isinstance(record, dict) and "op_code" in record
                        else "not an Optuna journal record"
                    )
                except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
                    problem = str(exc)
            if problem is not None:
                raise ValueError(f"--storage {url}: {path} is not a readable Optuna journal "
                                 f"(line {number}: {problem})")  # fmt: skip


class _StdoutHandler(logging.StreamHandler):
    """A stream handler on whatever ``sys.stdout`` is when it writes (a redirected or captured
    stdout included)."""

    @property
    def stream(self) -> Any:
        return sys.stdout

    @stream.setter
    def stream(self, value: Any) -> None:  # StreamHandler's constructor sets it
        pass


def log_to_stdout() -> None:
    """Optuna's log lines on stdout (its default handler writes them to stderr, where the CLI keeps
    only its one error line); idempotent."""
    import optuna

    optuna.logging.disable_default_handler()
    logger = logging.getLogger("optuna")
    if not any(isinstance(h, _StdoutHandler) for h in logger.handlers):
        handler = _StdoutHandler()
        handler.setFormatter(logging.Formatter("[%(levelname)1.1s %(asctime)s] %(message)s"))
        logger.addHandler(handler)


__all__ = ["log_to_stdout", "open_storage"]
