"""Gymnasium environments on the identified rocket-hardware models."""

from ssme_envs.envs.engine_tracking import EngineTrackingEnv
from ssme_envs.envs.vector import EngineTrackingVectorEnv

__all__ = ["EngineTrackingEnv", "EngineTrackingVectorEnv"]
