"""Gymnasium environments on the identified rocket-hardware models."""

from ssme_envs.envs.engine_throttle import EngineThrottleEnv
from ssme_envs.envs.engine_tracking import EngineTrackingEnv
from ssme_envs.envs.launcher_pitch import LauncherPitchEnv
from ssme_envs.envs.nozzle_tvc import NozzleTVCEnv
from ssme_envs.envs.vector import (
    EngineThrottleVectorEnv,
    EngineTrackingVectorEnv,
    LauncherPitchVectorEnv,
    NozzleTVCVectorEnv,
    TrackingVectorEnv,
)

__all__ = [
    "EngineThrottleEnv",
    "EngineThrottleVectorEnv",
    "EngineTrackingEnv",
    "EngineTrackingVectorEnv",
    "LauncherPitchEnv",
    "LauncherPitchVectorEnv",
    "NozzleTVCEnv",
    "NozzleTVCVectorEnv",
    "TrackingVectorEnv",
]
