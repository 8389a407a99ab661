"""The catalogue of the package's environments: one entry per env id, the one list to read.

Registration (``import ssme_envs``), the benchmark, the zoo settings and the evaluation read the
env ids and their facts here. Importing this module imports no env: an entry names its task and
env classes by import path, loaded on first use, so that ``import ssme_envs`` stays light.

>>> from ssme_envs.envs import catalogue
>>> list(catalogue.ENVS)  # doctest: +NORMALIZE_WHITESPACE
['ssme_envs/EngineTracking-v0', 'ssme_envs/EngineThrottle-v0', 'ssme_envs/NozzleTVC-v0',
 'ssme_envs/LauncherPitch-v0']
>>> catalogue.spec("ssme_envs/NozzleTVC-v0").observation.names[0]
'angle_deg'
"""

from __future__ import annotations

import importlib
import inspect
from dataclasses import dataclass
from typing import Any


def _load(path: str) -> Any:
    """The object at ``"module:qualified.name"``."""
    module, _, name = path.partition(":")
    target: Any = importlib.import_module(module)
    for part in name.split("."):
        target = getattr(target, part)
    return target


@dataclass(frozen=True)
class EnvEntry:
    """One environment of the catalogue.

    Parameters
    ----------
    id : str
        The gymnasium id.
    task : str
        Import path of the task class (a :class:`~ssme_envs.envs.task.TrackingTask`), e.g.
        ``"ssme_envs.envs.engine_task:EngineTask"``.
    build : str
        Its classmethod that builds a task from the env's keyword options.
    max_episode_steps : int
        The registered time limit (the default episode's length).
    design_model : str
        Where a controller's design model comes from (``design="identified"``).
    entry_point, vector_entry_point : str or None
        Import paths of the scalar and native vector env classes; None: the generic
        :class:`~ssme_envs.envs.tracking_env.TrackingEnv` and
        :class:`~ssme_envs.envs.vector.TrackingVectorEnv` on the task.
    """

    id: str
    task: str
    build: str
    max_episode_steps: int
    design_model: str
    entry_point: str | None = None
    vector_entry_point: str | None = None

    @property
    def task_type(self) -> type:
        """The task class (imports its module)."""
        return _load(self.task)

    def build_task(self, **options: Any) -> Any:
        """The task of the env made with ``options`` (the env's keyword arguments)."""
        return getattr(self.task_type, self.build)(**options)

    @property
    def observation(self) -> Any:
        """The observation layout (:class:`~ssme_envs.envs.task.Observation`): names, units, bounds."""
        return self.task_type.observation

    @property
    def action_names(self) -> tuple[str, ...]:
        return self.task_type.action_names

    @property
    def default_options(self) -> dict[str, Any]:
        """The env's keyword options and their defaults (those of the task's constructor)."""
        parameters = inspect.signature(getattr(self.task_type, self.build)).parameters
        return {name: p.default for name, p in parameters.items() if p.default is not inspect.Parameter.empty}

    def env_class(self) -> type:
        """The scalar env class."""
        if self.entry_point is not None:
            return _load(self.entry_point)
        from ssme_envs.envs.tracking_env import TrackingEnv

        return type(
            self.id.rsplit("/", 1)[-1].replace("-", "_"), (TrackingEnv,), {"build_task": self.build_task}
        )

    def vector_env_class(self) -> type:
        """The native vector env class."""
        if self.vector_entry_point is not None:
            return _load(self.vector_entry_point)
        from ssme_envs.envs.vector import TrackingVectorEnv

        name = self.id.rsplit("/", 1)[-1].replace("-", "_") + "_vector"
        return type(name, (TrackingVectorEnv,), {"build_task": self.build_task})


_ENGINE_DESIGN = (
    "the identified point model at the nearest Table I power (models/data/engine_identified_*.json)"
)
_NOZZLE_DESIGN = "the identified nozzle joint (models/data/nozzle_identified.json)"

ENVS: dict[str, EnvEntry] = {
    entry.id: entry
    for entry in (
        EnvEntry(
            "ssme_envs/EngineTracking-v0", "ssme_envs.envs.engine_task:EngineTask", "build", 250,
            _ENGINE_DESIGN, "ssme_envs.envs.engine_tracking:EngineTrackingEnv",
            "ssme_envs.envs.vector:EngineTrackingVectorEnv",
        ),
        EnvEntry(
            "ssme_envs/EngineThrottle-v0", "ssme_envs.envs.engine_throttle:ThrottleTask", "build_throttle",
            1500, _ENGINE_DESIGN + ", scheduled on power", "ssme_envs.envs.engine_throttle:EngineThrottleEnv",
            "ssme_envs.envs.vector:EngineThrottleVectorEnv",
        ),
        EnvEntry(
            "ssme_envs/NozzleTVC-v0", "ssme_envs.envs.nozzle_task:NozzleTask", "build", 500, _NOZZLE_DESIGN,
            "ssme_envs.envs.nozzle_tvc:NozzleTVCEnv", "ssme_envs.envs.vector:NozzleTVCVectorEnv",
        ),
        EnvEntry(
            "ssme_envs/LauncherPitch-v0", "ssme_envs.envs.launcher_pitch:LauncherTask", "build_launcher",
            500, "the rigid body's mu_a and mu_c (the servoed nozzle taken as ideal)",
            "ssme_envs.envs.launcher_pitch:LauncherPitchEnv", "ssme_envs.envs.vector:LauncherPitchVectorEnv",
        ),
    )
}  # fmt: skip


def spec(env_id: str) -> EnvEntry:
    """The catalogue entry of ``env_id`` (ValueError naming the known ids if none)."""
    try:
        return ENVS[env_id]
    except KeyError:
        raise ValueError(f"unknown env id {env_id!r}; the catalogue has {', '.join(ENVS)}") from None


def entry_of_task(task: Any) -> EnvEntry:
    """The catalogue entry whose task class is exactly ``task``'s (ValueError if none)."""
    for entry in ENVS.values():
        if entry.task_type is type(task):
            return entry
    raise ValueError(f"no env of the catalogue has a {type(task).__name__}")


def register(entry: EnvEntry) -> None:
    """Add ``entry`` to the catalogue and to gymnasium's registry (again: replaced)."""
    from gymnasium.envs.registration import register as gym_register
    from gymnasium.envs.registration import registry

    ENVS[entry.id] = entry
    registry.pop(entry.id, None)
    gym_register(
        id=entry.id,
        entry_point=entry.entry_point or entry.env_class(),
        vector_entry_point=entry.vector_entry_point or entry.vector_env_class(),
        max_episode_steps=entry.max_episode_steps,
    )


def register_all() -> None:
    """Register every env of the catalogue with gymnasium (once)."""
    from gymnasium.envs.registration import registry

    for entry in ENVS.values():
        if entry.id not in registry:
            register(entry)


__all__ = ["ENVS", "EnvEntry", "entry_of_task", "register", "register_all", "spec"]
