"""The controller protocol, and what the controllers share: batching, the env's task, plant ports."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np

from ssme_envs.envs.nozzle_tvc import DEG  # degrees per radian, re-exported for the controllers

T = TypeVar("T")


@runtime_checkable
class Controller(Protocol):
    """A controller for one env or for a batch of envs stepped together.

    ``reset(seed, num_envs)`` starts new episodes (``envs``: only those batch entries);
    ``act(observation, info)`` maps an observation (obs_dim,) or a batch (num_envs, obs_dim) to
    actions in the env's action space, (act_dim,) or (num_envs, act_dim), float32.
    """

    name: str

    def reset(self, seed: int | None = None, num_envs: int = 1, envs: np.ndarray | None = None) -> None: ...

    def act(self, observation: np.ndarray, info: dict | None = None) -> np.ndarray: ...


def task_of(env: Any) -> Any:
    """The task behind a scalar env (through its wrappers) or a native vector env."""
    for candidate in (env, getattr(env, "unwrapped", None), getattr(env, "env", None)):
        task = getattr(candidate, "task", None)
        if task is not None:
            return task
    raise TypeError(f"{type(env).__name__} is not an ssme-envs environment (it has no task)")


def by_kind(table: Mapping[type, T], obj: Any, what: str) -> T:
    """The entry of ``table`` for the most specific class of ``obj`` that it holds (along the
    method resolution order), so that a subclass's own entry wins whatever the table's order;
    TypeError when none."""
    for kind in type(obj).__mro__:
        if kind in table:
            return table[kind]
    raise TypeError(f"no {what} for {type(obj).__name__}")


def env_id_of(env: Any) -> str:
    """The registered id of an ssme-envs env: the catalogue entry of its task."""
    from ssme_envs.envs.catalogue import entry_of_task

    return entry_of_task(task_of(env)).id


def columns(observation: Any, *names: str) -> tuple[int, ...]:
    """The columns of the named observation entries in a task's layout
    (:class:`~ssme_envs.envs.task.Observation`), so that no controller writes a column number."""
    return tuple(observation.index(name) for name in names)


@dataclass(frozen=True)
class Ports:
    """How a controller designed on a plant model reads and writes an env: the plant output y
    and reference r in the model's units from observation columns (times ``scale``), and the
    action as the plant input divided by ``input_scale`` (the action's full scale)."""

    output_columns: tuple[int, ...]
    reference_columns: tuple[int, ...]
    scale: float  # observation units per model unit (100 for %, 180/pi for deg)
    input_scale: float  # model input units per action unit

    def read(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """y and r, each (N, p), in model units (r = 0 without reference columns)."""
        y = obs[:, self.output_columns] / self.scale
        if not self.reference_columns:
            return y, np.zeros_like(y)
        return y, obs[:, self.reference_columns] / self.scale


class BatchController:
    """Base of the controllers: state arrays with a leading batch axis, sized at reset."""

    name = "controller"

    def __init__(self) -> None:
        self.num_envs = 0
        self.state: dict[str, np.ndarray] = {}

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        """The controller's state for n fresh episodes."""
        return {}

    def reset(self, seed: int | None = None, num_envs: int = 1, envs: np.ndarray | None = None) -> None:
        if envs is None:
            if not isinstance(num_envs, int) or num_envs < 1:
                raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
            self.num_envs = num_envs
            self.state = self.initial_state(num_envs)
            return
        envs = np.asarray(envs, dtype=np.intp)
        if self.num_envs == 0 or np.any((envs < 0) | (envs >= self.num_envs)):
            raise ValueError(
                f"{self.name}: reset(envs=...) needs indices into the {self.num_envs} envs of a "
                f"reset(num_envs=...) made before, got {envs.tolist()}"
            )
        fresh = self.initial_state(len(envs))
        for key, value in fresh.items():
            self.state[key][envs] = value

    def act(self, observation: np.ndarray, info: dict | None = None) -> np.ndarray:
        obs = np.asarray(observation, dtype=np.float64)
        single = obs.ndim == 1
        batch = obs[None] if single else obs
        if self.num_envs == 0:
            self.reset(num_envs=len(batch))
        if batch.ndim != 2 or len(batch) != self.num_envs:
            raise ValueError(
                f"{self.name}: expected observations of shape ({self.num_envs}, d) after "
                f"reset(num_envs={self.num_envs}), got {obs.shape}"
            )
        actions = np.clip(self.compute(batch), -1.0, 1.0).astype(np.float32)
        return actions[0] if single else actions

    def compute(self, obs: np.ndarray) -> np.ndarray:
        """Actions (N, act_dim), before clipping into [-1, 1], for observations (N, obs_dim)."""
        raise NotImplementedError


__all__ = ["DEG", "BatchController", "Controller", "Ports", "by_kind", "columns", "env_id_of", "task_of"]
