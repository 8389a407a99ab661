"""Checks of the command line before work starts, and errors as one line.

:func:`error_line` turns what a run can raise on bad input or a failing machine (OSError, a
gymnasium error, RecursionError on deeply nested files, MemoryError, OverflowError) into the one
``error: ...`` line the command prints. :func:`check_memory` refuses a count option (episodes,
vector sizes, workers) whose estimated memory exceeds what the machine has free, before any work.
"""

from __future__ import annotations

import math
import os
import re
import signal
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ssme_envs.outputs import os_error_text

# Memory per stored episode-step of an evaluation is 8 (d + 2 m + 2) bytes (float64 observations,
# requested and applied actions, reward, alive); a rollout holds its lists and its arrays at once
# and the env's metrics copy them, so the pair being run counts 3 times over the stored ones. The
# native vector envs keep about 30-80 bytes per sub-env and step of the episode (references,
# noise); 96 leaves margin. Measured with tracemalloc on the four envs (1000-2000 episodes).
TRANSIENT_COPIES = 3
ENV_BYTES_PER_STEP = 96
WORKER_BYTES = 150 * 2**20  # one process of the nozzle fit's pools: interpreter, numpy, scipy
MEMORY_SHARE = 0.8  # of the available memory a run may plan to use


_INTEGER = re.compile(r"[+-]?[0-9]+")
_NUMBER = re.compile(
    r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?|[+-]?(nan|inf|infinity)", re.IGNORECASE
)


def integer(text: str) -> int:
    """An integer option's value, read as written: Python's ``int()`` would also read ``1_0`` as
    10 and other scripts' digits; ValueError otherwise (argparse names the option)."""
    if not _INTEGER.fullmatch(text.strip()):
        raise ValueError(text)
    return int(text)


def number(text: str) -> float:
    """A real option's value in decimal notation (``nan`` and ``inf`` are read, and refused by the
    option's own check with its name); ValueError for ``1_0``, ``0x1p-3`` and the like."""
    if not _NUMBER.fullmatch(text.strip()):
        raise ValueError(text)
    return float(text)


# argparse names the kind it expected from the converter's name: "invalid int value: 'x'"
integer.__name__ = "int"
number.__name__ = "float"


def check_finite(option: str, value: float | None, positive: bool = False) -> None:
    """ValueError unless ``value`` (when given) is finite (and > 0 with ``positive``)."""
    if value is None:
        return
    if not math.isfinite(value) or (positive and value <= 0):
        kind = "a positive number" if positive else "a finite number"
        raise ValueError(f"{option} must be {kind}, got {value:g}")


def check_count(option: str, value: int) -> None:
    """ValueError unless ``value`` >= 1."""
    if value < 1:
        raise ValueError(f"{option} must be a positive integer, got {value}")


def check_seed(value: int | None) -> None:
    """ValueError for a seed outside 0..2**32 - 1 (numpy's and gymnasium's seeding refuse negative
    ones, scipy's searches larger ones): before any work."""
    from ssme_envs.identification.arguments import MAX_SEED

    if value is not None and not 0 <= value <= MAX_SEED:
        raise ValueError(f"--seed must be a non-negative integer of at most {MAX_SEED}, got {value}")


def _read_int(path: str, key: str | None = None) -> int | None:
    try:
        text = Path(path).read_text()
    except OSError:
        return None
    if key is None:
        word = text.strip()
        return int(word) if word.isdigit() else None
    for line in text.splitlines():
        if line.startswith(key):
            return int(line.split()[1]) * 1024  # kB
    return None


def available_memory() -> int | None:
    """Bytes this process may still allocate: the least of the machine's available memory
    (/proc/meminfo, psutil or sysconf), a cgroup v2 limit and RLIMIT_AS; None when unknown."""
    limits = []
    free = _read_int("/proc/meminfo", "MemAvailable:")
    if free is None:
        try:
            import psutil

            free = int(psutil.virtual_memory().available)
        except ImportError:
            try:
                free = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
            except (AttributeError, ValueError, OSError):
                free = None
    if free is not None:
        limits.append(free)
    cap, used = _read_int("/sys/fs/cgroup/memory.max"), _read_int("/sys/fs/cgroup/memory.current")
    if cap is not None and used is not None:
        limits.append(cap - used)
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY:
            pages = int(Path("/proc/self/statm").read_text().split()[0])
            limits.append(soft - pages * os.sysconf("SC_PAGE_SIZE"))
    except (ImportError, OSError, ValueError, IndexError):
        pass
    return max(0, min(limits)) if limits else None


