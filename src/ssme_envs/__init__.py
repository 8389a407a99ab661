"""ssme-envs: identified SSME and movable-nozzle models, and Gymnasium environments on them."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("ssme-envs")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0"


def _register() -> None:
    from gymnasium.envs.registration import register, registry

    if "ssme_envs/EngineTracking-v0" in registry:
        return
    register(
        id="ssme_envs/EngineTracking-v0",
        entry_point="ssme_envs.envs.engine_tracking:EngineTrackingEnv",
        vector_entry_point="ssme_envs.envs.vector:EngineTrackingVectorEnv",
        max_episode_steps=250,
    )
    register(
        id="ssme_envs/EngineThrottle-v0",
        entry_point="ssme_envs.envs.engine_throttle:EngineThrottleEnv",
        vector_entry_point="ssme_envs.envs.vector:EngineThrottleVectorEnv",
        max_episode_steps=1500,
    )
    register(
        id="ssme_envs/NozzleTVC-v0",
        entry_point="ssme_envs.envs.nozzle_tvc:NozzleTVCEnv",
        vector_entry_point="ssme_envs.envs.vector:NozzleTVCVectorEnv",
        max_episode_steps=500,
    )
    register(
        id="ssme_envs/LauncherPitch-v0",
        entry_point="ssme_envs.envs.launcher_pitch:LauncherPitchEnv",
        vector_entry_point="ssme_envs.envs.vector:LauncherPitchVectorEnv",
        max_episode_steps=500,
    )


_register()

__all__ = ["__version__"]
