"""Gymnasium environments on the identified rocket-hardware models.

The env classes load on first access (``ssme_envs.envs.NozzleTVCEnv``), so that importing the
catalogue (:mod:`ssme_envs.envs.catalogue`) or one env module loads no other env's models.
"""

from __future__ import annotations

import importlib
from typing import Any

_HOMES = {
    "EngineThrottleEnv": "engine_throttle",
    "EngineTrackingEnv": "engine_tracking",
    "LauncherPitchEnv": "launcher_pitch",
    "NozzleTVCEnv": "nozzle_tvc",
    "EngineThrottleVectorEnv": "vector",
    "EngineTrackingVectorEnv": "vector",
    "LauncherPitchVectorEnv": "vector",
    "NozzleTVCVectorEnv": "vector",
    "TrackingVectorEnv": "vector",
}


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)


__all__ = sorted(_HOMES)