def _size(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if n < 1024 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError  # pragma: no cover


def check_memory(option: str, count: int, bytes_per_unit: float, what: str) -> None:
    """ValueError when ``count`` units of ``bytes_per_unit`` exceed the memory a run may use.

    The message names the option, the estimate, the limit and the largest count that fits.
    """
    need = count * math.ceil(bytes_per_unit)  # an int: no overflow for any count
    free = available_memory()
    if free is None or need <= MEMORY_SHARE * free:
        return
    most = int(MEMORY_SHARE * free // bytes_per_unit)
    raise ValueError(
        f"{option} {count} needs about {_size(min(need, 10**30))} of memory ({what}); "
        f"{_size(free)} is available (limit {MEMORY_SHARE:.0%} of it): use at most {most}"
    )


def env_shape(env_id: str) -> tuple[int, int, int]:
    """Observation size, action size and episode steps (its registered limit) of an env, from
    its catalogue entry."""
    from ssme_envs.envs.catalogue import spec
    from ssme_envs.evaluation import check_env_id

    entry = spec(check_env_id(env_id))
    return len(entry.observation.names), len(entry.action_names), entry.max_episode_steps


def evaluation_bytes(env_id: str, pairs: int) -> float:
    """Estimated bytes per episode of evaluating ``pairs`` (scenario, controller) pairs of an env."""
    obs, act, steps = env_shape(env_id)
    return steps * (8 * (obs + 2 * act + 2) * (pairs + TRANSIENT_COPIES) + ENV_BYTES_PER_STEP)


def positive_integers(option: str, text: str) -> tuple[int, ...]:
    """The value of an option of comma-separated positive integers; ValueError naming it."""
    try:
        values = tuple(integer(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"{option} must be comma-separated positive integers, got {text!r}") from None
    if any(v < 1 for v in values):
        raise ValueError(f"{option} must be positive integers, got {text!r}")
    return values


def check_episodes(episodes: int, plan: dict[str, int], option: str = "--episodes") -> None:
    """Refuse ``--episodes`` (or the ``option`` that sets them) whose rollouts would not fit:
    ``plan`` maps env id -> pairs run."""
    check_count(option, episodes)
    per_episode = sum(evaluation_bytes(env_id, pairs) for env_id, pairs in plan.items())
    pairs = sum(plan.values())
    check_memory(option, episodes, per_episode, f"{pairs} scenario-controller pairs kept for the plots")


def check_vector_sizes(sizes: Sequence[int], env_ids: Sequence[str]) -> None:
    """Refuse vector sizes (``bench --sizes``) whose envs would not fit in memory."""
    import gymnasium as gym

    import ssme_envs  # noqa: F401  (registers the environments)

    steps = max(int(gym.spec(e).max_episode_steps or 1000) for e in env_ids)
    check_memory("--sizes", max(sizes), ENV_BYTES_PER_STEP * steps + 1024, "envs of the largest size")


def check_workers(workers: int) -> None:
    """Refuse ``--workers`` below 1 or beyond what memory holds (one process each)."""
    check_count("--workers", workers)
    check_memory("--workers", workers, WORKER_BYTES, "one process each")


def check_training(config: dict[str, Any]) -> None:
    """Refuse a training config whose envs or buffers would not fit in memory: ``num_envs``
    (each env's episode buffers plus its share of PPO's float32 rollout of ``n_steps``) and an
    off-policy ``buffer_size`` (observations twice, actions, reward and done per transition)."""
    obs, act, steps = env_shape(config["env"])
    hyper = config.get("hyperparameters", {})
    rollout = 4 * 2 * (obs + act + 4) * int(hyper.get("n_steps", 2048)) if config["algo"] == "ppo" else 0
    check_memory("num_envs", config["num_envs"], ENV_BYTES_PER_STEP * steps + rollout, "envs and rollouts")
    if config["algo"] != "ppo":
        buffer = int(hyper.get("buffer_size", 1_000_000))
        check_memory("buffer_size", buffer, 4 * (2 * obs + act + 2), "replay buffer transitions")


def _gymnasium_error(exc: BaseException) -> bool:
    module = sys.modules.get("gymnasium.error")
    return module is not None and isinstance(exc, module.Error)


def one_line(text: str) -> str:
    """``text`` on one printable line: newlines become spaces, other control characters escapes."""
    text = " ".join(text.splitlines())
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def error_line(exc: BaseException) -> str | None:
    """The text after ``error: `` for an exception caused by the input or the machine; None for
    a bug (it keeps its traceback)."""
    if isinstance(exc, OSError):
        return os_error_text(exc)
    if isinstance(exc, RecursionError):
        return f"input nested too deeply to read ({exc})"
    if isinstance(exc, MemoryError):
        return "out of memory: ask for less (fewer episodes, smaller sizes or records)"
    if isinstance(exc, OverflowError):
        return f"number out of range ({exc})"
    if _gymnasium_error(exc):
        return f"gymnasium: {exc}"
    if isinstance(exc, ValueError):
        return str(exc)
    return None


@contextmanager
def sigint_in_main_process() -> Iterator[None]:
    """While inside, Ctrl-C raises KeyboardInterrupt in this process only: worker processes
    forked meanwhile ignore it and are ended by their pool, without tracebacks of their own. A
    second Ctrl-C while the first unwinds (a pool waiting for its workers) exits at once with
    code 130; what the run had written is then removed by the next run into its --out."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pid, presses = os.getpid(), []

    def handler(signum: int, frame: Any) -> None:
        if os.getpid() != pid:
            return
        presses.append(signum)
        if len(presses) > 1:
            os.write(2, b"error: interrupted (Ctrl-C)\n")
            os._exit(130)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler if previous is None else previous)


__all__ = [
    "available_memory",
    "check_count",
    "check_episodes",
    "check_finite",
    "check_memory",
    "check_seed",
    "check_training",
    "check_vector_sizes",
    "check_workers",
    "error_line",
    "evaluation_bytes",
    "integer",
    "number",
    "one_line",
    "os_error_text",
    "sigint_in_main_process",
]
