"""SB3's own ``.zip`` policies: loaded only on request (they unpickle), and converted once to
the pickle-free format of :mod:`agents.policy_files`.

Convert old run directories (``model.zip`` beside ``normalization.json`` and ``config.toml``)::

    python -m agents.policy_zip RUN_DIR [RUN_DIR ...] --allow-pickle

Each conversion checks that the deterministic actions of the new files and of the zip agree bit
for bit on random observations; the zip is left for you to delete.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from agents.json_fields import file_problem
from agents.normalization import NORMALIZATION, Normalization, read_normalization
from agents.policy_files import (
    PICKLE_WARNING,
    POLICY_JSON,
    WEIGHTS,
    LoadedPolicy,
    algorithm_class,
    load_policy,
    save_policy,
)


def load_sb3_zip(path: Path, algo: str, *, allow_pickle: bool = False) -> LoadedPolicy:
    """A policy from SB3's own ``.zip`` (with ``normalization.json`` beside it if there is one).
    SB3 unpickles parts of the zip, which can execute arbitrary code: refused (ValueError) unless
    ``allow_pickle=True``, and a warning is printed when allowed."""
    path = Path(path)
    if not allow_pickle:
        raise ValueError(
            f"{path}: refusing to load an SB3 zip: {PICKLE_WARNING}; pass allow_pickle=True "
            "(ssme-envs evaluate --allow-pickle) to load it anyway"
        )
    algorithm = algorithm_class(algo)
    normalization = check_sb3_zip(path)  # our own errors (the file, the normalization) before SB3's
    print(f"warning: {path}: {PICKLE_WARNING}", file=sys.stderr)
    try:
        model = algorithm.load(path, device="cpu")
    except (OSError, MemoryError):
        raise
    except Exception as exc:  # SB3 on a damaged zip: KeyError, AssertionError, JSON errors, ...
        raise sb3_zip_error(path, algo, exc) from None
    if normalization is None:
        print(f"warning: no {NORMALIZATION} beside {path}: observations go to the policy unnormalized",
              file=sys.stderr)  # fmt: skip
    return LoadedPolicy(model.policy, algo, None, normalization, path)


def check_sb3_zip(path: Path) -> Normalization | None:
    """Before SB3 opens an SB3 ``.zip`` (with ``allow_pickle``): ValueError naming ``path`` unless it
    is a regular file, or naming the ``normalization.json`` beside it if that one does not read
    (so that no error of ours is raised from inside SB3's load: see :func:`sb3_zip_error`).
    Returns the statistics beside it, None where there is no such file."""
    path = Path(path)
    problem = file_problem(path)
    if problem == "missing":
        raise ValueError(f"{path}: no such file")
    if problem is not None:
        raise ValueError(f"{path}: not an SB3 zip: it is {problem}, not a regular file")
    beside = path.parent / NORMALIZATION
    problem = file_problem(beside)
    if problem is None:
        return read_normalization(beside)
    if problem != "missing":  # not skipped: the policy would see unnormalized observations
        raise ValueError(f"{beside}: not valid JSON: it is {problem}, not a regular file")
    return None


def sb3_zip_error(path: Path, algo: str, exc: Exception) -> ValueError:
    """The ValueError naming ``path`` for what SB3's ``load`` raised on a damaged zip: it raises
    KeyError, AssertionError, AttributeError, JSON or UnicodeDecodeErrors, or a ValueError of its
    own, none naming the file or the problem in the user's terms."""
    import zipfile

    if isinstance(exc.__cause__, zipfile.BadZipFile):
        return ValueError(f"{path}: not an SB3 zip: not a zip file")
    if isinstance(exc, json.JSONDecodeError):
        detail = f"its data entry is not valid JSON ({exc})"
    elif isinstance(exc, UnicodeDecodeError):
        detail = "its data entry is not UTF-8 text"
    elif isinstance(exc, RecursionError):
        detail = "its data entry is nested too deeply"
    else:
        text = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)  # KeyError quotes it
        detail = str(text) or type(exc).__name__
    detail = " ".join(detail.split())  # one line for the CLI's error line
    if len(detail) > 300:
        detail = detail[:297] + "..."
    return ValueError(f"{path}: cannot load it as an SB3 {algo} zip ({detail})")


def convert_run(directory: Path, env_id: str, algo: str, *, allow_pickle: bool = False,
                observations: int = 500, seed: int = 0) -> int:  # fmt: skip
    """Convert a run directory's SB3 ``model.zip`` to ``policy.json`` + ``policy.safetensors``
    and check that deterministic actions agree bit for bit on ``observations`` random ones
    (drawn from the normalization statistics). Unpickles the zip: needs ``allow_pickle=True``.
    The zip is left in place. Returns the number of observations compared."""
    directory = Path(directory)
    old = load_sb3_zip(directory / "model.zip", algo, allow_pickle=allow_pickle)
    save_policy(old.policy, algo, env_id, directory)
    new = load_policy(directory)
    stats = new.normalization
    rng = np.random.default_rng(seed)
    obs = stats.mean + np.sqrt(stats.var) * rng.standard_normal((observations, len(stats.mean))) * 2.0
    normalized = stats.normalize(obs)
    before, _ = old.policy.predict(normalized, deterministic=True)
    after, _ = new.policy.predict(normalized, deterministic=True)
    if before.shape != after.shape or before.tobytes() != after.tobytes():
        raise ValueError(f"{directory}: converted policy acts differently from model.zip")
    return observations


def _main(argv: list[str]) -> int:
    """``python -m agents.policy_zip RUN_DIR ... --allow-pickle``: convert old run directories."""
    from agents.sb3 import check_config, load_config

    dirs = [Path(a) for a in argv if a != "--allow-pickle"]
    if "--allow-pickle" not in argv or not dirs:
        print(f"usage: python -m agents.policy_zip RUN_DIR [...] --allow-pickle ({PICKLE_WARNING})",
              file=sys.stderr)  # fmt: skip
        return 2
    for directory in dirs:
        try:
            config = check_config(load_config(directory / "config.toml"), str(directory / "config.toml"))
            count = convert_run(directory, config["env"], config["algo"], allow_pickle=True)
        except ValueError as exc:  # a damaged zip, config or normalization: one line, as the CLI's
            print(f"error: {exc}", file=sys.stderr)
            return 2
        print(f"{directory}: wrote {POLICY_JSON} and {WEIGHTS}; actions bit-equal on {count} observations")
    return 0


if __name__ == "__main__":
    raise SystemExit(_main(sys.argv[1:]))
