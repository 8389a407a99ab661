"""The optional compiled kernels: loaded where they were built and give their Python
references' bits on a check set at import, the references otherwise (or on request)."""

from __future__ import annotations

import importlib
import os
import warnings
from collections.abc import Callable
from typing import Any

NO_KERNEL = "SSME_ENVS_NO_KERNEL"  # set (not empty, not "0"): the references run, the same bits, slower


def references_requested() -> bool:
    """Whether :data:`NO_KERNEL` asks for the Python references (set, and not to "0")."""
    return os.environ.get(NO_KERNEL, "") not in ("", "0")


def load_kernel(name: str, agrees: Callable[[Any], bool], what: str) -> Any:
    """The compiled module ``ssme_envs.models.<name>`` where it was built and ``agrees(module)``;
    None otherwise (or where :data:`NO_KERNEL` is set), with a RuntimeWarning where it was built
    but differs (a compiler that fused or reordered operations, or a build of an older source).
    ``what`` names the kernel in the warning."""
    if references_requested():
        return None
    try:
        module = importlib.import_module(f"ssme_envs.models.{name}")
    except ImportError:
        return None
    try:
        same = agrees(module)
    except (AttributeError, TypeError, ValueError):  # a build of an older source: its calls differ
        same = False
    if not same:
        warnings.warn(
            f"ssme_envs: the compiled {what} kernel differs from its reference and is not used "
            "(rebuild it, `pip install .`, with a compiler that neither fuses multiply-adds nor "
            "uses fast math)",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    return module
